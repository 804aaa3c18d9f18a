"""What both integrators' compiled kernels share: the per-case inputs and the outputs they
fill, the configuration arithmetic, event and impact records, and the one classifier of a
profile break.

The vocabulary (configuration numbers, event kinds, status codes) is
:mod:`campipe.vocabulary`'s; this module compiles what the kernels call.
"""

from __future__ import annotations

import math
import mmap
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from campipe import vocabulary
from campipe.constants import TWO_PI
from campipe.engine.metrics import (
    CAM_IMPACTS,
    MAX_CAM_IMPACT_VELOCITY,
    MAX_SEATING_VELOCITY,
    N_ENGINE,
    SEAT_IMPACTS,
    SEATED_OFF_CAM,
    SEPARATION,
)
from campipe.profiles.packed import locate, next_break, piece_eval
from campipe.vocabulary import (
    CAM_IMPACT,
    CAM_SEPARATION,
    EV_FROM,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    EV_TO,
    EV_VELOCITY,
    N_COORDINATES,
    N_EVENT_FIELDS,
    SEAT_IMPACT,
    SEAT_SEPARATION,
)

#: How the kernels and their steps compile: cached, releasing the GIL, and without numba's
#: reference counting of arrays (``_nrt=False``). They allocate nothing (every array, work
#: arrays included, comes in from Python), so there is nothing to count; and the counting
#: that numba's pruning leaves in a step loop where arrays pass between a kernel's named
#: structures and its steps costs 30–60 % of a run. An allocation in a kernel is then a
#: compile error, not a silent slowdown.
KERNEL = {"cache": True, "nogil": True, "_nrt": False}
#: How a kernel's helper that is compiled on its own (see below) compiles: as a kernel, but
#: without the CPython wrapper (the code that unboxes its arguments, the batch's named
#: tuples, from Python objects): it is only called from other kernels, and the wrapper was
#: about two thirds of such a helper's compile.
HELPER = {**KERNEL, "no_cpython_wrapper": True}
# Which helpers are inlined (``inline="always"``, numba's IR inlining) and which are kernels
# of their own (``HELPER``) is set by compile time as much as run time: numba copies an
# inlined helper's IR into every call site and compiles each copy, while a helper of its own
# compiles once. So the work of a grid step (a step's loop) is inlined; a helper called once
# per segment, piece, event or sample, or from many places (``closed_form.eval_monitor``,
# ``exact._begin_segment``, ``steady._state_in_prepared_piece``) is a kernel of its own, and
# takes the batch's named tuples by reference (:func:`by_ref`). That cut a first run's
# compiling by about half, for 1–2 % of modal-exact's run time.


@intrinsic
def by_ref(typingctx, value):
    """A pointer to a copy of ``value`` (the batch's named tuples, as one tuple) in the
    calling kernel's stack frame, for its helpers of their own to take (:func:`deref`). Made
    once, where the kernel begins: the copy holds the arrays' descriptors, not their
    elements, and a helper changes elements, never which arrays the tuples hold.

    Passed by value, each of the tuples' hundred-odd arrays is a struct of five to eleven
    scalars: a helper taking them was compiled with some 700 parameters, packed into structs
    again on entry (0.26 s of compile for a one-line helper, 0.05 s by reference), and every
    call pushed all of them (modal-exact calls its sample helper at every output angle). By
    reference, a first run compiled about a tenth less, and modal-exact ran a quarter faster
    (the bench's 1000-case study on one thread: 0.45 s before, 0.33 s after); the results
    are the same to the bit (``tests/integration/test_digest.py``).
    """

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[value]
        pointer = cgutils.alloca_once(builder, model.get_data_type())
        builder.store(model.as_data(builder, args[0]), pointer)
        return pointer

    return types.CPointer(value)(value), codegen


@intrinsic
def deref(typingctx, pointer):
    """The value :func:`by_ref` points to."""
    if not isinstance(pointer, types.CPointer):
        raise TypingError(f"deref takes a pointer from by_ref, not {pointer}")

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[signature.return_type]
        return model.load_from_data_pointer(builder, args[0])

    return pointer.dtype(pointer), codegen


#: A kernel of its own called with a constant argument (a Python int or bool) is compiled
#: once per value: numba types the constant as a literal. Such arguments are passed as NumPy
#: scalars (``np.int64``, ``np.bool_``), one compile for all values; so are these event kinds.
CAM_SEP, SEAT_SEP = np.int64(CAM_SEPARATION), np.int64(SEAT_SEPARATION)
#: The off-the-cam angle columns, as :func:`count_angle` takes them from ``record_impact``.
NO_FOLLOW, SEATED_OFF = np.int64(SEPARATION), np.int64(SEATED_OFF_CAM)

#: The configuration arithmetic of :mod:`campipe.vocabulary`, compiled and inlined.
configuration = njit(inline="always")(vocabulary.configuration)
holds_cam = njit(inline="always")(vocabulary.holds_cam)
holds_seat = njit(inline="always")(vocabulary.holds_seat)

#: A profile break whose lift rate jumps by less than this [m/s] (beyond JUMP_RELATIVE of the
#: rates either side) is smooth: rounding in re-expanded polynomial pieces, not a velocity jump.
JUMP_FLOOR = 1e-9
JUMP_RELATIVE = 1e-9
#: A step down in lift larger than this [m] at a break is a drop (the engine refuses steps up).
DROP_FLOOR = 1e-12
#: A gap's level [m]: the penetration at which a contact closes (an impact), in both
#: integrators, far below any output's resolution and above rounding of the coordinates.
GAP_LEVEL = 1e-13
#: A flight whose closing velocity times its duration stays below this [m] (twice the most
#: the gap can have opened, a parabolic flight's height being v·t/4) never left its contact
#: (``record_impact``): a nanometre, far below what a contact resolves.
MICRO_FLIGHT = 1e-9
#: An angle off the cam taken back (``count_angle``) leaves its turn's column at its rounding,
#: a relative 1e-16 of what was added in pieces: below this fraction of the column it is 0.
ANGLE_ROUNDING = 1e-9
#: The tension [N] at which a resting contact releases (:func:`is_captured`), as a fraction of
#: modal-exact's force level (``eps_force``: 1e-9 × (preload + 1 N), where the other held
#: contacts release; their force falls through zero steeply, and that level moves their
#: release by under 1e-13 s, inside the event tolerance). A resting contact's force can hover
#: about zero, and its level is then the most tension a sample shows: a thousandth, 7e-10 N
#: for the thesis's train, under 1e-9 N and far above the rounding of the force (1e-13 N).
RESTING_LEVEL = 1e-3
#: What a break does to a follower held on the cam (:func:`classify_break`).
SMOOTH, RELEASE, JUMP = 0, 1, 2


class Cases(NamedTuple):
    """Per case of a batch: how it is driven, where it starts, and its contact laws (leading
    axis: case)."""

    omega: np.ndarray  # (n,) cam speed [rad/s]
    seat_q: np.ndarray  # (n,) q7 on the seat [m] (the valve reference where there is none)
    has_seat: np.ndarray  # (n,) bool: the valve has a seat
    form: np.ndarray  # (n,) bool: form closure (the cam never releases the follower)
    t0: np.ndarray  # (n,) start time [s], ≤ 0: integrated, not recorded, up to t = 0
    q0: np.ndarray  # (n, n_q) start coordinates [m, rad] (n_q: the batch's most coordinates)
    v0: np.ndarray  # (n, n_q) start velocities [m/s, rad/s]
    a0: np.ndarray  # (n, n_q) start accelerations [m/s², rad/s²]
    cfg0: np.ndarray  # (n,) int64 start configuration
    meff: np.ndarray  # (n, 4) impact masses [kg] (``contact.impact_masses`` order)
    #: (n, 2) the other contact's separation velocity per unit velocity change of the struck
    #: one (struck: cam, seat) [-] (``modal.ModalData.separation``)
    separation: np.ndarray
    capture: np.ndarray  # (n,) capture velocity [m/s]: slower impacts leave the contact resting
    #: (n, 2) coefficient of restitution of an impact at the cam and at the seat [-]: 0, the
    #: thesis's plastic impact; above 0 the struck contact bounces off (modal-exact only)
    restitution: np.ndarray
    valve_ref: np.ndarray  # (n,) q7 at zero valve lift [m]
    lift_bound: np.ndarray  # (n,) |valve lift| beyond this [m] is motion out of bounds
    speed_bound: np.ndarray  # (n,) a closing or valve speed beyond this [m/s] is out of bounds


class Outputs(NamedTuple):
    """The arrays a kernel fills in place (leading axis: case)."""

    q: np.ndarray  # (n, n_out, n_q) coordinates at the output angles [m, rad]
    v: np.ndarray  # (n, n_out, n_q) velocities [m/s, rad/s]
    force: np.ndarray  # (n, n_out, 2) (F1, F7), thesis signs [N]
    cam: np.ndarray  # (n, n_out) cam lift [m]
    cfg: np.ndarray  # (n, n_out) int8 configuration
    acc: np.ndarray  # (n, n_out, 2) accelerations of q1 and q7 [m/s²]
    #: (n, n_rev, N_ENGINE) per turn: the engine's metrics, a column each
    #: (``campipe.engine.metrics``: SEPARATION, CAM_IMPACTS, MAX_CAM_FORCE, …), SI
    per_rev: np.ndarray
    events: np.ndarray  # (n, max_events, N_EVENT_FIELDS), rows below n_events
    n_events: np.ndarray  # (n,) int64 events of each case (may exceed max_events)
    status: np.ndarray  # (n,) int64 vocabulary status code
    steps: np.ndarray  # (n,) int64 integration steps taken


def make_outputs(
    n: int,
    n_out: int,
    n_rev: int,
    max_events: int,
    n_coordinates: int = N_COORDINATES,
    cleared: bool = True,
) -> Outputs:
    """Outputs for n cases of up to ``n_coordinates`` coordinates, zeroed (events
    uninitialised past each case's count); with ``cleared`` False the histories (``q``, ``v``,
    ``force``, ``cam``, ``acc``) are left uninitialised too, for a kernel that writes every
    sample of every case (``Integrator.fills_outputs``): clearing them cost a 32-case run of
    the thesis's train 0.3 ms of its 10 (7 MB written twice).

    The float arrays are views of one zeroed block, the counts' rows and the configurations of
    another: a few allocations a call instead of eleven, and a block of 4 MB or more (about
    19 cases of a 4-turn run sampled every degree) comes in huge pages (numpy asks for them
    from 4 MB), which the kernel's first writes fault in 2 MB at a time, not 4 kB (numpy's
    separate arrays, each below 4 MB, cost a 32-case run a third of its time in page faults).
    """
    k = n * n_out
    nq = k * n_coordinates
    at = 2 * nq + 5 * k  # q, v, force (2), cam, acc (2), then per_rev
    if cleared:
        block = np.zeros(at + n * n_rev * N_ENGINE)
    else:
        block = np.empty(at + n * n_rev * N_ENGINE)
        block[at:] = 0.0  # the metrics accumulate
    # The counts' rows (int64, 8-aligned at the block's start), then the configurations.
    small = np.zeros(3 * n * 8 + k, np.int8)
    counts = small[: 3 * n * 8].view(np.int64).reshape(3, n)
    return Outputs(
        q=block[:nq].reshape(n, n_out, n_coordinates),
        v=block[nq : 2 * nq].reshape(n, n_out, n_coordinates),
        force=block[2 * nq : 2 * nq + 2 * k].reshape(n, n_out, 2),
        cam=block[2 * nq + 2 * k : 2 * nq + 3 * k].reshape(n, n_out),
        cfg=small[3 * n * 8 :].reshape(n, n_out),
        acc=block[2 * nq + 3 * k : at].reshape(n, n_out, 2),
        per_rev=block[at:].reshape(n, n_rev, N_ENGINE),
        events=sparse_empty((n, max_events, N_EVENT_FIELDS)),
        n_events=counts[0],
        status=counts[1],
        steps=counts[2],
    )


#: Bytes from which :func:`sparse_empty` maps its own memory (numpy advises huge pages from
#: 4 MB; below that an array is cleared in small pages anyway).
SPARSE_BYTES = 4 * 2**20


def sparse_empty(shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """An uninitialised array whose memory the system provides, cleared, in small pages and
    only where it is written: for a slab per case of which a case fills a few rows (the
    events: 4096 rows kept per case, about 20 written a case in two turns).

    numpy asks the system for huge pages for a large array, and the system then clears a
    whole 2 MB page where a case writes its first event: the slabs of ten cases. A batch
    of 5000 cases cleared its whole 1 GB of event rows, which took longer than the run
    itself; mapped here, it touches a small page a case.
    """
    size = math.prod(shape) * np.dtype(dtype).itemsize
    if size < SPARSE_BYTES:
        return np.empty(shape, dtype)
    memory = mmap.mmap(-1, size)
    if hasattr(mmap, "MADV_NOHUGEPAGE"):  # a system whose huge pages are on by default
        memory.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(memory, dtype).reshape(shape)


#: Turns [-] by which an angle may fall short of a turn's start and still count to that turn.
TURN_GUARD = 1e-9


@njit(inline="always")
def turn_of(w, t):
    """The cam turn holding time t [s] at speed w (turn 0 from t = 0; negative before). An
    angle on a turn's start to rounding (a round speed and step) counts to that turn."""
    return int(np.floor(w * t / TWO_PI + TURN_GUARD))


@njit(**HELPER)
def record_event(events, n_events, c, t, kind, c_from, c_to, velocity, impulse):
    """Append an event to case c's record (counted beyond the kept rows); nothing before
    t = 0 (the start's run-up) is recorded."""
    if t < 0.0:
        return
    k = n_events[c]
    if k < events.shape[1]:
        events[c, k, EV_TIME] = t
        events[c, k, EV_KIND] = kind
        events[c, k, EV_FROM] = c_from
        events[c, k, EV_TO] = c_to
        events[c, k, EV_VELOCITY] = velocity
        events[c, k, EV_IMPULSE] = impulse
    n_events[c] = k + 1


@njit(**HELPER)
def count_angle(per_rev, k, c, w, ta, tb, sign):
    """Add (``sign`` 1) or take back (-1) the cam angle of [ta, tb] ∩ [0, ∞) [s] at speed w
    to each of case c's turns it overlaps, in metric column k (an angle off the cam). What a
    take-back leaves below ANGLE_ROUNDING of the column is rounding and reads 0."""
    n_rev = per_rev.shape[1]
    a = max(w * ta, 0.0)
    b = w * tb
    r = int(a / TWO_PI)
    while a < b and r < n_rev:
        end = min(b, (r + 1) * TWO_PI)
        was = per_rev[c, r, k]
        now = was + sign * (end - a)
        per_rev[c, r, k] = 0.0 if now < ANGLE_ROUNDING * was else now
        a = end
        r += 1


@njit(**HELPER)
def record_impact(events, n_events, per_rev, meff, c, w, t, seat, other_held, c_from, c_to,
                  closing, capture, restitution):  # fmt: skip
    """Count an impact of case c at time t [s] (speed w) on the cam (``seat`` False) or the
    seat in its turn, keep the turn's largest closing velocity [m/s] (``per_rev``) and record
    the event with its impulse m_eff·(1 + e)·v_closing, e the ``restitution`` it bounced with
    (0: plastic); ``other_held``: the other contact is held (``contact.impact_masses``
    order). Nothing before t = 0 is recorded.

    A contact that closes slower than the capture velocity ``capture`` [m/s] right after it
    released (its release the last event, the flight's closing velocity × duration below
    MICRO_FLIGHT) never really left: its gap stayed far below any length a contact resolves.
    The release is taken back and the closing is no impact; so is the flight's angle, which
    the integrator counted off the cam as it went (``count_angle``): a cam flight's from its
    turn's no-follow (or seated-off-the-cam), a seat flight off the cam from no-follow to
    seated-off-the-cam. A slow landing after a real flight (a polydyne's valve returning to
    its seat) is an impact, counted."""
    if t < 0.0:
        return
    side = 1 if seat else 0
    k = n_events[c] - 1
    release = SEAT_SEPARATION if seat else CAM_SEPARATION
    if (
        closing < capture
        and 0 <= k < events.shape[1]
        and events[c, k, EV_KIND] == release
        and events[c, k, EV_TO] == c_from
        and closing * (t - events[c, k, EV_TIME]) < MICRO_FLIGHT
    ):
        n_events[c] = k
        t_left = events[c, k, EV_TIME]
        if not seat:
            flown = SEATED_OFF if holds_seat(c_from) else NO_FOLLOW
            count_angle(per_rev, flown, c, w, t_left, t, -1.0)
        elif not holds_cam(c_from):
            count_angle(per_rev, NO_FOLLOW, c, w, t_left, t, -1.0)
            count_angle(per_rev, SEATED_OFF, c, w, t_left, t, 1.0)
        return
    turn = turn_of(w, t)
    if turn < per_rev.shape[1]:
        count = SEAT_IMPACTS if seat else CAM_IMPACTS
        fastest = MAX_SEATING_VELOCITY if seat else MAX_CAM_IMPACT_VELOCITY
        per_rev[c, turn, count] += 1.0
        per_rev[c, turn, fastest] = max(per_rev[c, turn, fastest], closing)
    mass = meff[c, 2 * side + (1 if other_held else 0)]
    kind = SEAT_IMPACT if seat else CAM_IMPACT
    record_event(events, n_events, c, t, kind, c_from, c_to, closing,
                 mass * (1.0 + restitution) * closing)  # fmt: skip


@njit(inline="always")
def classify_break(l_left, dl_left, l_right, dl_right, w, form, capture):
    """What a profile break does to a follower held on the cam, and the lift-rate jump
    [m/s] there, from the lift [m] and its θ-derivative [m/rad] on either side at speed w.

    - RELEASE: the surface falls away (its rate drops, or its lift steps down) under a
      force-closed follower, which keeps its own velocity and leaves;
    - JUMP: the surface's rate jumps into the follower (or drags a form-closed one): an
      impact of the follower by the cam;
    - SMOOTH: a rate jump within rounding (JUMP_FLOOR, and JUMP_RELATIVE), or slower than the
      capture velocity ``capture`` [m/s]: the follower rests on the surface through it, as it
      would through an impact that slow (the rounding at a polydyne's piece joins, 6e-13 m/s,
      is no impact).

    Inlined: computed with the caller's floating-point flags.
    """
    jump = w * (dl_right - dl_left)
    scale = max(JUMP_RELATIVE * (abs(w * dl_left) + abs(w * dl_right)) + JUMP_FLOOR, capture)
    drop = l_right < l_left - DROP_FLOOR
    if (jump < -scale or drop) and not form:
        return RELEASE, jump
    if abs(jump) > scale:
        return JUMP, jump
    return SMOOTH, jump


#: A break within this fraction of the run's end (or of its start angle) is at the end (the
#: start): ``ends_on_a_break``, ``start_piece``.
AT_BREAK = 1e-12


@njit(inline="always")
def held_break(profiles, c, p, rev, w, form, capture):
    """The kind of the break that ends piece ``p`` of turn ``rev`` for a follower held on the
    cam (:func:`classify_break`, its one-sided lift and rate from the pieces either side)."""
    pn, revn, theta = next_break(profiles, c, p, rev)
    l_left, dl_left, _ = piece_eval(profiles, c, p, rev, theta)
    l_right, dl_right, _ = piece_eval(profiles, c, pn, revn, theta)
    return classify_break(l_left, dl_left, l_right, dl_right, w, form, capture)[0]


@njit(inline="always")
def start_piece(profiles, c, theta, cfg, w, form, capture):
    """(turn, piece, crosses): where a run starting at cam angle ``theta`` [rad] in
    configuration ``cfg`` begins. A start state is the state *before* anything at its
    instant: where ``theta`` is a break (to AT_BREAK) that a held follower cannot cross
    smoothly (an impact of the cam's rate jump, a release), the run begins on the piece that
    ends there and crosses the break first, as a run that reached it would (``crosses``
    True); else on the piece holding ``theta``. So a run continued from another's last state
    (which ends before a break at its end: ``ends_on_a_break``) and a periodic start at a
    break (``steady.periodic_starts``) count the break's event in the turn it starts."""
    rev, p = locate(profiles, c, theta)
    if not holds_cam(cfg):
        return rev, p, False
    th_b = rev * TWO_PI + profiles.breaks[c, p]
    if abs(theta - th_b) > AT_BREAK * (1.0 + abs(theta)):
        return rev, p, False
    pl, revl = p - 1, rev
    if pl < 0:
        pl, revl = profiles.n_pieces[c] - 1, rev - 1
    if held_break(profiles, c, pl, revl, w, form, capture) == SMOOTH:
        return rev, p, False
    return revl, pl, True


@njit(inline="always")
def ends_on_a_break(profiles, c, p, rev, t_break, t_end, cfg, w, form, capture):
    """The break ending piece ``p`` of turn ``rev`` at ``t_break`` [s] is at the run's end
    ``t_end`` [s] (to AT_BREAK) and a held follower cannot cross it smoothly: the run ends
    before it, its last state the one before the break (the next run's start crosses it:
    ``start_piece``)."""
    if t_break < t_end * (1.0 - AT_BREAK) or not holds_cam(cfg):
        return False
    return held_break(profiles, c, p, rev, w, form, capture) != SMOOTH


def jump_speed(dl_left: float, dl_right: float, capture: float) -> float:
    """The speed [rad/s] above which :func:`classify_break` takes a break whose lift rate
    [m/rad] is ``dl_left`` and ``dl_right`` either side for a jump or a release (not SMOOTH):
    w·|Δ| > max(JUMP_RELATIVE·w·(|dl_left| + |dl_right|) + JUMP_FLOOR, capture) for every w
    above it and at no w at or below it; +inf for a jump within rounding at every speed."""
    step = abs(dl_right - dl_left)
    relative = step - JUMP_RELATIVE * (abs(dl_left) + abs(dl_right))
    if relative <= 0.0:
        return math.inf
    return max(JUMP_FLOOR / relative, capture / step)


@njit(inline="always")
def other_releases(separation, capture, c, seat, dv):
    """An impact at the cam (``seat`` False) or the seat that changes its velocity by dv [m/s]
    with the other contact held: does the other release? The impulsive complementarity of two
    contacts: it keeps its hold only if its reaction impulse is compressive, which is where
    releasing it would not separate it; a separation slower than the capture velocity
    ``capture`` [m/s] is not resolved (the contact would close again at once), so the contact
    stays (``modal.ModalData.separation``)."""
    return separation[c, 1 if seat else 0] * dv > capture


def is_captured(closing: float, capture: float) -> bool:
    """An impact closing slower than the capture velocity [m/s] leaves its contact resting:
    it does not bounce. It counts as an impact unless it ends a flight of under a nanometre
    (``record_impact`` takes those back). Every integrator asks this (the compiled ones
    through :func:`captured`).

    A resting contact is held as any other: it releases where its force reaches zero (to
    RESTING_LEVEL in modal-exact), never held in tension. A valve landing with no force to
    spare then lifts off and lands again in a short series of bounces, each slower than the
    last, the model's own answer (newmark-linear's step ends find the same series); a
    release whose flight closes again at once, slower than the capture velocity, is taken
    back (``record_impact``), so the converged series leaves the contact resting."""
    return closing < capture


#: :func:`is_captured`, compiled and inlined for the kernels.
captured = njit(inline="always")(is_captured)
