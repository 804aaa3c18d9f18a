"""From a checked spec to the study's cases: expansion (each case resolved by
:mod:`campipe.study.spec.resolve`).

Expansion order: for each ``cases`` entry (or the base alone), the ``sweep`` grid (first key
outermost), then the ``zip`` rows, then the ``sample`` points, last varying fastest. Each
case is the base deep-merged with its entry (a ``profile`` of another ``kind`` replaces the
base's profile whole), then each axis's value set at its key.

A spec that sweeps the speed on an axis of its own expands into a
:class:`~campipe.study.spec.resolve.SpeedSweep`; a replay's and the plots' ``where`` and
columns are checked against the columns the archive will have.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from campipe.engine.settings import sample_count, turn_count
from campipe.errors import did_you_mean, excerpt
from campipe.io.compression import COMPRESSION
from campipe.study.spec.blocks import leaf_keys
from campipe.study.spec.check import MAX_PROBLEMS, Spec, SpecError
from campipe.study.spec.drive import with_drive
from campipe.study.spec.fields import (
    ENGINE_SPEED,
    SpecProblem,
    varied_fields,
)
from campipe.study.spec.limits import Limits, check_limits
from campipe.study.spec.resolve import (
    ResolvedCase,
    SpeedSweep,
    clean_value,
    freeze,
    parse_value,
    resolve,
    resolve_canonical,
)
from campipe.study.spec.variables import (
    DOF_NAMES,
    SETTLING_RECORD,
    case_coordinates,
    data_variables,
)
from campipe.study.where import QueryError, evaluate, parse_where


@dataclass(frozen=True)
class Axis:
    """One axis of the study, as the archive and ``campipe query --summary`` report it."""

    key: str  # dotted key varied ("speed", "model.spring_preload"), or "cases"
    kind: str  # "sweep", "zip", "sample" or "cases"
    size: int  # number of values


@dataclass
class Study:
    """A spec expanded into resolved cases."""

    spec: Spec  # the checked spec
    cases: Sequence[ResolvedCase]  # in archive order (a SpeedSweep or a list)
    axes: list[Axis]  # what varies, in expansion order
    varied: tuple[str, ...]  # extra dotted keys with a per-case coordinate in the archive
    revolutions: float  # cam turns the histories cover, shared [-]
    output_every: float  # output spacing, shared [rad]
    record: tuple[str, ...]  # optional histories stored
    compression: str = COMPRESSION  # the archive's (campipe.io.compression.COMPRESSIONS)
    #: each case runs until its response repeats (``run.revolutions: auto``), at most this
    #: many turns; 0: the run is ``revolutions`` long
    max_revolutions: int = 0

    @property
    def settle(self) -> bool:
        """Whether each case runs until its response repeats (``run.revolutions: auto``)."""
        return self.max_revolutions > 0

    @property
    def n_revolutions(self) -> int:
        """The length of the archive's revolution axis: the turns of a fixed run (a partial
        last one included), or the cap on a case's turns."""
        return self.max_revolutions if self.settle else turn_count(self.revolutions)

    @property
    def name(self) -> str:
        return self.spec.name


def archive_bytes(study: Study) -> int:
    """Size of the archive's variables before compression [bytes] (events not counted)."""
    n_out = sample_count(study.revolutions, study.output_every)
    n_rev = study.n_revolutions
    sizes = {"cam_angle": n_out, "revolution": n_rev, "dof": len(DOF_NAMES), "event": 0}
    per_case = 0
    for var in data_variables(study.record).values():
        if "case" not in var.dims:
            continue
        n = 1
        for d in var.dims[1:]:
            n *= sizes[d]
        per_case += n * np.dtype(var.dtype).itemsize
    per_case += 16 + 8 * 8 + 64  # case id, numeric coordinates, labels (about)
    return len(study.cases) * per_case + n_out * 8


# -- expansion ------------------------------------------------------------------------------


def deep_merge(base: Mapping, entry: Mapping) -> dict:
    """``entry`` over ``base``: mappings merge key by key, anything else replaces.

    A profile of another kind replaces the base's profile whole (its keys differ).
    """
    out = dict(base)
    for k, v in entry.items():
        old = out.get(k)
        if (
            k == "profile"
            and isinstance(v, Mapping)
            and isinstance(old, Mapping)
            and ("kind" in v and v["kind"] != old.get("kind"))
        ):
            out[k] = dict(v)
        elif isinstance(v, Mapping) and isinstance(old, Mapping):
            out[k] = deep_merge(old, v)
        else:
            out[k] = v
    return out


def set_key(case: dict, key: str, value: object) -> None:
    """Set a dotted key in a case, copying only the mapping on its way."""
    head, _, rest = key.partition(".")
    if not rest:
        case[head] = value
        return
    inner = dict(case.get(head) or {})
    set_key(inner, rest, value)
    case[head] = inner


@dataclass(frozen=True)
class _AxisRows:
    keys: tuple[str, ...]  # dotted keys set together
    rows: list[tuple]  # one tuple of values per position
    paths: tuple[str, ...]  # spec path of each key's value list


def sample_rows(spec: Spec) -> list[tuple]:
    """The sampled design's points, values written in SI units (exact floats)."""
    from scipy.stats import qmc

    s = spec.sample
    assert s is not None
    keys = list(s.ranges)
    generator = np.random.default_rng(s.seed)
    try:
        engine = qmc.LatinHypercube(d=len(keys), rng=generator)
    except TypeError:  # scipy < 1.15 names it seed
        engine = qmc.LatinHypercube(d=len(keys), seed=generator)
    unit = engine.random(s.n)
    fields = varied_fields()
    rows = []
    for u in unit:
        row = []
        for k, x in zip(keys, u, strict=True):
            lo, hi = s.ranges[k]
            row.append(f"{lo + float(x) * (hi - lo)!r} {fields[k].units}".rstrip())
        rows.append(tuple(row))
    return rows


def _axes(spec: Spec) -> list[_AxisRows]:
    out = [_AxisRows((k,), [(v,) for v in vals], (f"sweep.{k}",)) for k, vals in spec.sweep.items()]
    if spec.zip:
        keys = tuple(spec.zip)
        out.append(
            _AxisRows(
                keys, list(zip(*spec.zip.values(), strict=True)), tuple(f"zip.{k}" for k in keys)
            )
        )
    if spec.sample:
        keys = tuple(spec.sample.ranges)
        out.append(_AxisRows(keys, sample_rows(spec), tuple(f"sample.ranges.{k}" for k in keys)))
    return out


def raw_cases(
    spec: Spec, fixed: Mapping[int, int] | None = None
) -> Iterator[tuple[dict, dict[str, str]]]:
    """Every case as spec data, with where each of its varied values came from; with
    ``fixed`` (axis position → row), only the cases at those rows of those axes."""
    axes = _axes(spec)
    fixed = fixed or {}
    ranges = [(fixed[i],) if i in fixed else range(len(a.rows)) for i, a in enumerate(axes)]
    entries = spec.cases or [{}]
    for ci, entry in enumerate(entries):
        merged = deep_merge(spec.base, entry)
        entry_origins = {k: f"cases[{ci}].{k}" for k in leaf_keys(entry)} if spec.cases else {}
        for combo in itertools.product(*ranges):
            case = dict(merged)
            origins = dict(entry_origins)
            for axis, j in zip(axes, combo, strict=True):
                for key, value, path in zip(axis.keys, axis.rows[j], axis.paths, strict=True):
                    set_key(case, key, value)
                    origins[key] = (
                        f"{path}[{j}]"
                        if not path.startswith("sample")
                        else f"sample point {j} ({path})"
                    )
            yield case, origins


def count_cases(spec: Spec) -> int:
    n = len(spec.cases) or 1
    for a in _axes(spec):
        n *= len(a.rows)
    return n


def _origin(path: str, origins: Mapping[str, str]) -> str:
    """The spec path a case key's value came from: an axis, a case entry, or the base."""
    best = ""
    for key in origins:
        if (path == key or path.startswith(key + ".") or path.startswith(key + "[")) and len(
            key
        ) > len(best):
            best = key
    if not best:
        return path
    origin = origins[best]
    rest = path[len(best) :]
    return origin + rest if "point" not in origin else origin


def expand(
    spec: Spec, source: str = "spec", limits: Limits | None = None, by_speed: bool = True
) -> Study:
    """Expand and resolve every case of a checked spec, once it is known to stay within
    ``limits`` (default ``Limits()``; checked from the spec alone, before any case is built).

    A spec that sweeps the speed on an axis of its own gets a :class:`SpeedSweep` (unless
    ``by_speed`` is False): its other axes' combinations resolved once each. Any problem
    there, or two equal cases, is then found again case by case, to report it as below.

    Raises
    ------
    SpecError
        A limit exceeded; or problems found while resolving cases, each at the spec path its
        value came from, a repeated problem reported once with the cases it affects.
    """
    over = check_limits(spec, limits or Limits())
    if over:
        raise SpecError(over, source)
    swept = _speed_sweep(spec) if by_speed else None
    cases: Sequence[ResolvedCase] = swept if swept is not None else _each_case(spec, source)
    if spec.drive is not None:  # the engine's speed beside the cam's
        for case in swept.others() if swept is not None else cases:
            with_drive(case.values, spec.drive)
    run = spec.base["run"]
    if spec.replay:
        check_replay_columns(spec.replay, varied_keys(spec), tuple(run["record"]), source)
    if spec.plots:
        check_plot_columns(spec.plots, varied_keys(spec), tuple(run["record"]), source)
    axes = [Axis(k, "sweep", len(v)) for k, v in spec.sweep.items()]
    axes += [Axis(k, "zip", len(v)) for k, v in spec.zip.items()]
    if spec.sample:
        axes += [Axis(k, "sample", spec.sample.n) for k in spec.sample.ranges]
    if spec.cases:
        axes.append(Axis("cases", "cases", len(spec.cases)))
    settle = run["revolutions"] == "auto"
    return Study(
        spec=spec,
        cases=cases,
        axes=axes,
        varied=varied_keys(spec),
        revolutions=float(run["history_turns"] if settle else run["revolutions"]),
        output_every=float(
            parse_value("run.output_every", run["output_every"], "run.output_every")
        ),
        record=tuple(run["record"]) + ((SETTLING_RECORD,) if settle else ()),
        compression=str(run["compression"]),
        max_revolutions=int(run["max_revolutions"]) if settle else 0,
    )


def _each_case(spec: Spec, source: str) -> list[ResolvedCase]:
    """Every case of the spec resolved on its own, problems collected (see :func:`expand`)."""
    cases: list[ResolvedCase] = []
    # (spec path, message) → the first case's problem and every case it affects
    found: dict[tuple[str, str], tuple[SpecProblem, list[int]]] = {}
    for index, (raw, origins) in enumerate(raw_cases(spec)):
        try:
            cases.append(resolve(raw, index, spec.directory))
        except SpecProblem as exc:
            key = (_origin(exc.path, origins), exc.message)
            found.setdefault(key, (exc, []))[1].append(index)
            if len(found) >= MAX_PROBLEMS:
                break
    if found:
        problems = []
        for (path, message), (first, which) in found.items():
            shown = ", ".join(map(str, which[:5])) + (", ..." if len(which) > 5 else "")
            tail = f" (case {shown})" if len(which) == 1 else f" ({len(which)} cases: {shown})"
            problems.append(
                SpecProblem(path, message + tail, found=first.found, expected=first.expected)
            )
        raise SpecError(problems, source)
    check_unique(cases, spec, source)
    return cases


def _speed_sweep(spec: Spec) -> SpeedSweep | None:
    """The spec's cases as a :class:`SpeedSweep`, or None: no axis of the speed alone (or of
    one speed), or a problem or two equal cases, left for :func:`_each_case` to report."""
    axes = _axes(spec)
    k = next((i for i, a in enumerate(axes) if a.keys == ("speed",)), None)
    if k is None or len(axes[k].rows) < 2:
        return None
    try:
        speeds = [parse_value("speed", freeze(v), "speed") for (v,) in axes[k].rows]
        others = [
            resolve_canonical(raw, index, spec.directory)
            for index, (raw, _) in enumerate(raw_cases(spec, fixed={k: 0}))
        ]
    except SpecProblem:
        return None
    if len({clean_value(v) for v in speeds}) < len(speeds):
        return None
    if len({case.case_id for case, _ in others}) < len(others):
        return None
    return SpeedSweep(others, speeds, math.prod(len(a.rows) for a in axes[k + 1 :]))


def check_replay_columns(
    where: str, varied: tuple[str, ...], record: tuple[str, ...], source: str
) -> None:
    """``replay.where`` against the columns the archive will have, with their types: an
    unknown column or text compared with a number is refused now, not after the study."""
    columns, units = _future_columns(varied, record)
    try:
        evaluate(parse_where(where), columns, 1, units)
    except QueryError as exc:
        raise SpecError([SpecProblem("replay.where", exc.reason)], source) from None


def check_plot_columns(
    plots: list, varied: tuple[str, ...], record: tuple[str, ...], source: str
) -> None:
    """Each of ``plots:``'s ``where`` and its columns (x, y, z) against the columns the
    archive will have: refused now, not after the study."""
    columns, units = _future_columns(varied, record)
    problems = []
    for i, plot in enumerate(plots):
        if plot.where is not None:
            try:
                evaluate(parse_where(plot.where), columns, 1, units)
            except QueryError as exc:
                problems.append(SpecProblem(f"plots[{i}].where", exc.reason))
        for key in ("x", "y", "z"):
            name = getattr(plot, key)
            if name is None:
                continue
            values = columns.get(name)
            if values is None or values.dtype.kind not in "iuf" or values.ndim != 1:
                numeric = [k for k, v in columns.items() if v.dtype.kind in "iuf" and v.ndim == 1]
                what = "unknown column" if values is None else "not a column of numbers"
                problems.append(
                    SpecProblem(
                        f"plots[{i}].{key}",
                        f"{what} {excerpt(name)}{did_you_mean(name, numeric)} (columns: "
                        f"{', '.join(numeric)})",
                    )
                )
    if problems:
        raise SpecError(problems, source)


def _future_columns(
    varied: tuple[str, ...], record: tuple[str, ...]
) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Placeholder per-case columns of the archive to come, and their stored units."""
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {"case": ""}
    for name, var, _ in case_coordinates(varied).values():
        shape = (1, 7) if "mode" in var.dims else (1,)
        columns[name] = (
            np.array(["x"], dtype=object) if var.dtype == "str" else np.full(shape, np.nan)
        )
        units[name] = var.units or ""
    for name, var in data_variables(record).items():
        if var.dims == ("case",):
            columns[name] = np.full(1, np.nan)
            units[name] = var.units or ""
    columns["case"] = np.array(["x"], dtype=object)
    return columns, units


def check_unique(cases: list[ResolvedCase], spec: Spec, source: str) -> None:
    """Refuse two cases with one id (the same parameters reached twice, e.g. two equal
    case entries): the archive would hold two rows of one case."""
    seen: dict[str, int] = {}
    for c in cases:
        if c.case_id in seen:
            where = "cases" if spec.cases else "sweep"
            raise SpecError(
                [
                    SpecProblem(
                        where,
                        f"cases {seen[c.case_id]} and {c.index} are the same case (case id "
                        f"{c.case_id}): the spec reaches the same parameters twice; vary "
                        "each value once",
                    )
                ],
                source,
            )
        seen[c.case_id] = c.index


#: Keys always stored per case (their archive names: see campipe.study.spec.variables).
STANDARD_KEYS = ("speed", "seat", "profile", "defects", "closure", "run.integrator", "run.dt")


def varied_keys(spec: Spec) -> tuple[str, ...]:
    """Keys beyond the standard ones that an axis or a case entry varies."""
    keys = list(spec.sweep) + list(spec.zip)
    if spec.sample:
        keys += list(spec.sample.ranges)
    for entry in spec.cases:
        keys += [k for k in leaf_keys(entry) if k.startswith(("model.", "run."))]
    fields = varied_fields()
    out: list[str] = []
    for k in keys:
        if k in STANDARD_KEYS or k not in fields or k in out:
            continue
        out.append(k)
    if spec.drive is not None:  # the engine's speed, stored beside the cam's
        out.append(ENGINE_SPEED.key)
    return tuple(out)
