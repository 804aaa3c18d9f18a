"""Estimates for ``campipe validate``: the run time of ``campipe study`` (the archive's size is
:func:`campipe.study.spec.expand.archive_bytes`).

The run time is measured on this machine, through the code a study runs, not guessed:

- **a sample of the study** -- one batch for each worker (at the batch size the study will
  use), its cases spread evenly through the study so its speeds, seats and events are in
  proportion -- is run through :func:`~campipe.study.run.execute.run_study` into a temporary
  folder: computing, storing the batches, assembling the compressed archive with its
  checksums. Scaled to the study's cases, it gives the run's time beyond its fixed cost;
  its share the engine took is what its batches' engine calls took (each batch times its
  own, :attr:`~campipe.study.run.resume.StudyReport.engine_seconds`), shared among the
  workers they keep busy: no case runs twice to split the time;
- **the fixed cost** (setting up a run, a first run's imports) is a one-case run's time;
- **start-up**: loading each run-settings group's compiled kernel, which the first run in
  a process pays (:func:`measure_speeds`'s warm-up; a compilation is not counted, the study
  finds the kernel in numba's cache).

A study of at most twice the sample is run whole: its estimate is that run. A long study
(a fixed run of at least twice :func:`timed_turns`' longer run) whose cases take more than
:data:`WHOLE_SECONDS` is timed on its timed runs' cases run for two numbers of turns, the
time beyond extrapolated linearly in the turns (:func:`time_turns`): a case's later turns
cost about what the measured ones beyond the first do. Cases differ
(events, impacts), so it is a rough figure: within a factor of two of the run on the bundled
studies (the developer benchmark, ``benchmarks/study.py``, lists both). Not included: the
process's own start (imports, about a second) and a spec's ``replay:`` recording.
"""

from __future__ import annotations

import functools
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.settings import RunSettings, sample_count
from campipe.study.run.batches import plan_batches
from campipe.study.run.execute import run_study
from campipe.study.run.sizing import default_batch_size
from campipe.study.spec.expand import Study, archive_bytes
from campipe.study.spec.resolve import ResolvedCase, SpeedSweep, distinct_but_speed

#: Longest kernel warm-up counted as start-up [s]: a kernel loads from numba's cache in well
#: under a second; a longer warm-up is compiling, which the study (using the cache) skips.
MAX_LOAD_SECONDS = 1.0


@dataclass(frozen=True)
class Estimate:
    """What ``campipe validate`` prints about cost."""

    simulated: float  # simulated time of all cases together [s]
    seconds: float  # estimated wall time of the run on `workers` workers [s]
    workers: int  # workers assumed
    archive_bytes: int  # archive size before compression [bytes]
    engine: float = 0.0  # of `seconds`: the engine, shared among the workers [s]
    layer: float = 0.0  # of `seconds`: setting up, storing batches, writing the archive [s]
    startup: float = 0.0  # of `seconds`: loading the kernels, once per process [s]
    sample: int = 0  # cases of the timed sample run (all of them: the study ran whole)
    replay: float = 0.0  # of `seconds`: logging the spec's replay selection (campipe
    #                      validate adds it: campipe.replay.live.time_replay) [s]
    turns: tuple[int, int] | None = None  # a long study's cases timed for these turns and
    #                                       extrapolated (time_turns), None: for its own


def simulated_seconds(study: Study) -> float:
    """Simulated time of all the study's cases [s]; a speed sweep's summed over its other
    axes' combinations (their turns) times its speeds (Σ 1/ω), no case built."""
    if isinstance(study.cases, SpeedSweep):
        per_turn = sum(TWO_PI / speed for speed in study.cases.speeds)
        return sum(expected_turns(c.settings) for c in study.cases.others()) * per_turn
    return sum(expected_turns(c.settings) * TWO_PI / c.case.speed for c in study.cases)


def expected_turns(settings: RunSettings) -> float:
    """The turns a case runs: its fixed ``revolutions``, or for a run of automatic length
    a quarter of its cap (a case that follows the cam settles in one turn, one that never
    repeats runs the cap: a guess, which the timed sample run corrects)."""
    if settings.revolutions is None:
        return settings.max_revolutions / 4.0
    return settings.revolutions


def first_cases(study: Study) -> dict[RunSettings, ResolvedCase]:
    """Each run-settings group's first case (a speed sweep's: its first combination of the
    other axes, at the first speed)."""
    firsts: dict[RunSettings, ResolvedCase] = {}
    for c in distinct_but_speed(study.cases)[0]:
        firsts.setdefault(c.settings, c)
    return firsts


@functools.cache
def engine_import_seconds() -> float:
    """Import the engine's compiled side (numba, the kernels' modules), once a process: the
    seconds it took, 0 where this process had imported it before. A study's process makes
    this import before it loads a kernel (a few tenths of a second): validate imports the
    engine through here, so that its start-up (:func:`warm_up`) counts it."""
    before = "campipe.engine.batch" in sys.modules
    t = time.perf_counter()
    import campipe.engine.kernels  # noqa: F401  (numba: not for validate --no-estimate)

    return 0.0 if before else time.perf_counter() - t


def warm_up(study: Study) -> float:
    """Import the engine (:func:`engine_import_seconds`) and load each run-settings group's
    kernel with a tiny run of its first case (:func:`first_cases`); the time it took [s],
    each group's run at most :data:`MAX_LOAD_SECONDS`."""
    total = engine_import_seconds()
    from campipe.engine import run_batch

    for settings, c in first_cases(study).items():
        t = time.perf_counter()
        run_batch(
            [c.case],
            # (a turn's hundredth, nothing left out of it: the kernels load, no metric is read)
            replace(settings, revolutions=min(settings.revolutions or 1.0, 0.01), warmup=0),
            on_failure="record",
        )
        total += min(time.perf_counter() - t, MAX_LOAD_SECONDS)
    return total


def batch_size(study: Study, n: int, workers: int) -> int:
    """The default batch size of a run of ``n`` of the study's cases."""
    return default_batch_size(n, workers, sample_count(study.revolutions, study.output_every))


def busy_workers(study: Study, cases: Sequence[ResolvedCase], workers: int) -> int:
    """Workers the batches of ``cases`` keep busy (no more than there are batches)."""
    size = batch_size(study, len(study.cases), workers)
    return max(min(workers, len(plan_batches(cases, study.record, size))), 1)


def time_run(
    study: Study, cases: Sequence[ResolvedCase], workers: int, size: int | None = None
) -> tuple[float, float]:
    """Time :func:`run_study` on ``cases`` of ``study`` into a temporary folder.

    Parameters
    ----------
    study : Study
        The expanded study.
    cases : sequence of ResolvedCase
        The cases to run (the study's, or a sample of them).
    workers : int
        Workers of the run.
    size : int, optional
        Cases per batch (default: the run's own for ``cases``).

    Returns
    -------
    tuple of float
        The run's wall time, and its batches' engine calls' wall time summed over the
        batches (:attr:`~campipe.study.run.resume.StudyReport.engine_seconds`) [s].
    """
    sample = replace(study, cases=list(cases))
    with tempfile.TemporaryDirectory(prefix="campipe-estimate-") as folder:
        t = time.perf_counter()
        report = run_study(
            sample, Path(folder) / f"{study.name}.nc", workers=workers, batch_size=size
        )
        return time.perf_counter() - t, report.engine_seconds


#: Turns between a long study's two timed runs (:func:`timed_turns`).
TURNS_APART = 2
#: A long study's cases run whole all the same when their run of the longer number of turns,
#: scaled to theirs, is at most this [s]: a cheap turn's time is within the timing's noise,
#: which extrapolating over tens of turns would multiply.
WHOLE_SECONDS = 5.0


def timed_turns(study: Study, cases: Sequence[ResolvedCase]) -> tuple[int, int] | None:
    """The turns (a, b) ``cases`` of a long study are timed for: one after their warm-up, and
    :data:`TURNS_APART` more; None when the study runs until settled or is shorter than 2·b
    turns (timed as it is)."""
    if study.settle:
        return None
    first = max(c.settings.warmup_turns for c in cases) + 1
    last = first + TURNS_APART
    return (first, last) if study.revolutions >= 2 * last else None


def _turns_of(study: Study, cases: Sequence[ResolvedCase], turns: float) -> Study:
    """``study`` of ``cases`` alone, each run for ``turns``."""
    short = [replace(c, settings=replace(c.settings, revolutions=float(turns))) for c in cases]
    return replace(study, cases=short, revolutions=float(turns))


def time_turns(
    study: Study, cases: Sequence[ResolvedCase], workers: int, size: int | None = None
) -> tuple[float, float, tuple[int, int] | None]:
    """:func:`time_run` of ``cases`` for the study's turns, and the turns (a, b) it was timed
    on, or None. A long study's (:func:`timed_turns`) from runs of a and of b turns, the time
    and engine time beyond b extrapolated at their difference per turn (none below 0), in the
    batches the study's turns make; run whole when the run of b turns, scaled to the study's,
    is at most :data:`WHOLE_SECONDS`, as any other study's."""
    turns = timed_turns(study, cases)
    if turns is None:
        return (*time_run(study, cases, workers, size), None)
    a, b = turns
    if size is None:  # the study's own batches (fewer turns would make them larger)
        size = batch_size(study, len(cases), workers)
    longer, shorter = _turns_of(study, cases, b), _turns_of(study, cases, a)
    long, engine_long = time_run(longer, longer.cases, workers, size)
    if long * study.revolutions / b <= WHOLE_SECONDS:
        return (*time_run(study, cases, workers, size), None)
    short, engine_short = time_run(shorter, shorter.cases, workers, size)
    more = (study.revolutions - b) / (b - a)
    return (
        long + max(long - short, 0.0) * more,
        engine_long + max(engine_long - engine_short, 0.0) * more,
        turns,
    )


def sample_cases(study: Study, k: int) -> list[ResolvedCase]:
    """``k`` cases spread evenly through the study (its speeds, seats, ... in proportion)."""
    picks = np.unique(np.round(np.linspace(0, len(study.cases) - 1, k)).astype(int))
    return [study.cases[i] for i in picks]


def sample_size(study: Study, workers: int) -> int:
    """Cases of the sample run: one batch for each worker, at the study's batch size."""
    n = len(study.cases)
    return max(min(batch_size(study, n, workers) * workers, n), 2)


def estimate(study: Study, workers: int) -> Estimate:
    """Estimate the wall time of ``campipe study`` on ``workers`` workers (see the module).

    Parameters
    ----------
    study : Study
        The expanded study.
    workers : int
        Workers of the run (threads of the local scheduler).

    Returns
    -------
    Estimate
        ``seconds`` the whole; ``engine``, ``layer`` and ``startup`` its parts; ``sample``
        the cases timed.
    """
    workers = max(int(workers), 1)
    startup = warm_up(study)
    simulated = simulated_seconds(study)
    size = archive_bytes(study)
    n = len(study.cases)
    k = sample_size(study, workers)
    if n <= 2 * k:
        timed = list(study.cases)
        seconds, engine, turns = time_turns(study, timed, workers)
        engine /= busy_workers(study, timed, workers)
    else:
        timed = sample_cases(study, k)
        batch = batch_size(study, n, workers)  # the study's own batches, not the sample's
        first, _, _ = time_turns(study, timed[:1], workers)  # pays a process's first run's cost
        again, _, _ = time_turns(study, timed[:1], workers)
        ran, engine, turns = time_turns(study, timed, workers, batch)
        scale = n / len(timed)
        seconds = first + max(ran - again, 0.0) * scale
        engine *= scale / busy_workers(study, timed, workers)
    engine = min(engine, seconds)
    return Estimate(
        simulated,
        seconds + startup,
        workers,
        size,
        engine,
        seconds - engine,
        startup,
        len(timed),
        turns=turns,
    )
