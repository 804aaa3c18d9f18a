"""How many workers and how large the batches: what ``campipe validate`` reports and
:func:`~campipe.study.run.execute.run_study` cuts the cases into, computed from the study alone
(nothing of the engine or the archive is imported here)."""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence

import numpy as np

from campipe.study.spec.resolve import ResolvedCase, distinct_but_speed

#: Default batches hold MIN_BATCH_SIZE … MAX_BATCH_SIZE cases: about four batches per worker,
#: so the workers finish together, but not so small that the archive's per-batch work or the
#: engine's per-call set-up outweighs computing it (1000 cases on two workers, with netCDF
#: batch files: 32-case batches took 1.3 s in the study layer, 125-case ones 0.85 s).
MIN_BATCH_SIZE = 4
MAX_BATCH_SIZE = 256


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


#: Memory a batch's histories may take in the engine [bytes]; a batch of long histories
#: (many samples per case) is cut smaller to stay within it.
BATCH_MEMORY = 512 * 2**20
#: The engine's bytes per case and stored sample (q and v of seven coordinates, forces,
#: lifts, state, and the archive arrays made from them), roughly.
BYTES_PER_SAMPLE = 320


def default_batch_size(n_cases: int, workers: int, samples: int = 0) -> int:
    """About four batches per worker, within MIN_BATCH_SIZE … MAX_BATCH_SIZE cases, and
    fewer (down to one) when ``samples`` per case would take more than BATCH_MEMORY."""
    size = int(np.clip(-(-n_cases // (4 * max(workers, 1))), MIN_BATCH_SIZE, MAX_BATCH_SIZE))
    if samples:
        size = min(size, max(1, BATCH_MEMORY // (samples * BYTES_PER_SAMPLE)))
    return size


def count_batches(cases: Sequence[ResolvedCase], batch_size: int) -> int:
    """How many batches :func:`plan_batches` cuts ``cases`` into, without building them (a
    speed sweep's cases counted by its other axes' combinations)."""
    others, speeds = distinct_but_speed(cases)
    groups = Counter(c.settings for c in others)
    return sum(-(-n * speeds // batch_size) for n in groups.values())


#: Batches a worker has in flight at most (``campipe.study.run.workers``): one computing, one
#: queued; each future is dropped once its batch is stored.
IN_FLIGHT_PER_WORKER = 2


def in_flight_memory(
    n_cases: int, workers: int, samples: int, batch_size: int | None = None
) -> tuple[int, int, int]:
    """The memory the batches in flight take at most [bytes], the batches in flight and their
    size [cases]: IN_FLIGHT_PER_WORKER batches a worker (no more than there are), each of
    ``batch_size`` cases (default: :func:`default_batch_size`) at BYTES_PER_SAMPLE a case
    and sample. Whatever the study's size: the process's own memory (its imports, the
    kernels, the study's cases) comes beside it."""
    size = batch_size or default_batch_size(n_cases, workers, samples)
    batches = min(IN_FLIGHT_PER_WORKER * max(workers, 1), max(-(-n_cases // size), 1))
    return batches * size * max(samples, 1) * BYTES_PER_SAMPLE, batches, size
