"""How cost grows: time against number of cases and workers, throughput, archive size.

- :func:`engine_scaling`: batches of the engine alone on dask's threaded scheduler (the
  kernels release the GIL), 1 and 2 workers.
- :func:`study_scaling`: the same cases as a study through the study layer's executor
  (:func:`campipe.study.run.execute.run_study`), archive included; the archive's size per case.
- :func:`throughput`: case-steps per second of newmark-linear on a 256-case batch.

These functions time runs; :func:`study_scaling` writes its spec and archives under the
directory it is given (and nowhere else).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from campipe.bench.suite import OUTPUT_EVERY, rpm
from campipe.constants import INCH
from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.study import load_study
from campipe.study.run.execute import run_study

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

    layer: str  # "engine" (dask threads, no storage) or "study" (run_study, archive written)
    n_cases: int  # cases
    workers: int  # dask workers (threads)
    seconds: float  # wall time [s]
    archive_bytes: int  # archive file size (study only; 0 for engine) [bytes]

    @property
    def per_case(self) -> float:
        """Wall time per case [s]."""
        return self.seconds / self.n_cases


def _run_threads(
    cases: list[Case], settings: RunSettings, workers: int, batch_size: int = BATCH_SIZE
) -> list:
    import dask

    tasks = [
        dask.delayed(run_batch, pure=False)(cases[i : i + batch_size], settings)
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
    the threaded scheduler; best of ``repeats`` (one repeat above 1000 cases)."""
    settings = settings or RunSettings(revolutions=SCALING_REVOLUTIONS, output_every=OUTPUT_EVERY)
    _run_threads(scaling_cases(4), settings, 2)  # kernels and caches loaded
    out = []
    for n in counts:
        cases = scaling_cases(n)
        for w in workers:
            best = math.inf
            for _ in range(repeats if n <= 1000 else 1):
                t0 = time.perf_counter()
                _run_threads(cases, settings, w)
                best = min(best, time.perf_counter() - t0)
            out.append(ScalingPoint("engine", n, w, best, 0))
    return out


def scaling_spec(n: int) -> dict:
    """A study spec of ``n`` cases like :func:`scaling_cases` (the speeds of a sweep)."""
    spec = {
        "name": f"bench-scaling-{n}",
        "description": "campipe bench: time against number of cases",
        "model": {"preset": "thesis-1971"},
        "profile": {"kind": "harmonic", "lift": "1 in"},
        "closure": "force",
        "seat": "none",
        "speed": "9000 rpm",
        "run": {"revolutions": SCALING_REVOLUTIONS, "output_every": "1 deg"},
    }
    if n > 1:
        half = n // 2
        spec["sweep"] = (
            {
                "speed": {
                    "from": f"{SPEED_RANGE[0]:g} rpm",
                    "to": f"{SPEED_RANGE[1]:g} rpm",
                    "num": max(half, 1),
                },
                "seat": ["none", "0.1 in"],
            }
            if n % 2 == 0
            else {
                "speed": {
                    "from": f"{SPEED_RANGE[0]:g} rpm",
                    "to": f"{SPEED_RANGE[1]:g} rpm",
                    "num": n,
                }
            }
        )
    return spec


def study_scaling(
    counts: Sequence[int], directory: str | Path, workers: Sequence[int] = (1, 2)
) -> list[ScalingPoint]:
    """Wall time of ``campipe study`` on n cases (spec check, batches, archive) and the
    archive's size; spec and archives are written under ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    out = []
    for n in counts:
        path = directory / f"bench-scaling-{n}.yaml"
        path.write_text(yaml.safe_dump(scaling_spec(n), sort_keys=False))
        for w in workers:
            archive = directory / f"bench-scaling-{n}-w{w}.nc"
            archive.unlink(missing_ok=True)
            t0 = time.perf_counter()
            study = load_study(path)
            run_study(study, archive, scheduler="threads", workers=w)
            seconds = time.perf_counter() - t0
            out.append(ScalingPoint("study", len(study.cases), w, seconds, archive.stat().st_size))
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
