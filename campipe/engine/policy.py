"""The contact and impact policy of thesis Table I, written once for every integrator of rigid
contacts: which contact holds after an impact, when a slow impact leaves its contact resting
(capture), when a bounce ends a series, what a profile break does to a follower held on the
cam, the bound on a closing speed, and what is recorded.

An integrator locates the event (modal-exact exactly, newmark-linear at a step end) and then
calls one of these; what it does to its own state (modal-exact applies the impulse to its
modes, newmark-linear spreads it over the next step) stays in the integrator.

Each function takes the contact state ``rest`` (a record with ``rest_cam``, ``rest_seat``,
``bounced_cam``, ``bounced_seat``: modal-exact's run state or newmark-linear's contact state)
and is inlined, so it compiles with its caller's flags.

No contact is ever held in tension: a held contact, resting or not, releases where its
reaction reaches zero (the integrators' monitors; ``common.is_captured``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.common import (
    CAM_SEP,
    MICRO_FLIGHT,
    SEAT_SEP,
    SMOOTH,
    captured,
    configuration,
    other_releases,
    record_event,
    record_impact,
)
from campipe.vocabulary import UNBOUNDED


@njit(inline="always")
def strike(cases, out, rest, c, w, t, seat, other_held, c_from, closing, bounces):
    """An impact of case c at time t [s] (speed w) on the cam (``seat`` False) or the seat
    (``seat``: a NumPy bool, so that what it calls compiles once for both),
    closing at ``closing`` > 0 [m/s], from configuration ``c_from``, the other contact held
    or not (``other_held``).

    Plastic (the thesis's) unless ``bounces`` and the contact has a coefficient of
    restitution e > 0 (``cases.restitution``): then the impulse is (1 + e) times the plastic
    one and the struck contact is left. A slow impact is plastic whatever e, and leaves the
    contact resting (``common.captured``): the bounces of a series end there, or where the
    series has converged, a bounce's flight (closing velocity × time since the last bounce
    there) below MICRO_FLIGHT. A resting contact releases where its force reaches zero, as
    any held one (``common.is_captured``). The other contact, if held, stays held unless
    releasing it would separate it (``common.other_releases``). A closing faster than the
    case's speed bound ends the run (UNBOUNDED). The impact is recorded.

    Returns (held, new, other_held, e, dv): the configuration the impulse acts in (both the
    struck contact and the other as held after it), the configuration after the impact, the
    other contact held, the coefficient applied (0: plastic) and the struck coordinate's
    velocity change in thesis signs (q1 down approaches the cam moving down, q7 down opens).
    """
    side = 1 if seat else 0
    capture = cases.capture[c]
    e = cases.restitution[c, side] if bounces else 0.0
    resting = captured(closing, capture)
    if e > 0.0:
        bounced = rest.bounced_seat if seat else rest.bounced_cam
        resting = resting or closing * (t - bounced) < MICRO_FLIGHT
    bounce = e > 0.0 and not resting
    if not bounce:
        e = 0.0
    dv = closing if seat else -closing
    if bounce:
        dv *= 1.0 + e
    if other_held and other_releases(cases.separation, capture, c, seat, dv):
        other_held = False
        if seat:
            rest.rest_cam = False
        else:
            rest.rest_seat = False
    held = configuration(other_held, True) if seat else configuration(True, other_held)
    new = held
    if bounce:
        new = configuration(other_held, False) if seat else configuration(False, other_held)
        if seat:
            rest.rest_seat = False
            rest.bounced_seat = t
        else:
            rest.rest_cam = False
            rest.bounced_cam = t
    if resting:
        if seat:
            rest.rest_seat = True
        else:
            rest.rest_cam = True
    if closing > cases.speed_bound[c]:
        out.status[c] = UNBOUNDED
    record_impact(
        out.events, out.n_events, out.per_rev, cases.meff, c, w, t, seat, other_held,
        c_from, new, closing, capture, e,
    )  # fmt: skip
    return held, new, other_held, e, dv


@njit(inline="always")
def strike_at_break(cases, out, rest, c, w, t, seat_held, c_from, kind, jump, bounces):
    """A profile break under a follower held on the cam (``common.classify_break``'s
    ``kind`` and rate jump ``jump`` [m/s]): an impact of the follower by the cam surface
    unless SMOOTH. With ``bounces`` and a coefficient of restitution at the cam, a surface
    jumping into a force-closed follower throws it off. The seat, if held, releases where
    the impact would separate it. Recorded as an impact closing at |jump| (a flight too short
    to resolve is no reason to take it back here: the cam drove it).

    Returns (held, new, seat_held, e, dv) as :func:`strike` (held = new = ``c_from`` and dv
    = 0 for a SMOOTH break).
    """
    if kind == SMOOTH:
        return c_from, c_from, seat_held, 0.0, 0.0
    e = cases.restitution[c, 0] if bounces else 0.0
    bounce = jump > 0.0 and e > 0.0 and not cases.form[c]
    dv = -jump * (1.0 + e) if bounce else -jump
    if seat_held and other_releases(cases.separation, cases.capture[c], c, False, dv):
        seat_held = False
        rest.rest_seat = False
    held = configuration(True, seat_held)
    new = held
    if bounce:
        new = configuration(False, seat_held)
        rest.rest_cam = False
        rest.bounced_cam = t
    if abs(jump) > cases.speed_bound[c]:
        out.status[c] = UNBOUNDED
    record_impact(
        out.events, out.n_events, out.per_rev, cases.meff, c, w, t, np.bool_(False), seat_held,
        c_from, new, abs(jump), 0.0, e if bounce else 0.0,
    )  # fmt: skip
    return held, new, seat_held, e if bounce else 0.0, dv


@njit(inline="always")
def release(out, rest, c, t, seat, c_from, new, velocity):
    """A held contact lets go at t [s] (its force would pull, or the surface fell away at a
    break with the rate jump ``velocity`` [m/s]): it rests no more, and the release is
    recorded, from ``c_from`` to ``new``."""
    if seat:
        rest.rest_seat = False
        record_event(out.events, out.n_events, c, t, SEAT_SEP, c_from, new, velocity, 0.0)
    else:
        rest.rest_cam = False
        record_event(out.events, out.n_events, c, t, CAM_SEP, c_from, new, velocity, 0.0)
