"""Running a study: batches on a pool of workers, each stored as it finishes, one archive.

- Cases are grouped by their :class:`~campipe.engine.RunSettings` and cut into batches
  (:mod:`~campipe.study.run.batches`); one task runs a batch through the engine (one
  compiled call) and writes ``<archive>.parts/batch-<key>.npz``, on the worker that computed
  it wherever it can reach the folder (:mod:`~campipe.study.run.workers`).
- A rerun computes only the cases no batch file (and no existing archive) holds: an
  interrupted study resumes where it stopped (:mod:`~campipe.study.run.resume`).
- The archive is assembled while the batches run (:mod:`~campipe.study.run.assembly`): this
  process streams the stored rows, in case order, into one new file at a temporary path,
  renamed into place when complete; memory stays bounded by a block of rows.
- With ``parts=True`` the archive is a folder of parts (:mod:`campipe.io.parts`): each
  batch's worker writes its part, compressed, and this process only keeps count and writes
  the index last (:mod:`~campipe.study.run.parts`); nothing is assembled here. On a dask
  cluster every worker is checked first and the batches go out once
  (:mod:`~campipe.study.run.cluster`).
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

import dataclasses
import logging
import re
import shutil
import stat
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from campipe.constants import RPM
from campipe.engine.settings import sample_count
from campipe.io.archive import write_error, writing
from campipe.io.parts import index_path
from campipe.model import valve_train
from campipe.study.run.assembly import study_assembly
from campipe.study.run.batches import (
    LOCAL_SCHEDULERS,
    BatchHook,
    OptionError,
    Storage,
    Stored,
    gone_solid,
    ids_and_travels,
    parts_directory,
    plan_batches,
)
from campipe.study.run.cluster import PartCount
from campipe.study.run.part_files import part_layout
from campipe.study.run.parts import (
    clean_part_temporaries,
    find_parts,
    inspect_parts,
    refuse_parts,
    up_to_date_parts,
)
from campipe.study.run.progress import Progress
from campipe.study.run.results import BatchData, BatchPlan
from campipe.study.run.resume import (
    ArchiveState,
    Found,
    StudyReport,
    clean_temporaries,
    dropped_cases,
    earlier_cases,
    find_results,
    inspect_archive,
    refuse,
    spec_file,
    up_to_date,
)
from campipe.study.run.sizing import default_batch_size, default_workers
from campipe.study.run.workers import run_distributed, run_local, stored_here
from campipe.study.spec.expand import Study
from campipe.study.spec.notes import case_notes
from campipe.study.spec.resolve import ResolvedCase
from campipe.vocabulary import OK, STATUS

log = logging.getLogger(__name__)


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
    parts: bool = False,
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
        Replace a file at ``archive`` that is not this study's archive, and let a rerun
        remove the cases this study's archive holds that its spec no longer makes (a
        narrower sweep, an edited key) (default: refuse both, changing nothing).
    workers_store : bool
        On a dask.distributed cluster, workers that can reach the archive's folder write
        their batch files themselves (default); False: this process stores every batch, as
        it does for any worker that cannot reach the folder. The archive is the same.
    notice : callable, optional
        Called with a line of text before a wait the user should hear about: numba
        compiling the kernels the study needs (the first run after an install or upgrade).
    parts : bool
        Write a parts archive (:mod:`campipe.io.parts`): ``archive`` is a folder of one
        compressed netCDF file per batch, each written by the worker that computed it, and
        an index; this process only keeps count (``campipe pack`` writes the single file).
        ``keep_parts`` does not apply. Default: one netCDF file.

    A case that fails (non-finite, chatter) does not stop the study: the archive records its
    ``status`` and :attr:`StudyReport.statuses` names it by case id.

    Raises
    ------
    ArchiveExistsError
        If ``archive`` is a file that is not this study's archive, or this study's archive
        holds cases the spec does not make, and ``overwrite`` is False.
    campipe.io.archive.ArchiveBusyError
        If another run is writing the same archive (its lock, ``<archive>.lock``, is held).
    campipe.io.archive.ArchiveWriteError
        If a file cannot be written (a full disk, a read-only folder); what was stored stays.
    SchedulerError
        If the scheduler cannot be reached, or it or a worker fails.
    """
    started = time.monotonic()
    archive = Path(archive)
    if not check_scheduler(scheduler):
        # A cluster's workers resolve a relative path in their own working folders.
        archive = archive.absolute()
    run = _Run(scheduler, workers or 0, on_batch, workers_store, notice, command)
    if parts:
        return _run_parts(study, archive, run, batch_size, progress, started, overwrite)
    total = len(study.cases)
    # Checked before the lock, so a finished study in a read-only folder is still up to date.
    state = inspect_archive(study, archive)
    if state.up_to_date:
        log.info("%s already holds this study", archive)
        return up_to_date(archive, total, started)
    _check_replaceable(archive, state, overwrite)
    if state.what and not stat.S_ISREG(archive.stat().st_mode):
        raise refuse(archive, state)  # a folder is never replaced
    try:
        archive.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(archive, exc) from None
    with writing(archive):
        state = inspect_archive(study, archive)  # another run may have finished it meanwhile
        if state.up_to_date:
            return up_to_date(archive, total, started)
        _check_replaceable(archive, state, overwrite)
        notes = _state_notes(archive, state)
        before = earlier_cases(archive) if not state.what else []  # this study's, replaced
        dropped = dropped_cases(archive, before, study, overwrite)  # before anything changes
        clean_temporaries(archive)
        found, more = find_results(study, archive, archive_usable=not state.problems)
        notes += more
        missing = [c for c in study.cases if c.case_id not in found]
        notes += _case_notes(missing, study.record)
        workers = workers or (1 if scheduler == "synchronous" else default_workers())
        plans = _plan(study, missing, scheduler, workers, batch_size)
        run = _Run(scheduler, workers, on_batch, workers_store, notice, command)
        bar = progress(total, total - len(missing)) if progress else None
        statuses, engine, solid = _compute_and_assemble(study, archive, found, plans, run, bar)
        notes += solid_note(study, solid) + dropped
        scratch = parts_directory(archive)
        if not keep_parts and scratch.is_dir():
            shutil.rmtree(scratch, ignore_errors=True)
        return _ran(archive, total, missing, plans, started, notes, statuses, engine)


def _ran(archive, total, missing, plans, started, notes, statuses, engine) -> StudyReport:
    """The report of a run that computed the ``missing`` cases in ``plans`` (the others
    reused), started at ``started`` (time.monotonic), its batches' engine calls taking
    ``engine`` seconds in all."""
    return StudyReport(
        archive,
        total,
        total - len(missing),
        len(missing),
        len(plans),
        False,
        time.monotonic() - started,
        tuple(notes),
        statuses,
        engine,
    )


#: The schemes of a dask.distributed scheduler's address (``distributed.comm``'s).
SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def check_scheduler(scheduler: str) -> bool:
    """Whether ``scheduler`` runs on this machine (else it is a dask.distributed address:
    ``SCHEME://HOST:PORT``, or ``HOST:PORT`` as dask reads it, tcp); a local name that is not
    one of LOCAL_SCHEDULERS, and a scheme dask does not speak, are refused (a helper's
    ``tpc://`` and ``http://`` were 'cannot reach ... (ValueError)')."""
    scheme, sep, _ = scheduler.partition("://")
    if sep:
        if scheme.lower() not in SCHEMES:
            raise OptionError.at(
                "--scheduler",
                f"found {scheduler!r}: dask.distributed speaks {', '.join(SCHEMES)}, not "
                f"{scheme!r}; a scheduler's address is tcp://HOST:PORT (8786 by default; the "
                "dashboard's HTTP port, 8787, is not it)",
                found=scheduler,
            )
        return False
    if re.fullmatch(r"[\w.\-]+:\d+", scheduler):
        return False  # HOST:PORT, tcp
    if scheduler not in LOCAL_SCHEDULERS:
        raise OptionError.at(
            "--scheduler",
            f"found {scheduler!r}, expected one of {', '.join(LOCAL_SCHEDULERS)} or an "
            "address such as tcp://127.0.0.1:8786",
            found=scheduler,
        )
    return True


def _check_replaceable(archive: Path, state: ArchiveState, overwrite: bool) -> None:
    """Refuse a file at the archive's path that is not this study's archive, unless the run
    may overwrite it."""
    if not state.ours and (state.kept or not overwrite):
        raise refuse(archive, state)


def _case_notes(cases: list[ResolvedCase], record: tuple[str, ...]) -> list[str]:
    """The notes on the cases computed (``campipe.study.spec.notes.case_notes``)."""
    return [note for _, note in case_notes(cases, record)]


def _state_notes(archive: Path, state: ArchiveState) -> list[str]:
    """What the run does about the file it found at the archive's path, in words."""
    notes: list[str] = []
    if state.problems:
        notes.append(
            f"{archive} failed its checks ({'; '.join(state.problems)}): it is written again"
        )
    elif state.what:
        notes.append(f"{archive} was {state.what}: replaced (--overwrite)")
    return notes


def _plan(
    study: Study,
    missing: list[ResolvedCase],
    scheduler: str,
    workers: int,
    batch_size: int | None,
) -> list[BatchPlan]:
    """The batches of the cases no file holds yet."""
    total = len(study.cases)
    samples = sample_count(study.revolutions, study.output_every)
    size = batch_size or default_batch_size(len(missing), workers, samples)
    plans = plan_batches(missing, study.record, size)
    log.info(
        "%s: %d cases, %d reused from earlier runs; computing %d in %d batches of up to %d on %s",
        study.name,
        total,
        total - len(missing),
        len(missing),
        len(plans),
        size,
        scheduler,
    )
    return plans


@dataclass(frozen=True)
class _Run:
    """How a run computes its batches (:func:`run_study`'s options)."""

    scheduler: str  # a local scheduler's name, or a dask.distributed address
    workers: int  # threads or processes of a local scheduler
    on_batch: BatchHook | None  # the replay hook
    workers_store: bool  # a cluster's workers write their batch files where they can
    notice: Callable[[str], None] | None  # told before the kernels compile
    command: str  # recorded in the archive's history

    @property
    def local(self) -> bool:
        return self.scheduler in LOCAL_SCHEDULERS


def _compute_and_assemble(
    study: Study,
    archive: Path,
    found: Found,
    plans: list[BatchPlan],
    run: _Run,
    bar: Progress | None,
) -> tuple[dict[str, str], float, dict[int, tuple[float, float]]]:
    """Compute ``plans`` and write the archive as their batches are stored; case id → status
    name of the cases that did not finish cleanly, the seconds of the batches' engine calls,
    summed, and the cases whose spring went solid (``Assembly.solid``)."""
    storage = Storage(parts_directory(archive), study.record)
    by_id = {c.case_id: c for c in study.cases}
    by_key = {p.key: p for p in plans}
    sink = study_assembly(study, archive, found, run.command, spec_file(study, archive))
    engine = 0.0

    def stored(result: Stored | BatchData | PartCount) -> None:
        """A finished batch: stored here if its worker did not, then its rows go into the
        archive as far as the cases before them allow."""
        nonlocal engine
        s = stored_here(result, storage, run.on_batch, by_key)
        engine += s.engine_seconds
        log.debug("batch %s stored (%d cases)", s.key, s.n_cases)
        sink.add(s)
        for cid, code in zip(s.case_ids, s.statuses, strict=True):
            if code != OK:
                log.warning("case %s (index %d): %s", cid, by_id[cid].index, STATUS.get(code, code))
        if bar:
            bar.advance(s.n_cases)
        sink.advance()

    try:
        sink.advance()  # the cases reused from earlier runs, as far as they reach
        if plans and run.local:
            from campipe.engine.kernels import compile_first  # numba: not before it is needed

            # The kernels compiled here, before the workers start: they load them.
            compile_first({p.cases[0].settings: p.cases[0].case for p in plans}, run.notice)
        if plans and run.local:
            run_local(
                plans,
                run.scheduler,
                run.workers,
                storage,
                run.on_batch,
                stored,
                sink.create,
            )
        elif plans:
            sink.create()
            run_distributed(
                plans,
                run.scheduler,
                storage,
                run.on_batch is None and run.workers_store,
                stored,
            )
        sink.finish()
    finally:
        sink.abort()
    return sink.statuses, engine, sink.solid


def solid_note(
    study: Study, solid: dict[int, tuple[float, float]], checked: int | None = None
) -> list[str]:
    """A note on the cases whose valve lifts past its spring's travel to solid
    (``Assembly.solid``; a parts run's from its computed batches, ``checked`` of them where
    it reused others): the coils clash, and the model has no stop there."""
    if not solid:
        return []
    worst = max(solid, key=lambda k: solid[k][0] - solid[k][1])
    lift, travel = solid[worst]
    case = study.cases[worst]
    assumed = travel == valve_train().spring_travel_to_solid
    others = sorted(set(solid) - {worst}, key=lambda k: -solid[k][0])
    shown = ", ".join(study.cases[k].case_id for k in others[:4])
    also = f" (also {shown}{' …' if len(others) > 4 else ''})" if others else ""
    return [
        f"the valve spring goes solid (coil bind) in {len(solid)} of "
        + (
            f"the {checked} cases this run computed"
            if checked is not None
            else f"{len(study.cases)} cases"
        )  # fmt: skip
        + f"{also}: case {case.case_id} at {case.case.speed / RPM:.6g} cam rpm lifts its valve "
        f"{lift * 1e3:.4g} mm, past the spring's {travel * 1e3:.4g} mm travel to solid "
        f"(model.spring_travel_to_solid{', the default: the thesis gives none' if assumed else ''}"
        "). The model has no stop at solid: past it their motion is not a real train's "
        "(record: [spring] stores min_spring_clash_margin)"
    ]


def _run_parts(
    study: Study,
    archive: Path,
    run: _Run,
    batch_size: int | None,
    progress: Callable[[int, int], Progress] | None,
    started: float,
    overwrite: bool,
) -> StudyReport:
    """:func:`run_study` into a parts archive: the same checks, lock and resume; each batch a
    part its worker writes; the index written last."""
    total = len(study.cases)
    state = inspect_parts(study, archive)
    if state.up_to_date:
        log.info("%s already holds this study", archive)
        return up_to_date_parts(archive, total, started)
    if not state.ours:
        raise refuse_parts(archive, state)  # never a file or another folder
    try:
        archive.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(archive, exc) from None
    with writing(archive):
        state = inspect_parts(study, archive)  # another run may have finished it meanwhile
        if state.up_to_date:
            return up_to_date_parts(archive, total, started)
        notes = (
            [
                f"{archive} failed its checks ({'; '.join(state.problems)}): its damaged "
                "parts are computed again"
            ]
            if state.problems
            else []
        )
        before = earlier_cases(archive)
        dropped = dropped_cases(archive, before, study, overwrite)  # before anything changes
        clean_part_temporaries(archive)
        index_path(archive).unlink(missing_ok=True)  # the parts change: no index meanwhile
        layout = part_layout(study, run.command, spec_file(study, archive))
        found, more = find_parts(study, archive, layout)
        notes += more
        missing = [c for c in study.cases if c.case_id not in found.found]
        notes += _case_notes(missing, study.record)
        workers = run.workers or (1 if run.scheduler == "synchronous" else default_workers())
        run = dataclasses.replace(run, workers=workers)
        plans = _plan(study, missing, run.scheduler, workers, batch_size)
        storage = Storage(archive, study.record, layout)
        bar = progress(total, total - len(missing)) if progress else None
        by_key = {p.key: p for p in plans}
        engine = 0.0
        ids, travel = ids_and_travels(study)
        index = {cid: i for i, cid in enumerate(ids)}
        solid: dict[int, tuple[float, float]] = {}

        def stored(result: Stored | BatchData | PartCount) -> None:
            nonlocal engine
            s = stored_here(result, storage, run.on_batch, by_key)
            engine += s.engine_seconds
            found.add(s)
            if s.highest:  # the coils' clash, of a batch this run computed
                rows = np.array([index[cid] for cid in s.case_ids])
                solid.update(gone_solid(rows, np.asarray(s.highest), travel))
            if bar:
                bar.advance(s.n_cases)

        _compute(plans, run, storage, stored)
        for cid, name in found.statuses.items():
            log.warning("case %s: %s", cid, name)
        found.write_index(layout.attrs)
        checked = len(missing) if len(missing) < len(study.cases) else None
        notes += solid_note(study, solid, checked) + dropped
        statuses = {
            c.case_id: found.statuses[c.case_id] for c in study.cases if c.case_id in found.statuses
        }
        return _ran(archive, total, missing, plans, started, notes, statuses, engine)


def _compute(
    plans: list[BatchPlan],
    run: _Run,
    storage: Storage,
    stored: Callable[[Stored | BatchData | PartCount], None],
) -> None:
    """Compute ``plans`` on the run's workers, each stored batch handed to ``stored``."""
    if not plans:
        return
    if run.local:
        from campipe.engine.kernels import compile_first  # numba: not before it is needed

        compile_first({p.cases[0].settings: p.cases[0].case for p in plans}, run.notice)
        run_local(plans, run.scheduler, run.workers, storage, run.on_batch, stored)
    else:
        run_distributed(
            plans,
            run.scheduler,
            storage,
            run.on_batch is None and run.workers_store,
            stored,
        )
