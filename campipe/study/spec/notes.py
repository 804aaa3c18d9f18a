"""Notes on a study's cases that run but deserve a word (``campipe validate`` and
``campipe study`` print them): a lash adjuster moved once a turn or started extended past
the dry lash, lash the ramps do not take up, a valve spring's odd deflection or assumed
travel to solid, a mass in the wrong unit, a lever whose reduced mass moves far from its rest
value, an undercut cam, a contact stiffer than any valve train's. Each names its keys; none
refuses a case."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from campipe.engine import Case
from campipe.model import valve_train
from campipe.model.checks import DIRECT_ACTING, LUMPED
from campipe.model.levers import LEVERS
from campipe.profiles.levers import cam_of
from campipe.study.spec.resolve import ResolvedCase, distinct_but_speed, valve_lift_ratio


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
        "per-turn model): below the onset within 8 % a turn of the plunger carried within the "
        "turn (0.08 % on the bundled finger; 5.4 % on the bundled bucket, whose link rings in "
        "tension after landing); past it, where the plunger pumps up into the follower's "
        "flights, a turn's pump-up may be off by half, against a carried plunger that itself "
        "moves with its contacts' stiffness (docs/model.md). Compliant contacts (cam_contact, "
        "seat_contact) carry it within the turn"
    )


def extension_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases whose lash adjuster starts extended past the dry lash by more than
    holds the valve on its seat: its effective lash (``lash`` less what ``hla_extension``
    takes up) below −P·(the train's flexibility from the adjuster to the seat), P the seated
    spring force, so the valve starts held off its seat on the base circle until the plunger
    leaks down; most likely an extension written for another lash. The farthest named; None
    where there are none."""
    from campipe.model.hla import has_adjuster, seated_flexibility, taken_up

    combinations, speeds = distinct_but_speed(cases)
    worst, n = None, 0
    for c in combinations:
        t = c.case.train
        if not has_adjuster(t):
            continue
        effective = t.lash - float(taken_up(t, np.array(t.hla_extension)))
        held = -t.spring_preload * seated_flexibility(t)
        if effective < held:
            n += speeds
            if worst is None or effective < worst[0]:
                worst = (effective, held, t)
    if worst is None:
        return None
    effective, held, t = worst
    return (
        f"{n} case{'s start' if n != 1 else ' starts'} the lash adjuster extended past the dry "
        f"lash: model.hla_extension {t.hla_extension * 1e3:.4g} mm on model.lash "
        f"{t.lash * 1e3:.4g} mm leaves an effective lash of {effective * 1e3:.4g} mm, below the "
        f"{held * 1e3:.3g} mm at which the valve is held off its seat on the base circle: it "
        "starts open and stays so until the plunger leaks down (docs/model.md, Hydraulic lash "
        "adjuster); give the extension the lash takes"
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
        train, cam = c.case.train, cam_of(c.case.profile)
        if not train.cam_base_radius > 0.0:  # NaN: not given
            continue
        key = (*cam.content_key, train.cam_base_radius, train.cam_roller_radius)
        if key not in seen:
            seen[key] = undercut_text(cam, train.cam_base_radius, train.cam_roller_radius)
        if seen[key] is not None and seen[key] not in found:
            found.append(seen[key])
    if not found:
        return None
    more = f" ({len(found) - 1} more of the study's cams too)" if len(found) > 1 else ""
    return f"{found[0]}{more}"


#: The masses [kg] of a valve train's members a spec is noted outside of (``mass_note``):
#: they weigh grams to hundreds of grams (a lever's reduced to its valve likewise), so a mass
#: or an inertia in the wrong unit (kg for g, kg*m**2 for kg*mm**2) falls far outside.
MASS_RANGE = (1e-4, 5.0)


def _masses(train) -> list[tuple[str, str, float]]:
    """(key, what, mass [kg]) of a train whose masses a spec gives (not the thesis's, derived
    from its members' geometry)."""
    if train.layout in LEVERS:
        what = "the lever's mass reduced to the valve, (J + m_r·a²)/(b·cos α₀)²,"
        return [("lever_inertia", what, train.masses[0]), ("valve_mass", "", train.valve_mass)]
    if train.layout == DIRECT_ACTING:
        return [("tappet_mass", "", train.tappet_mass), ("valve_mass", "", train.valve_mass)]
    if train.layout == LUMPED:
        return [(f"masses[{i}]", "", m) for i, m in enumerate(train.masses)]
    return []


def mass_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the cases with a mass outside :data:`MASS_RANGE`, the farthest named: most
    likely written in the wrong unit. None where there are none."""
    combinations, speeds = distinct_but_speed(cases)
    odd = []
    for c in combinations:
        for key, what, mass in _masses(c.case.train):
            if not MASS_RANGE[0] <= mass <= MASS_RANGE[1]:
                odd.append((abs(math.log(mass / 0.05)), key, what, mass))
                break
    if not odd:
        return None
    _, key, what, mass = max(odd)
    n = speeds * len(odd)
    low, high = MASS_RANGE
    return (
        f"{n} case{'s have' if n != 1 else ' has'} a mass far from a valve train's grams: "
        f"model.{key}{' gives ' + what if what else ''} {mass * 1e3:.4g} g (outside "
        f"{low * 1e3:g} g to {high:g} kg): check its units (kg*mm**2 is not kg*m**2, g not kg)"
    )


#: How far a lever's mass reduced to the valve may move from its rest value over the cam's
#: turn (``lever_note``) before a note says that the dynamics hold it there: a rocker tilted
#: 10° below level moves it by 13 %, and an independent model with the exact inertia put its
#: onset 2.4 % below campipe's; the bundled level finger's 6.6 % is not noted.
REDUCED_MASS_CHANGE = 0.1


def lever_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on the lever layouts' cases whose lever turns enough over the cam's turn to move
    its mass reduced to the valve by more than :data:`REDUCED_MASS_CHANGE` of its rest value,
    at which the dynamics hold it (``campipe.model.levers``), the largest named. None where
    there are none."""
    from campipe.model.levers import lever_of, reduced_mass_factor
    from campipe.profiles.levers import cam_kinematics

    combinations, speeds = distinct_but_speed(cases)
    theta = np.radians(np.arange(0.0, 360.0, 0.5))
    worst, n = None, 0
    for c in combinations:
        train = c.case.train
        if train.layout not in LEVERS:
            continue
        angle = cam_kinematics(cam_of(c.case.profile), train, theta).angle
        factor = reduced_mass_factor(lever_of(train), angle)
        change = factor[np.argmax(np.abs(factor - 1.0))] - 1.0
        if abs(change) > REDUCED_MASS_CHANGE:
            n += speeds
            if worst is None or abs(change) > abs(worst[0]):
                worst = (change, train.lever_rest_angle)
    if worst is None:
        return None
    change, rest = worst
    return (
        f"{n} case{'s' if n != 1 else ''}' lever{'s turn' if n != 1 else ' turns'} enough to "
        f"change the lever's mass reduced to the valve by up to {change:+.1%} over the cam's "
        f"turn (cos²α₀/cos²α, model.lever_rest_angle {math.degrees(rest):g}°), which the "
        "dynamics hold at its rest value: the onset and the forces may be off by a few per "
        "cent (docs/model.md, Lever layouts; campipe model tabulates the factor)"
    )


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


#: The relative shortfall of the spring's force on the base circle from ``spring_preload``
#: (a train without lash) above which it is noted.
PRELOAD_SHORTFALL = 0.05


def preload_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on cases without lash whose spring pushes on the base circle more than
    :data:`PRELOAD_SHORTFALL` less than ``spring_preload`` (the force at the train's
    unstressed reference; ``campipe.model.spring.base_circle_force``): a soft chain's links
    give under it. None where there are none."""
    from campipe.model.spring import base_circle_force

    combinations, speeds = distinct_but_speed(cases)
    worst, n = None, 0
    for c in combinations:
        t = c.case.train
        if t.lash == t.lash or not t.spring_preload > 0.0:  # with lash: the seated force
            continue
        ratio = base_circle_force(t) / t.spring_preload
        if ratio < 1.0 - PRELOAD_SHORTFALL:
            n += speeds
            if worst is None or ratio < worst[0]:
                worst = (ratio, t)
    if worst is None:
        return None
    ratio, t = worst
    whose = f"{n} cases' springs push" if n != 1 else "1 case's spring pushes"
    return (
        f"{whose} on the base circle well below model.spring_preload: "
        f"{t.spring_preload:.4g} N is the force at the train's unstressed reference, and "
        f"without lash its links give under it, so the spring pushes "
        f"{ratio * t.spring_preload:.4g} N ({(1 - ratio) * 100:.3g} % less); for "
        f"{t.spring_preload:.4g} N there give {t.spring_preload / ratio:.4g} N, or set "
        "model.lash (then spring_preload is the seated force)"
    )


#: A cam speed [rpm] beyond any valve train's (an engine at 20 000 rpm turns its cams at
#: 10 000; the thesis's runs reach 20 000): a spec's speed above it is noted.
FASTEST_CAM_RPM = 30_000.0


def speed_note(cases: Sequence[ResolvedCase]) -> str | None:
    """A note on cases whose cam turns faster than :data:`FASTEST_CAM_RPM`: most likely a unit
    slip (rps for rpm); they run, and the motion is what the model gives. None where there
    are none."""
    from campipe.constants import RPM

    combinations, _ = distinct_but_speed(cases)
    swept = getattr(cases, "speeds", None)  # a speed sweep's, without building its cases
    if swept is not None:
        speeds = np.asarray(swept) / RPM
        fast = speeds[speeds > FASTEST_CAM_RPM]
        n = fast.size * len(combinations)
    else:
        speeds = np.array([c.case.speed / RPM for c in cases])
        fast = speeds[speeds > FASTEST_CAM_RPM]
        n = fast.size
    if not n:
        return None
    return (
        f"{n} case{'s turn' if n != 1 else ' turns'} the cam faster than {FASTEST_CAM_RPM:g} "
        f"rpm, beyond any valve train's (the fastest {fast.max():.6g} rpm): check the speed's "
        "units (rps is 60 rpm)"
    )


def case_notes(cases: Sequence[ResolvedCase], record: Sequence[str]) -> list[tuple[str, str]]:
    """(topic, note) of each note the cases (a study recording ``record``) deserve, in the
    order ``campipe validate`` prints them."""
    found = (
        ("lash adjuster", per_turn_note(cases)),
        ("lash adjuster", extension_note(cases)),
        ("lash", ramp_note(cases)),
        ("spring", spring_note(cases)),
        ("mass", mass_note(cases)),
        ("lever", lever_note(cases)),
        ("spring", travel_note(cases, record)),
        ("spring", preload_note(cases)),
        ("cam", cam_note(cases)),
        ("contact", contact_note(cases)),
        ("speed", speed_note(cases)),
    )
    return [(topic, note) for topic, note in found if note is not None]
