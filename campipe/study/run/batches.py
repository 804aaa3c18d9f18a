"""Batches: how large, of which cases, and their files (``<archive>.parts/batch-<key>.npz``).

Cases are grouped by their :class:`~campipe.engine.RunSettings` and cut into batches of
``batch_size``; one task runs a batch through the engine (one compiled call,
:func:`~campipe.study.run.results.compute_batch`). Each finished batch is written to its file
atomically (:mod:`campipe.io.batch_file`: no HDF5, so storing it never waits for the archive);
its key hashes the case ids it holds, so a changed spec never picks up another spec's results.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campipe.errors import CampipeError
from campipe.io import batch_file
from campipe.io.archive import write_error
from campipe.study.archive.layout import (
    CASE_ID,
    LAYOUT_VERSION,
    axis_arrays,
    axis_names,
    data_specs,
    record_text,
    variable_spec,
)
from campipe.study.run.keys import batch_key
from campipe.study.run.results import BatchData, BatchPlan
from campipe.study.spec.resolve import ResolvedCase, distinct_but_speed
from campipe.study.spec.variables import DOF_NAMES, VARIABLES

#: Default batches hold MIN_BATCH_SIZE … MAX_BATCH_SIZE cases: about four batches per worker,
#: so the workers finish together, but not so small that the archive's per-batch work or the
#: engine's per-call set-up outweighs computing it (1000 cases on two workers, with netCDF
#: batch files: 32-case batches took 1.3 s in the study layer, 125-case ones 0.85 s).
MIN_BATCH_SIZE = 4
MAX_BATCH_SIZE = 256

#: Called with each newly computed batch after it is stored (in the process that stores it:
#: a worker thread for local schedulers, this process for distributed). The replay logger,
#: :class:`campipe.replay.live.StudyReplay`, plugs in here (selecting with
#: :func:`campipe.study.query.tables.replay_mask`); ``campipe study`` leaves it out under the
#: processes scheduler, whose workers cannot log into this process's recording.
BatchHook = Callable[[BatchPlan, BatchData], None]


class OptionError(CampipeError, ValueError):
    """An option of a run that is refused (``key`` the option, such as ``--scheduler``)."""


class SchedulerError(CampipeError, RuntimeError):
    """The scheduler or a worker failed: unreachable, gone, killed, or running another
    campipe (``key`` ``--scheduler``, ``found`` the scheduler)."""


@dataclass(frozen=True)
class Stored:
    """A batch as stored in its file: where, its cases and what they hold."""

    key: str  # batch key
    path: Path  # the batch file
    case_ids: tuple[str, ...]  # its cases, in row order
    event_counts: tuple[int, ...]  # events of each
    statuses: tuple[int, ...]  # status of each (vocabulary.STATUS)
    numerics: str  # numerics_fingerprint() of the process that computed it
    #: the batch's arrays, when it was stored in this process: the archive takes its rows
    #: from here instead of reading the file back (never sent between processes)
    data: BatchData | None = field(default=None, compare=False, repr=False)

    def __getstate__(self) -> dict:
        return {**self.__dict__, "data": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    @property
    def n_cases(self) -> int:
        return len(self.case_ids)


def parts_directory(archive: Path) -> Path:
    """Where the batch files of an archive live: ``<archive>.parts`` beside it."""
    return archive.with_name(archive.name + ".parts")


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


def plan_batches(
    cases: Sequence[ResolvedCase], record: tuple[str, ...], batch_size: int
) -> list[BatchPlan]:
    """Group cases by run settings (study order kept inside a group), then cut into batches."""
    groups: dict[object, list[ResolvedCase]] = {}
    for c in cases:
        groups.setdefault(c.settings, []).append(c)
    plans = []
    for group in groups.values():
        for i in range(0, len(group), batch_size):
            chunk = tuple(group[i : i + batch_size])
            plans.append(BatchPlan(batch_key([c.case_id for c in chunk], record), chunk, record))
    return plans


def batch_layout(data: BatchData, record: tuple[str, ...]):
    """(sizes, variables, arrays, attributes) of a batch file."""
    sizes = {
        "case": data.n_cases,
        "cam_angle": data.cam_angle.size,
        "revolution": data.n_revolutions,
        "event": data.n_events,
    }
    if "q" in record:
        sizes["dof"] = len(DOF_NAMES)
    specs = [variable_spec(n, VARIABLES[n]) for n in axis_names(record)]
    specs.append(variable_spec(CASE_ID, VARIABLES[CASE_ID]))
    specs += data_specs(record, "")
    arrays = {
        **axis_arrays(data.cam_angle, data.n_revolutions),
        CASE_ID: data.case_ids,
        **data.arrays,
    }
    attrs = {
        "campipe_layout": LAYOUT_VERSION,
        "campipe_record": record_text(record),
        "campipe_numerics": data.numerics,
        "batch_key": data.key,
    }
    return sizes, specs, arrays, attrs


def store_batch(data: BatchData, directory: Path, record: tuple[str, ...]) -> Path:
    """Write a batch file atomically; returns its path."""
    _, specs, arrays, attrs = batch_layout(data, record)
    names = {v.name for v in specs}
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(directory, exc) from None
    # Uncompressed: a batch file lives only until the archive is assembled (compressing it
    # would cost as much again as the archive's own compression).
    path = directory / f"batch-{data.key}{batch_file.SUFFIX}"
    return batch_file.write(path, {k: a for k, a in arrays.items() if k in names}, attrs)
