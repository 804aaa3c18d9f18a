"""Running a study: batches on dask, each stored as it finishes, then one archive.

- Cases are grouped by their :class:`~campipe.engine.RunSettings` and cut into batches of
  ``batch_size``; one dask task runs a batch through the engine (one compiled call).
- Each finished batch is written to ``<archive>.parts/batch-<key>.nc`` atomically; the key
  hashes the case ids it holds, so a changed spec never picks up another spec's results.
- A rerun reads which case ids the batch files (and an existing archive) hold, and computes
  only the cases none of them has: an interrupted study resumes where it stopped.
- The archive is assembled by streaming the batch files' rows into one new file at a
  temporary path, renamed into place when complete; memory stays bounded by a batch.
- A run holds ``<archive>.lock`` throughout (``campipe.io.archive.writing``): a second run on
  the same archive stops with a clear error instead of removing the first one's files; the
  lock of a run that died on this host is taken over.

Schedulers: ``threads`` (dask's local threaded scheduler, one thread per core: the engine
releases the GIL), ``synchronous``, ``processes``, or the address of a dask.distributed
scheduler (``tcp://host:8786``; distributed is imported only then). With distributed, the
workers compute and this process stores, so workers need no access to the study's folder.
"""

from __future__ import annotations

import functools
import itertools
import logging
import os
import shutil
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from campipe.io.archive import (
    ArchiveFileError,
    NetCDFWriter,
    is_temporary,
    provenance,
    read_index,
    read_rows,
    read_variable,
    runs,
    write_file,
    writing,
)
from campipe.study.expand import ResolvedCase, Study
from campipe.study.layout import (
    LAYOUT_VERSION,
    archive_layout,
    batch_key,
    batch_layout,
    record_text,
    study_attrs,
    study_key,
)
from campipe.study.progress import Progress
from campipe.study.results import BatchData, BatchPlan, compute_batch, n_revolutions

log = logging.getLogger(__name__)

#: Local dask schedulers by name; anything with "://" is a dask.distributed address.
LOCAL_SCHEDULERS = ("threads", "synchronous", "processes")
#: Default batches hold MIN_BATCH_SIZE … MAX_BATCH_SIZE cases: several batches per worker,
#: but not so small that storing a batch costs more than computing it.
MIN_BATCH_SIZE = 4
MAX_BATCH_SIZE = 32
#: Rows read at a time when copying reused cases out of an existing archive.
COPY_ROWS = 64

#: Called with each newly computed batch after it is stored (in the process that stores it:
#: a worker thread for local schedulers, this process for distributed). The replay logger,
#: :class:`campipe.replay.live.StudyReplay`, plugs in here (selecting with
#: :func:`campipe.study.query.replay_mask`); ``campipe study`` leaves it out under the
#: processes scheduler, whose workers cannot log into this process's recording.
BatchHook = Callable[[BatchPlan, BatchData], None]


@dataclass(frozen=True)
class StudyReport:
    """What a run of a study did."""

    archive: Path  # the archive written (or found up to date)
    cases: int  # cases in the study
    reused: int  # cases taken from earlier runs' batch files or archive
    computed: int  # cases computed by this run
    batches: int  # batches computed by this run
    up_to_date: bool  # the archive already held this study: nothing was done
    seconds: float  # wall time [s]

    def summary(self) -> str:
        if self.up_to_date:
            return f"{self.archive}: up to date ({self.cases} cases); nothing to do"
        return (
            f"{self.archive}: {self.cases} cases ({self.reused} reused, {self.computed} "
            f"computed in {self.batches} batches) in {self.seconds:.1f} s"
        )


@dataclass(frozen=True)
class _Stored:
    key: str  # batch key
    n_cases: int  # cases in the batch


def parts_directory(archive: Path) -> Path:
    """Where the batch files of an archive live: ``<archive>.parts`` beside it."""
    return archive.with_name(archive.name + ".parts")


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def default_batch_size(n_cases: int, workers: int) -> int:
    """About four batches per worker, within MIN_BATCH_SIZE … MAX_BATCH_SIZE cases."""
    return int(np.clip(-(-n_cases // (4 * max(workers, 1))), MIN_BATCH_SIZE, MAX_BATCH_SIZE))


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


def store_batch(data: BatchData, directory: Path, record: tuple[str, ...]) -> Path:
    """Write a batch file atomically; returns its path."""
    sizes, specs, arrays, attrs = batch_layout(data, record)
    directory.mkdir(parents=True, exist_ok=True)
    # Uncompressed: a batch file lives only until the archive is assembled (compressing it
    # would cost as much again as the archive's own compression).
    return write_file(directory / f"batch-{data.key}.nc", sizes, specs, arrays, attrs, complevel=0)


def _usable(attrs: dict, record: tuple[str, ...]) -> bool:
    return attrs.get("campipe_layout") == LAYOUT_VERSION and attrs.get(
        "campipe_record"
    ) == record_text(record)


def find_results(study: Study, archive: Path) -> dict[str, tuple[Path, int, int]]:
    """Case id → (file, row, events) for every case of the study some file already holds:
    batch files first, then an existing archive of the same layout and record."""
    wanted = {c.case_id for c in study.cases}
    found: dict[str, tuple[Path, int, int]] = {}
    parts = parts_directory(archive)
    files = sorted(parts.glob("batch-*.nc")) if parts.is_dir() else []
    if archive.exists():
        files.append(archive)
    for path in files:
        try:
            ids, counts, attrs = read_index(path)
        except ArchiveFileError as exc:
            log.warning("ignoring %s: %s", path, exc)
            continue
        if not _usable(attrs, study.record):
            log.info("ignoring %s: another layout or record", path)
            continue
        for row, (cid, n_ev) in enumerate(zip(ids, counts, strict=True)):
            if cid in wanted and cid not in found:
                found[cid] = (path, row, int(n_ev))
    return found


def _clean_temporaries(archive: Path) -> None:
    """Remove temporary files a killed run left (this study's only)."""
    parts = parts_directory(archive)
    leftovers = list(parts.glob(".*.tmp")) if parts.is_dir() else []
    leftovers += [p for p in archive.parent.glob(f".{archive.name}.*.tmp") if is_temporary(p)]
    for p in leftovers:
        log.info("removing %s, left by an interrupted run", p)
        p.unlink(missing_ok=True)


def run_study(
    study: Study,
    archive: str | Path,
    *,
    scheduler: str = "threads",
    workers: int | None = None,
    batch_size: int | None = None,
    progress: Callable[[int, int], Progress] | None = None,
    keep_parts: bool = False,
    command: str = "campipe study",
    on_batch: BatchHook | None = None,
) -> StudyReport:
    """Run a study into one archive, resuming from whatever earlier runs left.

    Parameters
    ----------
    study : Study
        The expanded study (:func:`campipe.study.load_study`).
    archive : str or Path
        The archive to write.
    scheduler : str
        ``threads``, ``synchronous``, ``processes`` or a dask.distributed scheduler address
        such as ``tcp://127.0.0.1:8786``.
    workers : int, optional
        Threads or processes of a local scheduler (default: the cores available).
    batch_size : int, optional
        Cases per batch (default: about four batches per worker, at most 32 cases).
    progress : callable, optional
        ``progress(total, done) -> Progress``: makes the progress line.
    keep_parts : bool
        Keep the batch files after the archive is written (default: remove them).
    command : str
        The command line, recorded in the archive's ``history``.
    on_batch : callable, optional
        The replay hook, see :data:`BatchHook`.

    Raises
    ------
    campipe.engine.IntegrationError
        If a case fails; batches finished before it stay stored for the rerun.
    campipe.io.archive.ArchiveBusyError
        If another run is writing the same archive (its lock, ``<archive>.lock``, is held).
    """
    started = time.monotonic()
    archive = Path(archive)
    archive.parent.mkdir(parents=True, exist_ok=True)
    with writing(archive):
        _clean_temporaries(archive)
        total = len(study.cases)
        if archive.exists():
            try:
                _, _, attrs = read_index(archive)
                if attrs.get("study_key") == study_key(study):
                    log.info("%s already holds this study", archive)
                    return StudyReport(
                        archive, total, total, 0, 0, True, time.monotonic() - started
                    )
            except ArchiveFileError as exc:
                log.warning("existing %s unreadable (%s): it will be replaced", archive, exc)
        found = find_results(study, archive)
        missing = [c for c in study.cases if c.case_id not in found]
        local = "://" not in scheduler
        if local and scheduler not in LOCAL_SCHEDULERS:
            raise ValueError(
                f"--scheduler: found {scheduler!r}, expected one of "
                f"{', '.join(LOCAL_SCHEDULERS)} or an address such as "
                "tcp://127.0.0.1:8786"
            )
        workers = workers or (1 if scheduler == "synchronous" else default_workers())
        size = batch_size or default_batch_size(len(missing), workers)
        plans = plan_batches(missing, study.record, size)
        log.info(
            "%s: %d cases, %d reused from earlier runs; computing %d in %d batches of up "
            "to %d on %s",
            study.name,
            total,
            total - len(missing),
            len(missing),
            len(plans),
            size,
            scheduler,
        )
        bar = progress(total, total - len(missing)) if progress else None
        parts = parts_directory(archive)
        store = functools.partial(_store, parts, study.record, on_batch)

        def stored(s: _Stored) -> None:
            log.debug("batch %s stored (%d cases)", s.key, s.n_cases)
            if bar:
                bar.advance(s.n_cases)

        if plans:
            if local:
                _run_local(plans, scheduler, workers, store, stored)
            else:
                _run_distributed(plans, scheduler, store, stored)
        found = find_results(study, archive)
        assemble(study, archive, found, command)
        if not keep_parts and parts.is_dir():
            shutil.rmtree(parts)
        return StudyReport(
            archive,
            total,
            total - len(missing),
            len(missing),
            len(plans),
            False,
            time.monotonic() - started,
        )


def _store(
    parts: Path,
    record: tuple[str, ...],
    on_batch: BatchHook | None,
    data: BatchData,
    plan: BatchPlan,
) -> _Stored:
    store_batch(data, parts, record)
    if on_batch is not None:
        on_batch(plan, data)
    return _Stored(data.key, data.n_cases)


def _run_local(plans: list[BatchPlan], scheduler: str, workers: int, store, stored) -> None:
    import dask
    from dask.callbacks import Callback

    class _Done(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            if isinstance(result, _Stored):
                stored(result)

    tasks = []
    for p in plans:
        plan = dask.delayed(p, traverse=False)
        data = dask.delayed(compute_batch, pure=False)(plan, dask_key_name=f"compute-{p.key}")
        tasks.append(dask.delayed(store, pure=False)(data, plan, dask_key_name=f"store-{p.key}"))
    with _Done():
        dask.compute(*tasks, scheduler=scheduler, num_workers=workers)


def _run_distributed(plans: list[BatchPlan], address: str, store, stored) -> None:
    from distributed import Client, as_completed

    token = uuid.uuid4().hex[:8]
    with Client(address, set_as_default=False, timeout="30s") as client:
        threads = max(sum(client.nthreads().values()), 1)
        pending = iter(plans)
        by_key = {}

        def submit(p: BatchPlan):
            by_key[p.key] = p
            return client.submit(compute_batch, p, key=f"campipe-{p.key}-{token}", pure=False)

        # Keep at most two batches per worker thread in flight: memory stays bounded.
        queue = as_completed(
            [submit(p) for p in itertools.islice(pending, 2 * threads)], loop=client.loop
        )
        for future in queue:
            data = future.result()
            future.release()
            stored(store(data, by_key.pop(data.key)))
            nxt = next(pending, None)
            if nxt is not None:
                queue.add(submit(nxt))


def assemble(
    study: Study, archive: Path, found: dict[str, tuple[Path, int, int]], command: str
) -> Path:
    """Stream every case's rows from the files that hold them into a new archive."""
    missing = [c.case_id for c in study.cases if c.case_id not in found]
    if missing:
        raise RuntimeError(f"cases {missing[:5]} have no results; this is a defect")
    counts = np.array([found[c.case_id][2] for c in study.cases], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    first = found[study.cases[0].case_id][0]
    cam_angle = read_variable(first, "cam_angle")
    sizes, specs, static = archive_layout(
        study, int(offsets[-1]), cam_angle, n_revolutions(study.revolutions)
    )
    attrs = {**study_attrs(study), **provenance(command)}
    case_names = [s.name for s in specs if s.dims[:1] == ("case",) and s.name not in static]
    event_names = [s.name for s in specs if s.dims == ("event",) and s.name != "event_case"]
    by_file: dict[Path, list[tuple[int, int]]] = {}
    for pos, c in enumerate(study.cases):
        path, row, _ = found[c.case_id]
        by_file.setdefault(path, []).append((row, pos))
    with NetCDFWriter(archive, sizes, specs, attrs) as w:
        for name, values in static.items():
            w.write(name, values)
        for path, pairs in by_file.items():
            pairs.sort()
            for i in range(0, len(pairs), COPY_ROWS):
                chunk = pairs[i : i + COPY_ROWS]
                rows = np.array([r for r, _ in chunk])
                positions = np.array([p for _, p in chunk])
                data = read_rows(path, rows, case_names, event_names)
                for name in case_names:
                    w.write_rows(name, positions, data[name])
                _copy_events(w, data, positions, offsets, event_names)
        w.commit()
    log.info("wrote %s (%d cases, %d events)", archive, len(study.cases), offsets[-1])
    return archive


def _copy_events(
    w: NetCDFWriter, data: dict, positions: np.ndarray, offsets: np.ndarray, names: list[str]
) -> None:
    """Events of the rows read, case by case, to their place in the archive."""
    starts = np.concatenate([[0], np.cumsum(data["event_count"])])
    for a, b in runs(positions):
        lo, hi = int(starts[a]), int(starts[b])
        if hi == lo:
            continue
        target = slice(int(offsets[positions[a]]), int(offsets[positions[a]]) + hi - lo)
        for name in names:
            w.write(name, data[name][lo:hi], target)
        w.write(
            "event_case",
            np.repeat(positions[a:b], data["event_count"][a:b]).astype(np.int32),
            target,
        )
