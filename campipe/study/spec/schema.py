"""JSON Schema of a study spec, generated from the key table (:mod:`campipe.study.spec.fields`)
and the model's own schema (:func:`campipe.model.schema.model_schema`).

``schemas/study.schema.json`` is this module's output (a test keeps the two equal);
regenerate it with ``python -m campipe.study.spec.schema > schemas/study.schema.json``.

The schema checks a spec's shape (keys, types, quantities written with units, enumerations);
:func:`campipe.study.spec.check.check_spec` checks the rest (units of the right dimension, ranges,
a seat below full lift, the step limit) and names the key path of every problem.
"""

from __future__ import annotations

import json

from campipe.model import PARAMETERS
from campipe.model.schema import QUANTITY_PATTERN, model_schema, parameter_schema
from campipe.study.spec.check import NAME_PATTERN
from campipe.study.spec.design import DESIGN_KEYS, ENGINE_ONSET, METHODS, ONSET, metric_units
from campipe.study.spec.drive import DRIVE_FIELDS
from campipe.study.spec.fields import (
    CASE_FIELDS,
    CASE_KEYS,
    DEFECT_FIELDS,
    DEFECT_KINDS,
    ENGINE_SPEED,
    PROFILE_FIELDS,
    PROFILE_KINDS,
    PROFILE_OPTIONAL,
    SAMPLE_METHODS,
    SEARCHES,
    STUDY_WIDE,
    TOP_LEVEL,
    WHOLE_KEYS,
    Field,
    sample_keys,
    sweep_keys,
    varied_fields,
)
from campipe.study.spec.plots import ANGLES as PLOT_ANGLES
from campipe.study.spec.plots import COMMON_KEYS as PLOT_COMMON_KEYS
from campipe.study.spec.plots import KIND_KEYS as PLOT_KIND_KEYS
from campipe.study.spec.plots import KINDS as PLOT_KINDS
from campipe.study.spec.plots import SYSTEMS

SCHEMA_ID = "https://campipe.example/schemas/study.schema.json"


def field_schema(f: Field) -> dict[str, object]:
    """The schema of one key's value."""
    if f.kind == "parameter":
        return parameter_schema(f.key.removeprefix("model."))
    if f.kind == "quantity":
        out: dict[str, object] = {
            "type": "string",
            "pattern": QUANTITY_PATTERN,
            "description": f"{f.description}, a quantity with units, e.g. '1 {f.example}'",
        }
        words = (["none"] if f.allow_none else []) + (["default"] if f.allow_default else [])
        if words:
            alternatives: list[object] = [{"enum": words}, out]
            if f.allow_none:
                alternatives.insert(1, {"type": "null"})
            return {"anyOf": alternatives, "description": out.pop("description")}
        return out
    if f.kind in ("number", "integer"):
        out = {"type": f.kind, "description": f.description}
        if f.minimum is not None:
            out["exclusiveMinimum" if f.exclusive_minimum else "minimum"] = f.minimum
        if f.allow_default or f.allow_auto:  # run.warmup: default; run.revolutions: auto
            word = "default" if f.allow_default else "auto"
            return {"anyOf": [{"enum": [word]}, out], "description": out.pop("description")}
        return out
    if f.kind == "choice":
        return {"enum": list(f.choices), "description": f.description}
    if f.kind == "text":
        return {"type": "string", "minLength": 1, "description": f.description}
    if f.kind == "record":
        return {
            "type": "array",
            "items": {"enum": list(f.choices)},
            "uniqueItems": True,
            "description": f.description,
        }
    raise AssertionError(f.kind)


def _one_of_kinds(
    kinds: dict, fields: dict, optional: dict | None = None
) -> list[dict[str, object]]:
    """A profile or defect: one object per kind, with that kind's keys (``kinds[kind]``), all
    required, and its ``optional`` ones."""
    optional = optional or {}
    return [
        {
            "type": "object",
            "properties": {
                "kind": {"const": kind},
                **{k: field_schema(fields[k]) for k in keys + optional.get(kind, ())},
            },
            "required": ["kind", *keys],
            "additionalProperties": False,
        }
        for kind, keys in kinds.items()
    ]


def _run(study_wide: bool) -> dict[str, object]:
    keys = [k for k in CASE_FIELDS if k.startswith("run.") and (study_wide or k not in STUDY_WIDE)]
    return {
        "type": "object",
        "properties": {k.removeprefix("run."): field_schema(CASE_FIELDS[k]) for k in keys},
        "additionalProperties": False,
        "description": TOP_LEVEL["run"]
        if study_wide
        else "run settings of this case (the study-wide revolutions, output_every and record "
        "are set in the base)",
    }


def _case(patch: bool) -> dict[str, object]:
    props: dict[str, object] = {
        "model": {"$ref": "#/$defs/model"},
        "profile": {"$ref": "#/$defs/profile_patch" if patch else "#/$defs/profile"},
        "defects": {"$ref": "#/$defs/defects"},
        "closure": {"$ref": "#/$defs/closure"},
        "seat": {"$ref": "#/$defs/seat"},
        "speed": {"$ref": "#/$defs/speed"},
        "run": {"$ref": "#/$defs/case_run" if patch else "#/$defs/run"},
    }
    assert list(props) == list(CASE_KEYS)
    return props


def _value(key: str) -> dict[str, object]:
    """A reference to the schema of a case key's value (each declared once in $defs)."""
    if key in WHOLE_KEYS:
        return {"$ref": f"#/$defs/{key}"}
    head, _, rest = key.partition(".")
    if head == "model":
        return {"$ref": f"#/$defs/model/properties/{rest}"}
    if head == "profile":
        return {"$ref": f"#/$defs/profile_patch/properties/{rest}"}
    if head == "run":
        return {"$ref": f"#/$defs/run/properties/{rest}"}
    return {"$ref": f"#/$defs/{key}"}


def _parameter_number(key: str) -> bool:
    """``key`` is a model parameter that is a plain number (a loss factor)."""
    p = PARAMETERS[key.removeprefix("model.")]
    return p.continuous and not p.units


def _range(key: str, with_num: bool) -> dict[str, object] | None:
    """A {from, to[, num]} range of a scalar quantity, or None where none applies."""
    f = varied_fields().get(key)
    if f is not None and f.kind == "parameter" and not f.units and _parameter_number(key):
        return _range_object({"type": "number"}, with_num)
    scalar = f is not None and (
        f.kind == "quantity"
        or (f.kind == "parameter" and f.units and not f.key.endswith("damping_ratios"))
    )
    if not scalar:
        return None
    return _range_object({"$ref": "#/$defs/quantity"}, with_num)


def _range_object(bound: dict[str, object], with_num: bool) -> dict[str, object]:
    """{from, to[, num]}, ``from`` and ``to`` each matching ``bound``."""
    props: dict[str, object] = {"from": bound, "to": bound}
    if with_num:
        props["num"] = {"type": "integer", "minimum": 1}
    return {
        "type": "object",
        "properties": props,
        "required": list(props),
        "additionalProperties": False,
    }


def _axes(description: str) -> dict[str, object]:
    props = {}
    for key in sweep_keys():
        listed = {"type": "array", "minItems": 1, "items": _value(key)}
        rng = _range(key, True)
        props[key] = {"oneOf": [listed, rng]} if rng else listed
    return {
        "type": "object",
        "minProperties": 1,
        "properties": props,
        "additionalProperties": False,
        "description": description,
    }


def _plot(kind: str) -> dict[str, object]:
    """The schema of one ``plots:`` entry of ``kind``."""
    text = {"type": "string", "minLength": 1}
    keys: dict[str, object] = {
        "kind": {"const": kind, "description": PLOT_KINDS[kind]},
        "where": {**text, "description": "the cases to draw (the --where language)"},
        "units": {"enum": list(SYSTEMS), "description": "unit system of the values shown"},
        "output": {
            "type": "string",
            "pattern": r"\.(png|svg|pdf|PNG|SVG|PDF)$",
            "description": "file to write, relative to the archive's folder",
        },
        "x": {**text, "description": "column along x"},
        "y": {**text, "description": "metric: the value drawn; map: the column along y"},
        "z": {**text, "description": "the value coloured"},
        "level": {
            "anyOf": [{"type": "number"}, {"type": "string", "pattern": QUANTITY_PATTERN}],
            "description": "the contour's level: a number in the shown units, or a quantity",
        },
        "turn": {
            "anyOf": [{"type": "integer", "minimum": 1}, {"enum": ["last", "all"]}],
            "description": "the cam turn shown (default: all)",
        },
        "angle": {
            "enum": list(PLOT_ANGLES),
            "description": "the angle along x: the cam's (default) or the crank's (with drive)",
        },
        "range": {
            "anyOf": [
                {"type": "string", "minLength": 3},
                {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
            ],
            "description": "the angles shown, LO:HI in degrees of the angle along x",
        },
        "limit": {
            "anyOf": [
                {"type": "number"},
                {"type": "string", "pattern": QUANTITY_PATTERN},
                {
                    "type": "array",
                    "items": {
                        "anyOf": [
                            {"type": "number"},
                            {"type": "string", "pattern": QUANTITY_PATTERN},
                        ]
                    },
                },
            ],
            "description": "limit lines across the plot at these values of y (a number in "
            "the shown units, or a quantity)",
        },
    }
    allowed = (*PLOT_COMMON_KEYS, *PLOT_KIND_KEYS[kind])
    return {
        "type": "object",
        "properties": {k: v for k, v in keys.items() if k in allowed},
        "required": ["kind"],
        "additionalProperties": False,
    }


def _design() -> dict[str, object]:
    """The ``design:`` section (:mod:`campipe.study.spec.design`)."""
    vary = {}
    for k in sample_keys():
        rng = _range(k, False)
        if k != "speed" and rng is not None:
            bound = rng["properties"]["from"]  # type: ignore[index]
            props = {**rng["properties"], "tolerance": bound}  # type: ignore[dict-item]
            vary[k] = {**rng, "properties": props}
    bounded = {"min": {"$ref": "#/$defs/quantity"}, "max": {"$ref": "#/$defs/quantity"}}
    speeds = {"oneOf": [{"$ref": "#/$defs/quantity"}, {"type": "array", "minItems": 1,
              "items": {"$ref": "#/$defs/quantity"}}]}  # fmt: skip
    onset = {
        "type": "object",
        "properties": {**bounded, "level": {"$ref": "#/$defs/quantity"}},
        "minProperties": 1,
        "additionalProperties": False,
    }
    require: dict[str, object] = {
        ONSET: onset,
        ENGINE_ONSET: {**onset, "description": "the onset at the engine's speed (a drive)"},
    }
    for name, units in metric_units().items():
        bound = {"$ref": "#/$defs/quantity"} if units else {"type": "number"}
        props = {"min": bound, "max": bound, "at": speeds, "at_engine": speeds}
        require[name] = {"type": "object", "properties": props, "additionalProperties": False,
                         "oneOf": [{"required": ["at"]}, {"required": ["at_engine"]}]}  # fmt: skip
    one = {"type": "string", "minLength": 1}
    key = {"oneOf": [one, {"type": "array", "items": one, "minItems": 1, "maxItems": 2}]}
    return {
        "type": "object",
        "properties": {
            "vary": {
                "type": "object",
                "minProperties": 1,
                "properties": vary,
                "additionalProperties": False,
                "description": DESIGN_KEYS["vary"],
            },
            "require": {
                "type": "object",
                "minProperties": 1,
                "properties": require,
                "additionalProperties": False,
                "description": DESIGN_KEYS["require"],
            },
            "minimize": {**key, "description": DESIGN_KEYS["minimize"]},
            "maximize": {**key, "description": DESIGN_KEYS["maximize"]},
            "method": {"enum": list(METHODS), "description": DESIGN_KEYS["method"]},
            "max_evaluations": {
                "type": "integer",
                "minimum": 2,
                "description": DESIGN_KEYS["max_evaluations"],
            },
        },  # fmt: skip
        "required": ["vary", "require"],
        "oneOf": [{"required": ["minimize"]}, {"required": ["maximize"]}],
        "additionalProperties": False,
        "description": TOP_LEVEL["design"],
    }


def study_schema() -> dict[str, object]:
    """The JSON Schema of a study spec."""
    model = {k: v for k, v in model_schema().items() if k not in ("$schema", "$id")}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "campipe study spec",
        "type": "object",
        "required": ["name"],
        "properties": {
            "name": {"type": "string", "pattern": NAME_PATTERN, "description": TOP_LEVEL["name"]},
            "description": {"type": "string", "description": TOP_LEVEL["description"]},
            **_case(patch=False),
            "engine_speed": {"$ref": "#/$defs/engine_speed"},
            "drive": {
                "type": "object",
                "properties": {k: field_schema(f) for k, f in DRIVE_FIELDS.items()},
                "required": list(DRIVE_FIELDS),
                "additionalProperties": False,
                "description": TOP_LEVEL["drive"],
            },
            "sweep": {"$ref": "#/$defs/axes", "description": TOP_LEVEL["sweep"]},
            "zip": {"$ref": "#/$defs/axes", "description": TOP_LEVEL["zip"]},
            "cases": {
                "type": "array",
                "minItems": 1,
                "items": {"$ref": "#/$defs/case"},
                "description": TOP_LEVEL["cases"],
            },
            "sample": {
                "type": "object",
                "properties": {
                    "method": {"enum": list(SAMPLE_METHODS)},
                    "n": {"type": "integer", "minimum": 1},
                    "seed": {"type": "integer", "minimum": 0},
                    "ranges": {
                        "type": "object",
                        "minProperties": 1,
                        "properties": {k: _range(k, False) for k in sample_keys()},
                        "additionalProperties": False,
                    },
                },
                "required": ["method", "n", "seed", "ranges"],
                "additionalProperties": False,
                "description": TOP_LEVEL["sample"],
            },
            "replay": {
                "type": "object",
                "properties": {"where": {"type": "string", "minLength": 1}},
                "required": ["where"],
                "additionalProperties": False,
                "description": TOP_LEVEL["replay"],
            },
            "plots": {
                "type": "array",
                "items": {"oneOf": [_plot(kind) for kind in PLOT_KINDS]},
                "description": TOP_LEVEL["plots"],
            },
            "search": {
                "type": "object",
                "properties": {k: {"enum": list(v)} for k, v in SEARCHES.items()},
                "required": ["onset"],
                "additionalProperties": False,
                "description": TOP_LEVEL["search"],
            },
            "design": _design(),
        },
        "additionalProperties": False,
        "$defs": {
            "model": {**model, "description": TOP_LEVEL["model"]},
            "profile": {
                "oneOf": _one_of_kinds(PROFILE_KINDS, PROFILE_FIELDS, PROFILE_OPTIONAL),
                "description": TOP_LEVEL["profile"],
            },
            "profile_patch": {
                "type": "object",
                "properties": {
                    "kind": {"enum": list(PROFILE_KINDS)},
                    **{k: field_schema(f) for k, f in PROFILE_FIELDS.items()},
                },
                "additionalProperties": False,
                "description": "profile keys merged over the base's (a new kind replaces it)",
            },
            "defects": {
                "type": "array",
                "items": {"oneOf": _one_of_kinds(DEFECT_KINDS, DEFECT_FIELDS)},
                "description": TOP_LEVEL["defects"],
            },
            **{k: field_schema(CASE_FIELDS[k]) for k in ("closure", "seat", "speed")},
            "engine_speed": field_schema(ENGINE_SPEED),
            "quantity": {
                "type": "string",
                "pattern": QUANTITY_PATTERN,
                "description": "a quantity with units, e.g. '9000 rpm'",
            },
            "axes": _axes("key → list of values or {from, to, num}"),
            "run": _run(study_wide=True),
            "case_run": _run(study_wide=False),
            "case": {
                "type": "object",
                "properties": {
                    **_case(patch=True),
                    "engine_speed": {"$ref": "#/$defs/engine_speed"},
                },
                "additionalProperties": False,
                "description": TOP_LEVEL["cases"],
            },
        },
    }


def schema_text() -> str:
    """The schema file's text."""
    return json.dumps(study_schema(), indent=2, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    print(schema_text(), end="")
