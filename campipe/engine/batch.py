"""Run a batch of cases through an integrator: pack, check, call the compiled kernel, unpack.

Pure numerics: arrays in, arrays out; no files, no printing.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from campipe.constants import TWO_PI
from campipe.engine import exact, newmark, steady
from campipe.engine.closed_form import STATE, ExactRuns, ModalTrains, make_workspace
from campipe.engine.common import Cases, make_outputs
from campipe.engine.contact import (
    HELD,
    held_inverses,
    impact_masses,
    newmark_step_maps,
    quasi_static_batch,
    quasi_static_state,
)
from campipe.engine.modal import NS, ModalData, harmonic_responses, modal_data
from campipe.errors import CampipeError
from campipe.model import ValveTrain, system_matrices
from campipe.model.assembly import (
    NEWMARK_LINEAR_OMEGA_DT,
    SystemMatrices,
    configuration_frequencies,
)
from campipe.profiles import PackedProfiles, Profile, evaluate, evaluate_packed, pack
from campipe.vocabulary import (
    CAM,
    CAM_CONTACT,
    CHATTER,
    CONFIGURATIONS,
    EVENTS_TRUNCATED,
    FAILURES,
    NONFINITE,
    ROMAN,
    SEAT,
    UNBOUNDED,
)

log = logging.getLogger(__name__)

#: Integrators by name; ``default`` in a spec means DEFAULT_INTEGRATOR.
INTEGRATORS = ("modal-exact", "newmark-linear")
DEFAULT_INTEGRATOR = "modal-exact"
#: The step an integrator uses when a run names none [s]: the thesis's 1 µs for its
#: integrator; modal-exact is exact between events and sizes its own steps (a run's dt only
#: caps them).
DEFAULT_STEPS: dict[str, float | None] = {"newmark-linear": 1e-6, "modal-exact": None}
CLOSURES = ("force", "form")
#: Model fidelity of a run: "full", every case through its events with every mode. The
#: levels below it were measured and removed because they did not pay (docs/bench.md, "Model
#: only what a scene needs"): "reduced" (the upper modes quasi-static between events) saved
#: 4–24 % for valve-lift errors of 1e-5 to 1e-1 in and changed the event sequence of up to a
#: third of seated cases; a closed-form "steady" level cost as much as integrating, the
#: samples being the cost. The steady state's own path is ``engine.periodic``.
FIDELITIES = ("full",)
REMOVED_FIDELITIES = {"reduced": "it saved at most a fifth of the time for errors up to 0.1 in"}
#: How a run starts: on the periodic steady state of configuration I (``engine.steady``), or
#: the thesis's quasi-static state at θ = 0 (Appendix B, step 1), a transient.
STARTS = ("periodic", "quasi-static")
#: Turns integrated but left out of the metrics when a run names none, per start.
DEFAULT_WARMUP = {"periodic": 0, "quasi-static": 1}
#: An impact closing slower than this [m/s] leaves its contact resting (``common.captured``):
#: 1 mm/s, two to three orders below the seating velocities a designer reads (0.1–1 m/s) and
#: far above what the event location resolves (about 1e-8 m/s at 1e-12 s).
DEFAULT_CAPTURE_VELOCITY = 1e-3
#: Motion out of physical bounds ends a run (status UNBOUNDED): a valve lift beyond this many
#: times the full valve lift (plus the seat's offset), a closing or valve speed beyond this
#: many times the fastest the cam's surface moves (times the rocker ratio).
LIFT_BOUND = 3.0
SPEED_BOUND = 10.0


class RunSettingsError(CampipeError, ValueError):
    """Run settings the engine refuses; ``key`` is the spec key (``run.integrator``,
    ``run.fidelity``, ``run.dt``, ``run.tolerance``)."""


class StabilityError(RunSettingsError):
    """A step beyond the integrator's stability limit (``key`` ``run.dt``, ``found`` the
    step [s]); its ``reason`` leaves out which case of the batch set the limit."""


class CaseError(CampipeError, ValueError):
    """A case the engine refuses; ``key`` is ``closure`` or ``speed``."""


class IntegrationError(CampipeError, RuntimeError):
    """A run that produced a non-finite state, or chattered; ``found`` lists the cases."""


def resolve_integrator(name: str) -> str:
    """``default`` → the default integrator's name; refuse an unknown name."""
    resolved = DEFAULT_INTEGRATOR if name == "default" else name
    if resolved not in INTEGRATORS:
        known = ", ".join(("default", *INTEGRATORS))
        raise RunSettingsError.at(
            "run.integrator",
            f"unknown integrator {name!r}; known: {known}",
            found=name,
            expected=f"one of: {known}",
        )
    return resolved


@dataclass(frozen=True)
class Case:
    """One run: a valve train, a cam and how it is driven."""

    train: ValveTrain  # model parameters [SI]
    profile: Profile  # cam lift over one turn, defects applied
    speed: float  # cam speed [rad/s]
    seat: float = math.nan  # seat position as a valve lift [m]; NaN: no seat
    closure: str = "force"  # "force": spring-held, may separate; "form": never leaves the cam

    @property
    def has_seat(self) -> bool:
        return not math.isnan(self.seat)


@dataclass(frozen=True)
class RunSettings:
    """How a batch is integrated and sampled."""

    revolutions: float = 4.0  # cam turns, starting at θ = 0
    dt: float | None = None  # time step [s] (modal-exact: largest step); None: DEFAULT_STEPS
    output_every: float = math.radians(1.0)  # output spacing in cam angle [rad]
    integrator: str = "default"  # "default" or a name in INTEGRATORS
    tolerance: float = 1e-12  # event-time tolerance of integrators that locate events [s]
    max_events: int = 4096  # events kept per case
    fidelity: str = "full"  # "full" (see FIDELITIES)
    start: str = "periodic"  # "periodic" or "quasi-static" (see STARTS)
    warmup: int | None = None  # turns left out of the metrics; None: DEFAULT_WARMUP[start]
    capture_velocity: float = DEFAULT_CAPTURE_VELOCITY  # resting contact below this [m/s]

    @property
    def warmup_turns(self) -> int:
        """The turns integrated but left out of every metric."""
        if self.start not in STARTS:
            raise RunSettingsError.at(
                "run.start",
                f"unknown start {self.start!r}; known: {', '.join(STARTS)}",
                found=self.start,
                expected=f"one of: {', '.join(STARTS)}",
            )
        turns = DEFAULT_WARMUP[self.start] if self.warmup is None else self.warmup
        if not (0 <= turns < math.ceil(self.revolutions - 1e-12)):
            raise RunSettingsError.at(
                "run.warmup",
                f"found {turns!r} turns; a run of {self.revolutions:g} needs at least one "
                "measured turn after its warm-up",
                found=turns,
                expected=f"0 … {math.ceil(self.revolutions - 1e-12) - 1} turns",
            )
        return int(turns)

    def check_fidelity(self) -> None:
        """Refuse an unknown fidelity (a removed one with the reason)."""
        if self.fidelity not in FIDELITIES:
            why = REMOVED_FIDELITIES.get(self.fidelity)
            what = f"{self.fidelity!r} was removed: {why}" if why else f"unknown {self.fidelity!r}"
            raise RunSettingsError.at(
                "run.fidelity",
                f"{what}; known: {', '.join(FIDELITIES)} (the steady state and the no-follow "
                "onset without integrating: campipe onset)",
                found=self.fidelity,
                expected=f"one of: {', '.join(FIDELITIES)}",
            )

    @property
    def method(self) -> str:
        """The integrator's resolved name."""
        return resolve_integrator(self.integrator)

    @property
    def step(self) -> float | None:
        """The time step [s] (modal-exact: the cap on its steps, None for none)."""
        return DEFAULT_STEPS[self.method] if self.dt is None else self.dt


@dataclass
class BatchResult:
    """Histories at the output angles and metrics at full internal resolution, SI.

    Every metric comes per turn (``*_per_rev``, (n_cases, n_rev)) and as a summary over the
    measured turns (those after ``warmup``): the largest of a maximum, the mean per turn of a
    count or an angle.
    """

    cam_angle: np.ndarray  # (n_out,) cam angle of each sample [rad]
    time: np.ndarray  # (n_cases, n_out) [s]
    q: np.ndarray  # (n_cases, n_out, 7) coordinates [m, rad]
    v: np.ndarray  # (n_cases, n_out, 7) velocities [m/s, rad/s]
    acc: np.ndarray  # (n_cases, n_out, 2) accelerations of q1 and q7 [m/s²]
    cam_lift: np.ndarray  # (n_cases, n_out) [m]
    cam_force: np.ndarray  # (n_cases, n_out) cam contact force, compressive positive [N]
    seat_force: np.ndarray  # (n_cases, n_out) seat contact force, compressive positive [N]
    contact_state: np.ndarray  # (n_cases, n_out) int8, 1–4 = configurations I–IV
    valve_reference: np.ndarray  # (n_cases,) q7 at zero valve lift [m]
    measured: np.ndarray  # (n_rev,) bool: the turn counts in the summaries (after warm-up)
    #: (n_cases, n_rev) per turn: cam angle in configuration II, the follower off the cam with
    #: the valve off its seat (no-follow) [rad]
    separation_per_rev: np.ndarray
    #: (n_cases, n_rev) per turn: cam angle in configuration IV, the valve seated and the
    #: follower off the cam (the lash of a seated train) [rad]
    seated_off_cam_per_rev: np.ndarray
    cam_impacts_per_rev: np.ndarray  # (n_cases, n_rev) int
    seat_impacts_per_rev: np.ndarray  # (n_cases, n_rev) int
    max_cam_impact_velocity_per_rev: np.ndarray  # (n_cases, n_rev) [m/s]
    max_seating_velocity_per_rev: np.ndarray  # (n_cases, n_rev) [m/s]
    max_cam_force_per_rev: np.ndarray  # (n_cases, n_rev) [N]
    max_seat_force_per_rev: np.ndarray  # (n_cases, n_rev) [N]
    thesis_impact_force_per_rev: np.ndarray  # (n_cases, n_rev) [N]
    #: per case (n_ev, 6): columns vocabulary.EV_*
    events: list[np.ndarray] = field(default_factory=list)
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (n_cases,)
    #: (n_cases,) int64 vocabulary status: OK, EVENTS_TRUNCATED, or (``on_failure="record"``)
    #: a failure (``vocabulary.FAILURES``) whose histories and metrics are NaN
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    start_time: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n_cases,) t0 ≤ 0 [s]

    def _mean(self, per_rev: np.ndarray) -> np.ndarray:
        return per_rev[:, self.measured].mean(axis=1)

    def _max(self, per_rev: np.ndarray) -> np.ndarray:
        return per_rev[:, self.measured].max(axis=1)

    @property
    def separation(self) -> np.ndarray:
        """(n_cases,) no-follow per turn, mean over the measured turns [rad]."""
        return self._mean(self.separation_per_rev)

    @property
    def seated_off_cam(self) -> np.ndarray:
        """(n_cases,) configuration IV per turn, mean over the measured turns [rad]."""
        return self._mean(self.seated_off_cam_per_rev)

    @property
    def cam_impacts(self) -> np.ndarray:
        """(n_cases,) cam impacts per turn, mean over the measured turns."""
        return self._mean(self.cam_impacts_per_rev)

    @property
    def seat_impacts(self) -> np.ndarray:
        """(n_cases,) seat impacts per turn, mean over the measured turns."""
        return self._mean(self.seat_impacts_per_rev)

    @property
    def max_cam_impact_velocity(self) -> np.ndarray:
        """(n_cases,) largest closing velocity of a cam impact in the measured turns [m/s]."""
        return self._max(self.max_cam_impact_velocity_per_rev)

    @property
    def max_seating_velocity(self) -> np.ndarray:
        """(n_cases,) largest closing velocity of a seat impact in the measured turns [m/s]."""
        return self._max(self.max_seating_velocity_per_rev)

    @property
    def max_cam_force(self) -> np.ndarray:
        """(n_cases,) largest compressive cam force between impacts, measured turns [N]."""
        return self._max(self.max_cam_force_per_rev)

    @property
    def max_seat_force(self) -> np.ndarray:
        """(n_cases,) largest compressive seat force between impacts, measured turns [N]."""
        return self._max(self.max_seat_force_per_rev)

    @property
    def thesis_impact_force(self) -> np.ndarray:
        """(n_cases,) largest cam force including the steps an impact's impulse passes
        through: the thesis's peak "impact force" [N]. For newmark-linear it measures 1/Δt and
        does not converge; modal-exact applies impulses instantly, so it equals
        max_cam_force."""
        return self._max(self.thesis_impact_force_per_rev)

    @property
    def follower_lift(self) -> np.ndarray:
        """(n_cases, n_out) pushrod foot height in the cam's lift coordinate [m]."""
        return -self.q[:, :, CAM]

    @property
    def valve_lift(self) -> np.ndarray:
        """(n_cases, n_out) valve opening from its base-circle static position [m]."""
        return self.q[:, :, SEAT] - self.valve_reference[:, None]

    @property
    def valve_velocity(self) -> np.ndarray:
        """(n_cases, n_out) valve opening velocity [m/s]."""
        return self.v[:, :, SEAT]

    @property
    def valve_acceleration(self) -> np.ndarray:
        """(n_cases, n_out) valve opening acceleration [m/s²]."""
        return self.acc[:, :, 1]

    @property
    def follower_acceleration(self) -> np.ndarray:
        """(n_cases, n_out) pushrod foot acceleration in the cam's lift coordinate [m/s²]."""
        return -self.acc[:, :, 0]


@functools.lru_cache(maxsize=256)
def _matrices(train: ValveTrain) -> SystemMatrices:
    return system_matrices(train)


@dataclass(frozen=True)
class Prepared:
    """What a step size and a train fix for every case that shares them (cached)."""

    matrices: SystemMatrices  # M, C, K, modes, preload
    step_A: np.ndarray  # (4, 24, 8) newmark-linear's step per configuration: forces, and
    step_G: np.ndarray  # (4, 8, 8) accelerations and contact forces (contact.newmark_step_maps)
    impact_masses: np.ndarray  # (4,) see contact.impact_masses [kg]
    valve_reference: float  # q7 at zero valve lift [m]
    omega_max: np.ndarray  # (4,) highest natural frequency per configuration [rad/s]
    start_inverses: np.ndarray  # (2, 2, 7, 7) see start_inverses
    valve_ratio: float  # static valve lift per unit cam lift (the rocker ratio) [-]


@functools.lru_cache(maxsize=256)
def prepare(train: ValveTrain, dt: float) -> Prepared:
    sm = _matrices(train)
    omega_max = np.array(
        [configuration_frequencies(sm.mass, sm.stiffness, c).max() for c in (1, 2, 3, 4)]
    )
    return Prepared(
        sm,
        *newmark_step_maps(sm.mass, sm.damping, sm.stiffness, dt),
        impact_masses(sm.mass),
        valve_reference(sm),
        omega_max,
        start_inverses(sm),
        valve_ratio(sm),
    )


def valve_ratio(sm: SystemMatrices) -> float:
    """The static valve lift per unit cam lift: the rocker ratio with the members' give."""
    lifted = np.zeros(7)
    lifted[CAM] = -1.0  # one metre of cam lift
    q, _, _ = quasi_static_state(
        sm.mass, sm.damping, sm.stiffness, sm.preload, HELD[0], lifted, np.zeros(7), np.zeros(7)
    )
    return float(q[SEAT] - valve_reference(sm))


def start_inverses(sm: SystemMatrices) -> np.ndarray:
    """(2, 2, 7, 7): K_ff⁻¹ and M_ff⁻¹ (``contact.held_inverses``) in configurations I and
    III, the quasi-static start's."""
    return np.array([held_inverses(sm.mass, sm.stiffness, HELD[cfg - 1]) for cfg in (1, 3)])


@functools.lru_cache(maxsize=256)
def _modal(train: ValveTrain) -> ModalData:
    return modal_data(_matrices(train))


def visited_configurations(case: Case) -> tuple[int, ...]:
    """The configurations a case can reach: no seat keeps it in I/II; form closure in I/III."""
    if case.closure == "form":
        return (1, 3) if case.has_seat else (1,)
    return (1, 2, 3, 4) if case.has_seat else (1, 2)


def _newmark_limit(case: Case) -> tuple[float, int]:
    """newmark-linear's stability limit √12/ω_max [s] over the configurations a case can
    visit (thesis Appendix B), and the configuration that sets it."""
    omega_max = prepare(case.train, 0.0).omega_max
    worst = max(visited_configurations(case), key=lambda c: omega_max[c - 1])
    return float(NEWMARK_LINEAR_OMEGA_DT / omega_max[worst - 1]), worst


def stability_limit(case: Case, integrator: str = "newmark-linear") -> float:
    """Largest step [s] the integrator accepts for a case, over the configurations it can
    visit: newmark-linear's stability limit √12/ω_max (thesis Appendix B); modal-exact has
    none (inf): it is exact between events and sizes its own steps."""
    if resolve_integrator(integrator) != "newmark-linear":
        return math.inf
    return _newmark_limit(case)[0]


def check_stability(cases: Sequence[Case], settings: RunSettings) -> None:
    """Refuse a step beyond newmark-linear's stability limit in any configuration a case can
    visit, naming the limit."""
    if settings.method != "newmark-linear":
        return
    dt_run = settings.step
    assert dt_run is not None  # newmark-linear always has a step
    for i, case in enumerate(cases):
        limit, worst = _newmark_limit(case)
        if dt_run >= limit:
            beyond = f"{dt_run * 1e6:.4g} µs is beyond the stability limit of newmark-linear"
            bound = (
                f"({limit * 1e6:.4g} µs, configuration {ROMAN[worst]}); "
                f"use a step below {limit * 1e6:.4g} µs"
            )
            raise StabilityError(
                f"run.dt: {beyond} for case {i} {bound}",
                key="run.dt",
                found=dt_run,
                expected=f"a step below {limit * 1e6:.4g} µs",
                reason=f"{beyond} {bound}",
            )


def initial_state(case: Case, sm: SystemMatrices, seat_q: float):
    """Quasi-static start of one case at θ = 0: (q, v, a, configuration); see
    ``initial_states``."""
    q, v, a, cfg = initial_states(
        [sm],
        np.zeros(1, np.int64),
        pack([case.profile]),
        np.array([case.speed]),
        np.array([case.has_seat]),
        np.array([seat_q]),
    )
    return q[0], v[0], a[0], int(cfg[0])


def _unique_trains(cases: Sequence[Case]) -> tuple[list[ValveTrain], np.ndarray]:
    """The distinct trains of a batch and each case's index into them."""
    index: dict[ValveTrain, int] = {}
    which = np.empty(len(cases), np.int64)
    for i, case in enumerate(cases):
        which[i] = index.setdefault(case.train, len(index))
    return list(index), which


@njit(cache=True, nogil=True)
def _cam_at(profiles, theta):
    """(n, 3): lift [m] and its θ-derivatives of every packed profile at one angle."""
    n = profiles.n_pieces.shape[0]
    out = np.empty((n, 3))
    for c in range(n):
        out[c, 0], out[c, 1], out[c, 2] = evaluate_packed(profiles, c, theta)
    return out


def initial_states(mats, which, packed, omega, has_seat, seat_q, inverses=None):
    """Quasi-static start of every case at θ = 0 (thesis Appendix B, step 1): configuration
    I, or III where the valve starts on its seat. ``mats``: the distinct trains' matrices,
    ``which`` each case's index into them; ``inverses`` their ``start_inverses`` (computed
    here if not given)."""
    if inverses is None:
        inverses = [start_inverses(m) for m in mats]
    n = which.size
    cam = _cam_at(packed, 0.0)
    held_q = np.zeros((n, 7))
    held_v = np.zeros((n, 7))
    held_a = np.zeros((n, 7))
    held_q[:, CAM] = -cam[:, 0]
    held_v[:, CAM] = -omega * cam[:, 1]
    held_a[:, CAM] = -(omega**2) * cam[:, 2]
    held_q[:, SEAT] = seat_q
    M = np.stack([m.mass for m in mats])[which]
    C = np.stack([m.damping for m in mats])[which]
    K = np.stack([m.stiffness for m in mats])[which]
    load = np.stack([m.preload for m in mats])[which]
    q = np.empty((n, 7))
    v = np.empty((n, 7))
    a = np.empty((n, 7))
    for i_cfg, cfg in enumerate((1, 3)):
        kinv = np.stack([inv[i_cfg, 0] for inv in inverses])[which]
        minv = np.stack([inv[i_cfg, 1] for inv in inverses])[which]
        held = np.broadcast_to(HELD[cfg - 1], (n, 7))
        qc, vc, ac = np.empty((n, 7)), np.empty((n, 7)), np.empty((n, 7))
        quasi_static_batch(kinv, minv, M, C, K, load, held, held_q, held_v, held_a, qc, vc, ac)
        if cfg == 1:
            q, v, a = qc, vc, ac
            seated = has_seat & (q[:, SEAT] < seat_q)
        else:
            q[seated], v[seated], a[seated] = qc[seated], vc[seated], ac[seated]
    return q, v, a, np.where(seated, 3, 1).astype(np.int64)


def valve_reference(sm: SystemMatrices) -> float:
    """q7 with the cam on its base circle, no seat, in static equilibrium [m]."""
    q, _, _ = quasi_static_state(
        sm.mass,
        sm.damping,
        sm.stiffness,
        sm.preload,
        HELD[0],
        np.zeros(7),
        np.zeros(7),
        np.zeros(7),
    )
    return float(q[SEAT])


def output_angles(settings: RunSettings) -> np.ndarray:
    """Sample angles 0 … 2π·revolutions at ``output_every`` [rad]."""
    n = int(math.floor(settings.revolutions * 2 * math.pi / settings.output_every + 1e-9)) + 1
    return np.arange(n) * settings.output_every


def check_run(
    cases: Sequence[Case], settings: RunSettings, *, check_stability_limit: bool = True
) -> None:
    """Everything ``run_batch`` refuses, checked without running: an unknown integrator or
    fidelity, a non-positive step or tolerance, an unknown closure, a non-positive speed, a
    newmark-linear step beyond the stability limit.

    Raises
    ------
    RunSettingsError
        (StabilityError for the step limit) for a run setting, its ``key`` ``run.<name>``.
    CaseError
        For a case's closure or speed, its ``key`` ``closure`` or ``speed``.
    """
    dt_run = settings.step  # also refuses an unknown integrator
    settings.check_fidelity()
    if dt_run is not None and not (dt_run > 0 and math.isfinite(dt_run)):
        raise RunSettingsError.at(
            "run.dt",
            f"found {dt_run!r} s, expected a positive step",
            found=dt_run,
            expected="> 0 s",
        )
    if not (settings.tolerance > 0 and math.isfinite(settings.tolerance)):
        raise RunSettingsError.at(
            "run.tolerance",
            f"found {settings.tolerance!r} s, expected > 0",
            found=settings.tolerance,
            expected="> 0 s",
        )
    for i, case in enumerate(cases):
        if case.closure not in CLOSURES:
            raise CaseError.at(
                "closure",
                f"case {i} has {case.closure!r}, expected force or form",
                found=case.closure,
                expected="force or form",
            )
        if not case.speed > 0:
            raise CaseError.at(
                "speed",
                f"case {i} has {case.speed!r} rad/s, expected > 0",
                found=case.speed,
                expected="> 0 rad/s",
            )
    if check_stability_limit:
        check_stability(cases, settings)


def _run_newmark(preps, which, settings, dt_run, cases, packed, out) -> None:
    trains = newmark.NewmarkTrains(
        M=np.stack([p.matrices.mass for p in preps])[which],
        C=np.stack([p.matrices.damping for p in preps])[which],
        K=np.stack([p.matrices.stiffness for p in preps])[which],
        load=np.stack([p.matrices.preload for p in preps])[which],
        step_A=np.stack([p.step_A for p in preps])[which],
        step_G=np.stack([p.step_G for p in preps])[which],
    )
    dt = np.full(len(which), dt_run)
    n_steps = np.ceil(settings.revolutions * TWO_PI / (cases.omega * dt) - 1e-9)
    runs = newmark.NewmarkRuns(dt, n_steps.astype(np.int64), float(settings.output_every))
    contact = np.zeros(1, newmark.CONTACT_STATE)
    newmark.newmark_linear_batch(cases, trains, packed, runs, out, newmark.make_work(), contact)


def _modal_trains(trains, preps) -> tuple[ModalTrains, np.ndarray]:
    """The distinct trains' closed-form data, indexed in the kernels by each case's train, and
    their state matrices (for the harmonic responses)."""
    data = [_modal(t) for t in trains]
    modal_trains = ModalTrains(
        load=np.stack([p.matrices.preload for p in preps]),
        **{f: np.stack([getattr(d, f) for d in data]) for f in ModalTrains._fields if f != "load"},
    )
    return modal_trains, np.stack([d.a_mat for d in data])


def _exact_runs(settings, dt_run, full_state, which, modal_trains, a_mat, omega) -> ExactRuns:
    return ExactRuns(
        train=which,
        t_sample=settings.output_every / omega,
        t_end=settings.revolutions * TWO_PI / omega,
        zeta=harmonic_responses(which, modal_trains.n_free, a_mat, modal_trains.b_in, omega),
        dt_cap=float(dt_run or 0.0),
        tolerance=float(settings.tolerance),
        full_state=bool(full_state),
    )


class Start(NamedTuple):
    """Where each case of a batch starts (``start_states``)."""

    t0: np.ndarray  # (n,) start time [s], ≤ 0 (integrated, unrecorded, up to t = 0)
    q0: np.ndarray  # (n, 7) coordinates [m, rad]
    v0: np.ndarray  # (n, 7) velocities [m/s, rad/s]
    a0: np.ndarray  # (n, 7) accelerations [m/s², rad/s²]
    cfg0: np.ndarray  # (n,) int64 configuration


@dataclass(frozen=True)
class _Batch:
    """What a batch's kernels take, but where it starts (``_prepare_batch``)."""

    trains: list[ValveTrain]  # the distinct trains
    which: np.ndarray  # each case's index into them
    preps: list[Prepared]
    packed: PackedProfiles
    modal_trains: ModalTrains
    runs: ExactRuns
    cases: Cases  # starting nowhere yet


def _prepare_batch(cases: Sequence[Case], settings: RunSettings, full_state: bool) -> _Batch:
    dt_run = settings.step
    n = len(cases)
    trains, which = _unique_trains(cases)
    preps = [prepare(t, dt_run or 0.0) for t in trains]
    modal = [_modal(t) for t in trains]
    qref = np.array([p.valve_reference for p in preps])[which]
    has_seat = np.array([c.has_seat for c in cases], dtype=np.bool_)
    omega = np.array([c.speed for c in cases], dtype=float)
    modal_trains, a_mat = _modal_trains(trains, preps)
    lift_bound, speed_bound = _bounds(cases, preps, which, qref)
    return _Batch(
        trains=trains,
        which=which,
        preps=preps,
        packed=pack([c.profile for c in cases]),
        modal_trains=modal_trains,
        runs=_exact_runs(settings, dt_run, full_state, which, modal_trains, a_mat, omega),
        cases=Cases(
            omega=omega,
            seat_q=qref + np.where(has_seat, [c.seat for c in cases], 0.0),
            has_seat=has_seat,
            form=np.array([c.closure == "form" for c in cases], dtype=np.bool_),
            t0=np.zeros(n),
            q0=np.zeros((n, 7)),
            v0=np.zeros((n, 7)),
            a0=np.zeros((n, 7)),
            cfg0=np.full(n, CAM_CONTACT, np.int64),
            meff=np.stack([p.impact_masses for p in preps])[which],
            separation=np.stack([d.separation for d in modal])[which],
            hold=np.stack([d.hold for d in modal])[which],
            capture=np.full(n, float(settings.capture_velocity)),
            valve_ref=qref,
            lift_bound=lift_bound,
            speed_bound=speed_bound,
        ),
    )


def _starts(cases: Sequence[Case], settings: RunSettings, batch: _Batch) -> Start:
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
    step = settings.step if settings.method == "newmark-linear" else 0.0
    t0, q0, v0, a0 = _periodic_starts(
        cases, c, batch.modal_trains, batch.runs, batch.packed, np.full(len(cases), step),
        batch.preps, batch.which,
    )  # fmt: skip
    return Start(t0, q0, v0, a0, np.full(len(cases), CAM_CONTACT, np.int64))


def start_states(cases: Sequence[Case], settings: RunSettings) -> Start:
    """The start of each case under ``settings.start``: the periodic steady state of
    configuration I (``engine.steady``) or the thesis's quasi-static state at θ = 0. For
    newmark-linear the periodic start falls on a whole number of its steps before t = 0."""
    check_run(cases, settings, check_stability_limit=False)
    return _starts(cases, settings, _prepare_batch(cases, settings, full_state=False))


def _periodic_starts(case_list, cases, modal_trains, runs, packed, snap, preps, which):
    """Each case's start on the periodic steady state of configuration I
    (``steady.periodic_starts``): (t0, q0, v0, a0); refuses a case where configuration I holds
    nowhere on the turn."""
    n = cases.omega.size
    t0 = np.empty(n)
    q0 = np.empty((n, 7))
    v0 = np.empty((n, 7))
    z_turn = np.zeros((n, packed.n_pieces.max() + 1, NS))
    state = np.zeros(1, STATE)
    steady.periodic_starts(
        cases, modal_trains, packed, runs, make_workspace(), state, snap, z_turn, t0, q0, v0
    )
    bad = np.flatnonzero(np.isnan(t0))
    if bad.size:
        raise CaseError.at(
            "seat",
            f"cases {bad.tolist()}: the cam never drives the valve off its seat with the cam "
            "pushing (configuration I holds nowhere on the turn): the seat is above the "
            "valve's lift, or the speed pulls the follower off wherever the valve is open",
            found=bad.tolist(),
            expected="a seat below the valve's full lift",
        )
    # Accelerations from the equation of motion with the cam held (newmark-linear's start).
    a0 = np.zeros((n, 7))
    theta = cases.omega * t0
    for c in range(n):
        sm = preps[which[c]].matrices
        _, _, ddlift = evaluate(case_list[c].profile, theta[c])
        a0[c, CAM] = -(cases.omega[c] ** 2) * float(ddlift)
        free = np.array(CONFIGURATIONS[CAM_CONTACT].free)
        force = sm.preload - sm.stiffness @ q0[c] - sm.damping @ v0[c] - sm.mass @ a0[c]
        a0[c, free] = np.linalg.solve(sm.mass[np.ix_(free, free)], force[free])
    return t0, q0, v0, a0


def _bounds(cases: Sequence[Case], preps, which, qref) -> tuple[np.ndarray, np.ndarray]:
    """Each case's bounds on valve lift [m] and on closing and valve speeds [m/s]."""
    lift = np.empty(len(cases))
    speed = np.empty(len(cases))
    grid = np.linspace(0.0, TWO_PI, 2049)
    slopes: dict[int, tuple[float, float]] = {}
    for i, case in enumerate(cases):
        key = id(case.profile)
        if key not in slopes:
            lifts, rates, _ = evaluate(case.profile, grid)
            slopes[key] = (float(np.max(np.abs(lifts))), float(np.max(np.abs(rates))))
        max_lift, max_rate = slopes[key]
        ratio = abs(preps[which[i]].valve_ratio)
        seat = abs(case.seat) if case.has_seat else 0.0
        lift[i] = LIFT_BOUND * max_lift * ratio + seat
        speed[i] = SPEED_BOUND * case.speed * max_rate * max(ratio, 1.0)
    return lift, speed


def run_batch(
    cases: Sequence[Case],
    settings: RunSettings,
    *,
    full_state: bool = True,
    check_stability_limit: bool = True,
    on_failure: str = "raise",
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
    dt_run = settings.step
    n = len(cases)
    angles = output_angles(settings)
    n_out = angles.size
    n_rev = int(math.ceil(settings.revolutions - 1e-12))
    warmup = settings.warmup_turns
    batch = _prepare_batch(cases, settings, full_state)
    start = _starts(cases, settings, batch)
    cases_in = batch.cases._replace(**start._asdict())
    omega, qref = cases_in.omega, cases_in.valve_ref
    preps, which, packed, modal_trains, runs = (
        batch.preps, batch.which, batch.packed, batch.modal_trains, batch.runs
    )  # fmt: skip
    out = make_outputs(n, n_out, n_rev, settings.max_events)
    if settings.method == "newmark-linear":
        _run_newmark(preps, which, settings, dt_run, cases_in, packed, out)
    else:
        state = np.zeros(1, STATE)
        exact.modal_exact_batch(cases_in, modal_trains, packed, runs, out, make_workspace(), state)
    status, n_events = out.status, out.n_events
    bad = np.flatnonzero(status == NONFINITE)
    if bad.size and on_failure == "raise":
        how = f"{settings.method}, step {dt_run:g} s" if dt_run else settings.method
        why = (
            "the step is beyond the stability limit (the run was asked not to check it)"
            if not check_stability_limit
            else "this is a defect: please report it with the case"
        )
        raise IntegrationError(
            f"cases {bad.tolist()} became non-finite ({how}); {why}", found=bad.tolist()
        )
    bad = np.flatnonzero(status == CHATTER)
    if bad.size and on_failure == "raise":
        raise IntegrationError(
            f"cases {bad.tolist()}: contact events kept recurring at one instant (chatter); "
            "integrate them with newmark-linear",
            found=bad.tolist(),
        )
    bad = np.flatnonzero(status == UNBOUNDED)
    if bad.size and on_failure == "raise":
        how = f"{settings.method}, step {dt_run:g} s" if dt_run else settings.method
        raise IntegrationError(
            f"cases {bad.tolist()}: the motion left its physical bounds ({how}): a valve lift "
            f"beyond {LIFT_BOUND:g}× the full lift or a speed beyond {SPEED_BOUND:g}× the cam's; "
            "the step is too large for this case (use a smaller run.dt or modal-exact)",
            found=bad.tolist(),
        )
    for i in np.flatnonzero(status == EVENTS_TRUNCATED):
        log.warning(
            "case %d: %d events, only the first %d kept (raise run.max_events)",
            i,
            n_events[i],
            settings.max_events,
        )
    failed = np.flatnonzero(np.isin(status, FAILURES))
    for array in (out.q, out.v, out.acc, out.force, out.cam, out.sep_rev, out.seated_rev,
                  out.vmax, out.fmax):  # fmt: skip
        array[failed] = np.nan
    counts = out.counts.astype(float)
    counts[failed] = np.nan
    out = out._replace(counts=counts)
    kept = np.minimum(n_events, settings.max_events)
    measured = np.arange(n_rev) >= warmup
    return BatchResult(
        cam_angle=angles,
        time=angles[None, :] / omega[:, None],
        q=out.q,
        v=out.v,
        acc=out.acc,
        cam_lift=out.cam,
        cam_force=-out.force[:, :, 0],
        seat_force=out.force[:, :, 1],
        contact_state=out.cfg,
        valve_reference=qref,
        measured=measured,
        separation_per_rev=out.sep_rev,
        seated_off_cam_per_rev=out.seated_rev,
        cam_impacts_per_rev=out.counts[:, :, 0],
        seat_impacts_per_rev=out.counts[:, :, 1],
        max_cam_impact_velocity_per_rev=out.vmax[:, :, 0],
        max_seating_velocity_per_rev=out.vmax[:, :, 1],
        max_cam_force_per_rev=out.fmax[:, :, 0],
        max_seat_force_per_rev=out.fmax[:, :, 1],
        thesis_impact_force_per_rev=out.fmax[:, :, 2],
        events=[out.events[i, : kept[i]].copy() for i in range(n)],
        steps=out.steps,
        status=status,
        start_time=cases_in.t0,
    )
