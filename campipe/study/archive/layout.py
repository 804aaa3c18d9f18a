"""What goes into the archive (and a batch file): sizes, variables, axes and per-case
coordinates, all built from the declarations in :mod:`campipe.study.spec.variables`. What names
a run's results (the keys, the attributes that record them) is
:mod:`campipe.study.run.keys`'s."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from campipe.io.archive import VariableSpec
from campipe.study.spec.expand import Study
from campipe.study.spec.resolve import ResolvedCase
from campipe.study.spec.variables import (
    DOF_NAMES,
    DOF_UNITS,
    NO_SEAT,
    VARIABLES,
    Variable,
    case_coordinates,
    data_variables,
)

#: Version of the file layout: batch files and archives of another layout are not reused.
#: 2: per-case ``status``; checksums of every variable (``campipe_checksums``); the engine's
#: fingerprint (``campipe_numerics``); the spec's file (``spec_file``).
#: 3: the case ids are the coordinate ``case`` of the ``case`` dimension (was ``case_id``);
#: no seat is ``seat = -inf`` (was NaN).
LAYOUT_VERSION = "campipe-archive-3"


#: The variable along ``case`` holding each case's id, in batch files and the archive: named
#: here only.
CASE_ID = "case"


def record_text(record: Iterable[str]) -> str:
    return " ".join(record) or "-"


def variable_spec(name: str, var: Variable, coordinates: str | None = None) -> VariableSpec:
    attrs = var.attrs()
    if coordinates:
        attrs["coordinates"] = coordinates
    return VariableSpec(name, var.dims, var.dtype, attrs)


def axis_names(record: Iterable[str]) -> list[str]:
    names = ["cam_angle", "revolution"]
    if "q" in record:
        names += ["dof", "dof_units"]
    return names


def axis_arrays(cam_angle: np.ndarray, n_revolutions: int) -> dict[str, np.ndarray]:
    return {
        "cam_angle": cam_angle,
        "revolution": np.arange(1, n_revolutions + 1, dtype=np.int32),
        "dof": np.array(DOF_NAMES, dtype=object),
        "dof_units": np.array(DOF_UNITS, dtype=object),
    }


def data_specs(record: Iterable[str], case_coords: str) -> list[VariableSpec]:
    out = []
    for name, var in data_variables(record).items():
        coords = (
            case_coords
            if "case" in var.dims
            else ("event_case" if name != "event_case" and "event" in var.dims else None)
        )
        out.append(variable_spec(name, var, coords))
    return out


def coordinate_values(cases: Sequence[ResolvedCase], study: Study) -> dict[str, np.ndarray]:
    """Per-case coordinate arrays in archive units, in study order: ``case`` (the ids), then
    each case coordinate (no seat as :data:`~campipe.study.spec.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {CASE_ID: np.array([c.case_id for c in cases], dtype=object)}
    return {**out, **key_columns(cases, case_coordinates(study.varied))}


def key_columns(
    cases: Sequence[ResolvedCase], coordinates: Mapping[str, tuple[str, Variable, float]]
) -> dict[str, np.ndarray]:
    """The case coordinates ``coordinates`` names (spec key → (name, variable, factor), as
    :func:`~campipe.study.spec.variables.case_coordinates` gives them), each an array in archive
    units over ``cases`` (no seat as :data:`~campipe.study.spec.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {}
    for key, (name, var, factor) in coordinates.items():
        raw = [c.values[key] for c in cases]
        if var.dtype == "str":
            out[name] = np.array([str(v) for v in raw], dtype=object)
        elif var.dtype.startswith("i"):
            out[name] = np.array(raw, dtype=var.dtype)
        elif "mode" in var.dims:
            # a list per case (damping_ratios), as long as the longest, NaN beyond a shorter
            lists = [np.asarray(v, dtype=float) for v in raw]
            values = np.full((len(lists), max(v.size for v in lists)), np.nan)
            for i, v in enumerate(lists):
                values[i, : v.size] = v
            out[name] = values * factor
        else:
            values = np.array(raw, dtype=float) * factor
            if key == "speed":
                # rpm from rad/s: round away the conversion's last-digit noise (11000 rpm
                # stays 11000, so `--where "speed_rpm == 11000"` finds it)
                values = np.array([float(f"{v:.12g}") for v in values])
            if key == "seat":
                values = np.where(np.isnan(values), NO_SEAT, values)
            out[name] = values
    return out


def archive_layout(study: Study, n_events: int | None, cam_angle: np.ndarray, n_revolutions: int):
    """(sizes, variables, static arrays) of the study's archive; the static arrays are the
    axes and the per-case coordinates, the rest streams in from batch files. ``n_events``
    None makes ``event`` unlimited: the events are appended as the cases are written."""
    coords = case_coordinates(study.varied)
    coord_names = [name for name, _, _ in coords.values()]
    sizes: dict[str, int | None] = {
        "case": len(study.cases),
        "cam_angle": cam_angle.size,
        "revolution": n_revolutions,
        "event": n_events,
    }
    if "q" in study.record:
        sizes["dof"] = len(DOF_NAMES)
    specs = [variable_spec(n, VARIABLES[n]) for n in axis_names(study.record)]
    specs.append(variable_spec(CASE_ID, VARIABLES[CASE_ID]))
    values = coordinate_values(study.cases, study)
    for _key, (name, var, _) in coords.items():
        if "mode" in var.dims:
            sizes["mode"] = values[name].shape[1]
        specs.append(variable_spec(name, var))
    specs += data_specs(study.record, " ".join(coord_names))
    static = {**axis_arrays(cam_angle, n_revolutions), **values}
    static = {s.name: static[s.name] for s in specs if s.name in static}
    return sizes, specs, static
