"""A study's ``replay: {where: EXPR}``: its cases logged to rerun while the study runs.

:class:`StudyReplay` is the study layer's batch hook (:data:`campipe.study.execute.BatchHook`):
each newly computed batch's cases that the expression selects are logged as soon as the batch
is stored, into ``<archive stem>.rrd`` beside the archive. :meth:`StudyReplay.finish` then
adds the selected cases this run did not compute (taken from an earlier run's batches or
archive) from the finished archive, and the blueprint; the recording then holds the same
content ``campipe replay ARCHIVE --where EXPR`` writes.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

from campipe.replay.sketch import DEFAULT_MAGNIFICATION

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
        self, study, path: str | Path, magnification: float = DEFAULT_MAGNIFICATION
    ) -> None:
        from campipe.io import rerun_replay as rrio
        from campipe.study.layout import study_key

        self.study = study
        self.where = study.spec.replay
        self.path = Path(path)
        self.magnification = magnification
        self.key = study_key(study)
        self._io = rrio
        self._lock = threading.Lock()
        self._logged: dict[str, object] = {}
        self._rec = None

    def _log(self, cases) -> None:
        """Log cases, opening the recording (its file) with the first."""
        with self._lock:
            if self._rec is None:
                self._rec = self._io.recording_stream(
                    self._io.recording_id(self.key, ["study"], self.magnification),
                    f"{self.study.name} replay",
                )
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._rec.save(self.path)
            for case in cases:
                self._io.log_case(self._rec, case, self.magnification)
                self._logged[case.case_id] = case

    def __call__(self, plan, data) -> None:
        """The batch hook: log the batch's selected cases. A failure here is logged, never
        raised: the study goes on, and :meth:`finish` retries the cases from the archive."""
        from campipe.replay.cases import batch_cases

        try:
            cases = batch_cases(self.study, plan, data)
        except Exception as exc:  # noqa: BLE001 - the replay must not stop the study
            log.warning("replay: batch %s not logged (%s)", plan.key, exc)
            return
        if cases:
            self._log(cases)
            log.info("replay: logged %d case(s) of batch %s to %s", len(cases), plan.key, self.path)

    def finish(self, archive: str | Path) -> Path | None:
        """Log the selected cases not computed by this run from the finished archive, send
        the blueprint and close the recording. Returns its path, or None (and writes
        nothing) when the selection holds no case."""
        import xarray as xr

        from campipe.replay.cases import ReplayError, archive_cases, select_rows

        resolved = {c.case_id: c for c in self.study.cases}
        with xr.open_dataset(archive) as ds:
            try:
                rows = select_rows(ds, where=self.where)
            except ReplayError:
                rows = []
            ids = [str(ds["case_id"].values[r]) for r in rows]
            rest = [r for r, cid in zip(rows, ids, strict=True) if cid not in self._logged]
            if rest:
                self._log(archive_cases(ds, rest, resolved=resolved))
        if not ids:
            log.warning("replay: %r selects no case; no recording written", self.where)
            return None
        cases = [self._logged[cid] for cid in ids]
        self._rec.send_blueprint(self._io.blueprint(cases, self.magnification))
        self._rec.flush()
        self._rec.disconnect()
        return self.path
