"""Measurements: wall time of a run, its errors against a reference, the references and their
cross-check, and the time a method needs to reach a given error.

Timing rules: compiled kernels are loaded first (:func:`warm_up`), so compile time is never
counted; an engine setting is timed on a batch of copies of the case (per-case time = batch
time / copies, so the Python overhead of a call is amortised as in a study) and the best of a
few repeats is kept; a ``solve_ivp`` run is timed whole, best of its repeats.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from campipe.bench.ivp import IvpResult, solve_case
from campipe.bench.suite import OUTPUT_EVERY, Scene, suite
from campipe.constants import INCH
from campipe.engine import BatchResult, Case, RunSettings, run_batch
from campipe.vocabulary import CAM_SEPARATION, EV_KIND, EV_TIME

#: The converged reference: modal-exact (exact between events) with events located to 1e-14 s
#: and steps capped at 0.1 µs, so that no monitor excursion between grid points can hide.
REFERENCE_STEP_CAP = 0.1e-6  # [s]
REFERENCE = RunSettings(
    integrator="modal-exact", tolerance=1e-14, dt=REFERENCE_STEP_CAP, output_every=OUTPUT_EVERY
)
#: The reference's check, a different method: solve_ivp's DOP853 (explicit Runge–Kutta of
#: order 8, dense output of order 7, events by Brent's method on the dense output) at
#: rtol = atol = 1e-13 (``campipe.bench.ivp``).
CHECK_METHOD = "DOP853"
CHECK_RTOL = 1e-13
#: What the two references must agree to: valve lift [m], event angles [rad], separation per
#: turn [rad], seating and cam-impact velocities [m/s].
AGREEMENT = {
    "valve_lift": 1e-9 * INCH,
    "event_angle": math.radians(1e-5),
    "separation": math.radians(1e-5),
    "seating_velocity": 1e-6 * INCH,
    "impact_velocity": 1e-6 * INCH,
}
#: A batch is timed with enough copies to last about this long [s] (within 1 … Ladder.copies).
BATCH_SECONDS = 0.2
#: A batch is timed ``repeats`` times, and again while the repeats have taken less than
#: BATCH_SECONDS, up to this many: a cheap setting's best of three moved by a third from one
#: run to the next (smooth-9000's four tolerances, the same 360 steps, 0.060–0.091 ms), and
#: the regression gate named it slower.
MAX_REPEATS = 50


@dataclass(frozen=True)
class Outcome:
    """What the bench compares of one run of one case, SI."""

    valve_lift: np.ndarray  # (n_out,) valve lift at the output angles [m]
    events: np.ndarray  # (n_ev, 6) the engine's event rows (time, kind, from, to, v, impulse)
    separation_per_rev: np.ndarray  # (n_rev,) cam angle off the cam per turn [rad]
    max_seating_velocity: float  # [m/s]
    max_cam_impact_velocity: float  # [m/s]
    speed: float  # cam speed [rad/s]
    has_seat: bool  # the case has a valve seat


def outcome_of_batch(result: BatchResult, i: int, case: Case) -> Outcome:
    """Case ``i`` of an engine batch."""
    return Outcome(
        result.valve_lift[i].copy(),
        result.events[i].copy(),
        result.separation_per_rev[i].copy(),
        # over every turn, as the peer's: a fractional run's summaries leave its last turn out
        float(np.max(result.max_seating_velocity_per_rev[i])),
        float(np.max(result.max_cam_impact_velocity_per_rev[i])),
        case.speed,
        case.has_seat,
    )


def outcome_of_ivp(result: IvpResult, case: Case) -> Outcome:
    """A ``solve_ivp`` run."""
    return Outcome(
        result.valve_lift.copy(),
        result.events.copy(),
        result.separation_per_rev.copy(),
        result.max_seating_velocity,
        result.max_cam_impact_velocity,
        case.speed,
        case.has_seat,
    )


@dataclass(frozen=True)
class Errors:
    """Errors of a run against a reference (SI: m, rad, m/s); NaN where not defined."""

    valve_lift: float  # max |Δ valve lift| over the output angles [m]
    events_match: bool  # same event kinds in the same order as the reference
    event_angle: float  # max |Δθ| over all events, matched by order; NaN if they differ [rad]
    separation_angle: float  # the same over the separations only; NaN if none [rad]
    separation: float  # max |Δ| of the cam angle off the cam per turn [rad]
    seating_velocity: float  # |Δ| of the largest seating velocity; NaN without seat [m/s]
    impact_velocity: float  # |Δ| of the largest cam-impact velocity [m/s]

    def as_dict(self) -> dict[str, float | bool]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def errors(run: Outcome, reference: Outcome) -> Errors:
    """Errors of ``run`` against ``reference`` (same case, same output angles)."""
    a, b = run.events, reference.events
    match = a.shape[0] == b.shape[0] and np.array_equal(a[:, EV_KIND], b[:, EV_KIND])
    event_angle = separation_angle = math.nan
    if match and a.shape[0]:
        dtheta = np.abs(a[:, EV_TIME] - b[:, EV_TIME]) * reference.speed
        event_angle = float(dtheta.max())
        sep = b[:, EV_KIND] == CAM_SEPARATION
        separation_angle = float(dtheta[sep].max()) if sep.any() else math.nan
    return Errors(
        valve_lift=float(np.abs(run.valve_lift - reference.valve_lift).max()),
        events_match=bool(match),
        event_angle=event_angle,
        separation_angle=separation_angle,
        separation=float(np.abs(run.separation_per_rev - reference.separation_per_rev).max()),
        seating_velocity=(
            abs(run.max_seating_velocity - reference.max_seating_velocity)
            if reference.has_seat
            else math.nan
        ),
        impact_velocity=abs(run.max_cam_impact_velocity - reference.max_cam_impact_velocity),
    )


#: The error fields a reference's own check resolves them to (:func:`resolved`).
RESOLVED = (
    "valve_lift", "event_angle", "separation_angle", "separation", "seating_velocity",
    "impact_velocity",
)  # fmt: skip


def resolved(err: Errors, check: Errors) -> tuple[Errors, list[str]]:
    """``err`` (a run against the reference) with each error below the reference's own
    resolution, its difference from the second reference (``check``), raised to it: an error
    smaller than the two references' disagreement is not measured, only bounded by it (a
    scene's reported 1e-13 in, where the references differed by 4e-11 in, read as a
    2e10-fold accuracy). Returns the errors and the names of those raised."""
    raised = {}
    for name in RESOLVED:
        value, floor = getattr(err, name), getattr(check, name)
        if math.isfinite(value) and math.isfinite(floor) and value < floor:
            raised[name] = floor
    return replace(err, **raised), list(raised)


def warm_up() -> None:
    """Load (or compile) every kernel the bench times, on a scene that visits all four
    configurations, so that no timing includes compilation."""
    seat = suite()[2]
    for settings in (
        RunSettings(revolutions=0.3, integrator="newmark-linear"),
        RunSettings(revolutions=0.3, integrator="modal-exact"),
    ):
        run_batch([seat.case, seat.case], settings)


def time_engine(
    scene: Scene,
    settings: RunSettings,
    max_copies: int,
    repeats: int,
    batch_seconds: float = BATCH_SECONDS,
    full_state: bool = True,
) -> tuple[float, Outcome, int]:
    """Per-case wall time [s] of one setting, its outcome and the grid steps per case.

    An untimed single-case run first (it fills the engine's caches), which also sizes the
    timed batch: enough copies to last ``batch_seconds``, at most ``max_copies``; the batch
    timed ``repeats`` times, and more while the repeats have taken less than
    ``batch_seconds`` (at most :data:`MAX_REPEATS`), the best kept.
    ``full_state`` as ``run_batch``'s (False: only the contact coordinates are sampled).
    """
    settings = replace(settings, revolutions=scene.revolutions)
    t0 = time.perf_counter()
    first = run_batch([scene.case], settings, full_state=full_state)
    single = time.perf_counter() - t0
    copies = int(np.clip(round(batch_seconds / max(single, 1e-6)), 1, max_copies))
    best = best_time(
        lambda: run_batch([scene.case] * copies, settings, full_state=full_state),
        repeats,
        batch_seconds,
    )
    return best / copies, outcome_of_batch(first, 0, scene.case), int(first.steps[0])


def best_time(run: Callable[[], object], repeats: int, seconds: float = BATCH_SECONDS) -> float:
    """The least wall time [s] of ``run()`` over ``repeats`` runs, and more while the runs
    have taken less than ``seconds`` in all (at most :data:`MAX_REPEATS`)."""
    best = math.inf
    spent = 0.0
    done = 0
    while done < repeats or (spent < seconds and done < MAX_REPEATS):
        t0 = time.perf_counter()
        run()
        took = time.perf_counter() - t0
        best = min(best, took)
        spent += took
        done += 1
    return best


def time_ivp(scene: Scene, rtol: float, method: str, repeats: int) -> tuple[float, Outcome, int]:
    """Wall time [s] of the ``solve_ivp`` peer on one case, its outcome and its number of
    right-hand-side evaluations."""
    best = math.inf
    result = None
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        result = solve_case(scene.case, scene.revolutions, OUTPUT_EVERY, method=method, rtol=rtol)
        best = min(best, time.perf_counter() - t0)
    assert result is not None  # the loop runs at least once
    return best, outcome_of_ivp(result, scene.case), result.nfev


def reference(scene: Scene) -> Outcome:
    """The converged reference of a scene (``REFERENCE``)."""
    res = run_batch([scene.case], replace(REFERENCE, revolutions=scene.revolutions))
    return outcome_of_batch(res, 0, scene.case)


@dataclass(frozen=True)
class ReferenceCheck:
    """The reference against a second reference of a different method."""

    scene: str  # scene name
    errors: Errors  # the check's differences from the reference
    seconds: float  # wall time of the check run [s]
    agrees: bool  # every difference within AGREEMENT (and the events match)


def check_reference(scene: Scene, ref: Outcome) -> ReferenceCheck:
    """Run the second reference (``CHECK_METHOD`` at ``CHECK_RTOL``) and compare."""
    t0 = time.perf_counter()
    res = solve_case(
        scene.case, scene.revolutions, OUTPUT_EVERY, method=CHECK_METHOD, rtol=CHECK_RTOL
    )
    seconds = time.perf_counter() - t0
    err = errors(outcome_of_ivp(res, scene.case), ref)
    return ReferenceCheck(scene.name, err, seconds, agrees(err))


def agrees(err: Errors, limits: dict[str, float] = AGREEMENT) -> bool:
    """Every defined difference within its limit, and the same events."""
    if not err.events_match:
        return False
    for name, limit in limits.items():
        value = getattr(err, name)
        if not math.isnan(value) and value > limit:
            return False
    return True


def pareto(times: np.ndarray, errs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points no cheaper point beats: sorted by time, each with a smaller error than
    every cheaper one."""
    order = np.argsort(times, kind="stable")
    t_out: list[float] = []
    e_out: list[float] = []
    for i in order:
        if errs[i] > 0 and np.isfinite(errs[i]) and (not e_out or errs[i] < e_out[-1]):
            t_out.append(times[i])
            e_out.append(errs[i])
    return np.array(t_out), np.array(e_out)


def time_to_error(times, errs, target: float) -> tuple[float, str]:
    """Wall time a method needs to reach an error ≤ ``target``, from its ladder.

    Returns
    -------
    seconds : float
        Interpolated linearly in log time against log error between the two ladder points that
        bracket ``target``; the cheapest point's time if even that is below the target;
        extrapolated along the slope of the last (up to) three points if no point reaches
        it; inf if the ladder cannot say.
    how : str
        "cheapest" (the cheapest point already reaches it: an upper bound), "interpolated",
        "extrapolated" (no point of the ladder reaches it) or "not reached" (and no trend
        to extrapolate).
    """
    t, e = pareto(np.asarray(times, float), np.asarray(errs, float))
    if t.size == 0:
        return math.inf, "not reached"
    if e[0] <= target:
        return float(t[0]), "cheapest"
    below = np.flatnonzero(e <= target)
    if below.size:
        i = below[0]
        s = (math.log(t[i]) - math.log(t[i - 1])) / (math.log(e[i]) - math.log(e[i - 1]))
        return float(t[i - 1] * (target / e[i - 1]) ** s), "interpolated"
    if t.size >= 2:
        # The slope of the last (up to) three points, least squares in log–log.
        s = np.polyfit(np.log(e[-3:]), np.log(t[-3:]), 1)[0]
        if s < 0:
            return float(t[-1] * (target / e[-1]) ** s), "extrapolated"
    return math.inf, "not reached"


def measured_time_to_error(times, errs, target: float) -> tuple[float, bool]:
    """What the ladder itself shows of the time to reach ``target``, without extrapolating.

    Returns
    -------
    seconds : float
        As :func:`time_to_error` where a point reaches the target; otherwise the time of the
        ladder's most accurate point, which still does not: a finer setting is needed, so
        reaching the target costs more than that (a lower bound). inf for an empty ladder.
    reached : bool
        True when a ladder point reaches the target (``seconds`` is then the estimate
        itself), False when ``seconds`` is the lower bound.
    """
    seconds, how = time_to_error(times, errs, target)
    if how in ("cheapest", "interpolated"):
        return seconds, True
    t, _ = pareto(np.asarray(times, float), np.asarray(errs, float))
    return (float(t[-1]) if t.size else math.inf), False
