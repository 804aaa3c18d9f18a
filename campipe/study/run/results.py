"""One batch: run its cases through the engine and lay the results out as archive arrays.

:func:`compute_batch` is what a dask task runs: pure computation, arrays in and out (no
files); the caller stores the :class:`BatchData` (:mod:`campipe.io.archive`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata
from typing import TYPE_CHECKING

import numpy as np

import campipe
from campipe import engine
from campipe.engine.levers import at_the_cam
from campipe.engine.loads import MEMBER_LOADS, SPRING_HISTORIES
from campipe.engine.metrics import archived_metrics, batch_means_error
from campipe.model.layouts import placeholders
from campipe.sources import source_digest
from campipe.study.spec.resolve import ResolvedCase
from campipe.study.spec.variables import CAM_NORMAL_FORCE, data_variables
from campipe.vocabulary import (
    EV_FROM,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    EV_TO,
    EV_VELOCITY,
    N_COORDINATES,
)

if TYPE_CHECKING:
    from campipe.engine import BatchResult

#: Where the numbers come from: the source of these packages and modules enters
#: :func:`numerics_fingerprint`.
NUMERICS_SOURCES = (
    "engine",
    "profiles",
    "model",
    "vocabulary.py",
    "constants.py",
    "study/run/results.py",  # this module: the engine's results as archive arrays
)
#: Libraries whose versions enter :func:`numerics_fingerprint`: they compute the numbers too.
NUMERICS_LIBRARIES = ("numpy", "scipy", "numba")


@functools.cache
def numerics_fingerprint() -> str:
    """What computes a case's numbers: campipe's version, a SHA-256 of the source of the
    engine, the profiles, the model and this module, and the versions of numpy, scipy and
    numba, as one short text.

    Batch files and archives record it (``campipe_numerics``); results of another fingerprint
    are never reused, so an upgraded (or edited) engine never mixes its numbers with an older
    one's. A case id says *what* was run; this says *by what*.
    """
    digest = source_digest(NUMERICS_SOURCES)
    versions = []
    for lib in NUMERICS_LIBRARIES:
        try:
            versions.append(f"{lib}=={metadata.version(lib)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{lib}==?")
    return f"campipe {campipe.__version__}; source {digest[:16]}; " + ", ".join(versions)


@dataclass(frozen=True)
class BatchPlan:
    """The cases of one batch (sharing run settings) and what to record."""

    key: str  # batch key: hash of its case ids and what is recorded
    cases: tuple[ResolvedCase, ...]  # its cases, in study order
    record: tuple[str, ...]  # run.record of the study

    @property
    def size(self) -> int:
        return len(self.cases)


@dataclass
class BatchData:
    """A batch's archive arrays: name → array with the case (or event) axis first."""

    key: str  # the batch key
    case_ids: np.ndarray  # (n,) str
    arrays: dict[str, np.ndarray]  # data variables, see campipe.study.spec.variables
    cam_angle: np.ndarray  # (n_out,) [degree]
    n_revolutions: int  # length of the revolution axis
    numerics: str = ""  # numerics_fingerprint() of the process that computed it
    engine_seconds: float = 0.0  # wall time of its engine call (run_batch) [s]

    @property
    def n_cases(self) -> int:
        return self.case_ids.size

    @property
    def n_events(self) -> int:
        return int(self.arrays["event_case"].size)


def cam_angle_degrees(cam_angle: np.ndarray) -> np.ndarray:
    """Output angles [rad] → [degree], rounded to 1e-9 degree so 1° steps read as integers."""
    return np.round(np.degrees(cam_angle), 9)


def run_batch(cases, settings, **options) -> BatchResult:
    """:func:`campipe.engine.run_at_fidelity` (run_batch at the run's fidelity level), looked
    up when a batch first runs: the compiled kernels load then, not when a study is planned
    or found up to date."""
    return engine.run_at_fidelity(cases, settings, **options)


def full_state(record: tuple[str, ...]) -> bool:
    """Whether a run recording ``record`` needs every coordinate's history (``run_batch``'s
    ``full_state``): the coordinates, the member loads or the spring's histories; else only
    the contacts' coordinates are sampled."""
    wanted = set(data_variables(record))
    return (
        "q" in wanted
        or "spring_force" in wanted
        or bool(set(MEMBER_LOADS) & wanted)
        or bool(set(SPRING_HISTORIES) & wanted)
    )


def compute_batch(plan: BatchPlan) -> BatchData:
    """Run a batch's cases in one engine call and lay out its archive arrays.

    All cases of a plan share one :class:`~campipe.engine.RunSettings`. A case that fails
    (non-finite, chatter) does not stop the others: its ``status`` says so and its histories
    and metrics are NaN. The engine call's wall time goes with the arrays
    (:attr:`BatchData.engine_seconds`), wherever the batch ran.
    """
    settings = plan.cases[0].settings
    cases = [c.case for c in plan.cases]
    t = time.perf_counter()
    result = run_batch(cases, settings, full_state=full_state(plan.record), on_failure="record")
    seconds = time.perf_counter() - t
    # a lever's roller force and impacts at the cam (and the cam's radius, for its pressure)
    pressure = "max_cam_pressure" in data_variables(plan.record)
    data = batch_arrays(plan, at_the_cam(result, cases, settings.capture_velocity, pressure))
    data.engine_seconds = seconds
    return data


def batch_arrays(plan: BatchPlan, result: BatchResult) -> BatchData:
    """Archive arrays from an engine result (SI; angles in degrees)."""
    wanted = data_variables(plan.record)
    arrays: dict[str, np.ndarray] = {
        "time": result.time,
        "cam_lift": result.cam_lift,
        "follower_lift": result.follower_lift,
        "valve_lift": result.valve_lift,
        "cam_force": result.cam_force,
        "seat_force": result.seat_force,
        "contact_state": result.contact_state.astype(np.int8),
        "valve_velocity": result.valve_velocity,
        "valve_acceleration": result.valve_acceleration,
        "steps": np.asarray(result.steps, np.int64),
        "measured": np.broadcast_to(result.measured.astype(np.int8), result.per_rev.shape[:2]),
        "status": np.asarray(result.status, np.int8),
    }
    if result.period_turns.size:  # a run of automatic length (``engine.settle``)
        arrays["period_turns"] = result.period_turns.astype(np.int32)
        arrays["settled_revolution"] = (result.settled_turn + 1).astype(np.int32)
        arrays["revolutions_run"] = result.turns_run.astype(np.int32)
        arrays["recorded_revolution"] = (result.recorded_from + 1).astype(np.int32)
    for metric in archived_metrics():
        if metric.summary not in wanted:
            continue
        values = metric.to_archive(result.metric_per_rev(metric.key))
        arrays[metric.summary] = metric.summarise(values, result.measured)
        if metric.uncertainty in wanted:  # a mean of a run of automatic length
            never = result.period_turns == 0  # a settled case's mean is exact: NaN
            error = batch_means_error(values, result.measured)
            arrays[metric.uncertainty] = np.where(never, error, np.nan)
        # A failed case's counts are NaN: its per-revolution integers are written as -1.
        arrays[metric.per_rev] = (
            np.where(np.isnan(values), -1, values).astype(metric.dtype)
            if metric.dtype == "i4"
            else values
        )
    if "q" in wanted:
        arrays["q"] = result.q[:, :, :N_COORDINATES].copy()  # the dof axis: q1 … q7
        for i, c in enumerate(plan.cases):  # a short lumped chain's placeholders: NaN
            arrays["q"][i, :, placeholders(c.case.train)] = np.nan
    for name in set(MEMBER_LOADS) & set(wanted):
        arrays[name] = result.member_loads()[name]
    arrays.update(_spring_arrays(result, set(wanted)))
    if CAM_NORMAL_FORCE in wanted:  # the roller's force on the cam: the cam force (at_the_cam)
        arrays[CAM_NORMAL_FORCE] = result.cam_force
    arrays.update(
        event_arrays(
            result.events,
            [c.case.speed for c in plan.cases],
            result.recorded_from if result.recorded_from.size else None,
        )
    )
    missing = set(wanted) - set(arrays)
    assert not missing, missing
    arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items() if k in wanted}
    return BatchData(
        key=plan.key,
        case_ids=np.array([c.case_id for c in plan.cases], dtype=object),
        arrays=arrays,
        cam_angle=cam_angle_degrees(result.cam_angle),
        n_revolutions=result.n_turns,
        numerics=numerics_fingerprint(),
    )


def _spring_arrays(result: BatchResult, wanted: set[str]) -> dict:
    """The spring's histories, as far as ``wanted`` asks (its metrics are the metrics
    table's)."""
    if not set(SPRING_HISTORIES) & wanted:
        return {}
    histories = result.spring_histories()
    return {name: h for name, h in histories.items() if name in wanted}


def event_arrays(
    events: Sequence[np.ndarray], speeds: Sequence[float], first_turn: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Per-case event lists → the contiguous ragged event variables.

    Parameters
    ----------
    events : sequence of (n_ev, 6) arrays
        Columns as ``campipe.vocabulary.EV_*``.
    speeds : sequence of float
        Each case's cam speed [rad/s], to give each event its cam angle.
    first_turn : (n_cases,) int, optional
        Each case's first recorded turn (a run of automatic length): the cam angle counts
        from its start, as its histories' do.
    """
    counts = np.array([e.shape[0] for e in events], dtype=np.int32)
    ev = np.concatenate([e for e in events]) if len(events) else np.zeros((0, 6))
    if ev.size == 0:
        ev = np.zeros((0, 6))
    case = np.repeat(np.arange(len(events), dtype=np.int32), counts)
    omega = np.asarray(speeds, dtype=float)[case] if case.size else np.zeros(0)
    return {
        "event_count": counts,
        "event_case": case,
        "event_time": ev[:, EV_TIME].copy(),
        "event_cam_angle": np.degrees(ev[:, EV_TIME] * omega)
        - (0.0 if first_turn is None else 360.0 * np.asarray(first_turn)[case]),
        "event_kind": ev[:, EV_KIND].astype(np.int8),
        "event_from": ev[:, EV_FROM].astype(np.int8),
        "event_to": ev[:, EV_TO].astype(np.int8),
        "event_velocity": ev[:, EV_VELOCITY].copy(),
        "event_impulse": ev[:, EV_IMPULSE].copy(),
    }
