"""The archive, assembled while the batches run: this process streams the stored rows, in case
order, into one new file at a temporary path, renamed into place when complete; memory stays
bounded by a block of rows."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from campipe.engine.settings import output_angles
from campipe.io import batch_file
from campipe.io.archive import CASE_CHUNK, NetCDFWriter, VariableSpec, provenance, read_rows
from campipe.study.archive.layout import archive_layout
from campipe.study.run.batches import Stored, gone_solid, highest_lift, ids_and_travels
from campipe.study.run.keys import study_attrs
from campipe.study.run.results import cam_angle_degrees
from campipe.study.run.resume import Found, spec_file
from campipe.study.spec.expand import Study
from campipe.vocabulary import OK, STATUS

log = logging.getLogger(__name__)

#: A whole batch file's arrays (:func:`campipe.io.batch_file.read`), as the assembly reads a
#: batch it does not hold.
read_batch = batch_file.read


def assemble(study: Study, archive: Path, found: Found, command: str = "campipe study") -> Path:
    """Write the archive from files that already hold every case (``found``, see
    :func:`find_results`): what this process does on a cluster whose workers store their
    batches (the developer benchmark, ``benchmarks/study.py``, times it as the
    client's ceiling)."""
    sink = study_assembly(study, Path(archive), found, command, spec_file(study, Path(archive)))
    try:
        return sink.finish()
    finally:
        sink.abort()


@dataclass(frozen=True)
class Layout:
    """What an archive holds before its rows: dimensions (``event`` None: unlimited),
    variables, the arrays written whole (axes, case coordinates), global attributes."""

    sizes: Mapping[str, int | None]
    specs: Sequence[VariableSpec]
    static: Mapping[str, np.ndarray]
    attrs: Mapping[str, object]
    compression: str


def study_layout(study: Study, command: str, spec: str) -> Layout:
    """The layout of ``study``'s single-file archive (:func:`archive_layout`)."""
    cam_angle = cam_angle_degrees(output_angles(study.cases[0].settings))
    sizes, specs, static = archive_layout(study, None, cam_angle, study.n_revolutions)
    attrs = {**study_attrs(study), "spec_file": spec, **provenance(command)}
    return Layout(sizes, specs, static, attrs, study.compression)


def study_assembly(study: Study, archive: Path, found: Found, command: str, spec: str) -> Assembly:
    """The assembly of ``study``'s archive (its layout made when the archive is created)."""
    ids, travel = ids_and_travels(study)
    return Assembly(
        ids,
        archive,
        found,
        lambda: study_layout(study, command, spec),
        cam_angle_degrees(output_angles(study.cases[0].settings)),
        travel,
    )


#: Bytes of rows the assembly holds at a time (the rows of one write to the archive).
ASSEMBLY_BYTES = 32 * 2**20
#: Bytes of batches stored in this process that the assembly keeps in memory until their
#: rows are written, so they need not be read back from their files.
HELD_BYTES = 256 * 2**20


class Assembly:
    """The archive, written in case order while the study runs: a block of rows goes in as
    soon as the files holding it (batch files, an earlier archive) are stored, so the
    archive's compression overlaps the computing of later batches, the events are appended
    in case order and every variable is checksummed as it is written (no reading back).

    Blocks are whole chunks of ``CASE_CHUNK`` cases until the last, so no compressed chunk
    is written twice.
    """

    def __init__(
        self,
        ids: list[str],
        archive: Path,
        found: Found,
        layout: Callable[[], Layout],
        cam_angle: np.ndarray | None = None,
        travel: np.ndarray | None = None,
    ):
        self.archive = archive
        self.found = found  # case id → (file, row, events); grows as batches are stored
        self.ids = ids
        self.layout = layout  # made when the archive is created
        self.cursor = 0  # cases written
        self.writer: NetCDFWriter | None = None
        self.statuses: dict[str, str] = {}  # case id → status name, cases not ok
        #: each case's valve spring travel to solid [m], in study order (None: not checked)
        self.travel = travel
        #: study index → (the highest valve lift, its spring's travel to solid) [m] of a case
        #: that lifts past that travel in its stored turns (the coils clash: the model has no
        #: stop there)
        self.solid: dict[int, tuple[float, float]] = {}
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
        #: every batch's (the study's run settings set them: ``fields.STUDY_WIDE``)
        self.cam_angle = cam_angle
        self.held_bytes = 0
        self.position = {cid: pos for pos, cid in enumerate(self.ids)}
        self.last_row: dict[Path, int] = {}  # the last case each file supplies
        for pos, cid in enumerate(self.ids):
            if cid in found:
                self.last_row[found[cid][0]] = pos

    def add(self, s: Stored) -> None:
        """A stored batch: where its cases are. A batch stored in this process stays in
        memory until its rows are written (within HELD_BYTES; beyond it, its rows are read
        back from its file)."""
        for row, (cid, n_ev) in enumerate(zip(s.case_ids, s.event_counts, strict=True)):
            self.found[cid] = (s.path, row, n_ev)
        self.last_row[s.path] = max(self.position[cid] for cid in s.case_ids)
        if s.data is not None:
            if self.cam_angle is not None and not np.array_equal(s.data.cam_angle, self.cam_angle):
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
        layout = self.layout()
        sizes, specs, static = layout.sizes, layout.specs, layout.static
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
                n = np.prod([int(sizes[d] or 0) for d in s.dims[1:]], dtype=np.int64)
                per_case += int(n) * np.dtype(s.dtype).itemsize
        self.block = max(CASE_CHUNK, ASSEMBLY_BYTES // max(per_case, 1) // CASE_CHUNK * CASE_CHUNK)
        self.writer = NetCDFWriter(self.archive, sizes, specs, layout.attrs, layout.compression)
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
        if self.travel is not None and "valve_lift" in block:
            highest = highest_lift(block["valve_lift"])
            self.solid.update(gone_solid(np.arange(lo, hi), highest, self.travel))
        self._release(by_file, hi)
