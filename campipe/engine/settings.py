"""What a run is and how it is integrated, checked before anything is compiled: the cases,
the run settings, the integrators' names and limits, and the errors that refuse them.

Plain Python and NumPy (the model's matrices for the stability limit): a spec is checked and
a study planned without loading numba or a compiled kernel (``campipe.engine.batch`` runs
them).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe.constants import TWO_PI
from campipe.errors import CampipeError
from campipe.model import ValveTrain, lash_seat, system_matrices
from campipe.model.assembly import NEWMARK_LINEAR_OMEGA_DT, configuration_frequencies
from campipe.profiles import Profile
from campipe.vocabulary import CAM_AND_SEAT, CAM_CONTACT, CONFIGURATIONS, FREE, N_COORDINATES, ROMAN

#: The integrators of rigid contacts (the thesis's) by name; ``default`` in a spec means
#: DEFAULT_INTEGRATOR, or COMPLIANT for a case with a compliant contact law
#: (``engine.compliant``: the contacts as force elements, error-controlled).
INTEGRATORS = ("modal-exact", "newmark-linear")
DEFAULT_INTEGRATOR = "modal-exact"
COMPLIANT = "compliant"
#: Every integrator a run may name.
ALL_INTEGRATORS = (*INTEGRATORS, COMPLIANT)
#: The compliant integrator's relative tolerance is run.tolerance, but no finer than this
#: (the default 1e-12, modal-exact's event-time tolerance, is finer than Radau can reach).
COMPLIANT_RTOL_FLOOR = 1e-10
#: The step an integrator uses when a run names none [s]: the thesis's 1 µs for its
#: integrator; modal-exact is exact between events and sizes its own steps (a run's dt only
#: caps them).
DEFAULT_STEPS: dict[str, float | None] = {
    "newmark-linear": 1e-6,
    "modal-exact": None,
    "compliant": None,
}
CLOSURES = ("force", "form")
#: Model fidelity of a run, cheapest last: "full", every case through its events with every
#: mode; "steady", each case whose periodic steady state is configuration I's all turn (it
#: follows the cam, the valve clear of its seat) from that closed form, one turn computed and
#: repeated (``engine.periodic.run_at_fidelity``), the others in full. The full run starts on
#: that same steady state and stays there, so the two agree to FIDELITY_ERRORS. A level that did
#: not pay was removed (docs/bench.md, "Model only what a scene needs"; the CHANGELOG has the
#: figures): "reduced" (the upper modes quasi-static between events) saved little for its
#: error and changed the event sequence of many seated cases.
FIDELITIES = ("full", "steady")
REMOVED_FIDELITIES = {"reduced": "it saved at most a fifth of the time for errors up to 0.1 in"}
#: Each level's stated valve-lift error against the full engine [m], what a run's
#: ``fidelity_tolerance`` is compared with (the steady level's is checked by
#: tests/unit/test_fidelity.py).
FIDELITY_ERRORS = {"full": 0.0, "steady": 1e-9 * 0.0254}
#: The steady level samples one turn in closed form at about twice modal-exact's cost per
#: sample and repeats it: it pays from about four turns on (``campipe bench``'s fidelity
#: table), so a run that names a tolerance takes it from this many turns.
STEADY_MIN_TURNS = 6
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


def turn_count(revolutions: float) -> int:
    """The turns a run of ``revolutions`` covers, a partial last turn included: the length of
    its per-turn metrics (the archive's ``revolution`` axis)."""
    return int(math.ceil(revolutions - 1e-12))


def sample_count(revolutions: float, output_every: float) -> int:
    """The output samples of a run of ``revolutions`` turns, every ``output_every`` [rad] from
    θ = 0 (the last within 2π·revolutions)."""
    return int(math.floor(revolutions * TWO_PI / output_every + 1e-9)) + 1


def resolve_integrator(name: str) -> str:
    """``default`` → the default integrator's name; refuse an unknown name."""
    resolved = DEFAULT_INTEGRATOR if name == "default" else name
    if resolved not in ALL_INTEGRATORS:
        known = ", ".join(("default", *ALL_INTEGRATORS))
        raise RunSettingsError.at(
            "run.integrator",
            f"unknown integrator {name!r}; known: {known}",
            found=name,
            expected=f"one of: {known}",
        )
    return resolved


def case_integrator(name: str, train: ValveTrain, has_seat: bool = True) -> str:
    """``default`` → the integrator a case takes: COMPLIANT where a contact it can touch is
    compliant, else DEFAULT_INTEGRATOR; another name is resolved as given."""
    if name == "default" and compliant_contacts(train, has_seat):
        return COMPLIANT
    return resolve_integrator(name)


def compliant_contacts(train: ValveTrain, has_seat: bool) -> bool:
    """A train whose cam contact, or seat contact where there is a seat, is compliant."""
    return train.cam_contact != "rigid" or (has_seat and train.seat_contact != "rigid")


@functools.lru_cache(maxsize=256)
def _lash_seat(train: ValveTrain) -> float:
    """The seat a train's lash places (``campipe.model.lash_seat``), once per train."""
    return lash_seat(system_matrices(train), train.lash)


@dataclass(frozen=True)
class Case:
    """One run: a valve train, a cam and how it is driven."""

    train: ValveTrain  # model parameters [SI]
    profile: Profile  # cam lift over one turn, defects applied
    speed: float  # cam speed [rad/s]
    seat: float = math.nan  # seat position as a valve lift [m]; NaN: no seat
    closure: str = "force"  # "force": spring-held, may separate; "form": never leaves the cam

    def __post_init__(self) -> None:
        lash = getattr(self.train, "lash", math.nan)
        if math.isnan(lash):
            return
        seat = _lash_seat(self.train)
        if not math.isnan(self.seat) and self.seat != seat:
            raise CaseError.at(
                "seat",
                f"a seat at {self.seat:.6g} m beside a train's lash of {lash:.6g} m (which "
                f"places it at {seat:.6g} m); give one of them",
                found=self.seat,
                expected="no seat (NaN), or a train without lash",
            )
        object.__setattr__(self, "seat", seat)  # the lash places the seat

    @property
    def has_seat(self) -> bool:
        return not math.isnan(self.seat)

    @property
    def compliant(self) -> bool:
        """A compliant law at a contact the case can touch (``engine.compliant``)."""
        return compliant_contacts(self.train, self.has_seat)


@dataclass(frozen=True)
class RunSettings:
    """How a batch is integrated and sampled."""

    revolutions: float = 4.0  # cam turns, starting at θ = 0
    dt: float | None = None  # time step [s] (modal-exact: largest step); None: DEFAULT_STEPS
    output_every: float = math.radians(1.0)  # output spacing in cam angle [rad]
    integrator: str = "default"  # "default" or a name in INTEGRATORS
    tolerance: float = 1e-12  # event-time tolerance of integrators that locate events [s]
    max_events: int = 4096  # events kept per case
    fidelity: str = "full"  # a name in FIDELITIES
    #: a valve-lift error [m] the run accepts instead of a level: the cheapest level whose
    #: FIDELITY_ERRORS is within it (``level``); None: ``fidelity`` as named
    fidelity_tolerance: float | None = None
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
        if not (0 <= turns < turn_count(self.revolutions)):
            raise RunSettingsError.at(
                "run.warmup",
                f"found {turns!r} turns; a run of {self.revolutions:g} needs at least one "
                "measured turn after its warm-up",
                found=turns,
                expected=f"0 … {turn_count(self.revolutions) - 1} turns",
            )
        return int(turns)

    @property
    def level(self) -> str:
        """The fidelity the run uses: ``fidelity``, or with ``fidelity_tolerance`` the cheapest
        level whose stated error is within it: steady for runs of STEADY_MIN_TURNS turns or
        more (shorter, full costs no more), from the periodic start with modal-exact (the
        full run it stands for)."""
        self.check_fidelity()
        if self.fidelity_tolerance is None:
            return self.fidelity
        steady_ok = self.start == "periodic" and self.method == "modal-exact"
        pays = self.revolutions >= STEADY_MIN_TURNS
        if steady_ok and pays and FIDELITY_ERRORS["steady"] <= self.fidelity_tolerance:
            return "steady"
        return "full"

    def check_fidelity(self) -> None:
        """Refuse an unknown fidelity (a removed one with the reason), and the steady level
        without what it stands for (the periodic start, modal-exact)."""
        tol = self.fidelity_tolerance
        if tol is not None and not (tol >= 0 and math.isfinite(tol)):
            raise RunSettingsError.at(
                "run.fidelity_tolerance",
                f"found {tol!r} m, expected a valve-lift error of 0 or more",
                found=tol,
                expected="a length ≥ 0, e.g. 1e-6 in",
            )
        if self.fidelity == "steady" and (self.start != "periodic" or self.method != "modal-exact"):
            raise RunSettingsError.at(
                "run.fidelity",
                f"steady stands for modal-exact from the periodic start; found start "
                f"{self.start!r} and integrator {self.method!r} (use run.fidelity: full)",
                found=self.fidelity,
                expected="full, or start periodic with integrator modal-exact",
            )
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


@functools.lru_cache(maxsize=256)
def configuration_omega_max(train: ValveTrain) -> np.ndarray:
    """(4,) the highest natural frequency of each configuration I–IV [rad/s]."""
    sm = system_matrices(train)
    return np.array(
        [configuration_frequencies(sm.mass, sm.stiffness, c).max() for c in CONFIGURATIONS]
    )


def visited_configurations(case: Case) -> tuple[int, ...]:
    """The configurations a case can reach: no seat keeps it in I/II; form closure in I/III."""
    if case.closure == "form":
        return (CAM_CONTACT, CAM_AND_SEAT) if case.has_seat else (CAM_CONTACT,)
    return tuple(CONFIGURATIONS) if case.has_seat else (CAM_CONTACT, FREE)


def _newmark_limit(case: Case) -> tuple[float, int]:
    """newmark-linear's stability limit √12/ω_max [s] over the configurations a case can
    visit (thesis Appendix B), and the configuration that sets it."""
    omega_max = configuration_omega_max(case.train)
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


def output_angles(settings: RunSettings) -> np.ndarray:
    """Sample angles 0 … 2π·revolutions at ``output_every`` [rad]."""
    return (
        np.arange(sample_count(settings.revolutions, settings.output_every)) * settings.output_every
    )


def check_newmark_linear(cases: Sequence[Case], settings: RunSettings) -> None:
    """What newmark-linear cannot run, refused at ``run.integrator`` naming modal-exact, which
    runs both: a train of refined members (``<member>_elements`` > 1; it integrates the
    thesis's seven coordinates only), and one with a coefficient of restitution
    (``cam_restitution``, ``seat_restitution``; it applies the thesis's plastic impacts only).

    Raises
    ------
    RunSettingsError
        Key ``run.integrator``.
    """
    if settings.method != "newmark-linear":
        return
    refined = sorted({c.train.n_coordinates for c in cases} - {N_COORDINATES})
    if refined:
        raise RunSettingsError.at(
            "run.integrator",
            f"newmark-linear integrates the thesis's {N_COORDINATES} coordinates only, found "
            f"a train of {refined[-1]} (refined members, <member>_elements > 1); integrate it "
            "with run.integrator: modal-exact",
            found=refined,
            expected=f"{N_COORDINATES} coordinates, or run.integrator: modal-exact",
        )
    for c in cases:
        for name in ("cam_restitution", "seat_restitution"):
            e = getattr(c.train, name)
            if e > 0.0:
                raise RunSettingsError.at(
                    "run.integrator",
                    f"newmark-linear applies the thesis's plastic impacts only, found {name} "
                    f"{e:g}; integrate it with run.integrator: modal-exact, or set "
                    f"model.{name}: 0",
                    found=e,
                    expected=f"{name} 0, or run.integrator: modal-exact",
                )


def check_run(
    cases: Sequence[Case], settings: RunSettings, *, check_stability_limit: bool = True
) -> None:
    """Everything ``run_batch`` refuses, checked without running: an unknown integrator or
    fidelity, a non-positive step or tolerance, an unknown closure, a non-positive speed,
    newmark-linear on a train of refined members (more than seven coordinates) or with a
    coefficient of restitution, a newmark-linear step beyond the stability limit.

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
    check_contacts(cases, settings)
    check_newmark_linear(cases, settings)
    if check_stability_limit:
        check_stability(cases, settings)


def check_contacts(cases: Sequence[Case], settings: RunSettings) -> None:
    """Refuse a compliant case for a rigid integrator (or a rigid one for ``compliant``), and
    a compliant case the compliant integrator cannot run: a rigid contact beside a compliant
    one, or form closure."""
    for i, case in enumerate(cases):
        if not (case.compliant or settings.method == COMPLIANT):
            continue
        if not case.compliant:
            raise RunSettingsError.at(
                "run.integrator",
                f"compliant integrates compliant contacts, but case {i}'s are rigid: use "
                "default (or set model.cam_contact)",
                found=settings.integrator,
                expected="default, modal-exact or newmark-linear",
            )
        law = "cam_contact" if case.train.cam_contact != "rigid" else "seat_contact"
        if settings.integrator != "default" and settings.method != COMPLIANT:
            raise RunSettingsError.at(
                "run.integrator",
                f"{settings.method} integrates rigid contacts only, but case {i} has "
                f"{law}: {getattr(case.train, law)}: use default or compliant",
                found=settings.integrator,
                expected="default or compliant",
            )
        if case.train.cam_contact == "rigid" or (
            case.has_seat and case.train.seat_contact == "rigid"
        ):
            rigid = "cam_contact" if case.train.cam_contact == "rigid" else "seat_contact"
            raise CaseError.at(
                rigid,
                f"case {i} has a rigid {rigid.split('_')[0]} contact beside a compliant "
                f"{law.split('_')[0]} one: the compliant integrator takes both contacts "
                f"compliant; set {rigid} to kelvin-voigt or hertz",
                found="rigid",
                expected="kelvin-voigt or hertz",
            )
        if case.closure == "form":
            raise CaseError.at(
                "closure",
                f"case {i} has form closure with a compliant cam contact: a compliant "
                "contact never pulls, so the follower is held by the spring: use force",
                found="form",
                expected="force",
            )
