"""From a checked spec to the study's cases: expansion, resolution to engine inputs, case ids.

Expansion order: for each ``cases`` entry (or the base alone), the ``sweep`` grid (first key
outermost), then the ``zip`` rows, then the ``sample`` points, last varying fastest. Each
case is the base deep-merged with its entry (a ``profile`` of another ``kind`` replaces the
base's profile whole), then each axis's value set at its key.

Each case is resolved to SI and to the engine's :class:`~campipe.engine.Case` and
:class:`~campipe.engine.RunSettings`; its id is the SHA-256 of its canonical parameters
(every model parameter, the cam with its defects, speed, seat, closure and run settings, SI,
as sorted JSON). A measured lift table enters the id by its values, not its path.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np

from campipe.constants import INCH
from campipe.engine import Case, CaseError, RunSettings, RunSettingsError
from campipe.engine.settings import (
    case_integrator,
    check_contacts,
    check_newmark_linear,
    check_stability,
)
from campipe.errors import did_you_mean, excerpt
from campipe.io.compression import COMPRESSION
from campipe.io.lift_table import LiftTableError, read_lift_table, table_digest
from campipe.model import (
    PARAMETERS,
    ModelParameterError,
    ValveTrain,
    defining_values,
    lash_seat,
    system_matrices,
    valve_train,
)
from campipe.profiles import (
    Profile,
    Ramp,
    bump,
    flat,
    harmonic,
    max_lift,
    min_lift,
    polydyne,
    table,
)
from campipe.study.spec.check import (
    MAX_PROBLEMS,
    Spec,
    SpecError,
    check_defects,
    check_profile,
    leaf_keys,
)
from campipe.study.spec.fields import (
    CASE_FIELDS,
    DEFECT_FIELDS,
    PROFILE_FIELDS,
    RUN_SETTINGS,
    SpecProblem,
    varied_fields,
)
from campipe.study.spec.limits import Limits, check_limits
from campipe.study.spec.variables import case_coordinates, data_variables
from campipe.study.where import QueryError, evaluate, parse_where

#: Lift below the base circle tolerated as round-off [m].
LIFT_TOLERANCE = 1e-12
#: Hex digits of a case id (64 bits).
CASE_ID_LENGTH = 16


@dataclass(frozen=True)
class ResolvedCase:
    """One case of a study, ready for the engine."""

    index: int  # position in the study and the archive
    case: Case  # engine input
    settings: RunSettings  # how it is integrated (batches share these)
    values: dict[str, object]  # dotted key → value: SI floats, words, labels ("profile")
    case_id: str  # hash of the canonical parameters


@dataclass(frozen=True)
class Axis:
    """One axis of the study, as the archive and ``campipe query --summary`` report it."""

    key: str  # dotted key varied ("speed", "model.spring_preload"), or "cases"
    kind: str  # "sweep", "zip", "sample" or "cases"
    size: int  # number of values


#: A speed sweep of at most this many cases keeps its cases once built (``SpeedSweep``); a
#: larger one builds them again on each pass, holding only its other axes' combinations.
KEEP_CASES = 200_000


class SpeedSweep(Sequence[ResolvedCase]):
    """The cases of a spec that sweeps the speed on an axis of its own, in archive order,
    built when asked for: every combination of the other axes resolved once (its resolved
    case at the first speed, with the canonical parameters its id hashes), and each speed
    parsed once. Case ``i`` is its combination with its speed set; the speed enters nothing
    else a case resolves to, so that is exactly what resolving it would give (the tests
    compare the two), at a fraction of the time and memory: a million-case speed sweep is
    checked by resolving its other axes' combinations.

    ``inner`` is the number of cases the axes after the speed's make (its stride)."""

    def __init__(self, others: list[tuple[ResolvedCase, dict]], speeds: list[float], inner: int):
        self._others = others
        self._speeds = tuple(speeds)
        self._inner = inner
        self._kept: list[ResolvedCase] | None = None
        self._ids: dict[int, Callable[[float], str]] = {}  # by combination: its speed's id

    def __len__(self) -> int:
        return len(self._others) * len(self._speeds)

    @property
    def speeds(self) -> tuple[float, ...]:
        """The speeds each combination of the other axes runs at [rad/s], in axis order."""
        return self._speeds

    def others(self) -> list[ResolvedCase]:
        """One case per combination of the other axes (at the first speed), in study order."""
        return [case for case, _ in self._others]

    def _build(self, i: int) -> ResolvedCase:
        outer, rest = divmod(i, len(self._speeds) * self._inner)
        j, inner = divmod(rest, self._inner)
        k = outer * self._inner + inner
        case, canonical = self._others[k]
        speed = self._speeds[j]
        values = dict(case.values)
        values["speed"] = speed
        ids = self._ids.get(k)
        if ids is None:
            ids = self._ids[k] = speed_case_ids(canonical)
        return ResolvedCase(
            i, dataclasses.replace(case.case, speed=speed), case.settings, values, ids(speed)
        )

    @overload
    def __getitem__(self, i: int) -> ResolvedCase: ...

    @overload
    def __getitem__(self, i: slice) -> list[ResolvedCase]: ...

    def __getitem__(self, i: int | slice) -> ResolvedCase | list[ResolvedCase]:
        if self._kept is not None:
            return self._kept[i]
        if isinstance(i, slice):
            return [self._build(k) for k in range(*i.indices(len(self)))]
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"case {i} of {n}")
        return self._build(i % n)

    def __iter__(self) -> Iterator[ResolvedCase]:
        if self._kept is None and len(self) <= KEEP_CASES:
            self._kept = [self._build(i) for i in range(len(self))]
        if self._kept is not None:
            return iter(self._kept)
        return (self._build(i) for i in range(len(self)))


def distinct_but_speed(cases: Sequence[ResolvedCase]) -> tuple[Sequence[ResolvedCase], int]:
    """Cases standing for all (one per combination of the axes other than a speed sweep's)
    and how many speeds each stands for: what a count by anything but the speed needs."""
    if isinstance(cases, SpeedSweep):
        return cases.others(), len(cases.speeds)
    return cases, 1


@dataclass
class Study:
    """A spec expanded into resolved cases."""

    spec: Spec  # the checked spec
    cases: Sequence[ResolvedCase]  # in archive order (a SpeedSweep or a list)
    axes: list[Axis]  # what varies, in expansion order
    varied: tuple[str, ...]  # extra dotted keys with a per-case coordinate in the archive
    revolutions: float  # cam turns, shared [-]
    output_every: float  # output spacing, shared [rad]
    record: tuple[str, ...]  # optional histories stored
    compression: str = COMPRESSION  # the archive's (campipe.io.archive.COMPRESSIONS)

    @property
    def name(self) -> str:
        return self.spec.name


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


# -- resolution -----------------------------------------------------------------------------


def _freeze(value: object) -> object:
    if isinstance(value, Mapping):
        return tuple(sorted((k, _freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def _thaw(frozen: tuple) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in frozen}


@functools.lru_cache(maxsize=4096, typed=True)  # typed: True is not 1
def _parse(key: str, value: object, path: str) -> Any:
    """A case field's SI value, typed as the field's kind makes it (cached: a grid repeats its
    base values in every case)."""
    return (CASE_FIELDS.get(key) or varied_fields()[key]).parse(
        list(value) if isinstance(value, tuple) else value, path
    )


@functools.lru_cache(maxsize=1024)
def _train(preset: str, overrides: tuple) -> ValveTrain:
    try:
        train = valve_train(preset, _thaw(overrides), key_prefix="model.")
    except ModelParameterError as exc:
        raise SpecProblem.from_error(exc) from None
    check_train(train)
    return train


def check_train(train: ValveTrain) -> None:
    """The train's matrices and natural frequencies are finite and positive: parameters
    far out of range (a spring rate of 1e300 lbf/in) are refused here, not by the engine."""
    try:
        sm = system_matrices(train)
        ok = all(
            np.isfinite(a).all() for a in (sm.mass, sm.stiffness, sm.damping, sm.frequencies)
        ) and bool((sm.frequencies > 0).all())
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        ok = False
    if not ok:
        raise SpecProblem(
            "model",
            "the parameters give a model whose matrices or natural frequencies are not "
            "finite and positive; check the parameters' values and units",
        )


@functools.lru_cache(maxsize=256)
def _lift_table(path: Path, mtime_ns: int) -> tuple[np.ndarray, np.ndarray, str]:
    try:
        angles, lifts = read_lift_table(path)
    except LiftTableError as exc:
        raise SpecProblem("profile.file", str(exc)) from None
    return angles, lifts, table_digest(angles, lifts)


@functools.lru_cache(maxsize=1024)
def _profile(frozen: tuple, directory: Path) -> tuple[Profile, dict, dict[str, object]]:
    """(profile, canonical form, archive values) of a checked profile mapping."""
    spec = _thaw(frozen)
    kind = spec["kind"]
    values: dict[str, object] = {"profile.kind": kind}
    si = {k: PROFILE_FIELDS[k].parse(v, f"profile.{k}") for k, v in spec.items() if k != "kind"}
    try:
        if kind == "harmonic":
            profile = harmonic(si["lift"])
        elif kind.startswith("polydyne-"):
            ramp = None
            if "ramp_height" in si:
                shape = str(si.get("ramp_shape", "constant-velocity"))
                ramp = Ramp(float(si["ramp_height"]), float(si["ramp_duration"]), shape)
            profile = polydyne(
                kind.removeprefix("polydyne-"),
                si["lift"],
                si["rise"],
                si["dwell"],
                si["fall"],
                ramp=ramp,
            )
        else:
            path = (directory / si["file"]).resolve()
            try:
                mtime = path.stat().st_mtime_ns
            except OSError as exc:
                raise SpecProblem(
                    "profile.file",
                    f"found {excerpt(spec['file'])}, cannot read "
                    f"{path} ({exc.strerror}); the path is relative to the "
                    "spec",
                ) from None
            angles, lifts, digest = _lift_table(path, mtime)
            try:
                profile = table(angles, lifts)
            except ValueError as exc:
                raise SpecProblem("profile.file", f"{path}: {exc}") from None
            profile = dataclasses.replace(
                profile, label=f"table {Path(si['file']).name} ({angles.size} points)"
            )
            canonical = {"kind": kind, "table_sha256": digest}
            values.update({"profile.file": si["file"], "profile": profile.label})
            return profile, canonical, values
    except SpecProblem:
        raise
    except ValueError as exc:
        raise SpecProblem("profile", str(exc)) from None
    canonical = {"kind": kind, **{k: _clean(v) for k, v in si.items()}}
    values.update({f"profile.{k}": v for k, v in si.items()})
    values["profile"] = profile.label
    return profile, canonical, values


@functools.lru_cache(maxsize=1024)
def _with_defects(frozen_profile: tuple, frozen_defects: tuple, directory: Path):
    profile, canonical, values = _profile(frozen_profile, directory)
    out = profile
    defects = []
    for i, d in enumerate(_thaw_list(frozen_defects)):
        si = {
            k: DEFECT_FIELDS[k].parse(v, f"defects[{i}].{k}") for k, v in d.items() if k != "kind"
        }
        try:
            if d["kind"] == "flat":
                out = flat(out, si["from"], si["to"])
            else:
                out = bump(out, si["center"], si["height"], si["width"])
        except ValueError as exc:
            raise SpecProblem(f"defects[{i}]", str(exc)) from None
        defects.append({"kind": d["kind"], **{k: _clean(v) for k, v in si.items()}})
    label = out.label[len(profile.label) :].removeprefix(" + ") if defects else "none"
    low = min_lift(out)
    if low < -LIFT_TOLERANCE:
        where = (
            "defects" if defects else ("profile.file" if "profile.file" in values else "profile")
        )
        raise SpecProblem(
            where,
            f"the cam's lift falls to {low / INCH:.4g} in; expected a "
            "lift never below the base circle (0)",
        )
    high = max_lift(out)
    if not high > LIFT_TOLERANCE:
        where = "profile.file" if "profile.file" in values else "profile"
        raise SpecProblem(
            where,
            f"the cam's lift never rises above {high / INCH:.4g} in; expected a cam that "
            "lifts the follower",
        )
    return out, canonical, defects, values, label, high


def _thaw_list(frozen: tuple) -> list[dict]:
    return [dict(d) for d in frozen]


def _clean(v: object) -> object:
    """Floats as JSON keeps them; −0.0 as 0.0 (the same case)."""
    if isinstance(v, float):
        return v + 0.0
    if isinstance(v, tuple | list):
        return [_clean(x) for x in v]
    return v


def _canonical_json(value: object) -> str:
    """The text a case id hashes: JSON with sorted keys, no spaces, no NaN."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def case_id(canonical: Mapping) -> str:
    """The first 16 hex digits of the SHA-256 of the canonical parameters as sorted JSON."""
    return hashlib.sha256(_canonical_json(canonical).encode()).hexdigest()[:CASE_ID_LENGTH]


#: Where the speed goes in :func:`speed_case_ids`'s canonical JSON.
_SPEED_MARK = "\x00speed\x00"


def speed_case_ids(canonical: Mapping) -> Callable[[float], str]:
    """The :func:`case_id` of ``canonical`` at any speed (``canonical["speed"]`` replaced):
    the JSON before the speed is hashed once, and each id hashes only the speed and what
    follows it (2 µs a case instead of 15 for the thesis's parameters)."""
    mark = _canonical_json(_SPEED_MARK)
    head, found, tail = _canonical_json({**canonical, "speed": _SPEED_MARK}).partition(mark)
    if not found or mark in tail:  # a value that is the mark itself: the whole JSON each time
        return lambda speed: case_id({**canonical, "speed": _clean(speed)})
    before = hashlib.sha256(head.encode())
    after = tail.encode()

    def one(speed: float) -> str:
        h = before.copy()
        h.update(_canonical_json(_clean(speed)).encode())
        h.update(after)
        return h.hexdigest()[:CASE_ID_LENGTH]

    return one


def resolve(raw: Mapping, index: int, directory: Path) -> ResolvedCase:
    """One case (spec data, defaults filled in) → engine inputs, archive values and id.

    Raises
    ------
    SpecProblem
        With the key path inside the case (``seat``, ``profile.lift``, ``run.dt``).
    """
    return _resolve(raw, index, directory)[0]


def _resolve(raw: Mapping, index: int, directory: Path) -> tuple[ResolvedCase, dict]:
    """:func:`resolve`, and the canonical parameters the case id hashes."""
    values: dict[str, object] = {}
    model = dict(raw["model"])
    preset = model.pop("preset")
    train = _train(preset, _freeze(model))
    values["model.preset"] = preset
    for name in PARAMETERS:
        values[f"model.{name}"] = getattr(train, name)

    if "profile" not in raw:
        raise SpecProblem(
            "profile",
            "missing; give the cam in the base, an axis or a case, "
            "e.g. profile: {kind: harmonic, lift: 1 in}",
        )
    prof = check_profile(raw["profile"], "profile", partial=False)
    defects = check_defects(raw["defects"], "defects")
    profile, canonical_profile, canonical_defects, pvalues, dlabel, full = _with_defects(
        _freeze(prof), tuple(_freeze(d) for d in defects), directory
    )
    values.update(pvalues)
    values["defects"] = dlabel

    if "speed" not in raw:
        raise SpecProblem(
            "speed",
            "missing; give the cam speed in the base, an axis or a case, e.g. speed: 9000 rpm",
        )
    speed = _parse("speed", _freeze(raw["speed"]), "speed")
    seat = _parse("seat", _freeze(raw["seat"]), "seat")
    closure = _parse("closure", raw["closure"], "closure")
    ratio = train.rocker_valve_arm_length / train.rocker_pushrod_arm_length
    if not math.isnan(train.lash):
        if seat is not None:
            raise SpecProblem(
                "seat",
                f"found {excerpt(raw['seat'])} beside model.lash "
                f"{train.lash / INCH:.4g} in: the lash places the seat; give one of them "
                "(seat: none, or model.lash: none)",
            )
        seat = lash_seat(system_matrices(train), train.lash)
    if seat is not None:
        if seat >= full * ratio:
            raise (
                SpecProblem(
                    "seat",
                    f"found {excerpt(raw['seat'])}, expected a valve lift below "
                    f"the full valve lift {full * ratio / INCH:.4g} in (cam lift "
                    f"{full / INCH:.4g} in × rocker ratio {ratio:.4g}): above it "
                    "the valve never leaves its seat",
                )
                if math.isnan(train.lash)
                else SpecProblem(
                    "model.lash",
                    f"found {train.lash / INCH:.4g} in, expected less than the cam's full lift "
                    f"{full / INCH:.4g} in: the follower would never reach the rocker",
                )
            )
    run = raw["run"]
    # the engine's settings; the study's own (record, compression) are read by ``expand``
    rs = {k: _parse(f"run.{k}", _freeze(run[k]), f"run.{k}") for k in RUN_SETTINGS}
    rs["integrator"] = case_integrator(rs["integrator"], train, seat is not None)
    settings = RunSettings(**rs)
    check_settings(settings)
    case = Case(train, profile, speed, math.nan if seat is None else seat, closure)
    try:
        check_contacts([case], settings)
        check_newmark_linear([case], settings)
        check_stability([case], settings)
    except RunSettingsError as exc:
        raise SpecProblem.from_error(exc) from None
    except CaseError as exc:  # a contact law's key is a model parameter
        path = f"model.{exc.key}" if exc.key in PARAMETERS else None
        raise SpecProblem.from_error(exc, path) from None
    values.update(
        {
            "speed": speed,
            "seat": math.nan if seat is None else seat,
            "closure": closure,
            **{f"run.{name}": _archive_value(getattr(settings, name)) for name in RUN_SETTINGS},
            "run.integrator": settings.method,
            "run.dt": math.nan if settings.step is None else settings.step,
        }
    )
    canonical = {
        "model": {name: _clean(v) for name, v in defining_values(train).items()},
        "profile": canonical_profile,
        "defects": canonical_defects,
        "speed": _clean(speed),
        "seat": None if seat is None else _clean(seat),
        "closure": closure,
        "run": canonical_run(settings),
    }
    return ResolvedCase(index, case, settings, values, case_id(canonical)), canonical


#: Run settings every case id records; other RunSettings fields enter an id only when they
#: differ from their default, so a field the engine adds does not change existing ids.
CANONICAL_RUN = ("integrator", "dt", "revolutions", "output_every", "tolerance", "max_events")


def canonical_run(settings: RunSettings) -> dict[str, object]:
    """The run settings in a case id."""
    out: dict[str, object] = {
        "integrator": settings.method,
        "dt": None if settings.step is None else _clean(settings.step),
        "revolutions": _clean(float(settings.revolutions)),
        "output_every": _clean(settings.output_every),
        "tolerance": _clean(settings.tolerance),
        "max_events": settings.max_events,
    }
    for f in dataclasses.fields(RunSettings):
        if f.name not in CANONICAL_RUN and getattr(settings, f.name) != f.default:
            out[f.name] = _clean(getattr(settings, f.name))
    return out


def check_settings(settings: RunSettings) -> None:
    """Run the settings' own checks (integrator, step, fidelity) before anything runs, each
    refusal a problem at its key (``run.fidelity``)."""
    try:
        for name in ("method", "step", "warmup_turns"):
            getattr(settings, name, None)
        settings.check_fidelity()
    except RunSettingsError as exc:
        raise SpecProblem.from_error(exc) from None


def _archive_value(v: object) -> object:
    return math.nan if v is None else v


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
    return Study(
        spec=spec,
        cases=cases,
        axes=axes,
        varied=varied_keys(spec),
        revolutions=float(run["revolutions"]),
        output_every=float(_parse("run.output_every", run["output_every"], "run.output_every")),
        record=tuple(run["record"]),
        compression=str(run["compression"]),
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
        speeds = [_parse("speed", _freeze(v), "speed") for (v,) in axes[k].rows]
        others = [
            _resolve(raw, index, spec.directory)
            for index, (raw, _) in enumerate(raw_cases(spec, fixed={k: 0}))
        ]
    except SpecProblem:
        return None
    if len({_clean(v) for v in speeds}) < len(speeds):
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
    return tuple(out)
