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
from campipe.profiles.levers import valve_side
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


def per_turn_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases whose lash adjuster's plunger is moved once a turn, not carried
    within it (``engine.plunger.carried``: a finger's pivot with rigid contacts, or
    newmark-linear), with the per-turn model's error as docs/model.md states it; None where
    there are none."""
    from campipe.engine.plunger import carried
    from campipe.model.hla import adjuster

    combinations, speeds = distinct_but_speed(cases)
    n = speeds * sum(
        adjuster(c.case.train) is not None and not carried(c.case, c.settings.integrator)
        for c in combinations
    )
    if not n:
        return None
    return (
        f"{n} case{'s' if n != 1 else ''} move{'' if n != 1 else 's'} the lash adjuster's "
        "plunger once a turn (a finger's pivot with rigid contacts, or newmark-linear: the "
        "per-turn model): below the onset within 3 % a turn of the plunger carried within the "
        "turn; past it, where the plunger pumps up into the follower's flights, a turn's "
        "pump-up may be off by a third or more (docs/model.md). Compliant contacts "
        "(cam_contact, seat_contact) carry it within the turn"
    )


#: A lash the ramps do not take up is noted where the valve's kinematic landing velocity (the
#: cam's where its lift crosses the seat) is this much above the ramp's (``ramp_note``).
RAMP_EXCESS = 1.1


def ramp_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases whose lash the cam's ramps do not take up: the valve's seat (the
    lash and the train's compression under the preload, as a valve lift) above the opening
    ramp's top at the valve, so the follower lifts the valve off its seat, and sets it
    down, on the flanks, at a kinematic velocity (the cam's where its lift crosses the seat)
    more than RAMP_EXCESS × the ramp's. None where there are none (or no ramps)."""
    combinations, speeds = distinct_but_speed(cases)
    beyond = []
    for c in combinations:
        ramp = c.values.get("profile.ramp_duration")
        if not isinstance(ramp, float) or math.isnan(getattr(c.case.train, "lash", math.nan)):
            continue
        excess = _landing_excess(c.case, ramp)
        if excess > RAMP_EXCESS:
            beyond.append((excess, c.case.seat))
    if not beyond:
        return None
    n = speeds * len(beyond)
    excess, seat = max(beyond)
    return (
        f"{n} case{'s' if n != 1 else ''} take{'' if n != 1 else 's'} up more lash than the "
        f"cam's ramps: the valve leaves its seat, and lands on it, on the flanks, at up to "
        f"{excess:.3g} times the ramp's velocity by the cam's kinematics (a seat at "
        f"{seat * 1e3:.4g} mm of valve lift, the lash and the train's compression under the "
        "preload); a ramp above the seat keeps the landing at its velocity"
    )


#: The valve spring's deflection under its preload [m] a spec is noted outside of
#: (``spring_note``): valve springs take their preload over millimetres (the thesis's 16 mm,
#: the bundled bucket's 6 mm), so a rate or a preload in the wrong unit (N/m for N/mm) falls
#: far outside.
SPRING_DEFLECTION = (1e-4, 0.1)


def spring_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases whose valve spring holds its preload at a deflection (preload over
    rate) outside :data:`SPRING_DEFLECTION`: a rate or a preload most likely written in the
    wrong unit. None where there are none."""
    combinations, speeds = distinct_but_speed(cases)
    odd = []
    for c in combinations:
        t = c.case.train
        if t.spring_preload > 0.0 and t.spring_rate > 0.0:
            deflection = t.spring_preload / t.spring_rate
            low, high = SPRING_DEFLECTION
            if not low <= deflection <= high:
                odd.append((abs(math.log(deflection / 0.01)), deflection, t))
    if not odd:
        return None
    n = speeds * len(odd)
    _, deflection, t = max(odd, key=lambda o: o[0])
    whose = f"{n} cases' valve springs hold their" if n != 1 else "1 case's valve spring holds its"
    return (
        f"{whose} preload at a deflection far from a valve spring's millimetres: "
        f"{t.spring_preload:.4g} N over {t.spring_rate / 1e3:.4g} N/mm is "
        f"{deflection * 1e3:.4g} mm (model.spring_preload over model.spring_rate; a rate "
        "written in N/m for N/mm gives that)"
    )


#: The stiffest compliant contacts a valve train has, by its pair's modulus (E*): a steel
#: line contact 100 mm long, (π/2)·E*·w [N/m], and a point contact of 1 m relative radius,
#: (4/3)·E*·√R' [N/m^1.5]; a given constant beyond :data:`CONTACT_EXCESS` of it is noted.
CONTACT_WIDEST, CONTACT_FLATTEST, CONTACT_EXCESS = 0.1, 1.0, 10.0


def contact_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on a compliant contact's stiffness (``*_contact_stiffness``,
    ``*_hertz_constant``) beyond :data:`CONTACT_EXCESS` times the stiffest a valve train's
    contact of its material has: most likely written in the wrong unit, and a run takes steps
    as its period, √(m/k), so it runs long. None where there are none."""
    from campipe.model.contact import hertz_constant, line_contact_stiffness, pair_modulus

    combinations, speeds = distinct_but_speed(cases)
    worst = None
    for c in combinations:
        t = c.case.train
        pair = pair_modulus(t.contact_modulus, t.contact_poisson)
        for contact in ("cam", "seat"):
            for name, most, units in (
                (f"{contact}_contact_stiffness", line_contact_stiffness(pair, CONTACT_WIDEST),
                 "N/m"),
                (f"{contact}_hertz_constant", hertz_constant(pair, CONTACT_FLATTEST), "N/m^1.5"),
            ):  # fmt: skip
                value = getattr(t, name)
                if value > CONTACT_EXCESS * most and (worst is None or value / most > worst[0]):
                    worst = (value / most, name, value, most, units)
    if worst is None:
        return None
    ratio, name, value, most, units = worst
    what = "a steel line contact 100 mm long" if "stiffness" in name else (
        "a steel point contact of 1 m relative radius")  # fmt: skip
    return (
        f"model.{name} {value:.3g} {units} is {ratio:.3g}× {what} ({most:.3g} {units}, "
        "from contact_modulus): check its units; a compliant contact's run takes steps of its "
        "period, √(m/k), so a stiffer one runs longer"
    )


#: What ``run.record`` names that stores the valve spring's coil-clash margin.
CLASH_RECORDS = ("spring", "spring_clash_margin")


def travel_note(cases: Sequence[ResolvedCase], record: Sequence[str]) -> str | None:
    """A note on the cases of a layout other than the thesis's whose coil-clash margin (a
    ``record`` of the spring's) is taken against the thesis's spring travel to solid, the
    key's default: campipe assumes it for the thesis's train, which gives no spring geometry,
    and a chain's or a lever's spring is not that one. None where there are none."""
    if not set(record) & set(CLASH_RECORDS):
        return None
    combinations, speeds = distinct_but_speed(cases)
    assumed = valve_train().spring_travel_to_solid
    layouts = sorted(
        {c.case.train.layout for c in combinations if c.case.train.chain
         and c.case.train.spring_travel_to_solid == assumed}
    )  # fmt: skip
    if not layouts:
        return None
    return (
        f"the coil-clash margin of layout {', '.join(layouts)} is taken against the thesis's "
        f"assumed spring travel to solid, {assumed * 1e3:.4g} mm (1.6 in, "
        "model.spring_travel_to_solid's default): give your spring's own"
    )


def cam_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases whose cam, given its base circle (``model.cam_base_radius``), is
    undercut: no cam makes its lift under their follower (:mod:`campipe.profiles.curvature`);
    the first such cam, where and how. None where there are none."""
    combinations, _ = distinct_but_speed(cases)
    seen: dict[tuple, str | None] = {}
    found = []
    for c in combinations:
        train, profile = c.case.train, c.case.profile
        cam = getattr(profile, "cam", None) or profile  # a lever's excitation keeps its cam
        if not train.cam_base_radius > 0.0:  # NaN: not given
            continue
        key = (cam.breaks.tobytes(), cam.poly.tobytes(), cam.trig.tobytes(),
               train.cam_base_radius, train.cam_roller_radius)  # fmt: skip
        if key not in seen:
            seen[key] = undercut_text(cam, train.cam_base_radius, train.cam_roller_radius)
        if seen[key] is not None and seen[key] not in found:
            found.append(seen[key])
    if not found:
        return None
    more = f" ({len(found) - 1} more of the study's cams too)" if len(found) > 1 else ""
    return f"{found[0]}{more}"


def undercut_text(cam, base_radius: float, roller_radius: float) -> str | None:
    """What an undercut cam (:func:`campipe.profiles.curvature.cam_shape`) is, in words, or
    None where a cam makes the lift."""
    from campipe.profiles.curvature import cam_shape

    shape = cam_shape(cam, base_radius, roller_radius)
    start = shape.first_undercut
    if start is None:
        return None
    least, at = shape.least
    if roller_radius > 0.0:
        how = (
            f"its pitch curve turns sharper than the roller ({roller_radius * 1e3:.4g} mm, "
            f"cam_roller_radius) from {math.degrees(start):.1f}°, the cam's radius of "
            f"curvature falling to {least * 1e3:.4g} mm at {math.degrees(at):.1f}°"
        )
    else:
        how = (
            f"under a flat face its radius of curvature (base radius + lift + d²lift/dθ²) is "
            f"negative from {math.degrees(start):.1f}°, least {least * 1e3:.4g} mm at "
            f"{math.degrees(at):.1f}°"
        )
    return (
        f"the cam {cam.label} is undercut on a {base_radius * 1e3:.4g} mm base circle "
        f"(cam_base_radius): {how}; no cam makes this lift: give a larger cam_base_radius or "
        "a longer rise (the run computes the lift as given)"
    )


def _landing_excess(case: Case, ramp: float) -> float:
    """For a case whose seat is above the opening ramp's top at the valve (``ramp`` [rad]
    long, from 0), the cam's velocity where its lift at the valve first crosses the seat,
    over its velocity halfway up the ramp; NaN where the ramp takes the seat up (a smooth
    ramp's own velocity varies along it: that is no landing on the flank)."""
    from campipe.profiles import evaluate

    train = case.train  # a lever's and a chain's profile is the valve side's already
    on_valve_side = train.layout in LEVERS or train.chain
    scale = 1.0 if on_valve_side else valve_lift_ratio(train, case.profile, 1.0)  # a rocker's
    if case.seat <= scale * float(evaluate(case.profile, np.array([ramp]))[0][0]):
        return math.nan
    theta = np.linspace(ramp, math.pi, 4097)
    lift = scale * evaluate(case.profile, theta)[0]
    above = np.flatnonzero(lift >= case.seat)
    if not above.size or above[0] == 0:
        return math.nan
    k = above[0]
    at = theta[k - 1] + (case.seat - lift[k - 1]) / (lift[k] - lift[k - 1]) * (
        theta[k] - theta[k - 1]
    )
    velocity = evaluate(case.profile, np.array([at, 0.5 * ramp]))[1]
    return float(velocity[0] / velocity[1])


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
    unit = _length_unit(spec.get("lift"))  # the label's, as the spec wrote the lift
    try:
        if kind == "harmonic":
            profile = harmonic(si["lift"], unit)
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
    canonical = {"kind": kind, **{k: clean_value(v) for k, v in si.items()}}
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
                unit = _length_unit(d.get("height"))
                out = bump(out, si["center"], si["height"], si["width"], unit)
        except ValueError as exc:
            raise SpecProblem(f"defects[{i}]", str(exc)) from None
        defects.append({"kind": d["kind"], **{k: clean_value(v) for k, v in si.items()}})
    label = out.label[len(profile.label) :].removeprefix(" + ") if defects else "none"
    written = _thaw(frozen_profile).get("lift")
    low = min_lift(out)
    if low < -LIFT_TOLERANCE:
        where = (
            "defects" if defects else ("profile.file" if "profile.file" in values else "profile")
        )
        raise SpecProblem(
            where,
            f"the cam's lift falls to {_in_units(low, written)}; expected a "
            "lift never below the base circle (0)",
        )
    high = max_lift(out)
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
