"""The steady-state path: the periodic state below the no-follow onset without integrating
turns, its margin, and the onset speed as the margin's root.

Below the onset the follower never leaves the cam, so the train stays in configuration I,
linear and driven with the cam's period: its steady state is the closed form of
``campipe.engine.steady`` (z(0) = (I − e^{AT})⁻¹ b, exact piece by piece). Its *margin* is the
least cam compression −F1 over the turn: positive, the follower follows; the no-follow onset
is the lowest speed where it reaches zero. Where the valve reaches its seat the steady state
is piecewise (configurations I, III, IV, with impacts at the seat and the cam, plastic or with
the train's restitution): it is then the fixed point of the turn map over the exact piece
propagators, which is what ``modal-exact`` integrates turn by turn; the heavy damping of the
seated phase makes that map contract within a turn or two (``SEATED_TURNS``, checked), and
no-follow is configuration II in its last turn; with a seat the onset is where that
no-follow reaches a level (``onset_speeds``). The search certifies each interval it passes
free of no-follow, so it misses no window of it inside the range (``onset_speeds``).

Pure numerics: arrays in, arrays out; no files, no printing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe.constants import RPM, TWO_PI
from campipe.engine import steady
from campipe.engine.batch import (
    BatchResult,
    Case,
    CaseError,
    RunSettings,
    check_run,
    merge_results,
    output_angles,
    run_batch,
    train_matrices,
    train_modal,
    unique_trains,
    valve_reference,
)
from campipe.engine.closed_form import STATE, ExactRuns, ModalTrains, make_workspace, stack_trains
from campipe.engine.common import SMOOTH, Cases, classify_break
from campipe.engine.metrics import MAX_CAM_FORCE, N_ENGINE
from campipe.engine.modal import ModalData
from campipe.engine.settings import sample_count, turn_count
from campipe.model import ValveTrain
from campipe.model.assembly import preload_vector
from campipe.profiles import Profile, pack
from campipe.profiles.pieces import evaluate_pieces
from campipe.vocabulary import CAM, CAM_CONTACT, N_EVENT_FIELDS, OK, SEAT

#: Turns the engine integrates for a steady state with the valve seated on part of the turn
#: (from the periodic start of configuration I); the last is the steady state when it agrees
#: with the one before to SEATED_AGREEMENT [rad] of no-follow, else more turns follow, up to
#: MAX_SEATED_TURNS.
SEATED_TURNS = 3
MAX_SEATED_TURNS = 24
SEATED_AGREEMENT = 1e-9
#: Speeds at which the onset search first looks across a speed range; the intervals between
#: them are then certified free of no-follow or halved (``onset_speeds``).
SCAN_SPEEDS = 17
#: The certificate's safety factor: between two speeds where the design follows, the slope
#: of its margin is taken to be at most ONSET_SLOPE_FACTOR times the steepest of the chord
#: between them and the chords either side (``onset_speeds``).
ONSET_SLOPE_FACTOR = 2.0
#: The onset's default tolerance [rpm]; with a seat, its default level [deg of no-follow a
#: turn] (``onset_speeds``: why 0.5°).
DEFAULT_ONSET_TOLERANCE_RPM = 0.1
DEFAULT_ONSET_LEVEL_DEG = 0.5
DEFAULT_ONSET_LEVEL = math.radians(DEFAULT_ONSET_LEVEL_DEG)  # [rad]
#: The time-domain check: its offset either side of the onset, its turns from the periodic
#: start and the first of them left out (``confirm_onsets``).
CONFIRM_OFFSET = 0.005
CONFIRM_TURNS = 10
CONFIRM_WARMUP = 2


# --------------------------------------------------------------------------- packing


def _modal_at_preload(train: ValveTrain) -> ModalData:
    """The closed-form data of a train, its modes shared by every preload (``batch.train_modal``
    caches them): the preload only enters the constant forcing and the contact forces'
    constant part, linearly."""
    unit = train_modal(train.replace(spring_preload=1.0))
    p = train.spring_preload
    return dataclasses.replace(unit, b_load=unit.b_load * p, sigma0=unit.sigma0 * p)


@dataclass
class _SteadyBatch:
    """What the steady-state kernels take for a batch of cases, built once: the speeds
    (``cases.omega``) change in place between calls."""

    cases: Cases
    trains: ModalTrains
    packed: object
    runs: ExactRuns
    z_turn: np.ndarray
    matrices: list  # the distinct trains' SystemMatrices where a valve reference was needed
    which: np.ndarray

    def extremes(
        self, omega: np.ndarray, with_max: bool = True, active: np.ndarray | None = None
    ) -> np.ndarray:
        """(n, N_EXTREMES) at the speeds ``omega`` [rad/s] (``steady.steady_extremes``), NaN
        outside ``active``."""
        self.cases.omega[:] = omega
        out = np.full((omega.size, steady.N_EXTREMES), np.nan)
        if active is None:
            active = np.ones(omega.size, np.bool_)
        steady.steady_extremes(
            self.cases, self.trains, self.packed, self.runs,
            make_workspace(self.trains.load.shape[1]), np.zeros(1, STATE), self.z_turn,
            with_max, active, out,
        )  # fmt: skip
        return out


def _prepare(cases: Sequence[Case], *, need_reference: bool = False) -> _SteadyBatch:
    compliant = [i for i, c in enumerate(cases) if c.compliant]
    if compliant:
        raise CaseError.at(
            "cam_contact",
            f"cases {compliant} have a compliant contact: the steady-state path (and the "
            "onset) is the rigid model's closed form; integrate them (campipe study)",
            found=compliant,
            expected="rigid contacts",
        )
    n = len(cases)
    trains, which = unique_trains(cases)
    data = [_modal_at_preload(t) for t in trains]
    has_seat = np.array([c.has_seat for c in cases], dtype=np.bool_)
    matrices: list = [None] * len(trains)
    seated_trains = set(which[has_seat].tolist())
    for k, t in enumerate(trains):
        if need_reference or k in seated_trains:
            matrices[k] = train_matrices(t)
    refs = [valve_reference(m) if m else 0.0 for m in matrices]  # per train
    qref = np.array([refs[k] for k in which])
    modal_trains = stack_trains(data, [preload_vector(t) for t in trains])
    n_q = modal_trains.load.shape[1]  # the batch's most coordinates
    packed = pack([c.profile for c in cases])
    zeros = np.zeros(n)
    runs = ExactRuns(
        train=which, t_sample=zeros, t_end=zeros, zeta=np.zeros((n, 4, 2 * n_q), np.complex128),
        dt_cap=0.0, tolerance=1e-12, full_state=True,
    )  # fmt: skip
    state = Cases(
        omega=np.array([c.speed for c in cases], dtype=float),
        seat_q=qref + np.where(has_seat, [c.seat for c in cases], 0.0),
        has_seat=has_seat,
        form=np.array([c.closure == "form" for c in cases], dtype=np.bool_),
        t0=zeros, q0=np.zeros((n, n_q)), v0=np.zeros((n, n_q)), a0=np.zeros((n, n_q)),
        cfg0=np.full(n, CAM_CONTACT, np.int64), meff=np.zeros((n, 4)),
        separation=np.zeros((n, 2)), capture=zeros,
        restitution=np.zeros((n, 2)),
        valve_ref=qref, lift_bound=zeros, speed_bound=zeros,
    )  # fmt: skip
    z_turn = np.zeros((n, packed.n_pieces.max() + 1, 2 * n_q))
    return _SteadyBatch(state, modal_trains, packed, runs, z_turn, matrices, which)


# --------------------------------------------------------------------------- margins


@dataclass(frozen=True)
class SteadyExtremes:
    """Configuration I's periodic state over one turn, per case (``steady_extremes``)."""

    min_cam_force: np.ndarray  # (n,) least cam compression −F1: the margin [N]; inf: form closure
    min_cam_force_angle: np.ndarray  # (n,) where [rad]
    max_cam_force: np.ndarray  # (n,) largest cam compression [N]
    min_seat_height: np.ndarray  # (n,) the valve's least height above its seat [m]; inf: none
    min_seat_height_angle: np.ndarray  # (n,) where [rad]

    @property
    def holds(self) -> np.ndarray:
        """(n,) bool: configuration I holds all turn (the cam pushes, the valve stays off its
        seat; a least force or height of zero is the edge of a separation or a seating, and
        does not hold), so the closed form is the steady state wherever the profile has no
        break the follower cannot cross held (``break_events``)."""
        return (self.min_cam_force > 0.0) & (self.min_seat_height > 0.0)


def _as_extremes(out: np.ndarray) -> SteadyExtremes:
    return SteadyExtremes(*(out[:, k].copy() for k in range(steady.N_EXTREMES)))


def steady_extremes(cases: Sequence[Case]) -> SteadyExtremes:
    """The no-follow margin and the other extremes of configuration I's periodic state over a
    turn, for each case at its speed, in closed form (no turn integrated).

    The extremes are sampled at ``steady.EXTREME_SAMPLES`` a turn and refined by golden-section
    search; each holds for the closed form whether or not configuration I holds (see
    ``SteadyExtremes.holds``).
    """
    check_run(cases, RunSettings(), check_stability_limit=False)
    batch = _prepare(cases)
    return _as_extremes(batch.extremes(batch.cases.omega.copy()))


# --------------------------------------------------------------------------- histories


@dataclass(frozen=True)
class SteadyState:
    """The periodic steady state over one turn at the output angles, SI (as ``BatchResult``'s
    histories of one turn)."""

    cam_angle: np.ndarray  # (n_out,) [rad], 0 … 2π
    q: np.ndarray  # (n, n_out, n_q) [m, rad] (n_q: the most coordinates; NaN beyond a train's)
    v: np.ndarray  # (n, n_out, n_q) [m/s, rad/s]
    acc: np.ndarray  # (n, n_out, 2) accelerations of q1 and q7 [m/s²]
    cam_force: np.ndarray  # (n, n_out) cam compression [N]
    valve_reference: np.ndarray  # (n,) q7 at zero valve lift [m]
    extremes: SteadyExtremes

    @property
    def valve_lift(self) -> np.ndarray:
        """(n, n_out) valve opening from its base-circle static position [m]."""
        return self.q[:, :, SEAT] - self.valve_reference[:, None]

    @property
    def follower_lift(self) -> np.ndarray:
        """(n, n_out) pushrod foot height in the cam's lift coordinate [m]."""
        return -self.q[:, :, CAM]


def steady_state(cases: Sequence[Case], output_every: float = math.radians(1.0)) -> SteadyState:
    """The periodic steady state of each case over one turn, in closed form: what the
    event-driven engine's turns settle to below the no-follow onset, for one turn's samples.

    Parameters
    ----------
    cases : sequence of Case
        Any mix of trains, profiles, speeds and closures; a seat must stay clear of the valve.
    output_every : float
        Output spacing in cam angle [rad].

    Raises
    ------
    CaseError
        (key ``speed``) for a case whose follower leaves the cam somewhere on the turn, (key
        ``seat``) one whose valve reaches its seat: its steady state is not configuration I's.
    """
    check_run(cases, RunSettings(output_every=output_every), check_stability_limit=False)
    batch = _prepare(cases, need_reference=True)
    ext = _as_extremes(batch.extremes(batch.cases.omega.copy()))
    for key, bad, why in (
        ("speed", ext.min_cam_force < 0, "the follower leaves the cam (no-follow)"),
        ("seat", ext.min_seat_height < 0, "the valve reaches its seat"),
    ):
        if bad.any():
            idx = np.flatnonzero(bad).tolist()
            raise CaseError.at(
                key,
                f"cases {idx}: {why} in the steady state, so it is not configuration I's "
                "closed form; run them through run_batch",
                found=idx,
                expected="cases below the no-follow onset with the valve clear of its seat",
            )
    n_out = sample_count(1.0, output_every)
    angles = np.minimum(np.arange(n_out) * output_every, TWO_PI)
    return _samples(batch, ext, angles)


def _samples(
    batch: _SteadyBatch, ext: SteadyExtremes, angles: np.ndarray, active: np.ndarray | None = None
) -> SteadyState:
    """The steady state at ``angles`` (ascending, within one turn) of a prepared batch, for
    its ``active`` cases (default all; the others' samples are left NaN or unset)."""
    n = batch.cases.omega.size
    active = np.ones(n, np.bool_) if active is None else active
    n_out = angles.size
    n_q = batch.trains.load.shape[1]
    q = np.full((n, n_out, n_q), np.nan)
    v = np.full((n, n_out, n_q), np.nan)
    acc = np.empty((n, n_out, 2))
    force = np.empty((n, n_out))
    steady.steady_samples(
        batch.cases, batch.trains, batch.packed, batch.runs, make_workspace(n_q),
        np.zeros(1, STATE), batch.z_turn, angles, active, q, v, acc, force,
    )  # fmt: skip
    return SteadyState(angles, q, v, acc, force, batch.cases.valve_ref.copy(), ext)


# --------------------------------------------------------------------------- the level


def _break_limits(profile: Profile) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each break's one-sided lift [m] and lift rate [m/rad], left and right: break k ends
    piece k and starts piece k + 1 (the last, at 2π, starts the next turn's piece 0)."""
    n = profile.n_pieces
    left = evaluate_pieces(profile, np.arange(n), profile.breaks[1:])
    right_piece = np.arange(1, n + 1) % n
    right = evaluate_pieces(profile, right_piece, profile.breaks[right_piece])
    return left[0], left[1], right[0], right[1]


def break_events(cases: Sequence[Case], capture: float) -> np.ndarray:
    """(n,) bool: the case's profile has a break that a follower held on the cam cannot cross
    held at the case's speed (``common.classify_break``, the test the integrators apply: a lift
    rate that drops or a lift that steps down under a force-closed follower releases it; a
    rate that jumps into it, by more than the capture velocity ``capture`` [m/s], strikes it).

    Every turn of such a case has events (a release and a landing, or an impact) that
    configuration I's closed form cannot have: the thesis's flat across the nose, a
    constant-velocity ramp's velocity steps. A rate jump within rounding or below the capture
    velocity is crossed held, as the integrators cross it."""
    classify = classify_break.py_func  # the compiled test's own Python (numba's public py_func)
    limits: dict[int, tuple[np.ndarray, ...]] = {}
    out = np.zeros(len(cases), np.bool_)
    for i, case in enumerate(cases):
        key = id(case.profile)
        if key not in limits:
            limits[key] = _break_limits(case.profile)
        form = case.closure == "form"
        out[i] = any(
            classify(l0, d0, l1, d1, case.speed, form, capture)[0] != SMOOTH
            for l0, d0, l1, d1 in zip(*limits[key], strict=True)
        )
    return out


def steady_cases(cases: Sequence[Case], settings: RunSettings) -> np.ndarray:
    """(n,) bool: the cases ``run_at_fidelity`` takes from the closed form at the steady
    level (``_steady_mask``; compliant cases never). The probe it pays, alone."""
    check_run(cases, settings, check_stability_limit=False)
    take = np.zeros(len(cases), np.bool_)
    rigid = np.flatnonzero([not c.compliant for c in cases])
    if rigid.size:
        some = [cases[int(i)] for i in rigid]
        batch = _prepare(some)
        ext = _as_extremes(batch.extremes(batch.cases.omega.copy()))
        take[rigid] = _steady_mask(some, ext, settings)
    return take


def _steady_mask(cases: Sequence[Case], ext: SteadyExtremes, settings: RunSettings) -> np.ndarray:
    """Which of the rigid ``cases`` (their extremes ``ext``) the steady level takes: those whose
    periodic state is configuration I's all turn (``SteadyExtremes.holds``: the least cam force
    above zero, the valve clear of its seat) and whose profile the follower crosses held
    (no ``break_events``). The others have events every turn: the full engine runs them."""
    holds = ext.holds
    if holds.any():
        idx = np.flatnonzero(holds)
        jumps = break_events([cases[int(i)] for i in idx], settings.capture_velocity)
        holds = holds.copy()
        holds[idx[jumps]] = False
    return holds


def run_at_fidelity(cases: Sequence[Case], settings: RunSettings, **options) -> BatchResult:
    """:func:`~campipe.engine.batch.run_batch` at the run's fidelity level
    (``RunSettings.level``). ``full``: run_batch. ``steady``: each case whose periodic steady
    state is configuration I's all turn (``SteadyExtremes.holds``: it follows the cam with
    the valve clear of its seat) and whose profile has no break the follower cannot cross
    held at its speed (``break_events``: a velocity jump above the capture velocity, a step
    down) from that closed form, one turn's samples repeated over the run's turns with no
    events; the others (and compliant cases) by run_batch; the results in case order
    (``steady_cases`` names the first). The margin that decides it is the level's probe, paid
    per case."""
    if settings.level == "full":
        return run_batch(cases, settings, **options)
    check_run(cases, settings, check_stability_limit=options.get("check_stability_limit", True))
    rigid = np.flatnonzero([not c.compliant for c in cases])
    take = np.zeros(len(cases), np.bool_)
    parts = []
    if rigid.size:
        some = [cases[int(i)] for i in rigid]
        batch = _prepare(some, need_reference=True)
        ext = _as_extremes(batch.extremes(batch.cases.omega.copy()))  # the probe
        mask = _steady_mask(some, ext, settings)
        take[rigid] = mask
        if mask.any():
            held = [cases[int(i)] for i in rigid[mask]]
            parts.append((rigid[mask], _steady_result(batch, ext, mask, held, settings)))
    if not take.all():
        index = np.flatnonzero(~take)
        full = dataclasses.replace(settings, fidelity="full", fidelity_tolerance=None)
        parts.append((index, run_batch([cases[int(i)] for i in index], full, **options)))
    return merge_results(len(cases), parts)


def _steady_result(
    batch: _SteadyBatch,
    ext: SteadyExtremes,
    held: np.ndarray,
    cases: Sequence[Case],
    settings: RunSettings,
) -> BatchResult:
    """The run of the cases ``held`` (a mask) of ``batch`` (``cases``, in order), from its
    closed form, the probe's batch and extremes reused (``run_at_fidelity``)."""
    angles = output_angles(settings)
    turn, back = np.unique(np.mod(angles, TWO_PI), return_inverse=True)
    st = _samples(batch, ext, turn, held)
    omega = batch.cases.omega[held]
    n, n_rev = len(cases), turn_count(settings.recorded_revolutions)
    per_rev = np.zeros((n, n_rev, N_ENGINE))
    per_rev[:, :, MAX_CAM_FORCE] = ext.max_cam_force[held, None]
    q = st.q[held][:, back]
    return BatchResult(
        cam_angle=angles,
        time=angles[None, :] / omega[:, None],
        q=q,
        v=st.v[held][:, back],
        acc=st.acc[held][:, back],
        cam_lift=-q[:, :, CAM],  # the follower is on the cam
        cam_force=st.cam_force[held][:, back],
        seat_force=np.zeros((n, angles.size)),
        contact_state=np.full((n, angles.size), CAM_CONTACT, np.int8),
        valve_reference=st.valve_reference[held],
        measured=settings.measured_turns(n_rev),
        per_rev=per_rev,
        trains=[c.train for c in cases],
        events=[np.zeros((0, N_EVENT_FIELDS)) for _ in range(n)],
        steps=np.zeros(n, np.int64),
        status=np.full(n, OK, np.int64),
        start_time=np.zeros(n),
    )


# --------------------------------------------------------------------------- the onset


def seated_no_follow(cases: Sequence[Case]) -> tuple[np.ndarray, np.ndarray]:
    """No-follow per turn in the steady state of cases whose valve seats on part of the turn:
    the fixed point of the turn map over the exact piece propagators, by ``modal-exact`` from
    configuration I's periodic start, SEATED_TURNS turns and more until the last two turns'
    no-follow agree to SEATED_AGREEMENT.

    Returns
    -------
    separation : (n,) configuration II in the last turn [rad] (NaN: the run failed)
    converged : (n,) bool, the last two turns agreed
    """
    n = len(cases)
    sep = np.full(n, np.nan)
    converged = np.zeros(n, np.bool_)
    todo = np.arange(n)
    turns = SEATED_TURNS
    while todo.size and turns <= MAX_SEATED_TURNS:
        settings = RunSettings(revolutions=turns, output_every=math.radians(5.0))
        res = run_batch([cases[int(i)] for i in todo], settings, full_state=False,
                        on_failure="record")  # fmt: skip
        last = res.separation_per_rev[:, -1]
        ok = np.abs(last - res.separation_per_rev[:, -2]) <= SEATED_AGREEMENT
        sep[todo] = last
        converged[todo] = ok
        todo = todo[~ok & np.isfinite(last)]
        turns *= 2
    return sep, converged


@dataclass(frozen=True)
class Onset:
    """The no-follow onset of each design over a speed range (``onset_speeds``)."""

    speed: np.ndarray  # (n,) the onset [rad/s], within ± tolerance/2; NaN where none is found
    #: (n,) str: "found"; "below" (no-follow already at the range's lowest speed); "none" (the
    #: follower follows across the range)
    status: np.ndarray
    scan_speed: np.ndarray  # (n_scan,) the speeds looked at first [rad/s]
    #: (n, n_scan) the margin there, the least cam compression over the steady turn [N]; NaN
    #: where the valve seats on part of the turn (then the sign comes from ``seated_no_follow``)
    scan_margin: np.ndarray
    scan_no_follow: np.ndarray  # (n, n_scan) bool: no-follow in the steady state (at the level)
    seated: np.ndarray  # (n,) bool: the onset's bracket needed the seated steady state
    tolerance: float  # [rad/s]
    evaluations: np.ndarray  # (n,) steady states computed (closed form and seated)
    #: (n,) the level [rad of no-follow a turn] each design's onset reaches: 0 (first
    #: separation) without a seat
    level: np.ndarray | None = None


#: The kinds of a point of the search: its value is the closed form's margin [N], or the
#: level less the seated steady state's no-follow per turn [rad] (``_Points``).
_CLOSED, _TURN = 0, 1


def _evaluate(designs, batch, speeds, todo, level):
    """The steady state of the designs ``todo`` at speeds[i]: (value, kind, no-follow,
    margin). The value is positive where the design follows: the closed form's margin [N]
    where configuration I holds, or leaves the cam without a seat or at level 0; else (the
    valve seats on part of the turn, or it leaves the cam and a level is asked for) the
    level less the seated steady state's no-follow per turn [rad]. The margin is the closed
    form's, NaN where the valve seats."""
    n = len(designs)
    value = np.full(n, np.nan)
    kind = np.zeros(n, np.int8)
    no_follow = np.zeros(n, np.bool_)
    out = batch.extremes(np.where(todo, speeds, 1.0), with_max=False, active=todo)
    force = out[:, steady.MIN_FORCE]
    seats = todo & (out[:, steady.MIN_HEIGHT] < 0.0)
    turn = seats | (todo & (force < 0.0) & (level > 0.0))
    closed = todo & ~turn
    value[closed] = force[closed]
    no_follow[closed] = force[closed] < 0.0
    if turn.any():
        idx = np.flatnonzero(turn)
        sep, _ = seated_no_follow([dataclasses.replace(designs[i], speed=speeds[i]) for i in idx])
        kind[idx] = _TURN
        value[idx] = level[idx] - sep
        no_follow[idx] = np.where(level[idx] > 0.0, sep >= level[idx], sep > 0.0)
    margin = np.where(todo & ~seats, force, np.nan)
    return value, kind, no_follow, margin


@dataclass
class _Points:
    """The search's state per design: ``a`` the highest speed up to which no-follow is
    excluded (its value, kind), and a stack of speeds above it still to pass (the top the
    nearest), each with its value, kind and whether it is no-follow."""

    a: np.ndarray
    a_value: np.ndarray
    a_kind: np.ndarray
    slope: np.ndarray  # the last certified chord's slope (NaN: none of a's kind)
    speed: np.ndarray  # (n, capacity) the stack
    value: np.ndarray
    kind: np.ndarray
    no_follow: np.ndarray
    depth: np.ndarray  # (n,) the stack's height
    active: np.ndarray  # (n,) bool: still searching
    scale: np.ndarray  # (n, 2) Illinois's factors on a's and the top's values
    side: np.ndarray  # (n,) the end the last split replaced: −1 a, +1 the top, 0 none

    def top(self, k: int = 1) -> tuple[np.ndarray, ...]:
        """The k-th point from the top (k = 1: the top): speed, value, kind, no-follow;
        the bottom's where the stack is shallower."""
        rows = np.arange(self.depth.size)
        j = np.maximum(self.depth - k, 0)
        return (self.speed[rows, j], self.value[rows, j], self.kind[rows, j],
                self.no_follow[rows, j])  # fmt: skip

    def certify(self, tolerance: float) -> None:
        """Move ``a`` up through every interval to the top that is certified free of
        no-follow: both ends follow, of one kind, and (value_a + value_b) ≥ L·(b − a) with
        L = ONSET_SLOPE_FACTOR × the steepest of the chord, the chord certified before it
        and the chord after it; or the interval is no wider than the tolerance."""
        while True:
            live = self.active & (self.depth > 0)
            b, vb, kb, nb = self.top(1)
            c, vc, kc, _ = self.top(2)
            width = b - self.a
            same = self.a_kind == kb
            with np.errstate(invalid="ignore", divide="ignore"):
                # Equal values (form closure's +inf among them) make a flat chord.
                chord = np.where(vb == self.a_value, 0.0, (vb - self.a_value) / width)
                after = np.where(vc == vb, 0.0, (vc - vb) / (c - b))
                after = np.where((self.depth > 1) & (kc == kb), after, np.nan)
                steep = np.fmax(np.fmax(np.abs(chord), np.abs(after)), np.abs(self.slope))
                bound = ONSET_SLOPE_FACTOR * steep * width
                free = same & (self.a_value + vb >= bound)
            ok = live & ~nb & (free | (width <= tolerance))
            if not ok.any():
                return
            self.slope = np.where(ok, np.where(same, chord, np.nan), self.slope)
            self.a = np.where(ok, b, self.a)
            self.a_value = np.where(ok, vb, self.a_value)
            self.a_kind = np.where(ok, kb, self.a_kind)
            self.depth = self.depth - ok
            self.scale[ok, 0] = 1.0

    def split(self, tolerance: float) -> np.ndarray:
        """Where each live design looks next: the middle of a and the top, or, when the top
        is no-follow and both are the closed form's margins, the Illinois point (the chord's
        root, the end kept twice in a row weighted by ½) kept tolerance/4 inside."""
        b, vb, kb, nb = self.top(1)
        x = 0.5 * (self.a + b)
        secant = nb & (self.a_kind == _CLOSED) & (kb == _CLOSED)
        fa = self.a_value * self.scale[:, 0]
        fb = vb * self.scale[:, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            root = b - fb * (b - self.a) / (fb - fa)
        root = np.clip(root, self.a + 0.25 * tolerance, b - 0.25 * tolerance)
        return np.where(secant & np.isfinite(root), root, x)

    def push(self, todo, x, value, kind, no_follow) -> None:
        """Put the points just looked at on the stacks of the designs ``todo``; a point with
        no-follow replaces the whole stack (nothing above it matters any more), so the stack
        holds the scan and at most the halvings down to the tolerance."""
        rows = np.flatnonzero(todo)
        j = np.where(no_follow[rows], 0, self.depth[rows])
        nb = self.top(1)[3][rows]
        self.speed[rows, j] = x[rows]
        self.value[rows, j] = value[rows]
        self.kind[rows, j] = kind[rows]
        self.no_follow[rows, j] = no_follow[rows]
        self.depth[rows] = j + 1
        # Illinois: the end replaced twice in a row halves the other end's weight.
        replaced = np.where(no_follow[rows], 1, -1)
        again = replaced == self.side[rows]
        bracket = nb  # only while the top was no-follow is the split a chord's root
        self.scale[rows, 0] = np.where(
            bracket & again & (replaced > 0), 0.5 * self.scale[rows, 0], self.scale[rows, 0]
        )
        self.scale[rows, 1] = np.where(
            bracket & again & (replaced < 0), 0.5 * self.scale[rows, 1],
            np.where(replaced > 0, 1.0, self.scale[rows, 1]),
        )  # fmt: skip
        self.side[rows] = np.where(bracket, replaced, 0)


def _start(grid, value, kind, no_follow) -> _Points:
    """The search's state after the scan: ``a`` its lowest speed, the others on the stack."""
    n, m = value.shape
    cap = m + 128  # the scan's speeds, and halvings down to any tolerance (~60 at most)
    stack = np.full((n, cap), np.nan)
    speeds = stack.copy()
    kinds = np.zeros((n, cap), np.int8)
    flags = np.zeros((n, cap), np.bool_)
    speeds[:, : m - 1] = grid[:0:-1]
    stack[:, : m - 1] = value[:, :0:-1]
    kinds[:, : m - 1] = kind[:, :0:-1]
    flags[:, : m - 1] = no_follow[:, :0:-1]
    return _Points(
        a=np.full(n, grid[0]), a_value=value[:, 0].copy(), a_kind=kind[:, 0].copy(),
        slope=np.full(n, np.nan), speed=speeds, value=stack, kind=kinds, no_follow=flags,
        depth=np.full(n, m - 1), active=~no_follow[:, 0], scale=np.ones((n, 2)),
        side=np.zeros(n, np.int64),
    )  # fmt: skip


def onset_speeds(
    designs: Sequence[Case],
    low: float,
    high: float,
    tolerance: float = DEFAULT_ONSET_TOLERANCE_RPM * RPM,
    scan: int = SCAN_SPEEDS,
    level: float = DEFAULT_ONSET_LEVEL,
) -> Onset:
    """The no-follow onset of each design: the lowest speed in [low, high] at which its steady
    state leaves the cam with the valve off its seat (configuration II) — with a seat, for
    at least ``level`` of each turn.

    **Missing no window.** The steady state is looked at on ``scan`` speeds across the
    range; then, from the lowest speed up, each interval [a, b] between speeds where the
    design follows is *certified* free of no-follow, or halved and its halves looked at in
    turn. The value v of a speed is positive where it follows: the closed form's margin
    (the least cam compression over the turn) [N]; with a seat where the valve seats (or the
    train leaves the cam), the level less the seated steady state's no-follow per turn.
    Away from a jump v is Lipschitz in the speed (the margin is the least over the turn of a
    response smooth in ω; kinks where the least moves from one dip of the turn to another),
    so |v'| ≤ L on [a, b] gives v ≥ (v_a + v_b − L·(b − a))/2 there: the interval is
    certified when v_a + v_b ≥ L·(b − a), L taken as ONSET_SLOPE_FACTOR × the steepest of
    the chord over [a, b], the chord certified before it and the chord after it (of the
    same kind of value), or when b − a is no wider than the tolerance. The first speed
    found with no-follow closes a bracket [a, b] with everything below a certified; it is
    refined by the same rule (a point that follows moves a only once [a, point] is
    certified), split at the Illinois point of the margin's chord where both ends are the
    closed form's and halved otherwise, until b − a ≤ tolerance. So a range enclosing
    another gives the same onset to the tolerance as long as the bound holds: a window of
    no-follow is missed only if it is narrower than the tolerance or the margin falls to
    zero across it more than twice as steeply as on the chords either side — a slope no
    chord of the refinement sees. With a seat at level 0 (first separation) a follow point's
    value is 0, so only intervals flat on every chord certify: the bound says nothing there
    (the scan's and the refinement's speeds alone).

    **The level.** With a seat, the seat's and the ramp's impacts throw the follower off the
    cam for thousandths to tenths of a degree a turn over a wide band of speeds below the
    train's loss of control, where no-follow jumps to degrees a turn (a polydyne with ramps
    and 0.2 mm lash: under 0.12° a turn up to 5420 rpm, 3.3° at 5430 rpm, where the closed
    form's margin falls through zero). The default level, 0.5° a turn, sits between the two:
    the onset a designer means, the loss of control, not the first bounce; 0 gives the first
    separation. Without a seat the level is not used: the onset is the margin's root.

    Parameters
    ----------
    designs : sequence of Case
        Each design's train, profile, seat and closure (their ``speed`` is ignored).
    low, high : float
        The speed range [rad/s].
    tolerance : float
        Width of the final bracket [rad/s]; the onset is its middle.
    scan : int
        Speeds looked at first, at least 2.
    level : float
        With a seat, the no-follow a turn [rad] the onset reaches (≥ 0; 0: the first).
    """
    if not (0 < low < high and math.isfinite(high)):
        raise CaseError.at(
            "speed",
            f"found the range {low!r} … {high!r} rad/s, expected 0 < low < high",
            found=(low, high),
            expected="0 < low < high",
        )
    if not tolerance > 0:
        raise CaseError.at(
            "tolerance", f"found {tolerance!r} rad/s, expected > 0", found=tolerance,
            expected="> 0",
        )  # fmt: skip
    if not (level >= 0 and math.isfinite(level)):
        raise CaseError.at(
            "level", f"found {level!r} rad, expected ≥ 0", found=level, expected="≥ 0"
        )
    designs = [dataclasses.replace(d, speed=low) for d in designs]
    check_run(designs, RunSettings(), check_stability_limit=False)
    n = len(designs)
    batch = _prepare(designs)
    levels = np.where(batch.cases.has_seat, float(level), 0.0)
    grid = np.linspace(low, high, max(2, int(scan)))
    value = np.full((n, grid.size), np.nan)
    kind = np.zeros((n, grid.size), np.int8)
    no_follow = np.zeros((n, grid.size), np.bool_)
    margin = np.full((n, grid.size), np.nan)
    every = np.ones(n, np.bool_)
    for k, s in enumerate(grid):
        value[:, k], kind[:, k], no_follow[:, k], margin[:, k] = _evaluate(
            designs, batch, np.full(n, s), every, levels
        )
    evaluations = np.full(n, grid.size)
    pts = _start(grid, value, kind, no_follow)
    status = np.where(no_follow[:, 0], "below", "none").astype(object)
    for _ in range(100_000):
        pts.certify(tolerance)
        pts.active &= pts.depth > 0  # nothing left above a: follows across the range
        b, _, _, nb = pts.top(1)
        done = pts.active & nb & (b - pts.a <= tolerance)
        status[done] = "found"
        pts.active &= ~done
        if not pts.active.any():
            break
        x = pts.split(tolerance)
        vx, kx, nx, _ = _evaluate(designs, batch, x, pts.active, levels)
        evaluations += pts.active
        pts.push(pts.active, x, vx, kx, nx)
    b, _, kb, _ = pts.top(1)
    found = status == "found"
    speed = np.where(found, 0.5 * (pts.a + b), np.nan)
    seated = found & ((pts.a_kind == _TURN) | (kb == _TURN))
    return Onset(speed, status.astype(str), grid, margin, no_follow, seated, float(tolerance),
                 evaluations, levels)  # fmt: skip


def confirm_settings(revolutions: float = CONFIRM_TURNS) -> RunSettings:
    """The settings of :func:`confirm_onsets`'s runs (for a caller that compiles their kernels
    first)."""
    return RunSettings(revolutions=revolutions, warmup=min(CONFIRM_WARMUP, int(revolutions) - 1))


def confirm_onsets(
    designs: Sequence[Case], onset: np.ndarray, offset: float = CONFIRM_OFFSET,
    revolutions: float = CONFIRM_TURNS,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The time-domain engine just below and just above each onset: no-follow per turn, the
    mean over the measured turns (``revolutions`` from the periodic start, the first
    CONFIRM_WARMUP left out: the study archive's ``separation_deg_per_rev``) at
    onset·(1 ∓ offset). :func:`confirmed` says whether they agree with the onset.

    Returns
    -------
    below, above : (n,) [rad]; NaN where there is no onset
    """
    n = len(designs)
    below = np.full(n, np.nan)
    above = np.full(n, np.nan)
    idx = np.flatnonzero(np.isfinite(onset))
    if idx.size:
        cases = [
            dataclasses.replace(designs[int(i)], speed=onset[i] * f)
            for f in (1 - offset, 1 + offset)
            for i in idx
        ]
        res = run_batch(cases, confirm_settings(revolutions), full_state=False,
                        on_failure="record")  # fmt: skip
        below[idx] = res.separation[: idx.size]
        above[idx] = res.separation[idx.size :]
    return below, above


def confirmed(below: np.ndarray, above: np.ndarray, level: np.ndarray | float = 0.0) -> np.ndarray:
    """(n,) bool: the time-domain check agrees with the onset — below it the engine's
    no-follow a turn stays under the level (at level 0: none), above it reaches the level
    (at level 0: some). False where unchecked (NaN)."""
    level = np.broadcast_to(np.asarray(level, float), np.shape(below))
    with np.errstate(invalid="ignore"):
        under = np.where(level > 0.0, below < level, below == 0.0)
        over = np.where(level > 0.0, above >= level, above > 0.0)
    return np.isfinite(below) & np.isfinite(above) & under & over
