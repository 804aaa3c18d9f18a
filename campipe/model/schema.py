"""JSON Schema of the model parameters, generated from the one declaration in ``PARAMETERS``.

``schemas/model.schema.json`` is this function's output (a test keeps the two equal); the
study schema refers to it for the ``model:`` block. Regenerate it with

    python -m campipe.model.schema > schemas/model.schema.json
"""

from __future__ import annotations

import json

from campipe.model.parameters import PARAMETERS, PRESETS

QUANTITY_PATTERN = r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[A-Za-z°µ][A-Za-z0-9_*/ ^°µ.()-]*$"


def parameter_schema(name: str) -> dict[str, object]:
    """The schema of one model parameter's value."""
    p = PARAMETERS[name]
    if p.choices:
        return {"enum": list(p.choices), "description": p.long_name}
    if p.integer:
        return {
            "type": "integer",
            "minimum": int(p.minimum),
            "maximum": int(p.maximum),
            "description": p.long_name,
        }
    number: dict[str, object] = {"type": "number", "minimum": p.minimum}
    quantity = {"type": "string", "pattern": QUANTITY_PATTERN}
    if p.length:
        return {
            "type": "array",
            "items": quantity if p.units else number,
            "minItems": p.min_length,
            **({"maxItems": p.length} if p.units else {}),
            "description": p.long_name
            + (f", each a quantity with units, e.g. '1 {p.thesis_units}'" if p.units else ""),
        }
    if not p.units:
        return {**number, "description": p.long_name}
    example = f"a quantity with units, e.g. '1 {p.thesis_units}'"
    if p.allow_none:
        return {
            "anyOf": [quantity, {"const": "none"}, {"type": "null"}],
            "description": f"{p.long_name}; {example}, or none",
        }
    return {**quantity, "description": f"{p.long_name}, {example}"}


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


def schema_text() -> str:
    """The schema file's text."""
    return json.dumps(model_schema(), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    print(schema_text(), end="")
