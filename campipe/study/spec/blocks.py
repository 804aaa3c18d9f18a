"""The blocks of a spec checked one by one: a case's profile, defects, model and run, the
axes (sweep, zip, ranges), the case entries and the sampled design; each problem with its key
path (:mod:`campipe.study.spec.check` puts them together)."""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from campipe.errors import did_you_mean, excerpt
from campipe.model import PARAMETERS
from campipe.study.spec.fields import (
    CASE_FIELDS,
    CASE_KEYS,
    DEFECT_FIELDS,
    DEFECT_KINDS,
    PROFILE_FIELDS,
    PROFILE_KINDS,
    PROFILE_OPTIONAL,
    SAMPLE_METHODS,
    STUDY_WIDE,
    WHOLE_KEYS,
    Field,
    SpecProblem,
    sample_keys,
    sweep_keys,
    varied_fields,
)

#: Longest axis (a range's num, a sample's n) by default: also the default limit on cases
#: (campipe.study.spec.limits), so one axis alone never exceeds it.
MAX_AXIS_LENGTH = 100_000

T = TypeVar("T")


@dataclass(frozen=True)
class Sample:
    """A sampled design over ranges of scalar keys."""

    method: str  # one of SAMPLE_METHODS
    n: int  # number of points
    seed: int  # seed of the generator: the same seed gives the same points
    ranges: dict[str, tuple[float, float]]  # key → (from, to) in SI
    #: key → (from, to) as the spec wrote them ("200 lbf/in"), for the words that show them
    written: dict[str, tuple[str, str]] = field(default_factory=dict)


class Problems:
    """Collects problems; ``check`` runs one check and keeps its problem."""

    def __init__(self) -> None:
        self.items: list[SpecProblem] = []

    def add(self, path: str, message: str) -> None:
        self.items.append(SpecProblem(path, message))

    def check(self, fn: Callable[..., T], *args: object) -> T | None:
        try:
            return fn(*args)
        except SpecProblem as exc:
            self.items.append(exc)
            return None


def join(path: str, key: str | int) -> str:
    """``join("cases[1]", "seat") == "cases[1].seat"``; ints index lists."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


def as_mapping(value: object, path: str, what: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise SpecProblem(path, f"found {show(value)}, expected a mapping ({what})")
    for k in value:
        if not isinstance(k, str):
            raise SpecProblem(path, f"found the key {excerpt(k)}, expected keys that are strings")
    return value


def show(value: object) -> str:
    return excerpt(value)


def unknown_key(path: str, key: str, known) -> SpecProblem:
    known = list(known)
    listing = ", ".join(known) if len(known) <= 16 else ", ".join(known[:16]) + ", ..."
    return SpecProblem(
        join(path, key),
        f"unknown key {excerpt(key)}{did_you_mean(key, known)} (expected one of: {listing})",
    )


# -- blocks of a case ---------------------------------------------------------------------


def check_profile(value: object, path: str, partial: bool) -> dict:
    """A profile mapping; ``partial`` (a case entry merging over the base) needs no kind."""
    value = as_mapping(value, path, "a cam profile such as {kind: harmonic, lift: 1 in}")
    known = ("kind", *PROFILE_FIELDS)
    for k in value:
        if k not in known:
            raise unknown_key(path, k, known)
    kind = value.get("kind")
    if kind is None and not partial:
        raise SpecProblem(
            join(path, "kind"), "missing; expected one of: " + ", ".join(PROFILE_KINDS)
        )
    if kind is not None and (not isinstance(kind, str) or kind not in PROFILE_KINDS):
        raise SpecProblem(
            join(path, "kind"),
            f"found {excerpt(kind)}, expected one of: {', '.join(PROFILE_KINDS)}"
            + did_you_mean(kind, PROFILE_KINDS),
        )
    if kind is not None:
        keys = PROFILE_KINDS[kind]
        allowed = keys + PROFILE_OPTIONAL.get(kind, ())
        for k in value:
            if k != "kind" and k not in allowed:
                raise SpecProblem(
                    join(path, k),
                    f"not a key of a {kind} profile (its keys: {', '.join(allowed)})",
                )
        if not partial:
            for k in keys:
                if k not in value:
                    raise SpecProblem(
                        join(path, k), f"missing; a {kind} profile needs " + ", ".join(keys)
                    )
    for k, v in value.items():
        if k != "kind":
            PROFILE_FIELDS[k].parse(v, join(path, k))
    if not partial and ("ramp_height" in value) != ("ramp_duration" in value):
        given, missing = (
            ("ramp_height", "ramp_duration")
            if "ramp_height" in value
            else ("ramp_duration", "ramp_height")
        )
        raise SpecProblem(join(path, missing), f"missing; a ramp needs {missing} with {given}")
    if not partial and "ramp_shape" in value and "ramp_height" not in value:
        raise SpecProblem(
            join(path, "ramp_shape"),
            "a ramp shape without a ramp: add ramp_height and ramp_duration",
        )
    return dict(value)


def check_defects(value: object, path: str) -> list:
    if not isinstance(value, list):
        raise SpecProblem(
            path,
            f"found {show(value)}, expected a list of defects such as "
            "[{kind: flat, from: 268 deg, to: 272 deg}] (or [])",
        )
    for i, d in enumerate(value):
        p = join(path, i)
        d = as_mapping(d, p, "a defect such as {kind: flat, from: 268 deg, to: 272 deg}")
        kind = d.get("kind")
        if not isinstance(kind, str) or kind not in DEFECT_KINDS:
            found = "missing" if kind is None else f"found {excerpt(kind)}"
            raise SpecProblem(
                join(p, "kind"),
                f"{found}, expected one of: "
                + ", ".join(DEFECT_KINDS)
                + did_you_mean(kind, DEFECT_KINDS),
            )
        keys = DEFECT_KINDS[kind]
        for k in d:
            if k != "kind" and k not in keys:
                raise SpecProblem(
                    join(p, k),
                    f"not a key of a {kind} defect (its keys: "
                    f"{', '.join(keys)}){did_you_mean(k, keys)}",
                )
        si = {}
        for k in keys:
            if k not in d:
                raise SpecProblem(join(p, k), f"missing; a {kind} defect needs " + ", ".join(keys))
            si[k] = DEFECT_FIELDS[k].parse(d[k], join(p, k))
        if kind == "flat":
            check_flat(si["from"], si["to"], d, p)
    return copy.deepcopy(value)


def check_flat(start: float, end: float, d: Mapping, path: str) -> None:
    """A flat runs forward from ``from`` to ``to``, less than a turn: one through 0 deg is
    written past 360 deg (from: 350 deg, to: 370 deg), never as an end before its start."""
    if end <= start:
        raise SpecProblem(
            join(path, "to"),
            f"found to {excerpt(d['to'])} at or before from {excerpt(d['from'])}; a flat runs "
            "forward from 'from' to 'to' (for one through 0 deg write 'to' past 360 deg, e.g. "
            "from: 350 deg, to: 370 deg)",
            found=d["to"],
            expected="an angle after 'from'",
        )
    if end - start >= 2 * math.pi:
        raise SpecProblem(
            join(path, "to"),
            f"found from {excerpt(d['from'])} to {excerpt(d['to'])}, a turn or more; a flat "
            "is shorter than one turn",
            found=d["to"],
            expected="less than 360 deg after 'from'",
        )


def check_model(value: object, path: str) -> dict:
    value = as_mapping(value, path, "a preset plus parameter overrides")
    fields = varied_fields()
    for k, v in value.items():
        key = f"model.{k}"
        if key not in fields:
            raise unknown_key(path, k, ["preset", *PARAMETERS])
        fields[key].parse(v, join(path, k))
    return dict(value)


def check_run(value: object, path: str, study_wide: bool, problems: Problems) -> dict:
    value = as_mapping(value, path, "run settings")
    known = [k.removeprefix("run.") for k in CASE_FIELDS if k.startswith("run.")]
    for k, v in value.items():
        if k not in known:
            problems.items.append(unknown_key(path, k, known))
            continue
        if not study_wide and f"run.{k}" in STUDY_WIDE:
            problems.add(
                join(path, k),
                "the whole study shares it (it fixes the archive's cam_angle axis, "
                "variables or compression); set it in the base run",
            )
            continue
        problems.check(CASE_FIELDS[f"run.{k}"].parse, v, join(path, k))
    return dict(value)


def check_case_block(value: Mapping, path: str, partial: bool, problems: Problems) -> dict:
    """The case keys of the base (``partial=False``) or of one case entry."""
    out: dict = {}
    for k, v in value.items():
        p = join(path, k)
        if k == "model":
            out[k] = problems.check(check_model, v, p)
        elif k == "profile":
            out[k] = problems.check(check_profile, v, p, partial)
        elif k == "defects":
            out[k] = problems.check(check_defects, v, p)
        elif k == "run":
            out[k] = problems.check(check_run, v, p, not partial, problems)
        elif k in CASE_FIELDS:
            problems.check(CASE_FIELDS[k].parse, v, p)
            out[k] = v
    return out


# -- axes ----------------------------------------------------------------------------------

_NUMBER_UNIT = re.compile(r"^\s*(?P<number>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)\s*(?P<unit>.*)$")


def expand_range(
    value: Mapping, key: str, path: str, with_num: bool, max_len: int = MAX_AXIS_LENGTH
) -> list:
    """``{from: 1000 rpm, to: 20000 rpm, num: 39}`` → 39 values in the units of ``from``;
    a ``num`` beyond ``max_len`` is refused before any value is made."""
    need = ("from", "to", "num") if with_num else ("from", "to")
    for k in value:
        if k not in need:
            raise unknown_key(path, k, need)
    for k in need:
        if k not in value:
            raise SpecProblem(join(path, k), f"missing; a range needs {', '.join(need)}")
    field_ = range_field(key, path)
    lo = field_.parse(value["from"], join(path, "from"))
    hi = field_.parse(value["to"], join(path, "to"))
    if lo is None or hi is None:
        raise SpecProblem(path, "a range runs between two values; list 'none' separately")
    if not with_num:
        if not lo < hi:
            raise SpecProblem(
                path,
                f"found from {excerpt(value['from'])} ≥ to {excerpt(value['to'])}, "
                "expected from < to",
            )
        return [lo, hi]
    num = value["num"]
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise SpecProblem(join(path, "num"), f"found {excerpt(num)}, expected an integer ≥ 1")
    if num > max_len:
        raise SpecProblem(
            join(path, "num"),
            f"found {num}, beyond the limit of {max_len} values (--max-cases raises it)",
            found=num,
            expected=f"at most {max_len}",
        )
    if field_.kind in ("number", "integer"):
        return [float(v) for v in np.linspace(float(value["from"]), float(value["to"]), num)]
    # Space the values in the units the spec wrote, so 1000 … 20000 rpm step by whole rpm.
    start = _NUMBER_UNIT.match(str(value["from"]))
    end = _NUMBER_UNIT.match(str(value["to"]))
    unit = start["unit"].strip() if start else ""
    if start is None or not unit:
        return [f"{_number(v)} {field_.units}" for v in np.linspace(lo, hi, num)]
    first = float(start["number"])
    if end and end["unit"].strip() == unit:
        last = float(end["number"])
    else:
        last = hi / field_.parse(f"1 {unit}", join(path, "from"))
    return [f"{_number(v)} {unit}" for v in np.linspace(first, last, num)]


def _number(v: float) -> str:
    """Exact text of a float: ``6000`` for a whole number, else its shortest repr."""
    v = float(v)
    return str(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v)


def range_field(key: str, path: str) -> Field:
    f = varied_fields().get(key)
    if (
        f is None
        or f.kind not in ("quantity", "number", "parameter")
        or (f.kind == "parameter" and not PARAMETERS[key.removeprefix("model.")].continuous)
    ):
        raise SpecProblem(
            path, f"{key} is not a scalar quantity; list its values instead of a range"
        )
    if f.kind == "parameter":
        p = PARAMETERS[key.removeprefix("model.")]
        return Field(
            key,
            "quantity" if p.units else "number",
            p.long_name,
            units=p.units,
            example=p.thesis_units,
            minimum=p.minimum,
            exclusive_minimum=p.exclusive_minimum,
        )
    return f


def check_axis_value(key: str, value: object, path: str) -> object:
    """One value of a swept key, checked like the key itself."""
    if key == "profile":
        return check_profile(value, path, partial=False)
    if key == "defects":
        return check_defects(value, path)
    varied_fields()[key].parse(value, path)
    return value


def check_axes(
    value: object, path: str, zipped: bool, problems: Problems, max_len: int = MAX_AXIS_LENGTH
) -> dict[str, list]:
    """A ``sweep:`` or ``zip:`` mapping: key → values or range (at most ``max_len`` each)."""
    block = problems.check(as_mapping, value, path, "key → list of values or {from, to, num}")
    if block is None:
        return {}
    if not block:
        problems.add(path, "empty; expected at least one key to vary (or leave it out)")
        return {}
    keys = sweep_keys()
    out: dict[str, list] = {}
    for key, values in block.items():
        p = f"{path}.{key}"
        if key not in keys:
            if key in STUDY_WIDE:
                problems.add(
                    p,
                    "the whole study shares it (it fixes the archive's cam_angle "
                    "axis, variables or compression); it cannot vary",
                )
            else:
                problems.items.append(unknown_key(path, key, keys))
            continue
        if isinstance(values, Mapping) and key not in WHOLE_KEYS:
            got = problems.check(expand_range, values, key, p, True, max_len)
        elif isinstance(values, list):
            if not values:
                problems.add(
                    p, "empty list; expected at least one value (an empty axis makes an empty grid)"
                )
                continue
            before = len(problems.items)
            for i, v in enumerate(values):
                problems.check(check_axis_value, key, v, f"{p}[{i}]")
            got = values if len(problems.items) == before else None
        else:
            problems.add(
                p,
                f"found {show(values)}, expected a list of values"
                + ("" if key in WHOLE_KEYS else " or {from, to, num}"),
            )
            continue
        if got is not None:
            out[key] = list(got)
            if not zipped:
                _check_repeats(problems, p, [canonical_value(key, v) for v in got])
    if zipped:
        lengths = {k: len(v) for k, v in out.items()}
        if len(set(lengths.values())) > 1:
            problems.add(
                path,
                "zipped keys vary together and need equal lengths; found "
                + ", ".join(f"{k} {n}" for k, n in lengths.items()),
            )
        elif out:
            rows = zip(*([canonical_value(k, v) for v in vs] for k, vs in out.items()), strict=True)
            _check_repeats(problems, path, list(rows), "row")
    return out


def canonical_value(key: str, value: object) -> object:
    """An axis value as the case sees it (SI, parsed), hashable: two spellings of one value
    are equal (``9000 rpm`` and ``9000.0 rpm``)."""
    if key == "profile" and isinstance(value, Mapping):
        return _freeze_parsed(value, PROFILE_FIELDS)
    if key == "defects" and isinstance(value, list):
        return tuple(_freeze_parsed(d, DEFECT_FIELDS) for d in value)
    parsed = varied_fields()[key].parse(value, key)
    return tuple(parsed) if isinstance(parsed, list) else parsed


def _freeze_parsed(value: Mapping, fields: Mapping[str, Field]) -> tuple:
    return tuple(
        sorted(
            (k, fields[k].parse(v, k) if k in fields and k != "file" else v)
            for k, v in value.items()
        )
    )


def _check_repeats(problems: Problems, path: str, values: list, what: str = "value") -> None:
    """Refuse an axis that lists one value twice: it would run one case twice (two rows with
    one case id)."""
    first: dict[object, int] = {}
    for i, v in enumerate(values):
        if v in first:
            where = f"{path}[{i}]" if what == "value" else f"{path} (row {i})"
            problems.add(
                where,
                f"the same {what} as {path}[{first[v]}]; each {what} of an axis appears once "
                "(it would run the same case twice)",
            )
            return
        first[v] = i


def check_cases(value: object, problems: Problems) -> list[dict]:
    if not isinstance(value, list):
        problems.add("cases", f"found {show(value)}, expected a list of case mappings")
        return []
    if not value:
        problems.add("cases", "empty list; expected at least one case (or leave cases out)")
        return []
    out = []
    for i, entry in enumerate(value):
        p = join("cases", i)
        entry = problems.check(as_mapping, entry, p, "case keys merged over the base")
        if entry is None:
            continue
        for k in entry:
            if k not in CASE_KEYS:
                problems.items.append(unknown_key(p, k, CASE_KEYS))
        out.append(
            check_case_block({k: v for k, v in entry.items() if k in CASE_KEYS}, p, True, problems)
        )
    return out


def check_sample(
    value: object, problems: Problems, max_len: int = MAX_AXIS_LENGTH
) -> Sample | None:
    block = problems.check(
        as_mapping, value, "sample", "{method: latin-hypercube, n, seed, ranges: {key: {from, to}}}"
    )
    if block is None:
        return None
    before = len(problems.items)
    need = ("method", "n", "seed", "ranges")
    ok = True
    for k in block:
        if k not in need:
            problems.items.append(unknown_key("sample", k, need))
            ok = False
    for k in need:
        if k not in block:
            problems.add(f"sample.{k}", "missing; a sampled design needs " + ", ".join(need))
            ok = False
    if not ok:
        return None
    method = block["method"]
    if method not in SAMPLE_METHODS:
        problems.add(
            "sample.method",
            f"found {excerpt(method)}, expected one of: "
            + ", ".join(SAMPLE_METHODS)
            + did_you_mean(method, SAMPLE_METHODS),
        )
    n, seed = block["n"], block["seed"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        problems.add("sample.n", f"found {excerpt(n)}, expected an integer ≥ 1 (points to sample)")
    elif n > max_len:
        problems.add(
            "sample.n", f"found {n}, beyond the limit of {max_len} points (--max-cases raises it)"
        )
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        problems.add("sample.seed", f"found {excerpt(seed)}, expected an integer ≥ 0")
    ranges = problems.check(as_mapping, block["ranges"], "sample.ranges", "key → {from, to}")
    out: dict[str, tuple[float, float]] = {}
    written: dict[str, tuple[str, str]] = {}
    if ranges is not None:
        if not ranges:
            problems.add("sample.ranges", "empty; expected at least one key → {from, to}")
        keys = sample_keys()
        for key, r in ranges.items():
            p = f"sample.ranges.{key}"
            if key not in keys:
                problems.items.append(unknown_key("sample.ranges", key, keys))
                continue
            r = problems.check(as_mapping, r, p, "{from, to}")
            if r is not None:
                got = problems.check(expand_range, r, key, p, False)
                if got is not None:
                    out[key] = (got[0], got[1])
                    written[key] = (str(r["from"]).strip(), str(r["to"]).strip())
    if len(problems.items) > before:
        return None
    return Sample(method, n, seed, out, written)


def leaf_keys(entry: Mapping, prefix: str = "") -> list[str]:
    """Dotted keys a case entry sets: ``{model: {spring_preload: ..}}`` → model.spring_preload."""
    out = []
    for k, v in entry.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping) and k in ("model", "profile", "run"):
            out += leaf_keys(v, key + ".")
        else:
            out.append(key)
    return out
