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

import errno
import functools
import itertools
import logging
import os
import shutil
import stat
import time
import uuid
from collections.abc import Callable, Sequence
from concurrent.futures import BrokenExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campipe.errors import CampipeError
from campipe.io.archive import (
    ArchiveFileError,
    ArchiveWriteError,
    NetCDFWriter,
    is_temporary,
    provenance,
    read_attrs,
    read_index,
    read_rows,
    read_variable,
    runs,
    verify,
    write_error,
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
from campipe.study.limits import samples_per_case
from campipe.study.progress import Progress
from campipe.study.results import (
    BatchData,
    BatchPlan,
    compute_batch,
    n_revolutions,
    numerics_fingerprint,
)
from campipe.vocabulary import EVENTS_TRUNCATED, FAILURES, OK, STATUS

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


class ArchiveExistsError(CampipeError, ValueError):
    """A file at the archive path that is not this study's archive: another study's, a file
    that is not an archive, the spec itself (``key`` the path, ``found`` what it is).
    ``campipe study --overwrite`` replaces it."""


class OptionError(CampipeError, ValueError):
    """An option of a run that is refused (``key`` the option, such as ``--scheduler``)."""


class SchedulerError(CampipeError, RuntimeError):
    """The scheduler or a worker failed: unreachable, gone, killed, or running another
    campipe (``key`` ``--scheduler``, ``found`` the scheduler)."""


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
    #: what the run found and did about it: files that failed their checksums or came from
    #: another campipe, a replaced archive
    notes: tuple[str, ...] = ()
    #: case id → status name of every case that did not finish cleanly (vocabulary.STATUS)
    statuses: dict[str, str] = field(default_factory=dict)

    def summary(self) -> str:
        if self.up_to_date:
            return (
                f"{self.archive}: up to date ({self.cases} cases, checksums verified); "
                "nothing to do"
            )
        return (
            f"{self.archive}: {self.cases} cases ({self.reused} reused, {self.computed} "
            f"computed in {self.batches} batches) in {self.seconds:.1f} s"
        )

    def failures(self) -> dict[str, str]:
        """Case id → status of the cases that failed (their results are NaN)."""
        failed = {STATUS[code] for code in FAILURES}
        return {cid: s for cid, s in self.statuses.items() if s in failed}

    def truncated(self) -> list[str]:
        """Case ids of the cases that kept only run.max_events events."""
        return [cid for cid, s in self.statuses.items() if s == STATUS[EVENTS_TRUNCATED]]


@dataclass(frozen=True)
class _Stored:
    key: str  # batch key
    path: Path  # the batch file
    case_ids: tuple[str, ...]  # its cases, in row order
    event_counts: tuple[int, ...]  # events of each
    statuses: tuple[int, ...]  # status of each (vocabulary.STATUS)

    @property
    def n_cases(self) -> int:
        return len(self.case_ids)


@dataclass(frozen=True)
class ArchiveState:
    """What sits at an archive path before a run."""

    exists: bool  # a file (or folder) is there
    ours: bool  # it is this study's archive (same name and spec file): a run may replace it
    what: str  # for a file that is not ours: what it is, in words
    up_to_date: bool  # it holds this study, by this engine, and its checksums verify
    problems: tuple[str, ...] = ()  # why its checksums failed, if they did
    attrs: dict | None = None  # its global attributes, where they could be read


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
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(directory, exc) from None
    # Uncompressed: a batch file lives only until the archive is assembled (compressing it
    # would cost as much again as the archive's own compression).
    return write_file(directory / f"batch-{data.key}.nc", sizes, specs, arrays, attrs, complevel=0)


#: Where the cases some file already holds are: case id → (file, row, events).
Found = dict[str, tuple[Path, int, int]]


def _mismatch(attrs: dict, record: tuple[str, ...]) -> str | None:
    """Why a file's results cannot serve this study, or None if they can."""
    if attrs.get("campipe_layout") != LAYOUT_VERSION:
        return f"another layout ({attrs.get('campipe_layout', 'none')})"
    if attrs.get("campipe_record") != record_text(record):
        return f"another run.record ({attrs.get('campipe_record')})"
    if attrs.get("campipe_numerics") != numerics_fingerprint():
        return f"computed by another campipe ({attrs.get('campipe_numerics')})"
    return None


def _index_of(path: Path, found: Found, wanted: set[str]) -> None:
    ids, counts, _ = read_index(path)
    for row, (cid, n_ev) in enumerate(zip(ids, counts, strict=True)):
        if cid in wanted and cid not in found:
            found[cid] = (path, row, int(n_ev))


def find_results(
    study: Study, archive: Path, archive_usable: bool = True
) -> tuple[Found, list[str]]:
    """Where the study's cases already are, and notes on files set aside.

    Batch files first, then the archive (when ``archive_usable``: it passed its checks). A
    file is used only if it has this layout, record and engine (:func:`_mismatch`) and its
    checksums verify; a batch file that fails them is removed (its cases are computed again)
    and named in the notes.
    """
    wanted = {c.case_id for c in study.cases}
    found: Found = {}
    notes: list[str] = []
    parts = parts_directory(archive)
    files = sorted(parts.glob("batch-*.nc")) if parts.is_dir() else []
    other: dict[str, int] = {}
    for path in files:
        try:
            why = _mismatch(read_attrs(path), study.record)
        except Exception as exc:  # a damaged file fails to open in many ways
            why = None
            problems = [f"it cannot be read ({type(exc).__name__})"]
        else:
            problems = [] if why else verify(path)
        if why:
            other[why] = other.get(why, 0) + 1
            continue
        if problems:
            notes.append(
                f"{path} failed its checks ({'; '.join(problems)}): removed, its cases are "
                "computed again"
            )
            path.unlink(missing_ok=True)
            continue
        try:
            _index_of(path, found, wanted)
        except (ArchiveFileError, OSError, RuntimeError) as exc:
            notes.append(f"{path} cannot be read ({exc}): its cases are computed again")
    for why, n in other.items():
        notes.append(f"{n} batch file{'s' if n != 1 else ''} in {parts} set aside: {why}")
    if archive_usable and archive.is_file():
        try:
            why = _mismatch(read_attrs(archive), study.record)
        except Exception:  # not an archive at all (replaced with --overwrite)
            why = "it is not a campipe archive"
        if why:
            log.info("not reusing %s: %s", archive, why)
        elif problems := verify(archive):
            notes.append(f"{archive} failed its checks ({'; '.join(problems)}): not reused")
        else:
            _index_of(archive, found, wanted)
    for note in notes:
        log.warning("%s", note)
    return found, notes


def spec_file(study: Study, archive: Path) -> str:
    """The spec's path relative to the archive's folder ("" when not read from a file): an
    archive records it, so a second spec of the same name cannot replace the first's."""
    path = study.spec.path
    if path is None:
        return ""
    return os.path.relpath(Path(path).resolve(), archive.parent.resolve())


def inspect_archive(study: Study, archive: Path) -> ArchiveState:
    """What sits at ``archive``: nothing, this study's archive (up to date, or not, or
    damaged), or a file that is not this study's archive (refused without --overwrite)."""
    try:
        info = archive.stat()
    except FileNotFoundError:
        return ArchiveState(False, True, "", False)
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            raise OptionError.at(
                str(archive),
                "the file name is too long for this file system; choose a shorter archive "
                "path (-o)",
                found=str(archive),
            ) from None
        return ArchiveState(True, False, f"a path that cannot be read ({exc.strerror})", False)
    if stat.S_ISDIR(info.st_mode):
        return ArchiveState(True, False, "a folder", False)
    if not stat.S_ISREG(info.st_mode):
        return ArchiveState(True, False, "not a regular file", False)
    if study.spec.path is not None and archive.resolve() == Path(study.spec.path).resolve():
        return ArchiveState(True, False, "the spec itself", False)
    try:
        attrs = read_attrs(archive)
    except ArchiveFileError:
        raise  # open elsewhere in this process and too large to copy
    except Exception:  # not netCDF, or damaged beyond reading its attributes
        if carries_key(archive, study_key(study)):
            return ArchiveState(True, True, "", False, ("its attributes cannot be read",))
        return ArchiveState(
            True, False, "not a campipe archive (or one too damaged to read)", False
        )
    layout = str(attrs.get("campipe_layout", ""))
    if not layout.startswith("campipe-archive") or "study_name" not in attrs:
        return ArchiveState(
            True, False, "a netCDF file that is not a campipe archive", False, attrs=attrs
        )
    if layout != LAYOUT_VERSION:  # never mixed with this layout's cases
        return ArchiveState(
            True,
            False,
            f"an archive in another layout ({layout:.40}; this campipe writes {LAYOUT_VERSION})",
            False,
            attrs=attrs,
        )
    name = attrs.get("study_name")
    if name != study.name:
        return ArchiveState(
            True, False, f"the archive of another study ({name!s:.60})", False, attrs=attrs
        )
    mine, theirs = spec_file(study, archive), str(attrs.get("spec_file", ""))
    if mine and theirs and mine != theirs:
        return ArchiveState(
            True,
            False,
            f"the archive of another spec named {name!s:.60} ({theirs:.200})",
            False,
            attrs=attrs,
        )
    if attrs.get("study_key") != study_key(study):
        return ArchiveState(True, True, "", False, attrs=attrs)
    problems = tuple(verify(archive))
    return ArchiveState(True, True, "", not problems, problems, attrs)


#: Bytes of a damaged file searched for its study key (the attributes lie near the start).
KEY_SEARCH_BYTES = 4 * 2**20


def carries_key(path: Path, key: str) -> bool:
    """A file whose attributes cannot be read still holds this study's key near its start:
    it is this study's archive, damaged (a foreign file would not hold the 16 hex digits)."""
    try:
        with open(path, "rb") as f:
            head = f.read(KEY_SEARCH_BYTES)
    except OSError:
        return False
    return head.startswith(b"\x89HDF") and key.encode() in head


def _refuse(archive: Path, state: ArchiveState) -> ArchiveExistsError:
    return ArchiveExistsError.at(
        str(archive),
        f"exists and is {state.what}, not this study's archive; choose another archive path "
        "(-o), or replace it with --overwrite",
        found=state.what,
        expected="no file, or this study's archive",
    )


def _clean_temporaries(archive: Path) -> None:
    """Remove temporary files a killed run left (this study's only)."""
    parts = parts_directory(archive)
    leftovers = list(parts.glob(".*.tmp")) if parts.is_dir() else []
    leftovers += [p for p in archive.parent.glob(f".{archive.name}.*.tmp") if is_temporary(p)]
    for p in leftovers:
        log.info("removing %s, left by an interrupted run", p)
        p.unlink(missing_ok=True)


def _statuses(archive: Path) -> dict[str, str]:
    """Case id → status name of the archive's cases that did not finish cleanly."""
    ids = read_variable(archive, "case")
    codes = read_variable(archive, "status")
    return {
        str(i): STATUS.get(int(c), str(int(c))) for i, c in zip(ids, codes, strict=True) if c != OK
    }


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
    overwrite: bool = False,
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
    overwrite : bool
        Replace a file at ``archive`` that is not this study's archive (default: refuse).

    A case that fails (non-finite, chatter) does not stop the study: the archive records its
    ``status`` and :attr:`StudyReport.statuses` names it by case id.

    Raises
    ------
    ArchiveExistsError
        If ``archive`` is a file that is not this study's archive and ``overwrite`` is False.
    campipe.io.archive.ArchiveBusyError
        If another run is writing the same archive (its lock, ``<archive>.lock``, is held).
    campipe.io.archive.ArchiveWriteError
        If a file cannot be written (a full disk, a read-only folder); what was stored stays.
    SchedulerError
        If the scheduler cannot be reached, or it or a worker fails.
    """
    started = time.monotonic()
    archive = Path(archive)
    local = "://" not in scheduler
    if local and scheduler not in LOCAL_SCHEDULERS:
        raise OptionError.at(
            "--scheduler",
            f"found {scheduler!r}, expected one of {', '.join(LOCAL_SCHEDULERS)} or an "
            "address such as tcp://127.0.0.1:8786",
            found=scheduler,
        )
    total = len(study.cases)
    # Checked before the lock, so a finished study in a read-only folder is still up to date.
    state = inspect_archive(study, archive)
    if state.up_to_date:
        log.info("%s already holds this study", archive)
        return StudyReport(
            archive,
            total,
            total,
            0,
            0,
            True,
            time.monotonic() - started,
            statuses=_statuses(archive),
        )
    if not state.ours and not overwrite:
        raise _refuse(archive, state)
    if state.what and not stat.S_ISREG(archive.stat().st_mode):
        raise _refuse(archive, state)  # a folder is never replaced
    try:
        archive.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(archive, exc) from None
    with writing(archive):
        state = inspect_archive(study, archive)  # another run may have finished it meanwhile
        if state.up_to_date:
            return StudyReport(
                archive,
                total,
                total,
                0,
                0,
                True,
                time.monotonic() - started,
                statuses=_statuses(archive),
            )
        if not state.ours and not overwrite:
            raise _refuse(archive, state)
        notes: list[str] = []
        if state.problems:
            notes.append(
                f"{archive} failed its checks ({'; '.join(state.problems)}): it is written again"
            )
            log.warning("%s", notes[-1])
        elif state.what:
            notes.append(f"{archive} was {state.what}: replaced (--overwrite)")
        _clean_temporaries(archive)
        found, more = find_results(study, archive, archive_usable=not state.problems)
        notes += more
        missing = [c for c in study.cases if c.case_id not in found]
        workers = workers or (1 if scheduler == "synchronous" else default_workers())
        samples = samples_per_case(study.revolutions, study.output_every)
        size = batch_size or default_batch_size(len(missing), workers, samples)
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
        by_id = {c.case_id: c for c in study.cases}

        def stored(s: _Stored) -> None:
            log.debug("batch %s stored (%d cases)", s.key, s.n_cases)
            for row, (cid, n_ev) in enumerate(zip(s.case_ids, s.event_counts, strict=True)):
                found[cid] = (s.path, row, n_ev)
            for cid, code in zip(s.case_ids, s.statuses, strict=True):
                if code != OK:
                    log.warning(
                        "case %s (index %d): %s", cid, by_id[cid].index, STATUS.get(code, code)
                    )
            if bar:
                bar.advance(s.n_cases)

        if plans:
            if local:
                _run_local(plans, scheduler, workers, store, stored)
            else:
                _run_distributed(plans, scheduler, store, stored)
        assemble(study, archive, found, command, spec_file(study, archive))
        if not keep_parts and parts.is_dir():
            shutil.rmtree(parts, ignore_errors=True)
        return StudyReport(
            archive,
            total,
            total - len(missing),
            len(missing),
            len(plans),
            False,
            time.monotonic() - started,
            tuple(notes),
            _statuses(archive),
        )


def _store(
    parts: Path,
    record: tuple[str, ...],
    on_batch: BatchHook | None,
    data: BatchData,
    plan: BatchPlan,
) -> _Stored:
    if data.numerics != numerics_fingerprint():
        raise SchedulerError.at(
            "--scheduler",
            f"a worker computed with another campipe ({data.numerics}) than this one "
            f"({numerics_fingerprint()}); install the same campipe on every worker",
            found=data.numerics,
        )
    path = store_batch(data, parts, record)
    if on_batch is not None:
        on_batch(plan, data)
    return _Stored(
        data.key,
        path,
        tuple(str(c) for c in data.case_ids),
        tuple(int(n) for n in data.arrays["event_count"]),
        tuple(int(s) for s in data.arrays["status"]),
    )


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
    try:
        with _Done():
            dask.compute(*tasks, scheduler=scheduler, num_workers=workers)
    except BrokenExecutor as exc:
        raise SchedulerError.at(
            "--scheduler",
            f"a worker process of the {scheduler} scheduler died ({exc}); the batches "
            "finished before it are stored: rerun the same command to resume",
            found=scheduler,
        ) from None


#: How long to wait for a dask.distributed scheduler to answer [s].
CONNECT_TIMEOUT = 10


def _run_distributed(plans: list[BatchPlan], address: str, store, stored) -> None:
    from distributed import Client, as_completed

    token = uuid.uuid4().hex[:8]
    try:
        client = Client(address, set_as_default=False, timeout=f"{CONNECT_TIMEOUT}s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise SchedulerError.at(
            "--scheduler",
            f"cannot reach a dask scheduler at {address} within {CONNECT_TIMEOUT} s "
            f"({type(exc).__name__}); start one (dask scheduler, then dask worker {address}) "
            "or run on this machine (--scheduler threads)",
            found=address,
        ) from None
    try:
        with client:
            _submit_all(client, as_completed, plans, token, store, stored)
    except (SchedulerError, ArchiveWriteError, CampipeError):
        raise
    except Exception as exc:  # distributed raises many kinds when the cluster goes away
        raise SchedulerError.at(
            "--scheduler",
            f"the dask cluster at {address} failed ({type(exc).__name__}: {str(exc)[:200]}); "
            "the batches finished before it are stored: rerun the same command to resume",
            found=address,
        ) from None


def _submit_all(client, as_completed, plans, token, store, stored) -> None:
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


def assemble(study: Study, archive: Path, found: Found, command: str, spec: str = "") -> Path:
    """Stream every case's rows from the files that hold them into a new archive; ``spec``
    is the spec's path relative to the archive's folder (:func:`spec_file`)."""
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
    attrs = {**study_attrs(study), "spec_file": spec, **provenance(command)}
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
