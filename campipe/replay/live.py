"""A study's ``replay: {where: EXPR}``: its cases logged to rerun while the study runs.

:class:`StudyReplay` is the study layer's batch hook (:data:`campipe.study.run.execute.BatchHook`):
each newly computed batch's cases that the expression selects are logged as soon as the batch
is stored, into ``<archive stem>.rrd`` beside the archive. :meth:`StudyReplay.finish` then
adds the selected cases this run did not compute (taken from an earlier run's batches or
archive) from the finished archive, and the blueprint; the recording then holds the same
content ``campipe replay ARCHIVE --where EXPR`` writes.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from campipe.io import rerun_replay as rrio
from campipe.replay.cases import ReplayCase, ReplayError, archive_cases, batch_cases, select_rows
from campipe.replay.record import recording_case, series_units
from campipe.replay.sketch import DEFAULT_MAGNIFICATION
from campipe.study.archive.open import open_archive
from campipe.study.query.tables import stored_units
from campipe.study.run.keys import study_attrs, study_key
from campipe.study.run.results import BatchData, BatchPlan, compute_batch
from campipe.study.spec.coordinates import coordinate_values
from campipe.study.spec.expand import Study
from campipe.study.spec.variables import VARIABLES
from campipe.study.where import evaluate, parse_where

if TYPE_CHECKING:
    import rerun as rr

log = logging.getLogger(__name__)


def recording_path(archive: str | Path) -> Path:
    """Where a study's replay recording goes: beside the archive, suffix ``.rrd``."""
    return Path(archive).with_suffix(".rrd")


class StudyReplay:
    """Logs the spec's ``replay:`` selection of a study into one recording.

    Parameters
    ----------
    study : campipe.study.Study
        The expanded study; ``study.spec.replay`` is the selection.
    path : str or Path
        The recording to write (see :func:`recording_path`).
    magnification : float
        Factor on the sketch's deviations from the rigid-body motion [-].
    """

    def __init__(
        self, study: Study, path: str | Path, magnification: float = DEFAULT_MAGNIFICATION
    ) -> None:
        self.study = study
        self.where = study.spec.replay
        self.path = Path(path)
        self.magnification = magnification
        self.key = study_key(study)
        self._lock = threading.Lock()
        self._logged: dict[str, ReplayCase] = {}
        self._rec: rr.RecordingStream | None = None
        # The series in the spec's units, as campipe replay and query show the archive.
        stored = {n: str(VARIABLES[n].units or "") for n in rrio.SERIES}
        stored = {n: u for n, u in stored.items() if u not in ("", "1")}
        self.units = series_units(stored, study_attrs(study), "spec")

    def _log(self, cases: Sequence[ReplayCase]) -> None:
        """Log cases, opening the recording (its file) with the first."""
        with self._lock:
            if self._rec is None:
                self._rec = rrio.recording_stream(
                    rrio.recording_id(self.key, ["study"], self.magnification),
                    f"{self.study.name} replay",
                )
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._rec.save(self.path)
            for case in cases:
                rrio.log_case(
                    self._rec,
                    recording_case(case, self.magnification, self.units),
                    self.magnification,
                )
                self._logged[case.case_id] = case

    def __call__(self, plan: BatchPlan, data: BatchData) -> None:
        """The batch hook: log the batch's selected cases. A failure here is logged, never
        raised: the study goes on, and :meth:`finish` retries the cases from the archive."""
        try:
            cases = batch_cases(self.study, plan, data)
        except Exception as exc:  # noqa: BLE001 - the replay must not stop the study
            log.warning("replay: batch %s not logged (%s)", plan.key, exc)
            return
        if cases:
            self._log(cases)
            log.info("replay: logged %d case(s) of batch %s to %s", len(cases), plan.key, self.path)

    def close(self) -> None:
        """Close the recording as it is (no blueprint): a run that ends without finishing."""
        with self._lock:
            if self._rec is not None:
                self._rec.disconnect()
                self._rec = None

    def finish(self, archive: str | Path) -> Path | None:
        """Log the selected cases not computed by this run from the finished archive, send
        the blueprint and close the recording. Returns its path, or None (and writes
        nothing) when the selection holds no case."""
        resolved = {c.case_id: c for c in self.study.cases}
        with open_archive(archive) as ds:
            try:
                rows = select_rows(ds, where=self.where)
            except ReplayError:
                rows = np.zeros(0, np.int64)
            ids = [str(ds["case"].values[r]) for r in rows]
            rest = [r for r, cid in zip(rows, ids, strict=True) if cid not in self._logged]
            if rest:
                self._log(archive_cases(ds, rest, resolved=resolved))
        if not ids:
            log.warning("replay: %r selects no case; no recording written", self.where)
            return None
        cases = [self._logged[cid] for cid in ids]
        assert self._rec is not None  # opened by _log with the first case
        self._rec.send_blueprint(rrio.blueprint(cases, self.magnification, self.units))
        self._rec.flush()
        self._rec.disconnect()
        return self.path


def time_replay(study: Study, folder: str | Path) -> tuple[int | None, float]:
    """What the spec's ``replay:`` adds to a run: how many cases it selects (None when its
    condition reads a metric, known only once the cases have run) and the time logging one
    case takes [s], as the study's hook logs it (its q computed again when not recorded,
    its sketch, its recording), timed on the first case it selects (or the study's first)
    into a recording in ``folder``."""
    if not study.spec.replay:
        return 0, 0.0
    where = parse_where(study.spec.replay)
    columns = coordinate_values(study.cases, study)
    count: int | None = None
    first = study.cases[0]
    if where.names <= set(columns):
        mask = evaluate(where, columns, len(study.cases), stored_units(study.varied))
        count = int(mask.sum())
        if count == 0:
            return 0, 0.0
        first = study.cases[int(np.flatnonzero(mask)[0])]
    plan = BatchPlan("estimate", (first,), study.record)
    data = compute_batch(plan)
    every = dataclasses.replace(study, spec=dataclasses.replace(study.spec, replay="true"))
    hook = StudyReplay(every, Path(folder) / "estimate.rrd")
    t = time.perf_counter()
    hook(plan, data)
    seconds = time.perf_counter() - t
    hook.close()
    return count, seconds
