"""The workers: batches computed on this machine (``synchronous``, a pool of ``threads`` or of
``processes``) or on a dask.distributed cluster, each stored by the worker that computed it
wherever it can reach the archive's folder.

On a cluster, a worker that can reach the archive's folder (a shared file system, or this
machine) writes its own batch files, so the calling process only tracks and assembles; for a
worker that cannot, the calling process stores what it returns. dask.distributed is imported
only for a cluster.
"""

from __future__ import annotations

import functools
import itertools
import logging
import multiprocessing
import os
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    BrokenExecutor,
    Executor,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from campipe.errors import CampipeError
from campipe.io.archive import ArchiveWriteError, write_error
from campipe.study.run.batches import (
    LOCAL_SCHEDULERS,
    BatchHook,
    SchedulerError,
    Storage,
    Stored,
    highest_lifts,
)
from campipe.study.run.cluster import PartCount, collect, run_parts
from campipe.study.run.results import BatchData, BatchPlan, compute_batch, numerics_fingerprint

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")


def stored_here(
    result: Stored | BatchData | PartCount,
    storage: Storage,
    on_batch: BatchHook | None,
    plans: dict[str, BatchPlan],
) -> Stored:
    """A finished batch as stored: by this process if its worker returned the data (``plans``
    by key), else as the worker stored it (a part's counts: its cases from ``plans``)."""
    if isinstance(result, BatchData):
        return _store(storage, on_batch, result, plans[result.key])
    if isinstance(result, PartCount):
        return _checked(result.stored(plans[result.key], storage.directory))
    return _checked(result)


def _store(
    storage: Storage,
    on_batch: BatchHook | None,
    data: BatchData,
    plan: BatchPlan,
) -> Stored:
    """Write a computed batch's file (and call the hook): in a worker that can reach the
    archive's folder, or in this process."""
    if data.numerics != numerics_fingerprint():
        raise _other_campipe(data.numerics)
    path, checksum = storage.store(data, plan)
    if on_batch is not None:
        on_batch(plan, data)
    return Stored(
        data.key,
        path,
        tuple(str(c) for c in data.case_ids),
        tuple(int(n) for n in data.arrays["event_count"]),
        tuple(int(s) for s in data.arrays["status"]),
        data.numerics,
        checksum,
        None if storage.parts else data,  # a part's rows are not assembled here
        data.engine_seconds,
        highest_lifts(data) if storage.parts else (),  # (a single file's: its assembly's)
    )


def _checked(s: Stored) -> Stored:
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
    storage: Storage,
    reach: str | None,
    on_batch: BatchHook | None,
    plan: BatchPlan,
) -> Stored | BatchData:
    """What a worker runs for a batch: compute it, and write its file itself where it can
    reach the archive's folder (``reach``: :data:`SAME_MACHINE`, or the token of the file
    :func:`_reach_token` left there), returning only what was stored; otherwise (``reach``
    None, or the token not found) return the data for this process to store."""
    data = compute(plan)
    if reach is None or (reach != SAME_MACHINE and not _reaches(storage.directory, reach)):
        return data
    return _store(storage, on_batch, data, plan)


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


def run_local(
    plans: list[BatchPlan],
    scheduler: str,
    workers: int,
    storage: Storage,
    on_batch: BatchHook | None,
    stored: Callable[[Stored | BatchData], None],
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
        storage,
        SAME_MACHINE if in_worker else None,
        on_batch if in_worker else None,
    )
    pool = _local_pool(scheduler, workers)
    try:
        _bounded_local(pool, scheduler, workers, plans, task, stored, started)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def _local_pool(scheduler: str, workers: int) -> Executor | None:
    """The pool of a local scheduler: threads (the engine releases the GIL) or processes;
    None for ``synchronous`` (this thread)."""
    if scheduler == "synchronous":
        return None
    if scheduler == "threads":
        return ThreadPoolExecutor(
            workers, thread_name_prefix="campipe-batch", initializer=_yield_to_assembly
        )
    return ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_yield_to_assembly,
    )


def _bounded_local(
    pool: Executor | None,
    scheduler: str,
    workers: int,
    items: Iterable[T],
    task: Callable[[T], R],
    done: Callable[[R], None],
    started: Callable[[], None] = lambda: None,
) -> None:
    """Each item through ``task`` on ``pool`` (in this thread for None), ``done`` called in
    this thread with each result as it finishes; ``started`` once the first are under way."""
    if pool is None:
        started()
        for p in items:
            done(task(p))
        return
    try:
        # At most two items per worker in flight, each future dropped once done: a
        # finished future holds its batch's arrays, so submitting every batch at once kept
        # the whole study's results in memory until the end.
        pending = iter(items)
        in_flight = {pool.submit(task, p) for p in itertools.islice(pending, 2 * workers)}
        started()
        while in_flight:
            finished, in_flight = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in finished:
                done(future.result())
                nxt = next(pending, None)
                if nxt is not None:
                    in_flight.add(pool.submit(task, nxt))
    except BrokenExecutor as exc:
        raise SchedulerError.at(
            "--scheduler",
            f"a worker process of the {scheduler} scheduler died ({exc}); the batches "
            "finished before it are stored: rerun the same command to resume",
            found=scheduler,
        ) from None


#: A map over a scheduler: ``mapped(items, task)`` → each item's result, in the items' order.
Mapped = Callable[[Sequence[Any], Callable[[Any], Any]], list[Any]]


def _indexed(task: Callable[[T], R], item: tuple[int, T]) -> tuple[int, R]:
    """``task`` of an item numbered by its position (results arrive as they finish)."""
    return item[0], task(item[1])


@contextmanager
def task_map(scheduler: str, workers: int) -> Iterator[Mapped]:
    """A map on a study's scheduler, kept open for many calls (``campipe design``'s search:
    a pool or a cluster's client for the whole search): ``mapped(items, task)`` runs each
    item through ``task`` as a study runs its batches (the same pool, at most two items a
    worker in flight; on a cluster the same connection checks, waits on a cluster without
    workers and messages) and returns the results in the items' order. ``task`` and the
    items are pickled for ``processes`` and a cluster.

    Parameters
    ----------
    scheduler : str
        ``threads``, ``synchronous``, ``processes`` or a dask.distributed address.
    workers : int
        Threads or processes of a local scheduler.
    """

    def gather(items: Sequence[Any], run: Callable[[list, Callable], None]) -> list:
        results: list[Any] = [None] * len(items)

        def done(pair: tuple[int, Any]) -> None:
            results[pair[0]] = pair[1]

        run(list(enumerate(items)), done)
        return results

    if scheduler in LOCAL_SCHEDULERS:
        pool = _local_pool(scheduler, workers)

        def mapped(items: Sequence[Any], task: Callable[[Any], Any]) -> list[Any]:
            step = functools.partial(_indexed, task)
            return gather(
                items, lambda numbered, done: _bounded_local(
                    pool, scheduler, workers, numbered, step, done)
            )  # fmt: skip

        try:
            yield mapped
        finally:
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
        return
    from distributed import wait as wait_futures

    kept = "nothing of this search is kept: rerun the command"
    with _distributed_quiet(), _cluster(scheduler, kept) as client, client.as_current():

        def on_cluster(items: Sequence[Any], task: Callable[[Any], Any]) -> list[Any]:
            step = functools.partial(_indexed, task)
            tag = uuid.uuid4().hex[:8]
            return gather(
                items, lambda numbered, done: _submit_all(
                    client, wait_futures, numbered, tag, step, done, lambda p: str(p[0]))
            )  # fmt: skip

        yield on_cluster


#: How long to wait for a dask.distributed scheduler to answer [s].
CONNECT_TIMEOUT = 10
#: How long a study waits on a cluster without a worker (none at the start, or every one
#: lost) before it stops, resumable [s].
WORKER_TIMEOUT = 120
#: How often the cluster's workers are counted while no batch finishes [s].
WORKER_POLL = 0.5


#: distributed's loggers silenced while a study runs on a cluster (unless campipe logs
#: below WARNING, ``campipe -v``): a scheduler gone logged some 30 lines of its tracebacks
#: before the study's own message said the same.
DISTRIBUTED_LOGGERS = (
    "distributed",
    "distributed.client",
    "distributed.core",
    "distributed.comm",
    "distributed.batched",
)


def run_distributed(
    plans: list[BatchPlan],
    address: str,
    storage: Storage,
    workers_store: bool,
    stored: Callable[[Stored | BatchData | PartCount], None],
) -> None:
    """Batches on the dask.distributed cluster at ``address``, each stored batch handed to
    ``stored`` (a parts archive's workers write their parts and return their counts:
    :func:`campipe.study.run.cluster.run_parts`); a SchedulerError, resumable, if the
    cluster cannot be reached, has no worker for WORKER_TIMEOUT seconds, or fails."""
    with _distributed_quiet():
        _run_distributed(plans, address, storage, workers_store, stored)


@contextmanager
def _distributed_quiet() -> Iterator[None]:
    """:data:`DISTRIBUTED_LOGGERS` at CRITICAL for the block, unless campipe logs below
    WARNING (then theirs help). After a failure they stay so: the client's closing tasks
    log their tracebacks after the block has ended, repeating what the SchedulerError
    says."""
    import distributed  # noqa: F401 - its import sets its loggers' levels: first, then ours

    if logging.getLogger("campipe").getEffectiveLevel() < logging.WARNING:
        yield
        return
    loggers = [logging.getLogger(name) for name in DISTRIBUTED_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL)
    yield  # an exception leaves them quiet
    for logger, level in zip(loggers, levels, strict=True):
        logger.setLevel(level)


def _run_distributed(
    plans: list[BatchPlan],
    address: str,
    storage: Storage,
    workers_store: bool,
    stored: Callable[[Stored | BatchData | PartCount], None],
) -> None:
    from distributed import wait

    token = uuid.uuid4().hex
    reach = None
    parts = storage.directory
    try:
        with _cluster(address) as client:
            if workers_store:
                reach = _reach_token(parts, token)
            task = functools.partial(_batch_task, compute_batch, storage, reach, None)
            with client.as_current():  # distributed.wait takes the current client
                if storage.parts and reach is not None:
                    tag, reached = token[:8], _reach_file(parts, reach)
                    run_parts(
                        client, wait, _Idle(client), plans, storage, reached, reach,
                        compute_batch, stored, tag,
                    )  # fmt: skip
                else:
                    _submit_all(client, wait, plans, token[:8], task, stored)
    finally:
        if reach is not None:
            _reach_file(parts, reach).unlink(missing_ok=True)


#: What a study keeps of a cluster that failed, in its message.
KEPT = "the batches finished before it are stored: rerun the same command to resume"


@contextmanager
def _cluster(address: str, kept: str = KEPT) -> Iterator:
    """A client of the dask.distributed scheduler at ``address`` for the block, closed after
    it; a SchedulerError if it cannot be reached within CONNECT_TIMEOUT seconds or the
    cluster fails in the block (campipe's own errors pass as they are; ``kept``: what is
    kept of the work, in the message)."""
    try:
        client = _connect(address)
    except (OSError, TimeoutError, ValueError, TypeError, MemoryError) as exc:
        # MemoryError: a service that greets with a banner (SSH), its text read as the
        # length of a dask message
        why = "it answers, not as dask does" if isinstance(exc, MemoryError) else ""
        raise SchedulerError.at(
            "--scheduler",
            f"cannot reach a dask scheduler at {address} within {CONNECT_TIMEOUT} s "
            f"({why or type(exc).__name__}); start one (dask scheduler, then dask worker "
            f"{address}) or run on this machine (--scheduler threads)",
            found=address,
        ) from None
    try:
        with client:
            yield client
    except (SchedulerError, ArchiveWriteError, CampipeError):
        raise
    except Exception as exc:  # distributed raises many kinds when the cluster goes away
        raise SchedulerError.at(
            "--scheduler",
            f"the dask cluster at {address} failed ({type(exc).__name__}: {_line(exc)}); " + kept,
            found=address,
        ) from None


def _line(exc: BaseException, width: int = 200) -> str:
    """An exception's text on one line, at most ``width`` characters (distributed's span
    several): a longer one is cut at a space and ends in "...", not mid-word."""
    text = " ".join(str(exc).split())
    if len(text) <= width:
        return text
    return text[: width - 3].rsplit(" ", 1)[0] + "..."


def _connect(address: str):
    """A dask.distributed client of the scheduler at ``address``, or TimeoutError after
    CONNECT_TIMEOUT seconds: distributed's own timeout covers the connection, not the
    handshake, so a server that accepts and never answers as dask does (an HTTP server) held
    a study for good. The client is made on a thread of its own and waited for; one that
    never comes is left to the process's end (a daemon thread)."""
    import threading

    from distributed import Client

    made: list = []

    def connect() -> None:
        try:
            made.append(Client(address, set_as_default=False, timeout=f"{CONNECT_TIMEOUT}s"))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller below
            made.append(exc)

    thread = threading.Thread(target=connect, name="campipe-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_TIMEOUT + 1)
    if not made:
        raise TimeoutError(f"no dask handshake within {CONNECT_TIMEOUT} s")
    if isinstance(made[0], BaseException):
        raise made[0]
    return made[0]


def _reach_token(parts: Path, token: str) -> str:
    """Leave a file only a worker sharing this folder can read (:func:`_reaches`)."""
    try:
        parts.mkdir(parents=True, exist_ok=True)
        _reach_file(parts, token).write_text(token)
    except OSError as exc:
        raise write_error(parts, exc) from None
    return token


def _submit_all(client, wait, plans, token, task, stored, name=None) -> None:
    """Each of ``plans`` through ``task`` on the cluster, at most two a worker thread in
    flight, ``stored`` given each result as it finishes (``name``: a plan's part of its
    task's key, default its batch key)."""
    threads = max(sum(client.nthreads().values()), 1)
    left = iter(plans)
    named = name or (lambda p: p.key)

    def submit(p):
        return client.submit(task, p, key=f"campipe-{named(p)}-{token}", pure=False)

    def stored_then_next(result) -> list:
        stored(result)
        nxt = next(left, None)
        return [] if nxt is None else [submit(nxt)]

    # Keep at most two batches per worker thread in flight: memory stays bounded.
    in_flight = [submit(p) for p in itertools.islice(left, 2 * threads)]
    collect(wait, in_flight, _Idle(client), stored_then_next)


class _Idle:
    """A cluster without a worker, reported at once (a warning) and refused after
    :data:`WORKER_TIMEOUT` seconds without one: batches in flight on a cluster that has no
    worker (none joined, or all gone) would be waited on for good."""

    def __init__(self, client) -> None:
        self.client = client
        self.since: float | None = None  # monotonic time the workers were first missed

    @property
    def poll(self) -> float:
        """Seconds between the checks (:data:`WORKER_POLL`)."""
        return WORKER_POLL

    def check(self) -> None:
        if self.client.nthreads():
            if self.since is not None:
                log.warning("the dask cluster has workers again; the study goes on")
            self.since = None
            return
        now = time.monotonic()
        if self.since is None:
            self.since = now
            log.warning(
                "the dask cluster at %s has no worker: waiting up to %d s for one (dask "
                "worker %s), then stopping; the batches finished are kept",
                self.client.scheduler.address,
                WORKER_TIMEOUT,
                self.client.scheduler.address,
            )
        elif now - self.since > WORKER_TIMEOUT:
            address = self.client.scheduler.address
            raise SchedulerError.at(
                "--scheduler",
                f"the dask cluster at {address} had no worker for {WORKER_TIMEOUT} s; start "
                f"workers (dask worker {address}) and rerun the same command to resume (the "
                "batches finished are stored), or run on this machine (--scheduler threads)",
                found=address,
            )
