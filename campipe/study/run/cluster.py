"""A parts archive on a dask.distributed cluster: every worker checked before computing, the
study's batches sent once, each worker writing its parts and returning only their counts.

The client's work per batch is then one small result, and per case a few microseconds
(``campipe bench``'s cluster block measures it):

- :func:`check_workers`: a probe on each worker (``Client.run``) reads the token the client
  left in the parts archive's folder and writes a file there; a worker that does not see the
  folder (not a shared file system) or cannot write it stops the study before anything is
  computed, naming the path (:class:`PartsPathError`).
- :func:`run_parts`: the batches (their cases, the parts' layout) go to the cluster once,
  as one task's result every task depends on; each task names its batch by index
  (:func:`part_task`), and returns a :class:`PartCount`: the part's file, checksum, and its
  cases' event counts and statuses as two small arrays; the cases' ids stay with the
  client's plan. Of each case only what the engine and the part's coordinates need is sent
  (:class:`SentBatch`).

dask.distributed is imported by the caller (:mod:`~campipe.study.run.workers`), never here.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from campipe.engine.case import Case
from campipe.engine.settings import RunSettings
from campipe.errors import CampipeError
from campipe.io.parts import part_name
from campipe.study.run.batches import Storage, Stored, highest_lifts
from campipe.study.run.results import BatchData, BatchPlan
from campipe.study.spec.resolve import ResolvedCase


class PartsPathError(CampipeError, RuntimeError):
    """Workers of a cluster cannot write the parts archive's folder (``key`` the folder,
    ``found`` the workers' addresses and why)."""


@dataclass(frozen=True)
class PartCount:
    """What a worker returns for a part it wrote: no case ids (the client's plan holds them),
    no data."""

    key: str  # the batch key
    name: str  # the part's file name in the parts archive
    checksum: str  # the index's checksum of the part (campipe.io.parts.checksum_digest)
    event_counts: np.ndarray  # (n,) int32: events of each case, in the plan's order
    statuses: np.ndarray  # (n,) int8: status of each case (vocabulary.STATUS)
    numerics: str  # numerics_fingerprint() of the worker
    engine_seconds: float = 0.0  # wall time of the batch's engine call [s]
    highest: tuple[float, ...] = ()  # each case's highest valve lift [m] (``highest_lifts``)

    def stored(self, plan: BatchPlan, directory: Path) -> Stored:
        """The part as :class:`Stored`, its case ids from ``plan``."""
        return Stored(
            self.key,
            directory / self.name,
            tuple(c.case_id for c in plan.cases),
            tuple(self.event_counts.tolist()),
            tuple(self.statuses.tolist()),
            self.numerics,
            self.checksum,
            engine_seconds=self.engine_seconds,
            highest=self.highest,
        )


def probe(token_file: str, token: str) -> str:
    """Run on a worker: "" if it reads ``token`` in ``token_file`` (the client's, in the parts
    archive's folder) and can write a file beside it; otherwise why not, in words."""
    path = Path(token_file)
    try:
        seen = path.read_text()
    except OSError as exc:
        return (
            f"does not see the folder ({exc.strerror or type(exc).__name__}): "
            "not a path shared with this machine"
        )
    if seen != token:
        return "sees another folder at that path: not the one shared with this machine"
    mine = path.parent / f".probe-{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp"
    try:
        mine.write_bytes(b"campipe")
        mine.unlink()
    except OSError as exc:
        return f"cannot write there ({exc.strerror or type(exc).__name__})"
    return ""


def check_workers(client, directory: Path, token_file: Path, token: str) -> int:
    """The number of workers probed (:func:`probe`), each able to write ``directory``.

    Raises
    ------
    PartsPathError
        If any worker cannot, naming ``directory`` and the first such worker.
    """
    answers: dict[str, str] = client.run(probe, str(token_file), token)
    bad = {address: why for address, why in answers.items() if why}
    if bad:
        address, why = sorted(bad.items())[0]
        raise PartsPathError.at(
            str(directory),
            f"{len(bad)} of {len(answers)} workers cannot write the parts archive's folder "
            f"(worker {address} {why}); nothing was computed: give a folder every worker "
            "reaches and can write (a shared file system), with --parts-dir or -o",
            found=bad,
        )
    return len(answers)


@dataclass(frozen=True)
class SentBatch:
    """A batch as the cluster receives it: its cases column by column, and of their values
    only the case coordinates its part records (a resolved case's values hold every model
    parameter: six times the bytes, and their pickling the client's largest cost a case)."""

    key: str  # the batch key
    record: tuple[str, ...]  # run.record of the study
    settings: RunSettings  # shared by the batch's cases
    index: tuple[int, ...]  # each case's position in the study
    cases: tuple[Case, ...]  # engine inputs
    case_ids: tuple[str, ...]
    values: dict[str, list]  # spec key → each case's value, for the part's coordinates

    @classmethod
    def of(cls, plan: BatchPlan, keys: Sequence[str]) -> SentBatch:
        cases = plan.cases
        return cls(
            plan.key,
            plan.record,
            cases[0].settings,
            tuple(c.index for c in cases),
            tuple(c.case for c in cases),
            tuple(c.case_id for c in cases),
            {k: [c.values[k] for c in cases] for k in keys},
        )

    def plan(self) -> BatchPlan:
        """The batch's plan again, its cases' values only the coordinates'."""
        cases = tuple(
            ResolvedCase(i, case, self.settings, {k: v[j] for k, v in self.values.items()}, case_id)
            for j, (i, case, case_id) in enumerate(
                zip(self.index, self.cases, self.case_ids, strict=True)
            )
        )
        return BatchPlan(self.key, cases, self.record)


def part_task(
    index: int,
    shared: tuple[tuple[SentBatch, ...], Storage],
    token_file: str,
    token: str,
    compute: Callable[[BatchPlan], BatchData],
) -> PartCount:
    """What a worker runs for batch ``index`` of the ``shared`` batches and storage: compute
    it and write its part, if the worker sees the client's ``token_file`` (a worker that
    joined after :func:`check_workers` may not)."""
    batches, storage = shared
    why = probe(token_file, token)
    if why:
        raise PartsPathError.at(
            str(storage.directory),
            f"a worker {why}; give a folder every worker reaches and can write",
        )
    plan = batches[index].plan()
    data = compute(plan)
    _, checksum = storage.store(data, plan)
    return PartCount(
        data.key,
        part_name(data.key),
        checksum,
        np.asarray(data.arrays["event_count"], dtype=np.int32),
        np.asarray(data.arrays["status"], dtype=np.int8),
        data.numerics,
        data.engine_seconds,
        highest_lifts(data),
    )


def run_parts(
    client,
    wait,
    idle,
    plans: Sequence[BatchPlan],
    storage: Storage,
    token_file: Path,
    token: str,
    compute: Callable[[BatchPlan], BatchData],
    done: Callable[[PartCount], None],
    tag: str,
) -> None:
    """Every batch of ``plans`` as a part its worker writes, ``done`` called with each
    :class:`PartCount` as it arrives (``wait``: distributed's). The workers are probed first
    (:func:`check_workers`); the plans and storage go to the cluster once. While none
    finishes, ``idle.poll`` seconds apart, ``idle.check()`` counts the workers (and stops a
    study whose cluster has had none for too long)."""
    check_workers(client, storage.directory, token_file, token)
    # A task of its own, not scattered data: the scheduler keeps it and computes it again
    # on another worker if the one holding it dies.
    keys = tuple(storage.layout.coordinates) if storage.layout is not None else ()
    sent = tuple(SentBatch.of(p, keys) for p in plans)
    shared = client.submit(_shared, sent, storage, key=f"campipe-plans-{tag}", pure=False)
    futures = client.map(
        part_task,
        range(len(plans)),
        [shared] * len(plans),  # a dependency of each task, sent to each worker once
        token_file=str(token_file),
        token=token,
        compute=compute,
        key=[f"campipe-{p.key}-{tag}" for p in plans],
        pure=False,
    )

    def counted(result: PartCount) -> tuple:
        done(result)
        return ()

    collect(wait, list(futures), idle, counted)


def collect(wait, pending: list, idle, done: Callable[[Any], Iterable]) -> None:
    """Wait on the futures ``pending`` (``wait``: distributed's) and give each result to
    ``done`` as it finishes, the future released once read; ``done`` returns futures to
    wait on as well (the next batches), or none. While none finishes, ``idle.poll`` seconds
    apart, ``idle.check()`` counts the workers (and stops a study whose cluster has had none
    for too long), also while a finished one's result is fetched (:func:`_result`). A future
    that failed or was cancelled (its cluster lost) raises."""
    while pending:
        try:  # the first to finish, or none within the poll: then count the workers
            finished = set(wait(pending, timeout=idle.poll, return_when="FIRST_COMPLETED")[0])
        except TimeoutError:
            idle.check()
            continue
        for future in [f for f in pending if f in finished]:
            pending.remove(future)
            result = _result(future, idle)
            future.release()
            pending.extend(done(result))


def _result(future, idle):
    """A finished future's result, ``idle.poll`` seconds at a time with ``idle.check()``
    between: a result is fetched from the worker that holds it, and one that finished just
    before its worker left is computed again, which waits for a worker (the study waited for
    good when the cluster had none left)."""
    while True:
        try:
            return future.result(timeout=idle.poll)
        except TimeoutError:
            idle.check()


def _shared(
    batches: tuple[SentBatch, ...], storage: Storage
) -> tuple[tuple[SentBatch, ...], Storage]:
    """The object every :func:`part_task` reads its batch from."""
    return batches, storage
