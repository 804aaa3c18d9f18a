"""Estimates for ``campipe validate``: run time and archive size.

Run time is measured, not guessed: the first case of each group of run settings is
integrated for a short while and timed, giving the engine's speed on this machine for that
integrator (simulated seconds per wall-clock second); each case's simulated time divided by
its group's speed, summed and shared among the workers, is the estimate. Events and impacts
make some cases slower than the sample, so it is a rough figure.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import RunSettings, run_batch
from campipe.study.expand import ResolvedCase, Study
from campipe.study.results import n_revolutions
from campipe.study.variables import DOF_NAMES, data_variables

#: Cam turns of the timed sample run (at most the study's own).
SAMPLE_REVOLUTIONS = 0.5


@dataclass(frozen=True)
class Estimate:
    """What ``campipe validate`` prints about cost."""

    simulated: float  # simulated time of all cases together [s]
    seconds: float  # estimated wall time on `workers` workers [s]
    workers: int  # workers assumed
    archive_bytes: int  # archive size before compression [bytes]


def simulated_seconds(study: Study) -> np.ndarray:
    """(n_cases,) simulated time of each case [s]."""
    return np.array([c.settings.revolutions * TWO_PI / c.case.speed for c in study.cases])


def measure_speeds(study: Study) -> dict[RunSettings, float]:
    """Simulated seconds per wall-clock second of one worker, per run-settings group, timed
    on the group's first case."""
    firsts: dict[RunSettings, ResolvedCase] = {}
    for c in study.cases:
        firsts.setdefault(c.settings, c)
    speeds = {}
    for settings, c in firsts.items():
        # a warm-up run loads the compiled kernel, then the timed run
        run_batch(
            [c.case],
            replace(settings, revolutions=min(settings.revolutions, 0.01)),
            on_failure="record",
        )
        sample = replace(settings, revolutions=min(settings.revolutions, SAMPLE_REVOLUTIONS))
        t = time.perf_counter()
        run_batch([c.case], sample, on_failure="record")
        elapsed = max(time.perf_counter() - t, 1e-6)
        speeds[settings] = sample.revolutions * TWO_PI / c.case.speed / elapsed
    return speeds


def archive_bytes(study: Study) -> int:
    """Size of the archive's variables before compression [bytes] (events not counted)."""
    n_out = int(math.floor(study.revolutions * 360 / math.degrees(study.output_every) + 1e-9)) + 1
    n_rev = n_revolutions(study.revolutions)
    sizes = {"cam_angle": n_out, "revolution": n_rev, "dof": len(DOF_NAMES), "event": 0}
    per_case = 0
    for var in data_variables(study.record).values():
        if "case" not in var.dims:
            continue
        n = 1
        for d in var.dims[1:]:
            n *= sizes[d]
        per_case += n * np.dtype(var.dtype).itemsize
    per_case += 16 + 8 * 8 + 64  # case id, numeric coordinates, labels (about)
    return len(study.cases) * per_case + n_out * 8


def estimate(
    study: Study, workers: int, speeds: dict[RunSettings, float] | None = None
) -> Estimate:
    """Estimate a study's cost; ``speeds`` (see :func:`measure_speeds`) skips the timing."""
    speeds = speeds or measure_speeds(study)
    simulated = simulated_seconds(study)
    wall = sum(t / speeds[c.settings] for t, c in zip(simulated, study.cases, strict=True))
    seconds = wall / max(min(workers, len(study.cases)), 1)
    return Estimate(float(simulated.sum()), seconds, workers, archive_bytes(study))
