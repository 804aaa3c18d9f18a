"""Running a study: batches on a pool of workers, each stored as it finishes, one archive.

- Cases are grouped by their :class:`~campipe.engine.RunSettings` and cut into batches of
  ``batch_size``; one task runs a batch through the engine (one compiled call).
- Each finished batch is written to ``<archive>.parts/batch-<key>.npz`` atomically
  (:mod:`campipe.io.batch_file`: no HDF5, so storing it never waits for the archive), by the
  worker that computed it wherever it can reach the folder; the key hashes the case ids it
  holds, so a changed spec never picks up another spec's results.
- A rerun reads which case ids the batch files (and an existing archive) hold, and computes
  only the cases none of them has: an interrupted study resumes where it stopped.
- The archive is assembled while the batches run (:class:`_Assembly`): this process streams
  the stored rows, in case order, into one new file at a temporary path, renamed into place
  when complete; memory stays bounded by a block of rows.
- A run holds ``<archive>.lock`` throughout (``campipe.io.archive.writing``): a second run on
  the same archive stops with a clear error instead of removing the first one's files; the
  lock of a run that died on this host is taken over.

Schedulers: ``threads`` (a pool of threads, one per core: the engine releases the GIL),
``synchronous`` (in order, in this thread), ``processes`` (a pool of processes), or the
address of a dask.distributed scheduler (``tcp://host:8786``; dask.distributed is imported
only then). On a cluster, a worker that can reach the archive's folder (a shared file system,
or this machine) writes its own batch files, so this process only tracks and assembles; for
a worker that cannot, this process stores what it returns.
"""

from __future__ import annotations

import errno
import functools
import itertools
import logging
import multiprocessing
import os
import shutil
import stat
import sys
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import (
    BrokenExecutor,
    Executor,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    as_completed,
)
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campipe.engine.settings import output_angles, sample_count, turn_count
from campipe.errors import CampipeError
from campipe.io import batch_file
from campipe.io.archive import (
    CASE_CHUNK,
    ArchiveFileError,
    ArchiveWriteError,
    NetCDFWriter,
    is_temporary,
    provenance,
    read_attrs,
    read_index,
    read_rows,
    read_variable,
    verify,
    write_error,
    writing,
)
from campipe.io.spec_yaml import SpecFileError, read_spec
from campipe.study.expand import ResolvedCase, Study, distinct_but_speed
from campipe.study.layout import (
    CASE_ID,
    LAYOUT_VERSION,
    archive_layout,
    batch_key,
    batch_layout,
    record_text,
    spec_key,
    study_attrs,
    study_key,
)
from campipe.study.progress import Progress
from campipe.study.results import (
    BatchData,
    BatchPlan,
    cam_angle_degrees,
    compute_batch,
    numerics_fingerprint,
)
from campipe.vocabulary import EVENTS_TRUNCATED, FAILURES, OK, STATUS

log = logging.getLogger(__name__)

#: Local dask schedulers by name; anything with "://" is a dask.distributed address.
LOCAL_SCHEDULERS = ("threads", "synchronous", "processes")
#: Default batches hold MIN_BATCH_SIZE … MAX_BATCH_SIZE cases: about four batches per worker,
#: so the workers finish together, but not so small that the archive's per-batch work or the
#: engine's per-call set-up outweighs computing it (1000 cases on two workers, with netCDF
#: batch files: 32-case batches took 1.3 s in the study layer, 125-case ones 0.85 s).
MIN_BATCH_SIZE = 4
MAX_BATCH_SIZE = 256

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


#: A whole batch file's arrays (:func:`campipe.io.batch_file.read`), as the assembly reads a
#: batch it does not hold.
read_batch = batch_file.read


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
    if path.suffix == batch_file.SUFFIX:
        arrays = batch_file.read(path, (CASE_ID, "event_count"))
        ids, counts = arrays[CASE_ID], arrays["event_count"]
    else:
        ids, counts, _ = read_index(path, CASE_ID)
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
    files = sorted(parts.glob(f"batch-*{batch_file.SUFFIX}")) if parts.is_dir() else []
    other: dict[str, int] = {}
    for path in files:
        try:
            why = _mismatch(batch_file.read_attrs(path), study.record)
        except Exception as exc:  # a damaged file fails to open in many ways
            why = None
            problems = [f"it cannot be read ({type(exc).__name__})"]
        else:
            problems = [] if why else batch_file.verify(path)
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
        except (ArchiveFileError, OSError, RuntimeError, ValueError, KeyError) as exc:
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
    leftovers = [*parts.glob(".*.tmp"), *parts.glob(".reach-*")] if parts.is_dir() else []
    leftovers += [p for p in archive.parent.glob(f".{archive.name}.*.tmp") if is_temporary(p)]
    for p in leftovers:
        log.info("removing %s, left by an interrupted run", p)
        p.unlink(missing_ok=True)


def _statuses(archive: Path) -> dict[str, str]:
    """Case id → status name of the archive's cases that did not finish cleanly."""
    ids = read_variable(archive, CASE_ID)
    codes = read_variable(archive, "status")
    return {
        str(i): STATUS.get(int(c), str(int(c))) for i, c in zip(ids, codes, strict=True) if c != OK
    }


def finished(
    spec_path: str | Path, overrides: Mapping[str, object], archive: str | Path | None = None
) -> StudyReport | None:
    """The report of a study whose archive already holds it, found from the spec's text
    alone: no unit parsing, no model, no expansion. None when that cannot be told so
    cheaply (:func:`run_study` then checks the study as usual): the archive is missing, was
    written from another text, overrides, lift table or campipe (``spec_key``), names
    another study or spec, fails its checksums, or the spec records a replay.

    ``archive`` defaults to ``<name>.nc`` beside the spec, as ``campipe study`` writes it.
    """
    started = time.monotonic()
    spec_path = Path(spec_path)
    try:
        raw, text = read_spec(spec_path)
    except (SpecFileError, OSError):
        return None
    if (
        not isinstance(raw, Mapping)
        or "replay" in raw
        or any(k.split(".")[0] == "replay" for k in overrides)
    ):
        return None  # the replay is recorded again from the archive: the full path
    name = overrides.get("name", raw.get("name"))
    if not isinstance(name, str) or not name:
        return None
    archive = Path(archive) if archive else spec_path.parent / f"{name}.nc"
    try:
        if not archive.is_file() or spec_path.resolve() == archive.resolve():
            return None
        attrs = read_attrs(archive)
    except Exception:  # not there, not netCDF, damaged: the full check says which
        return None
    mine = os.path.relpath(spec_path.resolve(), archive.parent.resolve())
    if (
        attrs.get("study_name") != name
        or attrs.get("spec_file", mine) != mine
        or attrs.get("spec_key") != spec_key(text, overrides, spec_path.parent)
        or verify(archive)
    ):
        return None
    statuses = _statuses(archive)
    total = len(read_variable(archive, CASE_ID))
    return StudyReport(
        archive, total, total, 0, 0, True, time.monotonic() - started, statuses=statuses
    )


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
    workers_store: bool = True,
    notice: Callable[[str], None] | None = None,
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
        Cases per batch (default: about four batches per worker, at most 256 cases).
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
    workers_store : bool
        On a dask.distributed cluster, workers that can reach the archive's folder write
        their batch files themselves (default); False: this process stores every batch, as
        it does for any worker that cannot reach the folder. The archive is the same.
    notice : callable, optional
        Called with a line of text before a wait the user should hear about: numba
        compiling the kernels the study needs (the first run after an install or upgrade).

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
        return _up_to_date(archive, total, started)
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
            return _up_to_date(archive, total, started)
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
        samples = sample_count(study.revolutions, study.output_every)
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
        by_id = {c.case_id: c for c in study.cases}
        by_key = {p.key: p for p in plans}
        sink = _Assembly(study, archive, found, command, spec_file(study, archive))

        def stored(result: _Stored | BatchData) -> None:
            """A finished batch: stored here if its worker did not, then its rows go into
            the archive as far as the cases before them allow."""
            if isinstance(result, BatchData):
                s = _store(parts, study.record, on_batch, result, by_key[result.key])
            else:
                s = _checked(result)
            log.debug("batch %s stored (%d cases)", s.key, s.n_cases)
            sink.add(s)
            for cid, code in zip(s.case_ids, s.statuses, strict=True):
                if code != OK:
                    log.warning(
                        "case %s (index %d): %s", cid, by_id[cid].index, STATUS.get(code, code)
                    )
            if bar:
                bar.advance(s.n_cases)
            sink.advance()

        try:
            sink.advance()  # the cases reused from earlier runs, as far as they reach
            if plans and local:
                from campipe.engine.kernels import compile_first

                # The kernels compiled here, before the workers start: they load them.
                compile_first({p.cases[0].settings: p.cases[0].case for p in plans}, notice)
            if plans:
                if local:
                    _run_local(
                        plans,
                        scheduler,
                        workers,
                        parts,
                        study.record,
                        on_batch,
                        stored,
                        sink.create,
                    )
                else:
                    sink.create()
                    _run_distributed(
                        plans,
                        scheduler,
                        parts,
                        study.record,
                        on_batch is None and workers_store,
                        stored,
                    )
            sink.finish()
        finally:
            sink.abort()
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
            sink.statuses,
        )


def _up_to_date(archive: Path, total: int, started: float) -> StudyReport:
    return StudyReport(
        archive, total, total, 0, 0, True, time.monotonic() - started, statuses=_statuses(archive)
    )


def _store(
    parts: Path,
    record: tuple[str, ...],
    on_batch: BatchHook | None,
    data: BatchData,
    plan: BatchPlan,
) -> _Stored:
    """Write a computed batch's file (and call the hook): in a worker that can reach the
    archive's folder, or in this process."""
    if data.numerics != numerics_fingerprint():
        raise _other_campipe(data.numerics)
    path = store_batch(data, parts, record)
    if on_batch is not None:
        on_batch(plan, data)
    return _Stored(
        data.key,
        path,
        tuple(str(c) for c in data.case_ids),
        tuple(int(n) for n in data.arrays["event_count"]),
        tuple(int(s) for s in data.arrays["status"]),
        data.numerics,
        data,
    )


def _checked(s: _Stored) -> _Stored:
    """A batch a worker stored itself, refused if that worker runs another campipe."""
    if s.numerics != numerics_fingerprint():
        raise _other_campipe(s.numerics)
    return s


def _other_campipe(theirs: str) -> SchedulerError:
    return SchedulerError.at(
        "--scheduler",
        f"a worker computed with another campipe ({theirs}) than this one "
        f"({numerics_fingerprint()}); install the same campipe on every worker",
        found=theirs,
    )


#: A worker always reaches the archive's folder: it runs in this process or on this machine.
SAME_MACHINE = ""


def _batch_task(
    compute: Callable[[BatchPlan], BatchData],
    parts: Path,
    record: tuple[str, ...],
    reach: str | None,
    on_batch: BatchHook | None,
    plan: BatchPlan,
) -> _Stored | BatchData:
    """What a worker runs for a batch: compute it, and write its file itself where it can
    reach the archive's folder (``reach``: :data:`SAME_MACHINE`, or the token of the file
    :func:`_reach_token` left there), returning only what was stored; otherwise (``reach``
    None, or the token not found) return the data for this process to store."""
    data = compute(plan)
    if reach is None or (reach != SAME_MACHINE and not _reaches(parts, reach)):
        return data
    return _store(parts, record, on_batch, data, plan)


def _reach_file(parts: Path, token: str) -> Path:
    return parts / f".reach-{token}"


def _reaches(parts: Path, token: str) -> bool:
    """This worker sees the token file the client left in the archive's folder: the folder
    is shared (or the machine the same), not merely a folder of the same name."""
    try:
        return _reach_file(parts, token).read_text() == token
    except OSError:
        return False


#: Scheduling steps (``nice``) by which a batch thread runs below this process: the archive's
#: assembly, in this thread, is a study's one serial stage (netCDF compresses on one thread at
#: a time), so it takes a core whenever it has rows to write and the engine's threads share
#: what is left. With as many threads as cores, equal shares left the assembly a fraction of
#: a core (best of a few runs in process: 1000 cases 0.66 s against 0.60 s; 10000 cases 5.9 s
#: against 5.4 s).
WORKER_NICENESS = 5


def _yield_to_assembly() -> None:
    """Lower this worker thread's scheduling priority (Linux, where a thread has a niceness of
    its own); elsewhere, or where that is refused, leave it."""
    if not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + WORKER_NICENESS)
    except OSError:
        pass


def _run_local(
    plans: list[BatchPlan],
    scheduler: str,
    workers: int,
    parts: Path,
    record: tuple[str, ...],
    on_batch: BatchHook | None,
    stored: Callable[[_Stored | BatchData], None],
    started: Callable[[], None] = lambda: None,
) -> None:
    """Batches on this machine: in order in this thread (``synchronous``), or on a pool of
    threads (the engine releases the GIL) or of processes, each worker storing its batches.
    This thread calls ``started`` once they are under way (while the workers load their
    kernels and compute the first batches, it would wait), then hands each stored batch to
    ``stored`` as it finishes."""
    # The hook runs where the batch is stored: a worker thread, or this process.
    in_worker = scheduler != "processes" or on_batch is None
    task = functools.partial(
        _batch_task,
        compute_batch,
        parts,
        record,
        SAME_MACHINE if in_worker else None,
        on_batch if in_worker else None,
    )
    if scheduler == "synchronous":
        started()
        for p in plans:
            stored(task(p))
        return
    pool: Executor
    if scheduler == "threads":
        pool = ThreadPoolExecutor(
            workers, thread_name_prefix="campipe-batch", initializer=_yield_to_assembly
        )
    else:
        pool = ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_yield_to_assembly,
        )
    try:
        futures = [pool.submit(task, p) for p in plans]
        started()
        for future in as_completed(futures):
            stored(future.result())
    except BrokenExecutor as exc:
        raise SchedulerError.at(
            "--scheduler",
            f"a worker process of the {scheduler} scheduler died ({exc}); the batches "
            "finished before it are stored: rerun the same command to resume",
            found=scheduler,
        ) from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


#: How long to wait for a dask.distributed scheduler to answer [s].
CONNECT_TIMEOUT = 10


def _run_distributed(
    plans: list[BatchPlan],
    address: str,
    parts: Path,
    record: tuple[str, ...],
    workers_store: bool,
    stored: Callable[[_Stored | BatchData], None],
) -> None:
    from distributed import Client, as_completed

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
    token = uuid.uuid4().hex
    reach = None
    try:
        if workers_store:
            reach = _reach_token(parts, token)
        task = functools.partial(_batch_task, compute_batch, parts, record, reach, None)
        with client:
            _submit_all(client, as_completed, plans, token[:8], task, stored)
    except (SchedulerError, ArchiveWriteError, CampipeError):
        raise
    except Exception as exc:  # distributed raises many kinds when the cluster goes away
        raise SchedulerError.at(
            "--scheduler",
            f"the dask cluster at {address} failed ({type(exc).__name__}: {str(exc)[:200]}); "
            "the batches finished before it are stored: rerun the same command to resume",
            found=address,
        ) from None
    finally:
        if reach is not None:
            _reach_file(parts, reach).unlink(missing_ok=True)


def _reach_token(parts: Path, token: str) -> str:
    """Leave a file only a worker sharing this folder can read (:func:`_reaches`)."""
    try:
        parts.mkdir(parents=True, exist_ok=True)
        _reach_file(parts, token).write_text(token)
    except OSError as exc:
        raise write_error(parts, exc) from None
    return token


def _submit_all(client, as_completed, plans, token, task, stored) -> None:
    threads = max(sum(client.nthreads().values()), 1)
    pending = iter(plans)

    def submit(p: BatchPlan):
        return client.submit(task, p, key=f"campipe-{p.key}-{token}", pure=False)

    # Keep at most two batches per worker thread in flight: memory stays bounded.
    queue = as_completed(
        [submit(p) for p in itertools.islice(pending, 2 * threads)], loop=client.loop
    )
    for future in queue:
        result = future.result()
        future.release()
        stored(result)
        nxt = next(pending, None)
        if nxt is not None:
            queue.add(submit(nxt))


def assemble(study: Study, archive: Path, found: Found, command: str = "campipe study") -> Path:
    """Write the archive from files that already hold every case (``found``, see
    :func:`find_results`): what this process does on a cluster whose workers store their
    batches (``campipe bench`` times it as the client's ceiling)."""
    sink = _Assembly(study, Path(archive), found, command, spec_file(study, Path(archive)))
    try:
        return sink.finish()
    finally:
        sink.abort()


#: Bytes of rows the assembly holds at a time (the rows of one write to the archive).
ASSEMBLY_BYTES = 32 * 2**20
#: Bytes of batches stored in this process that the assembly keeps in memory until their
#: rows are written, so they need not be read back from their files.
HELD_BYTES = 256 * 2**20


class _Assembly:
    """The archive, written in case order while the study runs: a block of rows goes in as
    soon as the files holding it (batch files, an earlier archive) are stored, so the
    archive's compression overlaps the computing of later batches, the events are appended
    in case order and every variable is checksummed as it is written (no reading back).

    Blocks are whole chunks of ``CASE_CHUNK`` cases until the last, so no compressed chunk
    is written twice.
    """

    def __init__(self, study: Study, archive: Path, found: Found, command: str, spec: str):
        self.study = study
        self.archive = archive
        self.found = found  # case id → (file, row, events); grows as batches are stored
        self.ids = [c.case_id for c in study.cases]
        self.command = command
        self.spec = spec
        self.cursor = 0  # cases written
        self.writer: NetCDFWriter | None = None
        self.statuses: dict[str, str] = {}  # case id → status name, cases not ok
        self.block = CASE_CHUNK  # cases per write, set when the archive is created
        self.case_names: list[str] = []
        self.event_names: list[str] = []
        #: batches in memory (stored here, or read from their files for an earlier block):
        #: path → (arrays, bytes)
        self.held: dict[Path, tuple[dict[str, np.ndarray], int]] = {}
        #: batch files of the next block being read on a thread of their own while this
        #: block compresses (``_read_ahead``)
        self.reading: dict[Path, Future] = {}
        self.reader: ThreadPoolExecutor | None = None
        # Every batch's: the study's run settings set them (``fields.STUDY_WIDE``)
        self.cam_angle = cam_angle_degrees(output_angles(study.cases[0].settings))
        self.held_bytes = 0
        self.position = {cid: pos for pos, cid in enumerate(self.ids)}
        self.last_row: dict[Path, int] = {}  # the last case each file supplies
        for pos, cid in enumerate(self.ids):
            if cid in found:
                self.last_row[found[cid][0]] = pos

    def add(self, s: _Stored) -> None:
        """A stored batch: where its cases are. A batch stored in this process stays in
        memory until its rows are written (within HELD_BYTES; beyond it, its rows are read
        back from its file)."""
        for row, (cid, n_ev) in enumerate(zip(s.case_ids, s.event_counts, strict=True)):
            self.found[cid] = (s.path, row, n_ev)
        self.last_row[s.path] = max(self.position[cid] for cid in s.case_ids)
        if s.data is not None:
            if not np.array_equal(s.data.cam_angle, self.cam_angle):
                raise RuntimeError(f"batch {s.key}: other cam angles than the study's; a defect")
            self._hold(s.path, s.data.arrays)

    def _hold(self, path: Path, arrays: dict[str, np.ndarray]) -> None:
        """Keep a batch's arrays in memory until its rows are written, within HELD_BYTES."""
        size = sum(a.nbytes for a in arrays.values())
        if self.held_bytes + size <= HELD_BYTES:
            self.held[path] = (arrays, size)
            self.held_bytes += size

    def _rows(self, path: Path, rows: np.ndarray, hi: int) -> dict[str, np.ndarray]:
        """Rows (ascending) of a batch (from memory if held, else from its file, then held if
        it has rows past case ``hi``, the block's end) or of an archive, as :func:`read_rows`
        gives them. Consecutive rows are sliced, not gathered."""
        if path in self.held:
            arrays = self.held[path][0]
        elif path.suffix == batch_file.SUFFIX:
            ahead = self.reading.pop(path, None)
            arrays = read_batch(path) if ahead is None else ahead.result()
            if self.last_row[path] >= hi:  # read once, not again for the next block
                self._hold(path, arrays)
        else:
            return read_rows(path, rows, self.case_names, self.event_names[1:])
        counts = arrays["event_count"].astype(np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)])
        if rows[-1] - rows[0] + 1 == rows.size:
            take: slice | np.ndarray = slice(int(rows[0]), int(rows[-1]) + 1)
            pick: slice | np.ndarray = slice(int(starts[rows[0]]), int(starts[rows[-1] + 1]))
        else:
            take = rows
            pick = np.concatenate([np.arange(starts[r], starts[r + 1]) for r in rows])
        out = {name: arrays[name][take] for name in self.case_names}
        for name in self.event_names[1:]:
            out[name] = arrays[name][pick]
        out["event_count"] = counts[take].astype(np.int32)
        return out

    def _release(self, paths: Iterable[Path], upto: int) -> None:
        """Drop held batches whose rows all lie before case ``upto``."""
        for path in paths:
            if path in self.held and self.last_row[path] < upto:
                self.held_bytes -= self.held.pop(path)[1]

    def advance(self) -> None:
        """Write every whole chunk of cases whose rows are all stored, from the cursor on."""
        total = len(self.ids)
        end = self.cursor
        while end < total and self.ids[end] in self.found:
            end += 1
        if end < total:
            end = self.cursor + (end - self.cursor) // CASE_CHUNK * CASE_CHUNK
        while self.cursor < end:
            if self.writer is None:
                self._create()
            stop = min(end, self.cursor + self.block)
            self._write(self.cursor, stop)
            self.cursor = stop

    def finish(self) -> Path:
        """Write what is left and put the archive in place."""
        self.advance()
        if self.cursor < len(self.ids):
            missing = [cid for cid in self.ids[self.cursor :] if cid not in self.found]
            raise RuntimeError(f"cases {missing[:5]} have no results; this is a defect")
        assert self.writer is not None
        self._stop_reading()
        self.writer.commit()
        self.writer = None
        log.info("wrote %s (%d cases)", self.archive, len(self.ids))
        return self.archive

    def create(self) -> None:
        """Create the archive now, if there is anything to write, rather than with the first
        block (:meth:`advance`): its variables and axes depend on the study alone."""
        if self.writer is None and self.cursor < len(self.ids):
            self._create()

    def abort(self) -> None:
        """Remove the unfinished archive (nothing once :meth:`finish` put it in place)."""
        self._stop_reading()
        if self.writer is not None:
            self.writer.abort()
            self.writer = None

    def _create(self) -> None:
        study = self.study
        n_rev = turn_count(study.revolutions)
        sizes, specs, static = archive_layout(study, None, self.cam_angle, n_rev)
        attrs = {**study_attrs(study), "spec_file": self.spec, **provenance(self.command)}
        self.case_names = [
            s.name for s in specs if s.dims[:1] == ("case",) and s.name not in static
        ]
        # event_case first: it is made here, the others are read
        self.event_names = ["event_case"] + [
            s.name for s in specs if s.dims == ("event",) and s.name != "event_case"
        ]
        per_case = 0
        for s in specs:
            if s.name in self.case_names:
                n = np.prod([sizes[d] for d in s.dims[1:]], dtype=np.int64)
                per_case += int(n) * np.dtype(s.dtype).itemsize
        self.block = max(CASE_CHUNK, ASSEMBLY_BYTES // max(per_case, 1) // CASE_CHUNK * CASE_CHUNK)
        self.writer = NetCDFWriter(self.archive, sizes, specs, attrs, study.compression)
        for name, values in static.items():
            self.writer.write(name, values)

    def _read_ahead(self, lo: int, hi: int) -> None:
        """Start reading the batch files that hold cases lo … hi-1 (those already stored) and
        are neither in memory nor being read: their reading (file, CRC-32, arrays) overlaps
        the compression of the block before, as it does when a client assembles what a
        cluster's workers stored. Within HELD_BYTES with what is held (a file's size for its
        arrays'); the others are read when their rows are written."""
        try:
            room = HELD_BYTES - self.held_bytes - sum(p.stat().st_size for p in self.reading)
            for cid in self.ids[lo:hi]:
                entry = self.found.get(cid)
                if entry is None:
                    break
                path = entry[0]
                if path.suffix != batch_file.SUFFIX or path in self.held or path in self.reading:
                    continue
                room -= path.stat().st_size
                if room < 0:
                    break
                self._read(path)
        except OSError:  # a file gone: its reading, when its rows are written, says so
            return

    def _read(self, path: Path) -> None:
        """Read a batch file on the reading thread (``_rows`` takes it)."""
        if self.reader is None:
            self.reader = ThreadPoolExecutor(1, thread_name_prefix="campipe-read")
        self.reading[path] = self.reader.submit(read_batch, path)

    def _stop_reading(self) -> None:
        """Drop what is being read ahead and the reading thread."""
        self.reading.clear()
        if self.reader is not None:
            self.reader.shutdown(wait=False, cancel_futures=True)
            self.reader = None

    def _write(self, lo: int, hi: int) -> None:
        """Cases lo … hi-1 from the files that hold them, in one write per variable."""
        w = self.writer
        assert w is not None
        self._read_ahead(hi, min(hi + self.block, len(self.ids)))
        by_file: dict[Path, list[tuple[int, int]]] = {}
        for k in range(hi - lo):
            path, row, _ = self.found[self.ids[lo + k]]
            by_file.setdefault(path, []).append((row, k))
        block: dict[str, np.ndarray] = {}
        # (first case, rows' data, first event, end): runs of cases whose events are
        # consecutive in both the block and their file's rows
        events: list[tuple[int, dict, int, int]] = []
        for path, pairs in by_file.items():
            pairs.sort()
            rows = np.array([r for r, _ in pairs], dtype=np.int64)
            ks = np.array([k for _, k in pairs], dtype=np.int64)
            data = self._rows(path, rows, hi)
            run = ks[-1] - ks[0] + 1 == ks.size and bool(np.all(np.diff(ks) > 0))
            at: slice | np.ndarray = slice(int(ks[0]), int(ks[-1]) + 1) if run else ks
            for name in self.case_names:
                if name not in block:
                    block[name] = np.empty((hi - lo, *data[name].shape[1:]), data[name].dtype)
                block[name][at] = data[name]
            starts = np.concatenate([[0], np.cumsum(data["event_count"])])
            if run:
                events.append((int(ks[0]), data, 0, int(starts[-1])))
            else:
                events += [
                    (int(k), data, int(starts[j]), int(starts[j + 1])) for j, k in enumerate(ks)
                ]
        events.sort(key=lambda e: e[0])
        for name in self.case_names:
            w.write(name, block[name], slice(lo, hi))
        for name in self.event_names:
            if name == "event_case":
                values = np.repeat(np.arange(lo, hi, dtype=np.int32), block["event_count"])
                w.append(name, values)
            else:
                w.append(name, np.concatenate([d[name][a:b] for _, d, a, b in events]))
        for row in np.flatnonzero(block["status"] != OK).tolist():
            code = int(block["status"][row])
            self.statuses[self.ids[lo + row]] = STATUS.get(code, str(code))
        self._release(by_file, hi)
