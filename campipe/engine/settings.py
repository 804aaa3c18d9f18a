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
from campipe.engine import integrators
from campipe.engine.case import CLOSURES as CLOSURES
from campipe.engine.case import Case as Case
from campipe.engine.case import CaseError as CaseError
from campipe.engine.case import IntegrationError as IntegrationError
from campipe.engine.case import RunSettingsError as RunSettingsError
from campipe.engine.case import StabilityError as StabilityError
from campipe.engine.case import compliant_contacts as compliant_contacts
from campipe.engine.case import output_angles as output_angles
from campipe.engine.case import sample_count as sample_count
from campipe.engine.case import turn_count as turn_count
from campipe.engine.case import visited_configurations as visited_configurations
from campipe.model import ValveTrain
from campipe.model.hla import adjuster
from campipe.vocabulary import ROMAN

#: The integrators of rigid contacts (the thesis's) by name (``campipe.engine.integrators``);
#: ``default`` in a spec means DEFAULT_INTEGRATOR, or COMPLIANT for a case with a compliant
#: contact law (the contacts as force elements, error-controlled).
INTEGRATORS = integrators.names("rigid")
DEFAULT_INTEGRATOR = integrators.DEFAULT
COMPLIANT = integrators.names("compliant")[0]
#: Every integrator a run may name.
ALL_INTEGRATORS = integrators.names()
#: The step each integrator uses when a run names none [s]: the thesis's 1 µs for its
#: integrator; modal-exact is exact between events and sizes its own steps (a run's dt only
#: caps them).
DEFAULT_STEPS: dict[str, float | None] = {
    name: integrator.default_step for name, integrator in integrators.REGISTRY.items()
}
#: Model fidelity of a run, cheapest last: "full", every case through its events with every
#: mode; "steady", each case whose periodic steady state is configuration I's all turn (it
#: follows the cam with a least force above zero, the valve clear of its seat) and whose
#: profile has no velocity jump at its speed above the capture velocity (a flat, a
#: constant-velocity ramp: events every turn, ``engine.periodic.break_events``) from that
#: closed form, one turn computed and repeated (``engine.periodic.run_at_fidelity``), the
#: others in full. The full run starts on that same steady state and stays there, so the two
#: agree to FIDELITY_ERRORS. A level that did
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
#: times the larger of the full valve lift and the height a valve thrown off at the cam's
#: fastest valve speed rises against its spring (``batch.valve_flight``; plus the seat's
#: offset), a closing or valve speed beyond this many times the fastest the cam's surface
#: moves (times the rocker ratio).
LIFT_BOUND = 3.0
SPEED_BOUND = 10.0


def resolve_integrator(name: str) -> str:
    """``default`` → the default integrator's name; refuse an unknown name."""
    resolved = DEFAULT_INTEGRATOR if name == "default" else name
    if resolved not in integrators.REGISTRY:
        integrators.get(name)  # raises, naming the known ones
    return resolved


def case_integrator(name: str, train: ValveTrain, has_seat: bool = True) -> str:
    """``default`` → the integrator a case takes: COMPLIANT where a contact it can touch is
    compliant, else DEFAULT_INTEGRATOR; another name is resolved as given."""
    if name == "default" and compliant_contacts(train, has_seat):
        return COMPLIANT
    return resolve_integrator(name)


#: A run of automatic length counts a case settled with period p only once its repetition
#: has held for this many further periods (``engine.settle.confirmed``): the states at turn
#: boundaries p apart agree to ``settle_tolerance`` and keep contracting over
#: SETTLE_CONFIRM + 1 checks [periods]. A chaotic response passing near an unstable periodic
#: one repeats to the tolerance for a turn or two and then leaves it (the thesis train at
#: 9524 rpm with the seat at 0.1 in passed for period 4 at its 95th turn).
SETTLE_CONFIRM = 2


@dataclass(frozen=True)
class RunSettings:
    """How a batch is integrated and sampled."""

    #: cam turns, starting at θ = 0; None: each case until its response repeats
    #: (``engine.settle``), its last ``history_turns`` recorded
    revolutions: float | None = 4.0
    dt: float | None = None  # time step [s] (modal-exact: largest step); None: DEFAULT_STEPS
    output_every: float = math.radians(1.0)  # output spacing in cam angle [rad]
    integrator: str = "default"  # "default" or a name in INTEGRATORS
    tolerance: float = 1e-12  # event-time tolerance of integrators that locate events [s]
    max_events: int = 4096  # events kept per case
    #: the most steps of one case's adaptive integration (compliant); beyond, the case stops
    #: with status STEP_LIMIT (``--max-steps``)
    max_steps: int = 1_000_000_000
    fidelity: str = "full"  # a name in FIDELITIES
    #: a valve-lift error [m] the run accepts instead of a level: the cheapest level whose
    #: FIDELITY_ERRORS is within it (``level``); None: ``fidelity`` as named
    fidelity_tolerance: float | None = None
    start: str = "periodic"  # "periodic" or "quasi-static" (see STARTS)
    warmup: int | None = None  # turns left out of the metrics; None: DEFAULT_WARMUP[start]
    capture_velocity: float = DEFAULT_CAPTURE_VELOCITY  # resting contact below this [m/s]
    # Run length by convergence (``revolutions`` None, ``engine.settle``):
    history_turns: int = 1  # the last turns whose histories and events are recorded
    max_revolutions: int = 48  # the cap on a case's turns
    #: a settling case's states at turn boundaries p turns apart agree to this, relative to
    #: each coordinate's and velocity's range over a turn [-]
    settle_tolerance: float = 1e-5
    max_period: int = 4  # the longest period [turns] a settling case is checked for

    @property
    def settle(self) -> bool:
        """Whether each case runs until its response repeats (``revolutions`` None)."""
        return self.revolutions is None

    @property
    def recorded_revolutions(self) -> float:
        """The turns the histories cover: ``revolutions``, or ``history_turns`` when each
        case runs until settled."""
        return float(self.history_turns) if self.revolutions is None else self.revolutions

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
        if self.settle:
            return 0  # the settled window says which turns count (``engine.settle``)
        if not (0 <= turns < turn_count(self.recorded_revolutions)):
            raise RunSettingsError.at(
                "run.warmup",
                f"found {turns!r} turns; a run of {self.recorded_revolutions:g} needs at least one "
                "measured turn after its warm-up",
                found=turns,
                expected=f"0 … {turn_count(self.recorded_revolutions) - 1} turns",
            )
        return int(turns)

    def check_whole_turns(self) -> None:
        """Refuse a fixed run with no whole turn after its warm-up (1.5 turns from the
        quasi-static start, 0.5 turns), naming ``run.revolutions``: its metrics would read a
        part of a turn as a turn. A study's spec is checked so (``campipe validate``); the
        engine itself runs such a run and reads its part (its warm-up and timing runs)."""
        if self.settle:
            return
        turns = self.warmup_turns
        if whole_turn_count(self.recorded_revolutions) <= turns:
            raise RunSettingsError.at(
                "run.revolutions",
                f"found {self.recorded_revolutions:g}: after {turns} turn(s) of warm-up no whole "
                "turn is left, and the metrics read whole turns; run at least "
                f"{turns + 1} turns (a whole number reads best)",
                found=self.recorded_revolutions,
                expected=f"≥ {turns + 1} turns",
            )

    def measured_turns(self, n_rev: int) -> np.ndarray:
        """(n_rev,) bool: the turns the metrics' summaries read. Those after the warm-up, and
        whole: a fractional ``revolutions`` ends in a part of a turn, whose angles and counts
        are not a turn's (2.5 turns would average half a turn's separation as a whole one's),
        so it is left out (its values stay in the per-turn metrics). A run shorter than one
        turn (the engine's warm-up and timing runs) has only that part, and reads it."""
        measured = np.arange(n_rev) >= self.warmup_turns
        partial = whole_turn_count(self.recorded_revolutions) < n_rev
        if partial and measured[:-1].any():
            measured[-1] = False
        return measured

    @property
    def level(self) -> str:
        """The fidelity the run uses: ``fidelity``, or with ``fidelity_tolerance`` the cheapest
        level whose stated error is within it: steady for runs of STEADY_MIN_TURNS turns or
        more (shorter, full costs no more), from the periodic start with modal-exact (the
        full run it stands for)."""
        self.check_fidelity()
        if self.fidelity_tolerance is None or self.settle:
            return self.fidelity
        steady_ok = self.start == "periodic" and self.method == "modal-exact"
        pays = self.recorded_revolutions >= STEADY_MIN_TURNS
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
        if self.fidelity == "steady" and self.settle:
            raise RunSettingsError.at(
                "run.fidelity",
                "steady repeats one closed-form turn, and a run of automatic length settles a "
                "case that follows the cam in its first turn anyway: use run.fidelity: full "
                "(or fix run.revolutions)",
                found=self.fidelity,
                expected="full with run.revolutions: auto",
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


def whole_turn_count(revolutions: float) -> int:
    """The whole turns of a run of ``revolutions`` (its partial last turn not counted)."""
    return int(math.floor(revolutions + 1e-12))


def whole_turns(settings: RunSettings) -> int:
    """The turns a settling run records: ``history_turns``, a whole number ≥ 1 (refused
    otherwise, naming the key)."""
    turns = settings.history_turns
    if isinstance(turns, bool) or not (float(turns).is_integer() and turns >= 1):
        raise RunSettingsError.at(
            "run.history_turns",
            f"found {turns!r}: a run of automatic length records a whole number of its last turns",
            found=turns,
            expected="a whole number of turns ≥ 1",
        )
    return int(turns)


def _samples_divide_a_turn(settings: RunSettings, why: str) -> None:
    """Refuse an output spacing that does not divide a turn, for a run whose every turn starts
    where the last ended, on a sample (``why``: which run)."""
    per_turn = TWO_PI / settings.output_every
    if abs(per_turn - round(per_turn)) > 1e-9 * per_turn:
        raise RunSettingsError.at(
            "run.output_every",
            f"{math.degrees(settings.output_every):.6g} deg does not divide a turn: {why} "
            "every turn starts on a sample (use e.g. 1 deg or 0.5 deg)",
            found=math.degrees(settings.output_every),
            expected="360 deg / a whole number",
        )


def check_settling(settings: RunSettings) -> None:
    """Refuse settling settings that cannot work, naming the key: a sample spacing that does
    not divide a turn (each turn starts where the last ended, on a sample), a cap below the
    turns recorded or the turns a repetition of the longest period takes to be confirmed
    ((2 + SETTLE_CONFIRM)·max_period), a period bound below 1, a tolerance not above 0."""
    turns = whole_turns(settings)
    if settings.warmup is not None:
        raise RunSettingsError.at(
            "run.warmup",
            f"found {settings.warmup!r}: with run.revolutions: auto the settled window says "
            "which turns count; leave run.warmup out (or fix run.revolutions)",
            found=settings.warmup,
            expected="default",
        )
    _samples_divide_a_turn(settings, "with run.revolutions: auto")
    if settings.max_period < 1:
        raise RunSettingsError.at(
            "run.max_period",
            f"found {settings.max_period!r}, expected a period of 1 turn or more",
            found=settings.max_period,
            expected="≥ 1",
        )
    confirmed = (2 + SETTLE_CONFIRM) * settings.max_period
    if settings.max_revolutions < max(turns, confirmed):
        least = max(turns, confirmed)
        raise RunSettingsError.at(
            "run.max_revolutions",
            f"found {settings.max_revolutions!r}: it must allow the recorded turns and a "
            f"repetition of the longest period confirmed, {2 + SETTLE_CONFIRM} of its periods "
            f"({least} turns)",
            found=settings.max_revolutions,
            expected=f"≥ {least}",
        )
    tol = settings.settle_tolerance
    _positive(tol, "run.settle_tolerance", f"{tol!r}, expected a relative tolerance above 0",
              "> 0, e.g. 1e-5")  # fmt: skip


def stability_limit(case: Case, integrator: str = "newmark-linear") -> float:
    """Largest step [s] the integrator accepts for a case, over the configurations it can
    visit: newmark-linear's stability limit √12/ω_max (thesis Appendix B); modal-exact has
    none (inf): it is exact between events and sizes its own steps."""
    return integrators.get(resolve_integrator(integrator)).stability_limit(case)[0]


def check_stability(cases: Sequence[Case], settings: RunSettings) -> None:
    """Refuse a step beyond the integrator's stability limit in any configuration a case can
    visit, naming the limit."""
    dt_run = settings.step
    if dt_run is None:
        return
    integrator = integrators.get(settings.method)
    for i, case in enumerate(cases):
        limit, worst = integrator.stability_limit(case)
        if dt_run >= limit:
            beyond = f"{dt_run * 1e6:.4g} µs is beyond the stability limit of {integrator.name}"
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


def adjuster_turns(settings: RunSettings) -> int | None:
    """The turns of a run of trains with a hydraulic lash adjuster (``engine.lash_adjuster``:
    its plunger advances at each turn's end): 0 for a run shorter than a turn (no turn ends:
    the plunger stays), None for a run of automatic length, refusing a fraction of a turn
    beyond the first at ``run.revolutions``."""
    turns = settings.revolutions
    if turns is None:
        return None
    if turns < 1.0:
        return 0
    if turns != math.floor(turns):
        raise RunSettingsError.at(
            "run.revolutions",
            "a train with a hydraulic lash adjuster runs a whole number of turns (its "
            "plunger advances at each turn's end)",
            found=turns,
            expected="a whole number of turns",
        )
    return int(turns)


def check_adjuster_run(case: Case, settings: RunSettings, who: str) -> None:
    """Refuse, for a train with a hydraulic lash adjuster run more than a turn, an output
    spacing that does not divide a turn (its plunger's state is read at each turn's end, on a
    sample); ``who`` begins the reason ("case 3 has a lash adjuster, and")."""
    if adjuster(case.train) is not None:
        turns = adjuster_turns(settings)
        if turns and turns > 1:
            _samples_divide_a_turn(settings, who)


def check_run(
    cases: Sequence[Case], settings: RunSettings, *, check_stability_limit: bool = True
) -> None:
    """Everything ``run_batch`` refuses, checked without running: an unknown integrator or
    fidelity, a non-positive step or tolerance, an unknown closure, a non-positive speed,
    newmark-linear on a train of refined members (more than seven coordinates) or with a
    coefficient of restitution, a newmark-linear step beyond the stability limit, a train
    with a hydraulic lash adjuster on a run not of whole turns (``adjuster_turns``).

    Raises
    ------
    RunSettingsError
        (StabilityError for the step limit) for a run setting, its ``key`` ``run.<name>``.
    CaseError
        For a case's closure or speed, its ``key`` ``closure`` or ``speed``.
    """
    _check_settings(settings)
    for i, case in enumerate(cases):
        check_adjuster_run(case, settings, f"case {i} has a lash adjuster, and")
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
    if check_stability_limit:
        check_stability(cases, settings)


@functools.lru_cache(maxsize=64)
def _check_settings(settings: RunSettings) -> None:
    """``check_run``'s checks of the settings alone, once per settings (a refusal is not
    cached: it raises again at each call)."""
    dt_run = settings.step  # also refuses an unknown integrator
    settings.check_fidelity()
    if settings.settle:
        check_settling(settings)
    if dt_run is not None:
        _positive(dt_run, "run.dt", f"{dt_run!r} s, expected a positive step", "> 0 s")
    tol = settings.tolerance
    _positive(tol, "run.tolerance", f"{tol!r} s, expected > 0", "> 0 s")


def _positive(value: float, key: str, found: str, expected: str) -> None:
    """Refuse a run setting that is not a finite positive number: "found <found>"."""
    if not (value > 0 and math.isfinite(value)):
        raise RunSettingsError.at(key, f"found {found}", found=value, expected=expected)


def check_contacts(cases: Sequence[Case], settings: RunSettings) -> None:
    """Refuse a compliant case for an integrator of rigid contacts (or a rigid one for one of
    compliant contacts), then what the run's integrator refuses (its ``check``)."""
    integrator = integrators.get(settings.method)
    compliant = [case.compliant for case in cases]
    for i, case in enumerate(cases):
        if not (compliant[i] or integrator.contacts == "compliant"):
            continue
        if not compliant[i]:
            raise RunSettingsError.at(
                "run.integrator",
                f"{integrator.name} integrates compliant contacts, but case {i}'s are rigid: "
                "use default (or set model.cam_contact)",
                found=settings.integrator,
                expected=f"default, {', '.join(INTEGRATORS)}",
            )
        law = "cam_contact" if case.train.cam_contact != "rigid" else "seat_contact"
        if settings.integrator != "default" and integrator.contacts != "compliant":
            raise RunSettingsError.at(
                "run.integrator",
                f"{settings.method} integrates rigid contacts only, but case {i} has "
                f"{law}: {getattr(case.train, law)}: use default or {COMPLIANT}",
                found=settings.integrator,
                expected=f"default or {COMPLIANT}",
            )
    if any(compliant):
        integrators.get(COMPLIANT).check(cases, settings)
    if integrator.contacts != "compliant":
        integrator.check(cases, settings)
