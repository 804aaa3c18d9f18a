"""validate's estimate of a study and the study's run, each in a fresh process of its own
(:func:`estimate_and_run`), as a user meets them: ``campipe validate`` and then ``campipe
study``, each in a new process that loads the engine (numba and the compiled kernels) once.

This module imports no more of campipe than a spec's reading needs, so that a process
started on it pays the engine's loading inside the figure it times, as ``campipe validate``'s
estimate counts it (its part "loading the engine"). Python's own start and the spec's
reading are left out of both figures (validate says it leaves out the process's start).
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


def _estimate(spec: str, workers: int) -> tuple[int, float]:
    from campipe.study import load_study
    from campipe.study.run.estimate import estimate

    study = load_study(Path(spec))
    return len(study.cases), estimate(study, workers).seconds


def _run(spec: str, archive: str, workers: int) -> float:
    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    study = load_study(Path(spec))
    Path(archive).unlink(missing_ok=True)
    t0 = time.perf_counter()
    run_study(study, Path(archive), scheduler="threads", workers=workers)
    return time.perf_counter() - t0


def _fresh(fn, *args):
    """``fn(*args)`` in a new process (spawned: nothing of this one's engine inherited)."""
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=spawn) as pool:
        return pool.submit(fn, *args).result()


def estimate_and_run(spec: Path, archive: Path, workers: int) -> dict:
    """``spec``'s estimate (``campipe.study.run.estimate.estimate``, on ``workers``) and its
    run into ``archive`` (``run_study`` on as many threads), each timed in a fresh process
    from after the spec's reading, so each includes loading the engine."""
    cases, estimate = _fresh(_estimate, str(spec), workers)
    measured = _fresh(_run, str(spec), str(archive), workers)
    return {"study": spec.name, "cases": cases, "estimate": estimate, "measured": measured}
