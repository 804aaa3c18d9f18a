"""JSON Schema of the model parameters, generated from the one declaration in ``PARAMETERS``.

``schemas/model.schema.json`` is this function's output (a test keeps the two equal); the
study schema refers to it for the ``model:`` block.
"""

from __future__ import annotations

from campipe.model.parameters import PARAMETERS, PRESETS

QUANTITY_PATTERN = r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[A-Za-z°µ][A-Za-z0-9_*/ ^°µ.()-]*$"


def parameter_schema(name: str) -> dict[str, object]:
    """The schema of one model parameter's value."""
    p = PARAMETERS[name]
    if p.length:
        return {
            "type": "array",
            "items": {"type": "number", "minimum": p.minimum},
            "minItems": p.length,
            "maxItems": p.length,
            "description": p.long_name,
        }
    return {
        "type": "string",
        "pattern": QUANTITY_PATTERN,
        "description": f"{p.long_name}, a quantity with units, e.g. '1 {p.thesis_units}'",
    }


def model_schema() -> dict[str, object]:
    """The schema of a ``model:`` block: a preset plus any parameter by name."""
    properties: dict[str, object] = {
        "preset": {"enum": sorted(PRESETS), "description": "named parameter set"},
    }
    for name in PARAMETERS:
        properties[name] = parameter_schema(name)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://campipe.example/schemas/model.schema.json",
        "title": "campipe valve-train model",
        "type": "object",
        "properties": properties,
        "additionalProperties": False,
    }
