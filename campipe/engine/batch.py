"""Run a batch of cases through an integrator: pack, check, call the compiled kernel, unpack.

Pure numerics: arrays in, arrays out; no files, no printing. The run settings and cases live
in :mod:`campipe.engine.settings` (no numba); the names this module held before are imported
from there under their own names (``X as X``), so they stay importable from here.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import typeof

from campipe.constants import TWO_PI
from campipe.engine import failures, integrators, steady
from campipe.engine.closed_form import STATE as STATE
from campipe.engine.closed_form import (
    ExactRuns,
    ModalTrains,
    make_state,
    make_workspace,
    no_plungers,
    stack_trains,
)
from campipe.engine.common import Cases, make_outputs
from campipe.engine.contact import (
    held_mask,
    impact_masses,
    newmark_step_maps,
    static_position,
)
from campipe.engine.integrators import Integrator
from campipe.engine.integrators.modal_exact import arguments
from campipe.engine.kernel_call import plain
from campipe.engine.lash_adjuster import run_adjusted
from campipe.engine.modal import ModalData, modal_data
from campipe.engine.plunger_modes import Embedded, plunger_runs, regime_rows
from campipe.engine.quasi_static import START_CONFIGURATIONS as START_CONFIGURATIONS
from campipe.engine.quasi_static import cam_at as cam_at
from campipe.engine.quasi_static import initial_state as initial_state
from campipe.engine.quasi_static import initial_states, start_inverses
from campipe.engine.result import NO_TABLE, merge_results
from campipe.engine.result import BatchResult as BatchResult
from campipe.engine.settings import CLOSURES as CLOSURES
from campipe.engine.settings import (
    COMPLIANT,
    LIFT_BOUND,
    SPEED_BOUND,
    Case,
    CaseError,
    RunSettings,
    check_run,
    output_angles,
    turn_count,
)
from campipe.engine.settings import DEFAULT_CAPTURE_VELOCITY as DEFAULT_CAPTURE_VELOCITY
from campipe.engine.settings import DEFAULT_INTEGRATOR as DEFAULT_INTEGRATOR
from campipe.engine.settings import DEFAULT_STEPS as DEFAULT_STEPS
from campipe.engine.settings import DEFAULT_WARMUP as DEFAULT_WARMUP
from campipe.engine.settings import FIDELITIES as FIDELITIES
from campipe.engine.settings import INTEGRATORS as INTEGRATORS
from campipe.engine.settings import STARTS as STARTS
from campipe.engine.settings import RunSettingsError as RunSettingsError
from campipe.engine.settings import StabilityError as StabilityError
from campipe.engine.settings import check_stability as check_stability
from campipe.engine.settings import resolve_integrator as resolve_integrator
from campipe.engine.settings import stability_limit as stability_limit
from campipe.engine.settings import visited_configurations as visited_configurations
from campipe.engine.settle import run_settled
from campipe.model import ValveTrain, system_matrices
from campipe.model.assembly import SystemMatrices, configuration_frequencies
from campipe.model.contact_keys import impact_restitution
from campipe.model.hla import adjuster
from campipe.profiles import Profile, evaluate
from campipe.profiles.packed import Keyed, PackedProfiles, keyed, pack_cached
from campipe.vocabulary import (
    CAM,
    CAM_CONTACT,
    CONFIGURATIONS,
    N_COORDINATES,
    SEAT,
    free_coordinates,
)


@functools.lru_cache(maxsize=256)
def train_matrices(train: ValveTrain) -> SystemMatrices:
    """The train's system matrices, cached per train (``cache_clear`` to time them)."""
    if isinstance(train, Embedded):  # a carried plunger's train: its embedded ones
        return train.matrices()
    return system_matrices(train)


@dataclass(frozen=True)
class Prepared:
    """What a step size and a train fix for every case that shares them (cached)."""

    matrices: SystemMatrices  # M, C, K, modes, preload
    #: (4, 24, 8) newmark-linear's step per configuration: forces, and (4, 8, 8)
    #: accelerations and contact forces (contact.newmark_step_maps); None for a train of more
    #: than seven coordinates, which newmark-linear refuses (``settings.check_run``)
    step_A: np.ndarray | None
    step_G: np.ndarray | None
    impact_masses: np.ndarray  # (4,) see contact.impact_masses [kg]
    valve_reference: float  # q7 at zero valve lift [m]
    omega_max: np.ndarray  # (4,) highest natural frequency per configuration [rad/s]
    start_inverses: np.ndarray  # (3, 2, n, n) see start_inverses
    valve_ratio: float  # static valve lift per unit cam lift (the rocker ratio) [-]
    #: the height per unit speed [s] a valve thrown off its cam rises against its spring
    #: (``valve_flight``, ``_bounds``)
    flight: float


@functools.lru_cache(maxsize=256)
def prepare(train: ValveTrain, dt: float) -> Prepared:
    sm = train_matrices(train)
    own = train_matrices(train.train) if isinstance(train, Embedded) else sm  # (symmetric)
    omega_max = np.array(
        [configuration_frequencies(own.mass, own.stiffness, c).max() for c in CONFIGURATIONS]
    )
    step_A: np.ndarray | None = None
    step_G: np.ndarray | None = None
    if sm.mass.shape[0] == N_COORDINATES:
        step_A, step_G = newmark_step_maps(sm.mass, sm.damping, sm.stiffness, dt)
    reference, shape = _static_lift(sm)
    return Prepared(
        sm,
        step_A,
        step_G,
        impact_masses(sm.mass),
        float(reference[SEAT]),  # ``valve_reference``
        omega_max,
        start_inverses(sm),
        float(shape[SEAT]),  # ``valve_ratio``
        valve_flight(sm.mass, shape, train.spring_rate),
    )


def _static_lift(sm: SystemMatrices) -> tuple[np.ndarray, np.ndarray]:
    """(the static positions with the cam on its base circle, their change per metre of cam
    lift), configuration I, the members' give included."""
    n = sm.mass.shape[0]
    lifted = np.zeros(n)
    lifted[CAM] = -1.0  # one metre of cam lift
    reference = _base_circle_position(sm)
    held = held_mask(CAM_CONTACT, n)
    return reference, static_position(sm.mass, sm.stiffness, sm.preload, held, lifted) - reference


def valve_ratio(sm: SystemMatrices) -> float:
    """The static valve lift per unit cam lift: the rocker ratio with the members' give."""
    return float(_static_lift(sm)[1][SEAT])


@functools.lru_cache(maxsize=256)
def train_modal(train: ValveTrain) -> ModalData:
    """The train's closed-form data per configuration, cached per train."""
    return modal_data(train_matrices(train))


def unique_trains(cases: Sequence[Case]) -> tuple[list[ValveTrain], np.ndarray]:
    """The distinct trains of a batch and each case's index into them."""
    if len(cases) == 1:  # (a train's hash reads all its fields: a one-case call skips it)
        return [cases[0].train], np.zeros(1, np.int64)
    index: dict[ValveTrain, int] = {}
    which = np.empty(len(cases), np.int64)
    for i, case in enumerate(cases):
        which[i] = index.setdefault(case.train, len(index))
    return list(index), which


def valve_flight(mass: np.ndarray, shape: np.ndarray, spring_rate: float) -> float:
    """√(m/k) [s] of a train thrown off its cam: m = φᵀMφ, the mass the valve carries when
    the whole train moves with it as it does quasi-statically (φ the static ``shape`` of the
    cam lifting it, ``_static_lift``'s, per unit of the valve's travel), k the valve spring's
    rate. A valve leaving at speed v rises about v·√(m/k) against its spring (energy, one
    degree of freedom). 0 where the cam does not move the valve."""
    if shape[SEAT] == 0.0:  # a valve the cam does not drive (a test's valve alone): no throw
        return 0.0
    phi = shape / shape[SEAT]
    return math.sqrt(float(phi @ mass @ phi) / spring_rate)


def _base_circle_position(sm: SystemMatrices) -> np.ndarray:
    """The static positions with the cam on its base circle, no seat, configuration I [m]."""
    n = sm.mass.shape[0]
    return static_position(
        sm.mass, sm.stiffness, sm.preload, held_mask(CAM_CONTACT, n), np.zeros(n)
    )


def valve_reference(sm: SystemMatrices) -> float:
    """q7 with the cam on its base circle, no seat, in static equilibrium [m]."""
    return float(_base_circle_position(sm)[SEAT])


class TrainStack(NamedTuple):
    """What a batch's distinct trains (in order) give its kernels, stacked along a leading
    train axis (``train_stack``). Cached and shared by the batches of these trains: the
    kernels only read these arrays, and a batch takes its per-case rows by fancy indexing
    (copies; a one-case batch takes the arrays themselves)."""

    preps: tuple[Prepared, ...]
    modal: tuple[ModalData, ...]  # ``train_modal`` per train
    modal_trains: ModalTrains
    valve_ref: np.ndarray  # (n_trains,) ``Prepared.valve_reference``
    ratio: np.ndarray  # (n_trains,) |``Prepared.valve_ratio``|
    meff: np.ndarray  # (n_trains, 4) ``Prepared.impact_masses``
    flight: np.ndarray  # (n_trains,) ``Prepared.flight``
    separation: np.ndarray  # (n_trains, 2) ``ModalData.separation``
    restitution: np.ndarray  # (n_trains, 2) cam and seat coefficients of restitution
    #: per train: configuration I's free coordinates and its free mass block M_ff
    free: tuple[np.ndarray, ...]
    mass_ff: tuple[np.ndarray, ...]
    #: (n_trains, 6) a carried plunger's train's row in ``modal_trains`` per regime, the
    #: others' appended (``plunger_modes.regime_rows``); −1 for any other train
    regimes: np.ndarray


#: The most distinct trains whose stack ``train_stack`` caches: the batches whose
#: preparation weighs on a call; a larger one's stack is made per call, so that the cache
#: holds at most 256 stacks of a few trains.
CACHED_TRAINS = 4


def train_stack(trains: tuple[ValveTrain, ...], dt: float) -> TrainStack:
    """The ``TrainStack`` of a batch's distinct trains at step ``dt`` (0: none), cached for
    up to ``CACHED_TRAINS`` trains."""
    if len(trains) > CACHED_TRAINS:
        return _train_stack.__wrapped__(trains, dt)
    stack = _train_stack(trains, dt)
    # The per-train caches cleared (``prepare``, ``train_modal``: a test that swaps a
    # train's matrices) leave every stack made from them stale.
    for train, prep, modal in zip(trains, stack.preps, stack.modal, strict=True):
        if prepare(train, dt) is not prep or train_modal(train) is not modal:
            _train_stack.cache_clear()
            return _train_stack(trains, dt)
    return stack


@functools.lru_cache(maxsize=256)
def _train_stack(trains: tuple[ValveTrain, ...], dt: float) -> TrainStack:
    preps = tuple(prepare(t, dt) for t in trains)
    modal = [train_modal(t) for t in trains]
    regimes, data, loads = regime_rows(trains, modal, preps, train_modal, train_matrices)
    modal_trains = stack_trains(data, loads)
    free = tuple(np.array(free_coordinates(CAM_CONTACT, p.matrices.mass.shape[0])) for p in preps)
    return TrainStack(
        preps=preps,
        modal=tuple(modal),
        modal_trains=modal_trains,
        valve_ref=np.array([p.valve_reference for p in preps]),
        ratio=np.array([abs(p.valve_ratio) for p in preps]),
        meff=np.stack([p.impact_masses for p in preps]),
        flight=np.array([p.flight for p in preps]),
        separation=np.stack([d.separation for d in modal]),
        restitution=np.array(
            [[impact_restitution(t, "cam"), impact_restitution(t, "seat")] for t in trains]
        ),
        free=free,
        mass_ff=tuple(p.matrices.mass[np.ix_(f, f)] for p, f in zip(preps, free, strict=True)),
        regimes=regimes,
    )


def _exact_runs(settings, dt_run, full_state, which, omega, ns: int, trains, stack) -> ExactRuns:
    """The run's scalars and arrays per case; the harmonic responses ζ (states of ``ns``
    entries) are the kernels' to fill (``closed_form.harmonic_response``, at a case's start)."""
    zeta = np.zeros((omega.size, 4, ns), np.complex128)
    return ExactRuns(
        train=which,
        t_sample=settings.output_every / omega,
        t_end=settings.recorded_revolutions * TWO_PI / omega,
        zeta=zeta,
        dt_cap=float(dt_run or 0.0),
        tolerance=float(settings.tolerance),
        full_state=bool(full_state),
        **plunger_runs(trains, which, stack.regimes, ns // 2),
    )


class Start(NamedTuple):
    """Where each case of a batch starts (``start_states``)."""

    t0: np.ndarray  # (n,) start time [s], ≤ 0 (integrated, unrecorded, up to t = 0)
    q0: np.ndarray  # (n, n_q) coordinates [m, rad] (n_q: the batch's most coordinates)
    v0: np.ndarray  # (n, n_q) velocities [m/s, rad/s]
    a0: np.ndarray  # (n, n_q) accelerations [m/s², rad/s²]
    cfg0: np.ndarray  # (n,) int64 configuration


class PreparedBatch(NamedTuple):
    """What a batch's kernels take, but where it starts (``_prepare_batch``)."""

    case_list: Sequence[Case]  # the batch's cases
    trains: list[ValveTrain]  # the distinct trains
    which: np.ndarray  # each case's index into them
    preps: list[Prepared]
    packed: PackedProfiles
    modal_trains: ModalTrains
    runs: ExactRuns
    cases: Cases  # starting nowhere yet
    stack: TrainStack  # the distinct trains' cached data


def _prepare_batch(cases: Sequence[Case], settings: RunSettings, full_state: bool) -> PreparedBatch:
    """What the batch's kernels take. What the trains and the profiles fix comes from caches
    (``train_stack``, ``pack_cached``, ``_peaks``); only the per-case rows are made here (the
    harmonic responses in the kernels)."""
    if len(cases) == 1 and not isinstance(cases[0].train, Embedded):
        return _prepare_one(cases[0], settings, full_state)
    dt_run = settings.step
    n = len(cases)
    trains, which = unique_trains(cases)
    stack = train_stack(tuple(trains), dt_run or 0.0)
    qref = stack.valve_ref[which]
    has_seat = np.array([c.has_seat for c in cases], dtype=np.bool_)
    omega = np.array([c.speed for c in cases], dtype=float)
    modal_trains = stack.modal_trains
    n_q = modal_trains.load.shape[1]
    profiles = [keyed(c.profile) for c in cases]
    seat = np.array([c.seat if c.has_seat else 0.0 for c in cases])
    lift_bound, speed_bound = _bounds(
        profiles, stack.ratio[which], omega, seat, stack.flight[which]
    )
    return PreparedBatch(
        case_list=cases,
        trains=trains,
        which=which,
        preps=list(stack.preps),
        packed=pack_cached([c.profile for c in cases]),
        modal_trains=modal_trains,
        runs=_exact_runs(settings, dt_run, full_state, which, omega, 2 * n_q, trains, stack),
        cases=Cases(
            omega=omega,
            seat_q=qref + seat,
            has_seat=has_seat,
            form=np.array([c.closure == "form" for c in cases], dtype=np.bool_),
            t0=np.zeros(n),
            q0=np.zeros((n, n_q)),
            v0=np.zeros((n, n_q)),
            a0=np.zeros((n, n_q)),
            cfg0=np.array([CAM_CONTACT] * n, np.int64),
            meff=stack.meff[which],
            separation=stack.separation[which],
            capture=np.array([float(settings.capture_velocity)] * n),
            restitution=stack.restitution[which],
            valve_ref=qref,
            lift_bound=lift_bound,
            speed_bound=speed_bound,
        ),
        stack=stack,
    )


def _prepare_one(case: Case, settings: RunSettings, full_state: bool) -> PreparedBatch:
    """``_prepare_batch`` of a one-case batch, from scalars: the same numbers (each the same
    IEEE operations in the same order as the vectorised path's, on one element), in a few
    arrays and their views instead of some thirty numpy operations on one-element arrays."""
    dt_run = settings.step
    train = case.train
    stack = train_stack((train,), dt_run or 0.0)
    n_q = stack.modal_trains.load.shape[1]
    speed = float(case.speed)
    has_seat = case.has_seat
    seat = case.seat if has_seat else 0.0
    ratio = float(stack.ratio[0])
    lift_peak, rate_peak = _peaks(keyed(case.profile))
    floats = np.array(
        [
            speed,
            stack.valve_ref[0] + seat,  # seat_q
            float(settings.capture_velocity),
            LIFT_BOUND
            * max(lift_peak, speed * rate_peak * float(stack.flight[0]))
            * max(ratio, 1.0)
            + abs(seat),  # (``_bounds``' for one case)
            SPEED_BOUND * speed * rate_peak * max(ratio, 1.0),
            settings.output_every / speed,  # t_sample
            settings.recorded_revolutions * TWO_PI / speed,  # t_end
        ]
    )
    # Each a (1,) row of one array (C-contiguous views: the kernels' types).
    omega, seat_q, capture, lift_bound, speed_bound, t_sample, t_end = floats.reshape(7, 1)
    q0, v0 = np.zeros((2, 1, n_q))  # (a periodic start writes them)
    has_seat_, form = np.array([[has_seat], [case.closure == "form"]])
    shared = _one_case(n_q)
    which = shared.which
    runs = ExactRuns(
        train=which,
        t_sample=t_sample,
        t_end=t_end,
        zeta=np.zeros((1, 4, 2 * n_q), np.complex128),
        dt_cap=float(dt_run or 0.0),
        tolerance=float(settings.tolerance),
        full_state=bool(full_state),
        **shared.plungers,
    )
    return PreparedBatch(
        case_list=[case],
        trains=[train],
        which=which,
        preps=list(stack.preps),
        packed=pack_cached([case.profile]),
        modal_trains=stack.modal_trains,
        runs=runs,
        cases=Cases(
            omega=omega,
            seat_q=seat_q,
            has_seat=has_seat_,
            form=form,
            t0=np.zeros(1),
            q0=q0,
            v0=v0,
            a0=shared.a0,
            cfg0=shared.cfg0,
            meff=stack.meff,
            separation=stack.separation,
            capture=capture,
            restitution=stack.restitution,
            valve_ref=stack.valve_ref,
            lift_bound=lift_bound,
            speed_bound=speed_bound,
        ),
        stack=stack,
    )


class _OneCase(NamedTuple):
    """What every one-case batch of trains of ``n_q`` coordinates shares (``_one_case``)."""

    which: np.ndarray  # (1,) int64: the batch's one train
    cfg0: np.ndarray  # (1,) int64: configuration I at the start
    a0: np.ndarray  # (1, n_q): no start accelerations (modal-exact's periodic start)
    plungers: dict[str, np.ndarray]  # ``ExactRuns``' plunger fields: none carried


@functools.cache
def _one_case(n_q: int) -> _OneCase:
    """The arrays a one-case batch of trains of ``n_q`` coordinates shares with every other
    (``_prepare_one``), made once: read, never written, by the kernels and by the run (a
    start that is not the kernels' own replaces ``a0`` and ``cfg0``; a batch that carries a
    plunger takes ``plunger_runs``' own fields). Each allocation saved is a microsecond or
    two of a one-case call's fixed cost."""
    return _OneCase(
        which=np.zeros(1, np.int64),
        cfg0=np.full(1, CAM_CONTACT, np.int64),
        a0=np.zeros((1, n_q)),
        plungers=no_plungers(1, n_q),
    )


#: A one-case periodic start's step to snap to: none (read, never written: shared by every
#: call).
ONE_ZERO = np.zeros(1)

#: The integrators that start from q and v alone (modal-exact's closed form): ``run_batch``
#: leaves their periodic start's accelerations zero instead of solving for them.
NO_START_ACCELERATIONS = ("modal-exact",)


def _starts(
    cases: Sequence[Case], settings: RunSettings, batch: PreparedBatch, in_run: bool = False
) -> Start:
    """Where each case starts (``start_states``); ``in_run``: for ``run_batch``, which needs
    no accelerations for the integrators of ``NO_START_ACCELERATIONS``."""
    c = batch.cases
    if settings.start == "quasi-static":
        q0, v0, a0, cfg0 = initial_states(
            [p.matrices for p in batch.preps],
            batch.which,
            batch.packed,
            c.omega,
            c.has_seat,
            c.seat_q,
            [p.start_inverses for p in batch.preps],
        )
        return Start(np.zeros(len(cases)), q0, v0, a0, cfg0)
    step = settings.step if integrators.get(settings.method).fixed_step else 0.0
    accelerations = not in_run or settings.method not in NO_START_ACCELERATIONS
    t0, q0, v0, a0 = _periodic_starts(
        cases, c, batch.modal_trains, batch.runs, batch.packed, np.full(len(cases), step),
        batch.stack, batch.which, accelerations,
    )  # fmt: skip
    return Start(t0, q0, v0, a0, np.full(len(cases), CAM_CONTACT, np.int64))


def start_states(cases: Sequence[Case], settings: RunSettings) -> Start:
    """The start of each case under ``settings.start``: the periodic steady state of
    configuration I (``engine.steady``) or the thesis's quasi-static state at θ = 0. For
    newmark-linear the periodic start falls on a whole number of its steps before t = 0."""
    check_run(cases, settings, check_stability_limit=False)
    return _starts(cases, settings, _prepare_batch(cases, settings, full_state=False))


def integrator_types(cases: Sequence[Case], settings: RunSettings, full_state: bool) -> tuple:
    """The numba types of modal-exact's arguments in ``run_batch`` for these cases: the
    signature to compile its kernel ahead for (``campipe.engine.kernels.compile_kernels``),
    found without running a kernel (the start's or another)."""
    batch = _prepare_batch(cases, settings, full_state)
    modal_exact = integrators.get("modal-exact")
    prepared = modal_exact.prepare(batch, settings)
    args = arguments(prepared, batch.cases, _outputs(batch, settings))
    return tuple(typeof(a) for a in args)  # as a call types them


def _outputs(batch: PreparedBatch, settings: RunSettings, plan: _Plan | None = None):
    """The kernels' output arrays for a batch run with ``settings`` (``common.make_outputs``)."""
    plan = _plan(settings) if plan is None else plan
    n_q = batch.modal_trains.load.shape[1]
    cleared = not plan.integrator.fills_outputs
    return make_outputs(len(batch.which), plan.n_out, plan.n_rev, settings.max_events, n_q, cleared)


def _periodic_starts(
    case_list, cases, modal_trains, runs, packed, snap, stack, which, accelerations=True
):
    """Each case's start on the periodic steady state of configuration I
    (``steady.periodic_starts``): (t0, q0, v0, a0); refuses a case where configuration I holds
    nowhere on the turn."""
    n = cases.omega.size
    n_q = modal_trains.load.shape[1]
    t0 = np.empty(n)
    q0 = np.empty((n, n_q))
    v0 = np.empty((n, n_q))
    _find_periodic_starts(cases, modal_trains, runs, packed, snap, t0, q0, v0)
    if not accelerations:
        return t0, q0, v0, np.zeros_like(q0)
    return t0, q0, v0, _start_accelerations(case_list, cases.omega, t0, q0, v0, stack, which)


def _find_periodic_starts(cases, modal_trains, runs, packed, snap, t0, q0, v0) -> None:
    """``steady.periodic_starts`` into t0, q0 and v0 (which may be ``cases``' own: the
    kernel reads none of them); refuses a case where configuration I holds nowhere on the
    turn."""
    n, n_q = q0.shape
    z_turn = np.zeros((n, packed.breaks.shape[1], 2 * n_q))  # the most pieces + 1
    ws, state = make_workspace(n_q), make_state()
    structures = plain(cases, modal_trains, packed, runs, ws)
    steady.periodic_starts(*structures, state, snap, z_turn, t0, q0, v0)
    if math.isnan(t0[0]) if n == 1 else np.isnan(t0).any():
        bad = np.flatnonzero(np.isnan(t0))
        raise CaseError.at(
            "seat",
            f"cases {bad.tolist()}: the cam never drives the valve off its seat with the cam "
            "pushing (configuration I holds nowhere on the turn): the seat is above the "
            "valve's lift, or the speed pulls the follower off wherever the valve is open",
            found=bad.tolist(),
            expected="a seat below the valve's full lift",
        )


def _start_accelerations(case_list, omega, t0, q0, v0, stack: TrainStack, which) -> np.ndarray:
    """Accelerations from the equation of motion with the cam held (newmark-linear's start),
    by profile and by train over their cases at once (the same numbers as case by case:
    numpy's stacked matmul and solve take each case's matrix product and LAPACK solve)."""
    n, n_q = q0.shape
    a0 = np.zeros((n, n_q))
    theta = omega * t0
    profile = case_list[0].profile
    if all(case.profile is profile for case in case_list):
        a0[:, CAM] = -(omega**2) * evaluate(profile, theta)[2]
    else:
        by_profile: dict[Profile, list[int]] = {}
        for c, case in enumerate(case_list):
            by_profile.setdefault(case.profile, []).append(c)
        for profile, members in by_profile.items():
            a0[members, CAM] = -(omega[members] ** 2) * evaluate(profile, theta[members])[2]
    single = len(stack.preps) == 1
    for t, prep in enumerate(stack.preps):
        rows = np.arange(n) if single else np.flatnonzero(which == t)
        if rows.size == 0:
            continue
        sm, free = prep.matrices, stack.free[t]
        k = sm.mass.shape[0]

        def times(matrix, x, rows=rows, k=k):
            return (matrix[None] @ x[rows, :k, None])[..., 0]

        force = sm.preload - times(sm.stiffness, q0) - times(sm.damping, v0) - times(sm.mass, a0)
        solved = np.linalg.solve(stack.mass_ff[t][None], force[:, free, None])
        a0[rows[:, None], free] = solved[..., 0]
    return a0


@functools.lru_cache(maxsize=256)
def _peaks(profile: Keyed) -> tuple[float, float]:
    """A profile's largest |lift| [m] and |dlift/dθ| [m/rad] on a grid of 2049 angles."""
    lifts, rates, _ = evaluate(profile.profile, np.linspace(0.0, TWO_PI, 2049))
    return float(np.max(np.abs(lifts))), float(np.max(np.abs(rates)))


def _bounds(profiles: Sequence[Keyed], ratio, omega, seat, flight) -> tuple[np.ndarray, np.ndarray]:
    """Each case's bounds on valve lift [m] and on closing and valve speeds [m/s], from its
    profile's peaks, its train's |valve ratio|, its seat (0 where it has none) and its
    ``TrainStack.flight``: ``LIFT_BOUND`` times the larger of the full lift and the height a
    valve thrown at the cam's fastest valve speed rises against its spring, v·√(m/k) (an
    energy bound of one mass: a train far past its onset is thrown beyond its lift), at a
    valve ratio of at least 1: the static ratio counts the links' give, which a valve on a
    soft link overcomes near its resonance while it follows the cam (a helper's chain)."""
    peaks = np.array([_peaks(p) for p in profiles]).reshape(len(profiles), 2)
    thrown = np.maximum(peaks[:, 0], omega * peaks[:, 1] * flight)
    lift = LIFT_BOUND * thrown * np.maximum(ratio, 1.0) + np.abs(seat)
    speed = SPEED_BOUND * omega * peaks[:, 1] * np.maximum(ratio, 1.0)
    return lift, speed


def run_batch(
    cases: Sequence[Case],
    settings: RunSettings,
    *,
    full_state: bool = True,
    check_stability_limit: bool = True,
    on_failure: str = "raise",
    start: Start | None = None,
) -> BatchResult:
    """Integrate every case of a batch in one compiled call.

    Parameters
    ----------
    cases : sequence of Case
        Any mix of trains, profiles, speeds, seats and closures.
    settings : RunSettings
        Shared by the batch: revolutions, step, output spacing, integrator.
    full_state : bool
        Histories of all seven coordinates (default), or only what the contacts need: q1, q7
        and their velocities (modal-exact then leaves the others NaN, so a scene that shows
        cam, follower and valve lifts does not pay for the rest).
    check_stability_limit : bool
        Refuse a newmark-linear step beyond the stability limit (default). False only to
        demonstrate the limit: the run then diverges and raises IntegrationError.
    on_failure : {"raise", "record"}
        A case that fails (``vocabulary.NONFINITE``, ``CHATTER``): raise IntegrationError
        naming them (default), or record it in ``BatchResult.status`` and return the others'
        results; a failed case's histories and metrics are then NaN (its events are those
        before the failure).
    start : Start, optional
        Where each case starts, at t = 0 (a run of automatic length starts each turn where
        the last ended: ``engine.settle``); default: ``settings.start``'s.

    Raises
    ------
    StabilityError
        For a step beyond the stability limit, before anything runs.
    IntegrationError
        If a case failed and ``on_failure`` is "raise".
    """
    if on_failure not in ("raise", "record"):
        raise ValueError(f"on_failure: found {on_failure!r}, expected 'raise' or 'record'")
    check_run(cases, settings, check_stability_limit=check_stability_limit)
    if any(adjuster(c.train) for c in cases):  # the plunger carried, or moved between turns
        return run_adjusted(cases, settings, _run_turn, carried_run=_run_carried,
                            on_failure=on_failure,
                            check_stability_limit=check_stability_limit)  # fmt: skip
    return _run_checked(cases, settings, full_state, check_stability_limit, on_failure, start)


def _run_carried(cases, settings, start=None, full_state=True, **options) -> BatchResult:
    """``run_batch`` of cases whose lash adjuster's plunger is a state of their run
    (``engine.plunger``), each in its frame (``lash_adjuster.run_carried``); ``options``
    are run_batch's others, as ``run_adjusted`` hands them on."""
    start = None if start is None else Start(*start)
    return _run_checked(cases, settings, full_state, start=start, **options)


def _run_checked(
    cases: Sequence[Case],
    settings: RunSettings,
    full_state: bool,
    check_stability_limit: bool,
    on_failure: str,
    start: Start | None,
) -> BatchResult:
    """``run_batch`` past its checks and its lash adjusters."""
    if settings.settle:
        return run_settled(
            cases,
            settings,
            _run_turn,
            [train_matrices(c.train) for c in cases],
            check_stability_limit=check_stability_limit,
            on_failure=on_failure,
        )
    if settings.integrator == "default" and any(c.compliant for c in cases):
        options = {
            "full_state": full_state,
            "check_stability_limit": check_stability_limit,
            "on_failure": on_failure,
        }
        return _run_by_contacts(cases, settings, options, start)
    n = len(cases)
    plan = _plan(settings)
    batch = _prepare_batch(cases, settings, full_state)
    if start is None and plan.start_in_place:
        # The start written into the batch's own t0, q0 and v0 (a0 stays zero, cfg0 I).
        cases_in = batch.cases
        snap = ONE_ZERO if n == 1 else np.zeros(n)  # no step to snap to
        _find_periodic_starts(cases_in, batch.modal_trains, batch.runs, batch.packed,
                              snap, cases_in.t0, cases_in.q0, cases_in.v0)  # fmt: skip
    else:
        if start is None:
            start = _starts(cases, settings, batch, in_run=True)
        cases_in = batch.cases._replace(**start._asdict())
    out = _outputs(batch, settings, plan)
    integrator = plan.integrator
    # (the plungers where the integrator carries them: ``engine.plunger``)
    carried = integrator.run(integrator.prepare(batch, settings), cases_in, out)
    status, n_events = out.status, out.n_events
    if status[0] if n == 1 else np.count_nonzero(status):  # not every case OK
        failures.raise_or_blank(out, settings, on_failure, check_stability_limit, integrator)
    angles = plan.angles.copy()
    omega, qref = cases_in.omega, cases_in.valve_ref
    lift_zero: float | np.ndarray  # where each case's valve lift reads 0
    if n == 1:  # (the same numbers as below, without a loop's arrays)
        lift_zero = cases[0].lift_zero
        events = [out.events[0, : min(int(n_events[0]), settings.max_events)].copy()]
    else:
        lift_zero = np.array([c.lift_zero for c in cases])
        kept = np.minimum(n_events, settings.max_events)
        events = [out.events[i, : kept[i]].copy() for i in range(n)]
    return BatchResult(
        cam_angle=angles,
        time=angles[None, :] / omega[:, None],
        q=out.q,
        v=out.v,
        acc=out.acc,
        cam_lift=out.cam,
        cam_force=0.0 - out.force[:, :, 0],  # (+0.0 off the cam, not −0.0)
        seat_force=out.force[:, :, 1],
        contact_state=out.cfg,
        valve_reference=qref + lift_zero,  # 0 on a lash's seat
        measured=plan.measured.copy(),
        per_rev=out.per_rev,
        trains=[c.train for c in cases],
        events=events,
        steps=out.steps,
        status=status,
        start_time=cases_in.t0,
        lash_adjuster=NO_TABLE if carried is None else carried.table,
        extension=NO_TABLE if carried is None else carried.extension,
    )


class _Plan(NamedTuple):
    """What a run's settings fix for every call (``_plan``)."""

    angles: np.ndarray  # (n_out,) the output angles (``output_angles``; copied per result)
    measured: np.ndarray  # (n_rev,) the turns the summaries read (copied per result)
    n_out: int  # output samples
    n_rev: int  # turns, a partial last one included
    integrator: Integrator
    #: a periodic start written into the batch's own start arrays (``NO_START_ACCELERATIONS``)
    start_in_place: bool


@functools.lru_cache(maxsize=64)
def _plan(settings: RunSettings) -> _Plan:
    """The ``_Plan`` of settings ``check_run`` has passed, cached per settings."""
    n_rev = turn_count(settings.recorded_revolutions)
    angles = output_angles(settings)
    angles.flags.writeable = False  # (a result takes a copy)
    measured = settings.measured_turns(n_rev)
    measured.flags.writeable = False
    return _Plan(
        angles=angles,
        measured=measured,
        n_out=angles.size,
        n_rev=n_rev,
        integrator=integrators.get(settings.method),
        start_in_place=settings.start == "periodic" and settings.method in NO_START_ACCELERATIONS,
    )


def _run_turn(cases, settings, start=None, **options) -> BatchResult:
    """One turn of a run of automatic length (``settle.run_settled``), from ``start``'s
    (t0, q0, v0, a0, cfg0) or, for the first, from ``settings.start``'s."""
    return run_batch(cases, settings, start=None if start is None else Start(*start), **options)


def _run_by_contacts(
    cases: Sequence[Case], settings: RunSettings, options, start: Start | None = None
) -> BatchResult:
    """A batch under the default integrator with compliant cases: those through the
    compliant integrator, the others through the default, the results in case order."""
    flags = np.array([c.compliant for c in cases])
    parts = []
    for which, name in ((flags, COMPLIANT), (~flags, "default")):
        index = np.flatnonzero(which)
        if index.size:
            run = dataclasses.replace(settings, integrator=name)
            part_start = None if start is None else Start(*(a[index] for a in start))
            part = run_batch([cases[int(i)] for i in index], run, start=part_start, **options)
            parts.append((index, part))
    return merge_results(len(cases), parts)
