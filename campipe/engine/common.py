"""What both integrators' compiled kernels share: the per-case inputs and the outputs they
fill, the configuration arithmetic, event and impact records, and the one classifier of a
profile break.

The vocabulary (configuration numbers, event kinds, status codes) is
:mod:`campipe.vocabulary`'s; this module compiles what the kernels call.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from campipe import vocabulary
from campipe.vocabulary import (
    CAM_IMPACT,
    EV_FROM,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    EV_TO,
    EV_VELOCITY,
    N_COORDINATES,
    N_EVENT_FIELDS,
    SEAT_IMPACT,
)

#: How the kernels and their steps compile: cached, releasing the GIL, and without numba's
#: reference counting of arrays (``_nrt=False``). They allocate nothing (every array, work
#: arrays included, comes in from Python), so there is nothing to count; and the counting
#: that numba's pruning leaves in a step loop where arrays pass between a kernel's named
#: structures and its steps costs 30–60 % of a run. An allocation in a kernel is then a
#: compile error, not a silent slowdown.
KERNEL = {"cache": True, "nogil": True, "_nrt": False}

#: The configuration arithmetic of :mod:`campipe.vocabulary`, compiled and inlined.
configuration = njit(inline="always")(vocabulary.configuration)
holds_cam = njit(inline="always")(vocabulary.holds_cam)
holds_seat = njit(inline="always")(vocabulary.holds_seat)

#: A profile break whose lift rate jumps by less than this [m/s] (beyond 1e-9 relative) is
#: smooth: rounding in re-expanded polynomial pieces, not a velocity jump.
JUMP_FLOOR = 1e-9
#: A step down in lift larger than this [m] at a break is a drop (the engine refuses steps up).
DROP_FLOOR = 1e-12
#: What a break does to a follower held on the cam (:func:`classify_break`).
SMOOTH, RELEASE, JUMP = 0, 1, 2


class Cases(NamedTuple):
    """Per case of a batch: how it is driven and where it starts (leading axis: case)."""

    omega: np.ndarray  # (n,) cam speed [rad/s]
    seat_q: np.ndarray  # (n,) q7 on the seat [m] (the valve reference where there is none)
    has_seat: np.ndarray  # (n,) bool: the valve has a seat
    form: np.ndarray  # (n,) bool: form closure (the cam never releases the follower)
    q0: np.ndarray  # (n, 7) start coordinates [m, rad]
    v0: np.ndarray  # (n, 7) start velocities [m/s, rad/s]
    a0: np.ndarray  # (n, 7) start accelerations [m/s², rad/s²]
    cfg0: np.ndarray  # (n,) int64 start configuration
    meff: np.ndarray  # (n, 4) impact masses [kg] (``contact.impact_masses`` order)


class Outputs(NamedTuple):
    """The arrays a kernel fills in place (leading axis: case)."""

    q: np.ndarray  # (n, n_out, 7) coordinates at the output angles [m, rad]
    v: np.ndarray  # (n, n_out, 7) velocities [m/s, rad/s]
    force: np.ndarray  # (n, n_out, 2) (F1, F7), thesis signs [N]
    cam: np.ndarray  # (n, n_out) cam lift [m]
    cfg: np.ndarray  # (n, n_out) int8 configuration
    sep_rev: np.ndarray  # (n, n_rev) cam angle off the cam per turn [rad]
    counts: np.ndarray  # (n, 2) int64 cam and seat impacts
    vmax: np.ndarray  # (n, 2) largest cam and seat closing velocity [m/s]
    #: (n, 3) largest compressive cam and seat force between impacts, and the cam force
    #: including the steps an impulse passes through (the thesis's "impact force") [N]
    fmax: np.ndarray
    events: np.ndarray  # (n, max_events, N_EVENT_FIELDS), rows below n_events
    n_events: np.ndarray  # (n,) int64 events of each case (may exceed max_events)
    status: np.ndarray  # (n,) int64 vocabulary status code
    steps: np.ndarray  # (n,) int64 integration steps taken


def make_outputs(n: int, n_out: int, n_rev: int, max_events: int) -> Outputs:
    """Outputs for n cases, zeroed (events uninitialised past each case's count)."""
    return Outputs(
        q=np.zeros((n, n_out, N_COORDINATES)),
        v=np.zeros((n, n_out, N_COORDINATES)),
        force=np.zeros((n, n_out, 2)),
        cam=np.zeros((n, n_out)),
        cfg=np.zeros((n, n_out), np.int8),
        sep_rev=np.zeros((n, n_rev)),
        counts=np.zeros((n, 2), np.int64),
        vmax=np.zeros((n, 2)),
        fmax=np.zeros((n, 3)),
        events=np.empty((n, max_events, N_EVENT_FIELDS)),
        n_events=np.zeros(n, np.int64),
        status=np.zeros(n, np.int64),
        steps=np.zeros(n, np.int64),
    )


@njit(**KERNEL)
def record_event(events, n_events, c, t, kind, c_from, c_to, velocity, impulse):
    """Append an event to case c's record (counted beyond the kept rows)."""
    k = n_events[c]
    if k < events.shape[1]:
        events[c, k, EV_TIME] = t
        events[c, k, EV_KIND] = kind
        events[c, k, EV_FROM] = c_from
        events[c, k, EV_TO] = c_to
        events[c, k, EV_VELOCITY] = velocity
        events[c, k, EV_IMPULSE] = impulse
    n_events[c] = k + 1


@njit(**KERNEL)
def record_impact(events, n_events, counts, vmax, meff, c, t, seat, other_held, c_from, c_to,
                  closing):  # fmt: skip
    """Count a plastic impact of case c on the cam (``seat`` False) or the seat, keep its
    largest closing velocity [m/s] in ``vmax`` and record the event with its impulse
    m_eff·v_closing; ``other_held``: the other contact is held (``contact.impact_masses``
    order)."""
    side = 1 if seat else 0
    counts[c, side] += 1
    vmax[c, side] = max(vmax[c, side], closing)
    mass = meff[c, 2 * side + (1 if other_held else 0)]
    kind = SEAT_IMPACT if seat else CAM_IMPACT
    record_event(events, n_events, c, t, kind, c_from, c_to, closing, mass * closing)


@njit(inline="always")
def classify_break(l_left, dl_left, l_right, dl_right, w, form):
    """What a profile break does to a follower held on the cam, and the lift-rate jump
    [m/s] there, from the lift [m] and its θ-derivative [m/rad] on either side at speed w.

    - RELEASE: the surface falls away (its rate drops, or its lift steps down) under a
      force-closed follower, which keeps its own velocity and leaves;
    - JUMP: the surface's rate jumps into the follower (or drags a form-closed one): an
      impact of the follower by the cam;
    - SMOOTH: a rate jump within rounding (JUMP_FLOOR, and 1e-9 relative).

    Inlined: computed with the caller's floating-point flags.
    """
    jump = w * (dl_right - dl_left)
    scale = 1e-9 * (abs(w * dl_left) + abs(w * dl_right)) + JUMP_FLOOR
    drop = l_right < l_left - DROP_FLOOR
    if (jump < -scale or drop) and not form:
        return RELEASE, jump
    if abs(jump) > scale:
        return JUMP, jump
    return SMOOTH, jump
