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
no-follow is configuration II in its last turn.

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
#: Speeds at which the onset search first looks across a speed range (the first sign change
#: of the margin is then refined): a dip of the margin narrower than the range / (SCAN − 1)
#: can be missed.
SCAN_SPEEDS = 33
#: The onset's default tolerance [rpm] and the time-domain check's offset either side of it.
DEFAULT_ONSET_TOLERANCE_RPM = 0.1
CONFIRM_OFFSET = 0.005
CONFIRM_TURNS = 4


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
    scan_no_follow: np.ndarray  # (n, n_scan) bool: no-follow in the steady state
    seated: np.ndarray  # (n,) bool: the onset's bracket needed the seated steady state
    tolerance: float  # [rad/s]
    evaluations: np.ndarray  # (n,) steady states computed (closed form and seated)


def _separates(designs, batch, speeds, todo):
    """(margin [N], no-follow, seated) at speeds[i] for the designs ``todo`` (bool mask)."""
    n = len(designs)
    margin = np.full(n, np.nan)
    out = batch.extremes(np.where(todo, speeds, 1.0), with_max=False, active=todo)
    seated = todo & (out[:, steady.MIN_HEIGHT] < 0.0)
    closed = todo & ~seated
    margin[closed] = out[closed, steady.MIN_FORCE]
    no_follow = closed & (margin < 0.0)
    if seated.any():
        idx = np.flatnonzero(seated)
        sep, _ = seated_no_follow([dataclasses.replace(designs[i], speed=speeds[i]) for i in idx])
        no_follow[idx] = sep > 0.0
    return margin, no_follow, seated


def onset_speeds(
    designs: Sequence[Case],
    low: float,
    high: float,
    tolerance: float = DEFAULT_ONSET_TOLERANCE_RPM * RPM,
    scan: int = SCAN_SPEEDS,
) -> Onset:
    """The no-follow onset of each design: the lowest speed in [low, high] at which its steady
    state leaves the cam with the valve off its seat (configuration II).

    The margin (``steady_extremes``) is looked at on ``scan`` speeds across the range; the
    first sign change is refined to ``tolerance`` by the Illinois method on the margin where
    the closed form holds at both ends, by bisection where the valve seats (the seated steady
    state, ``seated_no_follow``, gives only whether no-follow occurs).

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
    designs = [dataclasses.replace(d, speed=low) for d in designs]
    check_run(designs, RunSettings(), check_stability_limit=False)
    n = len(designs)
    batch = _prepare(designs)
    grid = np.linspace(low, high, max(2, int(scan)))
    margin = np.full((n, grid.size), np.nan)
    no_follow = np.zeros((n, grid.size), np.bool_)
    every = np.ones(n, np.bool_)
    for k, s in enumerate(grid):
        margin[:, k], no_follow[:, k], _ = _separates(designs, batch, np.full(n, s), every)
    evaluations = np.full(n, grid.size)
    first = np.where(no_follow.any(axis=1), no_follow.argmax(axis=1), -1)
    status = np.where(first < 0, "none", np.where(first == 0, "below", "found"))
    todo = first > 0
    right = np.maximum(first, 1)
    a = np.where(todo, grid[right - 1], np.nan)
    b = np.where(todo, grid[right], np.nan)
    fa = margin[np.arange(n), right - 1]
    fb = margin[np.arange(n), right]
    bisect = ~(np.isfinite(fa) & np.isfinite(fb))
    seated = np.where(todo, bisect, False)
    side = np.zeros(n, np.int64)  # the end the last step replaced: −1 a, +1 b (Illinois)
    for _ in range(200):
        todo &= (b - a) > tolerance
        if not todo.any():
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            x = np.where(bisect, 0.5 * (a + b), b - fb * (b - a) / (fb - fa))
        x = np.clip(x, a + 0.25 * tolerance, b - 0.25 * tolerance)
        fx, sep_x, seated_x = _separates(designs, batch, x, todo)
        evaluations += todo
        bisect |= seated_x
        below = todo & ~sep_x
        above = todo & sep_x
        # Illinois: halve the kept end's value when the same end is replaced twice in a row.
        fb = np.where(below & (side < 0), 0.5 * fb, fb)
        fa = np.where(above & (side > 0), 0.5 * fa, fa)
        a = np.where(below, x, a)
        fa = np.where(below, fx, fa)
        b = np.where(above, x, b)
        fb = np.where(above, fx, fb)
        side = np.where(below, -1, np.where(above, 1, side))
        seated |= seated_x
    speed = np.where(status == "found", 0.5 * (a + b), np.nan)
    return Onset(speed, status, grid, margin, no_follow, seated, float(tolerance), evaluations)


def confirm_settings(revolutions: float = CONFIRM_TURNS) -> RunSettings:
    """The settings of :func:`confirm_onsets`'s runs (for a caller that compiles their kernels
    first)."""
    return RunSettings(revolutions=revolutions)


def confirm_onsets(
    designs: Sequence[Case], onset: np.ndarray, offset: float = CONFIRM_OFFSET,
    revolutions: float = CONFIRM_TURNS,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The time-domain engine just below and just above each onset: no-follow per turn, the
    mean over ``revolutions`` turns from the periodic start (the study archive's
    ``separation_deg_per_rev``) at onset·(1 ∓ offset).

    Any turn counts: just above the onset the engine leaves the cam in its first turn, lands
    slower than its capture velocity and may then rest on the cam (``common.captured``), so
    its later turns can follow for a few tenths of a per cent above the steady state's onset.

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
