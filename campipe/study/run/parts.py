"""A study into a parts archive (:mod:`campipe.io.parts`): what sits at its path, which parts
an earlier run left serve this study, the index written once every case is in a part, and
``campipe pack``, the single-file archive written from the parts.

Resume keeps the single-file archive's guarantees: a part is reused only if it has this
layout, record and engine and its checksums verify; a damaged part is removed and its cases
computed again; the index goes while a run changes the parts and is written (atomically)
only when they hold every case.
"""

from __future__ import annotations

import logging
import stat
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campipe.io.archive import (
    CHECKSUM_ATTR,
    LOCK,
    VariableSpec,
    is_temporary,
    open_dataset,
    read_attrs,
    verify,
)
from campipe.io.outputs import Kind, netcdf_attrs
from campipe.io.parts import (
    INDEX,
    PartsIndexError,
    checksum_digest,
    index_path,
    part_checksum,
    part_files,
    read_index,
    write_index,
)
from campipe.io.watch import watched
from campipe.study.archive.layout import LAYOUT_VERSION
from campipe.study.run.assembly import Assembly, Layout
from campipe.study.run.batches import Stored
from campipe.study.run.keys import study_key
from campipe.study.run.part_files import PartLayout
from campipe.study.run.resume import (
    ArchiveExistsError,
    ArchiveState,
    StudyReport,
    checked_files,
    spec_file,
)
from campipe.study.spec.coordinates import CASE_ID
from campipe.study.spec.expand import Study
from campipe.vocabulary import OK, STATUS

log = logging.getLogger(__name__)


# -- what sits at the path --------------------------------------------------------------------


def inspect_parts(study: Study, archive: Path) -> ArchiveState:
    """What sits at a parts archive's path: nothing, this study's parts archive (finished and
    verified, or not), or something a parts archive never replaces (a file, another folder,
    another study's parts archive)."""
    try:
        info = archive.stat()
    except FileNotFoundError:
        return ArchiveState(False, True, "", False)
    except OSError as exc:
        return ArchiveState(True, False, f"a path that cannot be read ({exc.strerror})", False)
    if not stat.S_ISDIR(info.st_mode):
        return ArchiveState(True, False, "a file (a parts archive is a folder)", False, kept=True)
    if not index_path(archive).exists():
        foreign = [
            p.name
            for p in archive.iterdir()
            if not (p.name.startswith("part-") and p.name.endswith(".nc"))
            and not is_temporary(p)
            and not p.name.startswith(".reach-")  # a killed cluster run's token
        ]
        if foreign:
            what = f"a folder that is not a parts archive (it holds {foreign[0]!r})"
            return ArchiveState(True, False, what, False)
        return ArchiveState(True, True, "", False)  # a run's parts, its index not yet written
    try:
        index = read_index(archive)
    except PartsIndexError as exc:
        return ArchiveState(True, True, "", False, (str(exc),))
    attrs = index.get("attrs", {})
    name = attrs.get("study_name")
    if attrs.get("campipe_layout") != LAYOUT_VERSION:
        what = f"a parts archive in another layout ({attrs.get('campipe_layout')!s:.40})"
        return ArchiveState(True, False, what, False, attrs=attrs)
    if name != study.name:
        what = f"the parts archive of another study ({name!s:.60})"
        return ArchiveState(True, False, what, False, attrs=attrs)
    mine, theirs = spec_file(study, archive), str(attrs.get("spec_file", ""))
    same = attrs.get("study_key") == study_key(study)  # moved or copied with its spec: ours
    if mine and theirs and mine != theirs and not same:
        what = f"the parts archive of another spec named {name!s:.60} ({theirs:.200})"
        return ArchiveState(True, False, what, False, attrs=attrs)
    if attrs.get("study_key") != study_key(study):
        return ArchiveState(True, True, "", False, attrs=attrs)
    problems = tuple(check_parts(archive, index))
    return ArchiveState(True, True, "", not problems, problems, attrs)


def refuse_parts(archive: Path, state: ArchiveState) -> ArchiveExistsError:
    """What a parts archive says of a path it will not write into."""
    return ArchiveExistsError.at(
        str(archive),
        f"exists and is {state.what}, not this study's parts archive; a parts archive "
        "replaces nothing (not with --overwrite either): choose another path (-o), or remove "
        "it",
        found=state.what,
        expected="no file, or this study's parts archive",
    )


def check_parts(archive: Path, index: dict) -> list[str]:
    """What is wrong with the parts an index names: missing, replaced (another checksum than
    the index's) or damaged (their checksums do not verify). Reads every part whole."""
    problems = []
    for entry in index["parts"]:
        path = archive / str(entry["file"])
        if not path.is_file():
            problems.append(f"{entry['file']} is missing")
            continue
        try:
            if part_checksum(path) != entry["checksum"]:
                problems.append(f"{entry['file']} is not the part the index names")
                continue
        except Exception as exc:  # a damaged file fails to open in many ways
            problems.append(f"{entry['file']} cannot be read ({type(exc).__name__})")
            continue
        problems += [f"{entry['file']}: {p}" for p in verify(path)]
    return problems


def clean_part_temporaries(archive: Path) -> None:
    """Remove the temporary files a killed run left in a parts archive."""
    if archive.is_dir():
        for p in [*archive.glob(".*.tmp"), *archive.glob(".reach-*")]:
            log.info("removing %s, left by an interrupted run", p)
            p.unlink(missing_ok=True)


# -- the parts a run finds and makes ----------------------------------------------------------


@dataclass
class Parts:
    """The parts that serve a study, as a run finds and adds them: per part its cases, events
    and checksum; the cases each part supplies; the statuses of cases not ok."""

    study: Study
    archive: Path
    #: part file → (case ids, event counts, checksum), in the order found or stored
    parts: dict[Path, tuple[tuple[str, ...], tuple[int, ...], str]] = field(default_factory=dict)
    found: set[str] = field(default_factory=set)  # case ids some part supplies
    statuses: dict[str, str] = field(default_factory=dict)  # case id → status name, not ok

    def add(self, s: Stored) -> None:
        """A part a worker stored: only its counts are kept (a few µs per case)."""
        self.parts[s.path] = (s.case_ids, s.event_counts, s.checksum)
        self.found.update(s.case_ids)
        for cid, code in zip(s.case_ids, s.statuses, strict=True):
            if code != OK:
                self.statuses[cid] = STATUS.get(code, str(code))

    def write_index(self, attrs: Mapping[str, object]) -> Path:
        """The index, with the archive's global attributes ``attrs`` (this run's: a part
        reused from an earlier run records that run's): the parts that supply a case of the
        study, ordered by the first case they supply; then every other part is removed from
        the folder."""
        ids = [c.case_id for c in self.study.cases]
        position = {cid: k for k, cid in enumerate(ids)}
        missing = [cid for cid in ids if cid not in self.found]
        if missing:
            raise RuntimeError(f"cases {missing[:5]} have no part; this is a defect")
        first = {}
        for path, (cases, _, _) in self.parts.items():
            at = [position[c] for c in cases if c in position]
            if at:
                first[path] = min(at)
        listed = sorted(first, key=first.__getitem__)
        entries: list[dict[str, object]] = [
            {
                "file": path.name,
                "cases": len(self.parts[path][0]),
                "events": int(sum(self.parts[path][1])),
                "checksum": self.parts[path][2],
            }
            for path in listed
        ]
        index = write_index(self.archive, attrs, ids, entries, self.study.compression)
        keep = {p.name for p in listed}
        for path in part_files(self.archive):
            if path.name not in keep:
                log.info("removing %s: no case of this study", path)
                path.unlink(missing_ok=True)
        return index


def find_parts(study: Study, archive: Path, layout: PartLayout) -> tuple[Parts, list[str]]:
    """The parts earlier runs left in ``archive`` that serve this study, and notes on those
    set aside: a part of another layout, record or engine, or with other variables than
    ``layout``'s (a spec that varies other keys), is left out of the index (and removed with
    it); a damaged one is removed now, its cases computed again."""
    wanted = {c.case_id for c in study.cases}
    out = Parts(study, archive)
    notes: list[str] = []
    checked = checked_files(
        part_files(archive) if archive.is_dir() else [], read_attrs, verify, study.record,
        notes, f"part in {archive}", lambda path: _misfit(path, layout),
    )  # fmt: skip
    for path, attrs in checked:
        ids, counts, statuses = _part_rows(path)
        if not wanted.intersection(ids):
            continue
        checksum = checksum_digest(str(attrs.get(CHECKSUM_ATTR, "")))
        out.add(Stored("", path, ids, counts, statuses, "", checksum))
    return out, notes


@watched
def _misfit(path: Path, layout: PartLayout) -> str | None:
    """Why a part's variables are not those of ``layout``'s parts (names, dimensions and
    their lengths, coordinates), or None if they are: only such parts read as one."""
    with LOCK, open_dataset(path) as ds:
        if set(ds.variables) != {v.name for v in layout.specs}:
            return "other variables (the spec varies other keys)"
        for d, n in layout.sizes.items():
            if d not in ("case", "event") and (
                d not in ds.dimensions or len(ds.dimensions[d]) != n
            ):
                return f"another length of {d}"
        for v in layout.specs:
            var = ds.variables[v.name]
            theirs = var.getncattr("coordinates") if "coordinates" in var.ncattrs() else None
            if var.dimensions != v.dims or theirs != v.attrs.get("coordinates"):
                return f"another {v.name} (the spec varies other keys)"
    return None


@watched
def _part_rows(path: Path) -> tuple[tuple[str, ...], tuple[int, ...], tuple[int, ...]]:
    """A part's case ids, event counts and statuses."""
    with LOCK, open_dataset(path) as ds:
        ds.set_auto_mask(False)
        ids = tuple(str(c) for c in ds.variables[CASE_ID][:])
        counts = tuple(int(n) for n in ds.variables["event_count"][:])
        codes = tuple(int(s) for s in ds.variables["status"][:])
    return ids, counts, codes


def up_to_date_parts(archive: Path, total: int, started: float) -> StudyReport:
    """The report of a parts archive that already holds the study."""
    index = read_index(archive)
    statuses: dict[str, str] = {}
    for entry in index["parts"]:
        ids, _, codes = _part_rows(archive / str(entry["file"]))
        for cid, code in zip(ids, codes, strict=True):
            if code != OK:
                statuses[cid] = STATUS.get(code, str(code))
    wanted = set(index["case"])
    statuses = {k: v for k, v in statuses.items() if k in wanted}
    return StudyReport(
        archive, total, total, 0, 0, True, time.monotonic() - started, statuses=statuses
    )


# -- one file from the parts ------------------------------------------------------------------


def pack(archive: str | Path, output: str | Path, command: str = "campipe pack") -> Path:
    """Write the single-file archive of a parts archive: the file ``campipe study`` writes
    without ``--parts``, variable for variable (its global attributes are the index's, with
    the pack in its ``history``).

    Raises
    ------
    campipe.io.parts.PartsIndexError
        If ``archive`` is not a finished parts archive.
    campipe.io.archive.ArchiveFileError
        If a part the index names is missing or not the part the index names.
    """
    archive, output = Path(archive), Path(output)
    index = read_index(archive)
    found: dict[str, tuple[Path, int, int]] = {}
    for entry in index["parts"]:
        path = archive / str(entry["file"])
        if not path.is_file() or part_checksum(path) != entry["checksum"]:
            raise PartsIndexError.at(
                str(archive),
                f"{entry['file']} is missing or not the part the index names; rerun the "
                "study to compute its cases again",
            )
        ids, counts, _ = _part_rows(path)
        for row, (cid, n) in enumerate(zip(ids, counts, strict=True)):
            found.setdefault(cid, (path, row, n))
    order = [str(c) for c in index["case"]]
    attrs = dict(index["attrs"])
    now = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    attrs["history"] = f"{attrs.get('history', '')}\n{now} {command}".strip()
    first = archive / str(index["parts"][0]["file"])
    layout = _layout_of(first, len(order), attrs, str(index["compression"]))
    sink = Assembly(order, output, found, lambda: layout)
    try:
        return sink.finish()
    finally:
        sink.abort()


def pack_kind(archive: Path) -> Kind:
    """What ``campipe pack`` may replace without ``--overwrite``: a netCDF archive of the
    same study (its ``study_key`` the index's), as an earlier pack wrote it."""
    key = read_index(archive)["attrs"].get("study_key")

    def ours(path: Path) -> bool:
        attrs = netcdf_attrs(path)
        return attrs is not None and key is not None and attrs.get("study_key") == key

    return Kind("this parts archive's single file", ours)


def pack_inputs(archive: Path) -> list[tuple[Path, str]]:
    """What ``campipe pack`` reads, which its output never replaces: the index and parts."""
    files = [index_path(archive), *part_files(archive)]
    return [(p, f"a file of the parts archive {archive.name}") for p in files]


@watched
def _layout_of(part: Path, n_cases: int, attrs: dict, compression: str) -> Layout:
    """The single-file archive's layout, read from one of its parts: its dimensions (case the
    study's, event unlimited), variables and axes."""
    with LOCK, open_dataset(part) as ds:
        ds.set_auto_mask(False)
        sizes: dict[str, int | None] = {d: len(v) for d, v in ds.dimensions.items()}
        sizes["case"], sizes["event"] = n_cases, None
        specs, axes = [], {}
        for name, var in ds.variables.items():
            dtype = "str" if var.dtype is str else np.dtype(var.dtype).str.lstrip("<>|=")
            specs.append(VariableSpec(name, var.dimensions, dtype, _var_attrs(var)))
            if "case" not in var.dimensions and "event" not in var.dimensions:
                axes[name] = np.asarray(var[:])
    return Layout(sizes, specs, axes, attrs, compression)


def _var_attrs(var) -> dict[str, object]:
    return {k: var.getncattr(k) for k in var.ncattrs()}


__all__ = [
    "INDEX",
    "Parts",
    "check_parts",
    "clean_part_temporaries",
    "find_parts",
    "inspect_parts",
    "pack",
    "pack_inputs",
    "pack_kind",
    "refuse_parts",
    "up_to_date_parts",
]
