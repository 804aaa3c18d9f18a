"""Each case of a study resolved to engine inputs and a stable id.

A case (spec data, defaults filled in) is resolved to SI and to the engine's
:class:`~campipe.engine.Case` and :class:`~campipe.engine.RunSettings`; its id is the SHA-256
of its canonical parameters (every model parameter, the cam with its defects, speed, seat,
closure and run settings, SI, as sorted JSON). A measured lift table enters the id by its
values, not its path. A speed sweep's cases are built on demand (:class:`SpeedSweep`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np

from campipe.engine import Case, CaseError, RunSettings, RunSettingsError
from campipe.engine.settings import (
    case_integrator,
    check_adjuster_run,
    check_contacts,
    check_settling,
    check_stability,
)
from campipe.errors import excerpt
from campipe.io.lift_table import LiftTableError, read_lift_table, table_digest
from campipe.model import (
    PARAMETERS,
    ModelParameterError,
    ValveTrain,
    defining_values,
    system_matrices,
    train_lash_seat,
    valve_train,
)
from campipe.model.levers import LEVERS
from campipe.profiles import (
    INCHES,
    LengthUnit,
    Profile,
    Ramp,
    bump,
    flat,
    format_length,
    harmonic,
    max_lift,
    min_lift,
    polydyne,
    table,
)
from campipe.profiles.defects import flat_dip, flat_step, level_again
from campipe.profiles.levers import valve_side
from campipe.profiles.pieces import format_angle
from campipe.study.spec.blocks import check_defects, check_profile
from campipe.study.spec.fields import (
    CASE_FIELDS,
    DEFECT_FIELDS,
    PROFILE_FIELDS,
    RUN_SETTINGS,
    SpecProblem,
    varied_fields,
)
from campipe.units import QuantityError, parse_quantity, written_units

#: Lift below the base circle tolerated as round-off [m].
LIFT_TOLERANCE = 1e-12
#: A lift table's periodic cubic spline below the base circle tolerated as its ringing, a
#: fraction of the cam's lift: a polydyne tabulated every 1° (each point ≥ 0) dips 4.4e-10 m
#: below 0 beside its dwell under a 10 mm lift, and every 2° about 7e-9 m.
TABLE_RING = 1e-6
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


def freeze(value: object) -> object:
    if isinstance(value, Mapping):
        return tuple(sorted((k, freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(freeze(v) for v in value)
    return value


def _thaw(frozen: tuple) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in frozen}


@functools.lru_cache(maxsize=4096, typed=True)  # typed: True is not 1
def parse_value(key: str, value: object, path: str) -> Any:
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


def valve_lift_ratio(train: ValveTrain, profile: Profile, full: float) -> float:
    """The valve's full lift per unit of the cam's (``full`` [m]) as a rigid train: the
    rocker's arm ratio, 1 for a lumped chain, a lever layout's kinematic valve lift's top over
    the cam's (``campipe.profiles.levers``)."""
    if train.layout in LEVERS:
        try:
            return max_lift(valve_side(profile, train)) / full
        except ModelParameterError as exc:  # a lever the cam swings too far
            raise SpecProblem.from_error(exc, f"model.{exc.key}") from None
    if train.chain:
        return 1.0
    return train.rocker_valve_arm_length / train.rocker_pushrod_arm_length


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
def _lift_table(path: Path, mtime_ns: int) -> tuple[np.ndarray, np.ndarray, str, str]:
    """(angles, lifts, digest, the lift's units as the header writes them) of a table."""
    try:
        angles, lifts, units = read_lift_table(path)
    except LiftTableError as exc:
        raise SpecProblem("profile.file", str(exc)) from None
    return angles, lifts, table_digest(angles, lifts), units


@functools.lru_cache(maxsize=1024)
def _profile(frozen: tuple, directory: Path) -> tuple[Profile, dict, dict[str, object], object]:
    """(profile, canonical form, archive values, its lift as written: the spec's ``lift``, a
    table's "1 <its header's units>", for messages in those units) of a checked profile
    mapping."""
    spec = _thaw(frozen)
    kind = spec["kind"]
    values: dict[str, object] = {"profile.kind": kind}
    si = {k: PROFILE_FIELDS[k].parse(v, f"profile.{k}") for k, v in spec.items() if k != "kind"}
    unit = _length_unit(spec.get("lift"))  # the label's, as the spec wrote the lift
    try:
        if kind == "harmonic":
            profile = harmonic(si["lift"], unit)
        elif kind.startswith("polydyne-"):
            ramp = None
            if "ramp_height" in si:
                if not si["ramp_height"] < si["lift"]:
                    raise SpecProblem(
                        "profile.ramp_height",
                        f"found {excerpt(spec['ramp_height'])}, expected a ramp below the "
                        f"lift ({excerpt(spec['lift'])}): the ramps take the lash up, "
                        "fractions of a millimetre",
                    )
                shape = str(si.get("ramp_shape", "constant-velocity"))
                ramp = Ramp(float(si["ramp_height"]), float(si["ramp_duration"]), shape)
            profile = polydyne(
                kind.removeprefix("polydyne-"),
                si["lift"],
                si["rise"],
                si["dwell"],
                si["fall"],
                ramp=ramp,
                unit=unit,
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
            angles, lifts, digest, lift_units = _lift_table(path, mtime)
            try:
                profile = table(angles, lifts)
            except ValueError as exc:
                raise SpecProblem("profile.file", f"{path}: {exc}") from None
            profile = dataclasses.replace(
                profile, label=f"table {Path(si['file']).name} ({angles.size} points)"
            )
            canonical = {"kind": kind, "table_sha256": digest}
            values.update({"profile.file": si["file"], "profile": profile.label})
            return profile, canonical, values, f"1 {lift_units}"
    except SpecProblem:
        raise
    except ValueError as exc:
        raise SpecProblem("profile", str(exc)) from None
    canonical = {"kind": kind, **{k: clean_value(v) for k, v in si.items()}}
    values.update({f"profile.{k}": v for k, v in si.items()})
    values["profile"] = profile.label
    return profile, canonical, values, spec.get("lift")


@functools.lru_cache(maxsize=1024)
def _with_defects(frozen_profile: tuple, frozen_defects: tuple, directory: Path):
    profile, canonical, values, written = _profile(frozen_profile, directory)
    out = profile
    defects = []
    for i, d in enumerate(_thaw_list(frozen_defects)):
        si = {
            k: DEFECT_FIELDS[k].parse(v, f"defects[{i}].{k}") for k, v in d.items() if k != "kind"
        }
        if d["kind"] == "flat":
            _check_flat(out, si["from"], si["to"], i, written)
        try:
            if d["kind"] == "flat":
                out = flat(out, si["from"], si["to"])
            else:
                unit = _length_unit(d.get("height"))
                out = bump(out, si["center"], si["height"], si["width"], unit)
        except ValueError as exc:
            raise SpecProblem(f"defects[{i}]", str(exc)) from None
        defects.append({"kind": d["kind"], **{k: clean_value(v) for k, v in si.items()}})
    label = out.label[len(profile.label) :].removeprefix(" + ") if defects else "none"
    low, high = min_lift(out), max_lift(out)
    ring = TABLE_RING * high if "profile.file" in values else 0.0
    if low < -max(LIFT_TOLERANCE, ring):
        where = (
            "defects" if defects else ("profile.file" if "profile.file" in values else "profile")
        )
        raise SpecProblem(
            where,
            f"the cam's lift falls to {_in_units(low, written)}; expected a "
            "lift never below the base circle (0)",
        )
    if not high > LIFT_TOLERANCE:
        where = "profile.file" if "profile.file" in values else "profile"
        raise SpecProblem(
            where,
            f"the cam's lift never rises above {_in_units(high, written)}; expected a cam that "
            "lifts the follower",
        )
    return out, canonical, defects, values, label, high


def _thaw_list(frozen: tuple) -> list[dict]:
    return [dict(d) for d in frozen]


def clean_value(v: object) -> object:
    """Floats as JSON keeps them; −0.0 as 0.0 (the same case)."""
    if isinstance(v, float):
        return v + 0.0
    if isinstance(v, tuple | list):
        return [clean_value(x) for x in v]
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
        return lambda speed: case_id({**canonical, "speed": clean_value(speed)})
    before = hashlib.sha256(head.encode())
    after = tail.encode()

    def one(speed: float) -> str:
        h = before.copy()
        h.update(_canonical_json(clean_value(speed)).encode())
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
    return resolve_canonical(raw, index, directory)[0]


def resolve_canonical(raw: Mapping, index: int, directory: Path) -> tuple[ResolvedCase, dict]:
    """:func:`resolve`, and the canonical parameters the case id hashes."""
    values: dict[str, object] = {}
    model = dict(raw["model"])
    preset = model.pop("preset")
    train = _train(preset, freeze(model))
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
        freeze(prof), tuple(freeze(d) for d in defects), directory
    )
    values.update(pvalues)
    values["defects"] = dlabel

    if "speed" not in raw:
        raise SpecProblem(
            "speed",
            "missing; give the cam speed in the base, an axis or a case, e.g. speed: 9000 rpm "
            "(or the engine's, engine_speed: 18000 rpm, with drive: {cam_per_crank: 0.5}); a "
            "spec for campipe design needs one too, whatever speeds its requirements give",
        )
    speed = parse_value("speed", freeze(raw["speed"]), "speed")
    seat = parse_value("seat", freeze(raw["seat"]), "seat")
    closure = parse_value("closure", raw["closure"], "closure")
    ratio = valve_lift_ratio(train, profile, full)
    if not math.isnan(train.lash):
        seat = _lash_placed_seat(raw, model, train, seat)
    if seat is not None and seat >= full * ratio:
        raise (
            SpecProblem(
                "seat",
                f"found {excerpt(raw['seat'])}, expected a valve lift below "
                f"the full valve lift {_in_units(full * ratio, raw['seat'], prof.get('lift'))} "
                f"(cam lift {_in_units(full, prof.get('lift'))} × rocker ratio {ratio:.4g}): "
                "above it "
                "the valve never leaves its seat",
            )
            if math.isnan(train.lash)
            else SpecProblem(
                "model.lash",
                f"found {_lash_words(model, train)}, which places the seat at "
                f"{_in_units(seat, model.get('lash'))}, expected a seat below the full "
                f"valve lift {_in_units(full * ratio, model.get('lash'))}: the follower would "
                "never reach the rocker",
            )
        )
    run = raw["run"]
    # the engine's settings; the study's own (record, compression) are read by ``expand``
    rs = {k: parse_value(f"run.{k}", freeze(run[k]), f"run.{k}") for k in RUN_SETTINGS}
    rs["integrator"] = case_integrator(rs["integrator"], train, seat is not None)
    settings = RunSettings(**rs)
    check_settings(settings)
    case = Case(train, profile, speed, math.nan if seat is None else seat, closure)
    try:
        check_contacts([case], settings)
        check_stability([case], settings)
        check_adjuster_run(case, settings, "the model has a lash adjuster, and")
    except RunSettingsError as exc:
        raise SpecProblem.from_error(exc) from None
    except CaseError as exc:  # a contact law's key is a model parameter
        path = f"model.{exc.key}" if exc.key in PARAMETERS else None
        raise SpecProblem.from_error(exc, path) from None
    values.update(
        {
            "speed": speed,
            "seat": math.nan if seat is None else case.seat - case.lift_zero,  # 0: a lash's
            "closure": closure,
            **{f"run.{name}": _archive_value(getattr(settings, name)) for name in RUN_SETTINGS},
            "run.integrator": settings.method,
            "run.dt": math.nan if settings.step is None else settings.step,
        }
    )
    canonical = {
        "model": {name: clean_value(v) for name, v in defining_values(train).items()},
        "profile": canonical_profile,
        "defects": canonical_defects,
        "speed": clean_value(speed),
        "seat": None if seat is None else clean_value(seat),
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
        "dt": None if settings.step is None else clean_value(settings.step),
        "revolutions": "auto"
        if settings.revolutions is None
        else clean_value(float(settings.revolutions)),
        "output_every": clean_value(settings.output_every),
        "tolerance": clean_value(settings.tolerance),
        "max_events": settings.max_events,
    }
    for f in dataclasses.fields(RunSettings):
        if f.name not in CANONICAL_RUN and getattr(settings, f.name) != f.default:
            out[f.name] = clean_value(getattr(settings, f.name))
    return out


def _lash_placed_seat(raw: Mapping, model: Mapping, train: ValveTrain, seat: float | None) -> float:
    """The seat a train's lash places (``campipe.model.lash_seat``); a seat given beside it
    refused at ``seat``, with the seat the lash places in the spec's units."""
    placed = train_lash_seat(train)
    if seat is not None:
        where = _in_units(placed, model.get("lash"), raw["seat"])
        raise SpecProblem(
            "seat",
            f"found {excerpt(raw['seat'])} beside model.lash {_lash_words(model, train)}, "
            f"which places the seat at {where} (a valve lift from the valve's static position "
            "on the base circle, as seat is given); give one of them (seat: none, or "
            "model.lash: none)",
        )
    return placed


def _lash_words(model: Mapping, train: ValveTrain) -> str:
    """The train's lash as the spec wrote it and its side: ``0.2 mm on the valve side``."""
    written = model.get("lash")
    lash = excerpt(written) if isinstance(written, str) else _in_units(train.lash)
    return f"{lash} on the {train.lash_side} side"


def _length_unit(*written: object) -> LengthUnit:
    """The unit of the first of the spec's values ``written`` that is a length with units
    (``0.2 mm``: millimetres, as written), else the thesis's inches. Its size is read as a
    quantity's value is, kept from run to run (pint stays unloaded on a warm run)."""
    for text in written:
        units = written_units(text)
        if units:
            try:
                return LengthUnit(units, parse_quantity(f"1 {units}", "m", ""))
            except QuantityError:
                continue
    return INCHES


#: A flat's step in the lift at its end tolerated as round-off [m] (a nanometre).
FLAT_STEP = 1e-9


def _check_flat(profile, start: float, end: float, i: int, written: object) -> None:
    """Refuse defects[i], a flat from ``start`` to ``end`` [rad] on ``profile``, that no
    grinding makes: its ends at unequal lift (a step in the lift at its end: a helper's flat
    at 350–370° on the thesis's harmonic cam dropped it 0.174 in at once; one at 100–120°
    raised it 0.059 in within a sample, 20 608 lbf), or the lift below its start's within it
    (the flat would add metal)."""
    step = flat_step(profile, start, end)
    dip = flat_dip(profile, start, end)
    if abs(step) <= FLAT_STEP and dip <= FLAT_STEP:
        return
    if abs(step) > FLAT_STEP:
        what = (
            f"the lift at its end ({format_angle(end)} deg) is "
            f"{_in_units(abs(step), written)} {'higher' if step > 0 else 'lower'}: a step in "
            "the cam"
        )
    else:
        what = f"the lift falls {_in_units(dip, written)} below it within: it would add metal"
    back = level_again(profile, start)
    at = f"{math.degrees(back or 0.0):.6f}".rstrip("0").rstrip(".")
    where = f"end it at {at} deg, where the lift comes back to it, or " if back else ""
    raise SpecProblem(
        f"defects[{i}]",
        f"a flat holds the lift where it starts ({format_angle(start)} deg), and {what}, which "
        f"no grinding makes; {where}place it across the nose or on a dwell",
    )


def _in_units(value: float, *written: object) -> str:
    """A length ``value`` [m] in the units of the first of the spec's values ``written``
    that is a length with units (``0.2 mm``), else in inches."""
    return format_length(value, _length_unit(*written))


def check_settings(settings: RunSettings) -> None:
    """Run the settings' own checks (integrator, step, fidelity) before anything runs, each
    refusal a problem at its key (``run.fidelity``)."""
    try:
        for name in ("method", "step", "warmup_turns"):
            getattr(settings, name, None)
        settings.check_fidelity()
        settings.check_whole_turns()
        if settings.settle:
            check_settling(settings)
    except RunSettingsError as exc:
        raise SpecProblem.from_error(exc) from None


def _archive_value(v: object) -> object:
    return math.nan if v is None else v
