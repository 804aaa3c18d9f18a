"""The valve-train model: parameters, presets, element and system matrices (thesis Ch. II)."""

from campipe.model.assembly import (
    COORDINATES,
    SystemMatrices,
    assemble,
    configuration_frequencies,
    modal_damping,
    newmark_linear_stability_limit,
    normal_modes,
    system_matrices,
    to_display_units,
)
from campipe.model.parameters import (
    ELEMENTS,
    PARAMETERS,
    PRESETS,
    ModelParameterError,
    ValveTrain,
    parse_parameter,
    thesis_train,
    valve_train,
)

__all__ = [
    "COORDINATES",
    "ELEMENTS",
    "PARAMETERS",
    "PRESETS",
    "ModelParameterError",
    "SystemMatrices",
    "ValveTrain",
    "assemble",
    "configuration_frequencies",
    "modal_damping",
    "newmark_linear_stability_limit",
    "normal_modes",
    "parse_parameter",
    "system_matrices",
    "thesis_train",
    "to_display_units",
    "valve_train",
]
