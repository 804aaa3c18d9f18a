"""The steady-state path: the periodic state below the no-follow onset without integrating
turns, its margin, and the onset speed as the margin's root.

Below the onset the follower never leaves the cam, so the train stays in configuration I,
linear and driven with the cam's period: its steady state is the closed form of
``campipe.engine.steady`` (z(0) = (I − e^{AT})⁻¹ b, exact piece by piece). Its *margin* is the
least cam compression −F1 over the turn: positive, the follower follows; the no-follow onset
is the lowest speed where it reaches zero. Where the valve reaches its seat the steady state
is piecewise (configurations I, III, IV, with impacts at the seat and the cam, plastic or with
the train's restitution): it is then the fixed point of the turn map over the exact piece
propagators, which is what ``modal-exact`` integrates turn by turn (``campipe.engine.onset``,
which also searches for the onset).

Pure numerics: arrays in, arrays out; no files, no printing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import steady, steady_samples
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
from campipe.engine.closed_form import (
    ExactRuns,
    ModalTrains,
    make_state,
    make_workspace,
    no_plungers,
    stack_trains,
)
from campipe.engine.common import DROP_FLOOR, SMOOTH, Cases, classify_break, jump_speed
from campipe.engine.metrics import MAX_CAM_FORCE, N_ENGINE
from campipe.engine.modal import ModalData
from campipe.engine.settings import sample_count, turn_count
from campipe.model import ValveTrain
from campipe.model.assembly import preload_vector
from campipe.model.contact_keys import impact_restitution
from campipe.model.hla import adjuster
from campipe.model.lash import installed_preload, reference_preload
from campipe.profiles import Profile, pack
from campipe.profiles.pieces import evaluate_pieces
from campipe.vocabulary import CAM, CAM_CONTACT, N_EVENT_FIELDS, OK, SEAT

# --------------------------------------------------------------------------- packing


def _modal_at_preload(train: ValveTrain) -> ModalData:
    """The closed-form data of a train, its modes shared by every preload (``batch.train_modal``
    caches them): the preload only enters the constant forcing and the contact forces'
    constant part, linearly."""
    unit = train_modal(train.replace(spring_preload=installed_preload(train, 1.0)))
    p = reference_preload(train)
    return dataclasses.replace(unit, b_load=unit.b_load * p, sigma0=unit.sigma0 * p)


@dataclass
class SteadyBatch:
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
            make_workspace(self.trains.load.shape[1]), make_state(), self.z_turn,
            with_max, active, out,
        )  # fmt: skip
        return out


def prepare_steady(
    cases: Sequence[Case], *, need_reference: bool = False, capture: float | None = None
) -> SteadyBatch:
    """The closed form's inputs for rigid ``cases`` at their speeds (the speeds may be set
    again: ``SteadyBatch.extremes``). ``capture`` [m/s]: the capture velocity below which a
    cam rate jump is no impact (``common.classify_break``; default the run's default), as in
    the run the closed form stands for."""
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
        dt_cap=0.0, tolerance=1e-12, full_state=True, **no_plungers(n, n_q),
    )  # fmt: skip
    state = Cases(
        omega=np.array([c.speed for c in cases], dtype=float),
        seat_q=qref + np.where(has_seat, [c.seat for c in cases], 0.0),
        has_seat=has_seat,
        form=np.array([c.closure == "form" for c in cases], dtype=np.bool_),
        t0=zeros, q0=np.zeros((n, n_q)), v0=np.zeros((n, n_q)), a0=np.zeros((n, n_q)),
        cfg0=np.full(n, CAM_CONTACT, np.int64), meff=np.zeros((n, 4)),
        separation=np.zeros((n, 2)),
        capture=np.full(n, RunSettings().capture_velocity if capture is None else capture),
        restitution=np.zeros((n, 2)),
        valve_ref=qref, lift_bound=zeros, speed_bound=zeros,
    )  # fmt: skip
    z_turn = np.zeros((n, packed.n_pieces.max() + 1, 2 * n_q))
    return SteadyBatch(state, modal_trains, packed, runs, z_turn, matrices, which)


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
    batch = prepare_steady(cases)
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
    batch = prepare_steady(cases, need_reference=True)
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
    batch: SteadyBatch, ext: SteadyExtremes, angles: np.ndarray, active: np.ndarray | None = None
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
    steady_samples.steady_samples(
        batch.cases, batch.trains, batch.packed, batch.runs, make_workspace(n_q),
        make_state(), batch.z_turn, angles, active, q, v, acc, force,
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


def _cases_break_limits(cases: Sequence[Case]) -> list[tuple[np.ndarray, ...]]:
    """Each case's ``_break_limits``, once per profile the cases share."""
    limits: dict[int, tuple[np.ndarray, ...]] = {}
    for case in cases:
        if id(case.profile) not in limits:
            limits[id(case.profile)] = _break_limits(case.profile)
    return [limits[id(case.profile)] for case in cases]


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
    out = np.zeros(len(cases), np.bool_)
    for i, (case, limits) in enumerate(zip(cases, _cases_break_limits(cases), strict=True)):
        form = case.closure == "form"
        out[i] = any(
            classify(l0, d0, l1, d1, case.speed, form, capture)[0] != SMOOTH
            for l0, d0, l1, d1 in zip(*limits, strict=True)
        )
    return out


def leave_speeds(cases: Sequence[Case], capture: float) -> np.ndarray:
    """(n,) the speed [rad/s] above which a follower held on the case's cam leaves it at a
    break (``common.classify_break`` as in ``break_events``; ``common.jump_speed``): a release
    (the lift rate drops, or the lift steps down: at every speed), or a rate jump into a
    force-closed follower that bounces off (a coefficient of restitution at the cam); +inf
    where none does (form closure, a plastic follower on a rising step). The closed form
    carries every other break (a plastic impact's impulse: ``steady``); above this speed the
    follower leaves configuration I every turn."""
    out = np.full(len(cases), np.inf)
    for i, (case, limits) in enumerate(zip(cases, _cases_break_limits(cases), strict=True)):
        if case.closure == "form":
            continue
        bounces = impact_restitution(case.train, "cam") > 0.0
        for l0, d0, l1, d1 in zip(*limits, strict=True):
            if l1 < l0 - DROP_FLOOR:
                out[i] = 0.0
            elif d1 < d0 or bounces:
                out[i] = min(out[i], jump_speed(float(d0), float(d1), capture))
    return out


def steady_cases(cases: Sequence[Case], settings: RunSettings) -> np.ndarray:
    """(n,) bool: the cases ``run_at_fidelity`` takes from the closed form at the steady
    level (``_steady_mask``; compliant cases never). The probe it pays, alone."""
    check_run(cases, settings, check_stability_limit=False)
    take = np.zeros(len(cases), np.bool_)
    rigid = np.flatnonzero([not c.compliant for c in cases])
    if rigid.size:
        some = [cases[int(i)] for i in rigid]
        batch = prepare_steady(some, capture=settings.capture_velocity)
        ext = _as_extremes(batch.extremes(batch.cases.omega.copy()))
        take[rigid] = _steady_mask(some, ext, settings)
    return take


def _steady_mask(cases: Sequence[Case], ext: SteadyExtremes, settings: RunSettings) -> np.ndarray:
    """Which of the rigid ``cases`` (their extremes ``ext``) the steady level takes: those whose
    periodic state is configuration I's all turn (``SteadyExtremes.holds``: the least cam force
    above zero, the valve clear of its seat) and whose profile the follower crosses held
    (no ``break_events``), without a hydraulic lash adjuster. The others have events every
    turn, or a plunger that moves: the full engine runs them."""
    # a hydraulic lash adjuster's plunger moves turn by turn: never one turn's closed form
    holds = ext.holds & np.array([adjuster(c.train) is None for c in cases], np.bool_)
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
        batch = prepare_steady(some, need_reference=True, capture=settings.capture_velocity)
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
    batch: SteadyBatch,
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
