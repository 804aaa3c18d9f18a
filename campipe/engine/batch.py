"""Run a batch of cases through an integrator: pack, check, call the compiled kernel, unpack.

Pure numerics: arrays in, arrays out; no files, no printing.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe.engine import newmark
from campipe.engine.contact import (
    CAM,
    HELD,
    SEAT,
    effective_mass_inverses,
    impact_masses,
    quasi_static_state,
)
from campipe.model import ROMAN, ValveTrain, system_matrices
from campipe.model.assembly import SystemMatrices, configuration_frequencies
from campipe.model.assembly import NEWMARK_LINEAR_OMEGA_DT
from campipe.profiles import Profile, evaluate, pack

log = logging.getLogger(__name__)

#: Integrators by name; ``default`` in a spec means DEFAULT_INTEGRATOR.
INTEGRATORS = ("newmark-linear",)
DEFAULT_INTEGRATOR = "newmark-linear"
#: The step an integrator uses when a run names none [s].
DEFAULT_STEPS = {"newmark-linear": 1e-6}
CLOSURES = ("force", "form")


def resolve_integrator(name: str) -> str:
    """``default`` → the default integrator's name; refuse an unknown name."""
    resolved = DEFAULT_INTEGRATOR if name == "default" else name
    if resolved not in INTEGRATORS:
        raise ValueError(
            f"run.integrator: unknown integrator {name!r}; known: default, "
            + ", ".join(INTEGRATORS)
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
    dt: float | None = None  # time step [s]; None: the integrator's DEFAULT_STEPS entry
    output_every: float = math.radians(1.0)  # output spacing in cam angle [rad]
    integrator: str = "default"  # "default" or a name in INTEGRATORS
    tolerance: float = 1e-12  # event-time tolerance of integrators that locate events [s]
    max_events: int = 4096  # events kept per case

    @property
    def method(self) -> str:
        """The integrator's resolved name."""
        return resolve_integrator(self.integrator)

    @property
    def step(self) -> float:
        """The time step [s]."""
        return DEFAULT_STEPS[self.method] if self.dt is None else self.dt


class StabilityError(ValueError):
    """A step beyond the integrator's stability limit."""


class IntegrationError(RuntimeError):
    """A run that produced a non-finite state."""


@dataclass
class BatchResult:
    """Histories at the output angles and metrics at full internal resolution, SI."""

    cam_angle: np.ndarray  # (n_out,) cam angle of each sample [rad]
    time: np.ndarray  # (n_cases, n_out) [s]
    q: np.ndarray  # (n_cases, n_out, 7) coordinates [m, rad]
    cam_lift: np.ndarray  # (n_cases, n_out) [m]
    cam_force: np.ndarray  # (n_cases, n_out) cam contact force, compressive positive [N]
    seat_force: np.ndarray  # (n_cases, n_out) seat contact force, compressive positive [N]
    contact_state: np.ndarray  # (n_cases, n_out) int8, 1–4 = configurations I–IV
    valve_reference: np.ndarray  # (n_cases,) q7 at zero valve lift [m]
    separation_per_rev: np.ndarray  # (n_cases, n_rev) cam angle off the cam per turn [rad]
    cam_impacts: np.ndarray  # (n_cases,) int
    seat_impacts: np.ndarray  # (n_cases,) int
    max_cam_impact_velocity: np.ndarray  # (n_cases,) [m/s]
    max_seating_velocity: np.ndarray  # (n_cases,) [m/s]
    max_cam_force: np.ndarray  # (n_cases,) largest compressive cam force between impacts [N]
    max_seat_force: np.ndarray  # (n_cases,) likewise at the seat [N]
    events: list[np.ndarray] = field(default_factory=list)  # per case (n_ev, 6), see newmark.EV_*
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (n_cases,)

    @property
    def follower_lift(self) -> np.ndarray:
        """(n_cases, n_out) pushrod foot height in the cam's lift coordinate [m]."""
        return -self.q[:, :, CAM]

    @property
    def valve_lift(self) -> np.ndarray:
        """(n_cases, n_out) valve opening from its base-circle static position [m]."""
        return self.q[:, :, SEAT] - self.valve_reference[:, None]


@functools.lru_cache(maxsize=256)
def _matrices(train: ValveTrain) -> SystemMatrices:
    return system_matrices(train)


@dataclass(frozen=True)
class Prepared:
    """What a step size and a train fix for every case that shares them (cached)."""

    matrices: SystemMatrices  # M, C, K, modes, preload
    minv: np.ndarray  # (4, 7, 7) effective-mass inverses per configuration
    impact_masses: np.ndarray  # (4,) see contact.impact_masses [kg]
    valve_reference: float  # q7 at zero valve lift [m]
    limits: np.ndarray  # (4,) newmark-linear stability limit per configuration [s]


@functools.lru_cache(maxsize=256)
def prepare(train: ValveTrain, dt: float) -> Prepared:
    sm = _matrices(train)
    limits = np.array([
        NEWMARK_LINEAR_OMEGA_DT / configuration_frequencies(sm.mass, sm.stiffness, c).max()
        for c in (1, 2, 3, 4)
    ])
    return Prepared(
        sm,
        effective_mass_inverses(sm.mass, sm.damping, sm.stiffness, dt),
        impact_masses(sm.mass),
        valve_reference(sm),
        limits,
    )


def visited_configurations(case: Case) -> tuple[int, ...]:
    """The configurations a case can reach: no seat keeps it in I/II; form closure in I/III."""
    if case.closure == "form":
        return (1, 3) if case.has_seat else (1,)
    return (1, 2, 3, 4) if case.has_seat else (1, 2)


def stability_limit(case: Case) -> float:
    """Largest stable step [s] of newmark-linear over the configurations the case can visit."""
    limits = prepare(case.train, 0.0).limits
    return float(min(limits[c - 1] for c in visited_configurations(case)))


def check_stability(cases: Sequence[Case], settings: RunSettings) -> None:
    """Refuse a step beyond the stability limit of any configuration a case can visit."""
    dt_run = settings.step
    for i, case in enumerate(cases):
        limits = prepare(case.train, 0.0).limits
        worst = min(visited_configurations(case), key=lambda c: limits[c - 1])
        limit = limits[worst - 1]
        if dt_run >= limit:
            raise StabilityError(
                f"run.dt: {dt_run * 1e6:.4g} µs is beyond the stability limit of "
                f"{settings.method} for case {i} ({limit * 1e6:.4g} µs, configuration "
                f"{ROMAN[worst]}); use a step below {limit * 1e6:.4g} µs"
            )


def initial_state(case: Case, sm: SystemMatrices, seat_q: float):
    """Quasi-static start at θ = 0 in configuration I (III where the valve starts on its seat)."""
    lift, dlift, ddlift = (float(x[0]) for x in evaluate(case.profile, np.array([0.0])))
    w = case.speed
    held_q = np.zeros(7)
    held_v = np.zeros(7)
    held_a = np.zeros(7)
    held_q[CAM], held_v[CAM], held_a[CAM] = -lift, -w * dlift, -w * w * ddlift
    q, v, a = quasi_static_state(sm.mass, sm.damping, sm.stiffness, sm.preload, HELD[0],
                                 held_q, held_v, held_a)
    if case.has_seat and q[SEAT] < seat_q:
        held_q[SEAT] = seat_q
        q, v, a = quasi_static_state(sm.mass, sm.damping, sm.stiffness, sm.preload, HELD[2],
                                     held_q, held_v, held_a)
        return q, v, a, 3
    return q, v, a, 1


def valve_reference(sm: SystemMatrices) -> float:
    """q7 with the cam on its base circle, no seat, in static equilibrium [m]."""
    q, _, _ = quasi_static_state(sm.mass, sm.damping, sm.stiffness, sm.preload, HELD[0],
                                 np.zeros(7), np.zeros(7), np.zeros(7))
    return float(q[SEAT])


def output_angles(settings: RunSettings) -> np.ndarray:
    """Sample angles 0 … 2π·revolutions at ``output_every`` [rad]."""
    n = int(math.floor(settings.revolutions * 2 * math.pi / settings.output_every + 1e-9)) + 1
    return np.arange(n) * settings.output_every


def run_batch(cases: Sequence[Case], settings: RunSettings) -> BatchResult:
    """Integrate every case of a batch in one compiled call.

    Parameters
    ----------
    cases : sequence of Case
        Any mix of trains, profiles, speeds, seats and closures.
    settings : RunSettings
        Shared by the batch: revolutions, step, output spacing, integrator.

    Raises
    ------
    StabilityError
        For a step beyond the stability limit, before anything runs.
    IntegrationError
        If a case's state became non-finite.
    """
    dt_run = settings.step  # also refuses an unknown integrator
    if not (dt_run > 0 and math.isfinite(dt_run)):
        raise ValueError(f"run.dt: found {dt_run!r} s, expected a positive step")
    for i, case in enumerate(cases):
        if case.closure not in CLOSURES:
            raise ValueError(f"closure: case {i} has {case.closure!r}, expected force or form")
        if not case.speed > 0:
            raise ValueError(f"speed: case {i} has {case.speed!r} rad/s, expected > 0")
    check_stability(cases, settings)
    n = len(cases)
    angles = output_angles(settings)
    n_out = angles.size
    n_rev = int(math.ceil(settings.revolutions - 1e-12))

    NP = newmark.NP
    M = np.zeros((n, NP, NP))
    C = np.zeros((n, NP, NP))
    K = np.zeros((n, NP, NP))
    load = np.zeros((n, NP))
    minv = np.zeros((n, 4, NP, NP))
    meff = np.empty((n, 4))
    q0 = np.zeros((n, NP))
    v0 = np.zeros((n, NP))
    a0 = np.zeros((n, NP))
    cfg0 = np.empty(n, np.int64)
    seat_q = np.zeros(n)
    qref = np.empty(n)
    for i, case in enumerate(cases):
        prep = prepare(case.train, dt_run)
        sm = prep.matrices
        M[i], C[i], K[i], load[i] = sm.mass, sm.damping, sm.stiffness, sm.preload
        minv[i] = prep.minv
        meff[i] = prep.impact_masses
        qref[i] = prep.valve_reference
        seat_q[i] = qref[i] + (case.seat if case.has_seat else 0.0)
        q0[i], v0[i], a0[i], cfg0[i] = initial_state(case, sm, seat_q[i])
    omega = np.array([c.speed for c in cases], dtype=float)
    dt = np.full(n, dt_run)
    n_steps = np.ceil(settings.revolutions * 2 * np.pi / (omega * dt) - 1e-9).astype(np.int64)
    has_seat = np.array([c.has_seat for c in cases], dtype=np.bool_)
    form = np.array([c.closure == "form" for c in cases], dtype=np.bool_)
    packed = pack([c.profile for c in cases])

    q_out = np.zeros((n, n_out, 7))
    force_out = np.zeros((n, n_out, 2))
    cam_out = np.zeros((n, n_out))
    cfg_out = np.zeros((n, n_out), np.int8)
    sep_rev = np.zeros((n, n_rev))
    counts = np.zeros((n, 2), np.int64)
    vmax = np.zeros((n, 2))
    fmax = np.zeros((n, 2))
    events = np.zeros((n, settings.max_events, newmark.N_EVENT_FIELDS))
    n_events = np.zeros(n, np.int64)
    status = np.zeros(n, np.int64)
    newmark.newmark_linear_batch(
        M, C, K, load, minv, meff, q0, v0, a0, cfg0, seat_q, has_seat, form, omega, dt, n_steps,
        packed.breaks, packed.poly, packed.trig, packed.n_pieces,
        settings.output_every, q_out, force_out, cam_out, cfg_out,
        sep_rev, counts, vmax, fmax, events, n_events, status,
    )
    bad = np.flatnonzero(status == newmark.NONFINITE)
    if bad.size:
        raise IntegrationError(
            f"cases {bad.tolist()} became non-finite; a step of {dt_run:g} s is inside the "
            "stability limit, so this is a defect: please report it with the case"
        )
    for i in np.flatnonzero(status == newmark.EVENTS_TRUNCATED):
        log.warning("case %d: %d events, only the first %d kept (raise run.max_events)",
                    i, n_events[i], settings.max_events)
    kept = np.minimum(n_events, settings.max_events)
    return BatchResult(
        cam_angle=angles,
        time=angles[None, :] / omega[:, None],
        q=q_out,
        cam_lift=cam_out,
        cam_force=-force_out[:, :, 0],
        seat_force=force_out[:, :, 1],
        contact_state=cfg_out,
        valve_reference=qref,
        separation_per_rev=sep_rev,
        cam_impacts=counts[:, 0],
        seat_impacts=counts[:, 1],
        max_cam_impact_velocity=vmax[:, 0],
        max_seating_velocity=vmax[:, 1],
        max_cam_force=fmax[:, 0],
        max_seat_force=fmax[:, 1],
        events=[events[i, : kept[i]].copy() for i in range(n)],
        steps=n_steps,
    )
