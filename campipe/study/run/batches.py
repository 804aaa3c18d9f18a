"""Batches: how large, of which cases, and their files (``<archive>.parts/batch-<key>.npz``).

Cases are grouped by their :class:`~campipe.engine.RunSettings` and cut into batches of
``batch_size``; one task runs a batch through the engine (one compiled call,
:func:`~campipe.study.run.results.compute_batch`). Each finished batch is written to its file
atomically (:mod:`campipe.io.batch_file`: no HDF5, so storing it never waits for the archive);
its key hashes the case ids it holds, so a changed spec never picks up another spec's results.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campipe.errors import CampipeError
from campipe.io import batch_file
from campipe.io.archive import write_error
from campipe.study.archive.layout import (
    LAYOUT_VERSION,
    axis_arrays,
    axis_names,
    data_specs,
    record_text,
    variable_spec,
)
from campipe.study.run.keys import batch_key
from campipe.study.run.part_files import PartLayout, store_part
from campipe.study.run.results import BatchData, BatchPlan
from campipe.study.spec.coordinates import CASE_ID
from campipe.study.spec.resolve import ResolvedCase
from campipe.study.spec.variables import DOF_NAMES, VARIABLES

#: Called with each newly computed batch after it is stored (in the process that stores it:
#: a worker thread for local schedulers, this process for distributed). The replay logger,
#: :class:`campipe.replay.live.StudyReplay`, plugs in here (selecting with
#: :func:`campipe.study.query.tables.replay_mask`); ``campipe study`` leaves it out under the
#: processes scheduler, whose workers cannot log into this process's recording.
BatchHook = Callable[[BatchPlan, BatchData], None]

#: Local dask schedulers by name; anything else is a dask.distributed address
#: (``execute.check_scheduler``).
LOCAL_SCHEDULERS = ("threads", "synchronous", "processes")


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
    #: a part's checksum in a parts archive's index (campipe.io.parts.checksum_digest);
    #: "" for a batch file
    checksum: str = ""
    #: the batch's arrays, when it was stored in this process: the archive takes its rows
    #: from here instead of reading the file back (never sent between processes)
    data: BatchData | None = field(default=None, compare=False, repr=False)
    #: wall time of the engine call that computed it (:attr:`BatchData.engine_seconds`) [s]
    engine_seconds: float = field(default=0.0, compare=False)
    #: each case's highest valve lift at its samples [m] (the coil-bind note), where this run
    #: computed it and the batch records the valve's lift; () else
    highest: tuple[float, ...] = field(default=(), compare=False)

    def __getstate__(self) -> dict:
        return {**self.__dict__, "data": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    @property
    def n_cases(self) -> int:
        return len(self.case_ids)


@dataclass(frozen=True)
class Storage:
    """Where finished batches go: batch files in ``directory`` (scratch, the single-file
    archive is assembled from them), or, with a part ``layout``, the parts of the parts
    archive ``directory`` (:mod:`campipe.study.run.part_files`). Sent with every task."""

    directory: Path  # <archive>.parts, or the parts archive itself
    record: tuple[str, ...]  # run.record of the study
    layout: PartLayout | None = None  # the parts' layout; None: batch files

    @property
    def parts(self) -> bool:
        return self.layout is not None

    def store(self, data: BatchData, plan: BatchPlan) -> tuple[Path, str]:
        """Write a batch's file atomically: its path, and its checksum for the index ("" for
        a batch file)."""
        if self.layout is None:
            return store_batch(data, self.directory, self.record), ""
        return store_part(data, plan, self.directory, self.layout)


def parts_directory(archive: Path) -> Path:
    """Where the batch files of an archive live: ``<archive>.parts`` beside it."""
    return archive.with_name(archive.name + ".parts")


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


def highest_lift(lift: np.ndarray) -> np.ndarray:
    """(n,) each case's highest valve lift [m] over its samples (``lift`` (n, samples); a
    failed case's NaN: −inf)."""
    lift = np.asarray(lift, float)
    return np.where(np.isnan(lift), -np.inf, lift).max(axis=1)


def highest_lifts(data: BatchData) -> tuple[float, ...]:
    """:func:`highest_lift` of a computed batch, or () where it records no valve lift: what
    the coil-bind note compares with each spring's travel to solid (:func:`gone_solid`)."""
    lift = data.arrays.get("valve_lift")
    return () if lift is None else tuple(highest_lift(lift).tolist())


def gone_solid(
    rows: np.ndarray, highest: np.ndarray, travel: np.ndarray
) -> dict[int, tuple[float, float]]:
    """Study index → (highest valve lift, travel to solid) [m] of the cases at study indices
    ``rows`` whose ``highest`` lift passes their spring's ``travel`` to solid (each case's, in
    study order): the coils clash, and the model has no stop there (``execute.solid_note``)."""
    rows, highest = np.asarray(rows, np.int64), np.asarray(highest, float)
    past = highest > travel[rows]
    pairs = zip(rows[past].tolist(), highest[past].tolist(), strict=True)
    return {r: (h, float(travel[r])) for r, h in pairs}


def ids_and_travels(study) -> tuple[list[str], np.ndarray]:
    """Each case's id and its valve spring's travel to solid [m] (:func:`gone_solid`), in
    study order, in one pass over the study's cases (a large speed sweep builds them on each
    pass)."""
    ids, travel = [], []
    for c in study.cases:
        ids.append(c.case_id)
        travel.append(c.case.train.spring_travel_to_solid)
    return ids, np.array(travel)
