"""How the engine's cost grows: time against number of cases and workers, throughput.

- :func:`engine_scaling`: batches of the engine alone on dask's threaded scheduler (the
  kernels release the GIL), 1 and 2 workers.
- :func:`throughput`: case-steps per second of newmark-linear on a 256-case batch.

These functions time runs and write nothing. The same cases through the study layer, archive
included, are the developer's benchmark's (``benchmarks/scaling.py`` in the repository).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from campipe.bench.measure import BATCH_SECONDS, best_time
from campipe.bench.suite import OUTPUT_EVERY, rpm
from campipe.constants import INCH
from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic

#: The population the scaling runs sweep: the harmonic cam over this speed range [rpm],
#: alternately without a seat and with one at 0.1 in.
SPEED_RANGE = (6000.0, 14000.0)
SCALING_REVOLUTIONS = 2.0
#: Cases per dask task in the engine-only runs (the study layer sizes its own batches).
BATCH_SIZE = 32


def scaling_cases(n: int) -> list[Case]:
    """``n`` cases spread over ``SPEED_RANGE``, alternately without and with a seat."""
    train = thesis_train()
    cam = harmonic(INCH)
    speeds = np.linspace(*SPEED_RANGE, n) if n > 1 else np.array([9000.0])
    return [
        Case(train, cam, rpm(s), seat=math.nan if i % 2 == 0 else 0.1 * INCH)
        for i, s in enumerate(speeds)
    ]


@dataclass(frozen=True)
class ScalingPoint:
    """One timed run of n cases on w workers."""

    layer: str  # "engine" (dask threads, no storage); the developer's benchmark adds "study"
    n_cases: int  # cases
    workers: int  # dask workers (threads)
    seconds: float  # wall time [s]
    archive_bytes: int  # archive file size (a study's; 0 for the engine) [bytes]

    @property
    def per_case(self) -> float:
        """Wall time per case [s]."""
        return self.seconds / self.n_cases


def _run_threads(
    cases: list[Case], settings: RunSettings, workers: int, batch_size: int = BATCH_SIZE
) -> list:
    import dask

    # Each batch wrapped untraversed: a call's arguments are searched for dask objects, into
    # every Case (a dataclass) and its train and profile, which cost more than the engine
    # (1000 cases on one worker 0.69-0.80 s, 0.28 s run as they are).
    tasks = [
        dask.delayed(run_batch, pure=False)(
            dask.delayed(cases[i : i + batch_size], traverse=False), settings
        )
        for i in range(0, len(cases), batch_size)
    ]
    return list(dask.compute(*tasks, scheduler="threads", num_workers=workers))


def engine_scaling(
    counts: Sequence[int],
    workers: Sequence[int] = (1, 2),
    settings: RunSettings | None = None,
    repeats: int = 2,
) -> list[ScalingPoint]:
    """Wall time of the engine alone on n cases, batches of ``BATCH_SIZE`` as dask tasks on
    the threaded scheduler; best of ``repeats`` or more (``measure.best_time``: a 1-case
    point takes a millisecond, and a best of two moved by 2× between runs), one run above
    1000 cases."""
    settings = settings or RunSettings(revolutions=SCALING_REVOLUTIONS, output_every=OUTPUT_EVERY)
    _run_threads(scaling_cases(4), settings, 2)  # kernels and caches loaded
    out = []
    for n in counts:
        cases = scaling_cases(n)
        for w in workers:
            cheap = n <= 1000  # more runs than ``repeats`` where they are cheap; one above
            best = best_time(
                lambda: _run_threads(cases, settings, w),  # noqa: B023
                repeats if cheap else 1,
                BATCH_SECONDS if cheap else 0.0,
            )
            out.append(ScalingPoint("engine", n, w, best, 0))
    return out


@dataclass(frozen=True)
class Throughput:
    """Case-steps per second of one batch (the throughput benchmark)."""

    integrator: str  # integrator name
    n_cases: int  # cases in the batch
    workers: int  # threads sharing it
    revolutions: float  # cam turns per case
    case_steps: int  # steps summed over the cases (modal-exact: grid steps)
    seconds: float  # best wall time [s]

    @property
    def rate(self) -> float:
        """Case-steps per second."""
        return self.case_steps / self.seconds


def throughput(
    n_cases: int = 256,
    workers: int = 2,
    integrator: str = "newmark-linear",
    revolutions: float = 4.0,
    repeats: int = 3,
) -> Throughput:
    """Case-steps per second of a batch of ``n_cases``: the harmonic cam over 6000–20000 rpm,
    without a seat and with one at 0.1 in by turns, split over ``workers`` threads (worker k
    takes cases k, k + workers, …, so each gets the same mix of speeds), best of
    ``repeats``."""
    train = thesis_train()
    cam = harmonic(INCH)
    speeds = np.linspace(6000.0, 20000.0, n_cases)
    cases = [
        Case(train, cam, rpm(s), seat=math.nan if (i // 2) % 2 == 0 else 0.1 * INCH)
        for i, s in enumerate(speeds)
    ]
    settings = RunSettings(
        revolutions=revolutions, integrator=integrator, output_every=OUTPUT_EVERY
    )
    run_batch(cases[:2], replace(settings, revolutions=0.1))
    size = -(-n_cases // workers)
    interleaved = [c for k in range(workers) for c in cases[k::workers]]
    best = math.inf
    steps = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        results = _run_threads(interleaved, settings, workers, batch_size=size)
        best = min(best, time.perf_counter() - t0)
        steps = int(sum(r.steps.sum() for r in results))
    return Throughput(integrator, n_cases, workers, revolutions, steps, best)
