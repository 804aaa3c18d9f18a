"""Resuming a study: what sits at the archive's path, which of the study's cases earlier
runs' batch files (and an earlier archive) already hold, and a finished study told from its
spec's text alone.

A rerun reads which case ids the batch files (and an existing archive) hold, and computes only
the cases none of them has: an interrupted study resumes where it stopped. A file is used only
if it has this layout, record and engine and its checksums verify.
"""

from __future__ import annotations

import errno
import logging
import os
import stat
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from campipe.errors import CampipeError
from campipe.io import batch_file
from campipe.io.archive import (
    ArchiveFileError,
    is_temporary,
    read_attrs,
    read_index,
    read_variable,
    verify,
)
from campipe.io.spec_yaml import SpecFileError, read_spec
from campipe.study.archive.layout import LAYOUT_VERSION, record_text
from campipe.study.run.batches import OptionError, parts_directory
from campipe.study.run.keys import spec_key, study_key
from campipe.study.run.results import numerics_fingerprint
from campipe.study.spec.coordinates import CASE_ID
from campipe.study.spec.expand import Study
from campipe.vocabulary import EVENTS_TRUNCATED, FAILURES, OK, STATUS

log = logging.getLogger(__name__)


class ArchiveExistsError(CampipeError, ValueError):
    """A file at the archive path that is not this study's archive: another study's, a file
    that is not an archive, the spec itself (``key`` the path, ``found`` what it is).
    ``campipe study --overwrite`` replaces it."""


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
    #: the computed batches' engine calls' wall time, summed over the batches (each on its
    #: worker: on several workers the sum exceeds the share of ``seconds`` they took) [s]
    engine_seconds: float = 0.0

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
class ArchiveState:
    """What sits at an archive path before a run."""

    exists: bool  # a file (or folder) is there
    ours: bool  # it is this study's archive (same name and spec file): a run may replace it
    what: str  # for a file that is not ours: what it is, in words
    up_to_date: bool  # it holds this study, by this engine, and its checksums verify
    problems: tuple[str, ...] = ()  # why its checksums failed, if they did
    attrs: dict | None = None  # its global attributes, where they could be read
    #: it is the study's own input (its spec, a lift table it reads) or a folder: never
    #: replaced, not even with --overwrite
    kept: bool = False


#: Where the cases some file already holds are: case id → (file, row, events).
Found = dict[str, tuple[Path, int, int]]


def mismatch(attrs: dict, record: tuple[str, ...]) -> str | None:
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


def checked_files(
    paths: Iterable[Path],
    read: Callable[[Path], dict],
    check: Callable[[Path], list[str]],
    record: tuple[str, ...],
    notes: list[str],
    what: str,
    misfit: Callable[[Path], str | None] | None = None,
) -> Iterator[tuple[Path, dict]]:
    """The files among ``paths`` to reuse, each with its attributes (``read``): those of this
    layout, record and engine (:func:`mismatch`), fit (``misfit``, when given) and whose
    checksums verify (``check``). One that fails its checks or cannot be read is removed and
    named in ``notes`` (its cases are computed again); the others are not reused (and removed
    with the run's scratch, or left out of the parts' index and removed), counted in one note
    a reason (``what``: "batch file in <folder>", "part in <archive>")."""
    other: dict[str, int] = {}
    for path in paths:
        try:
            attrs = read(path)
            why = mismatch(attrs, record) or (misfit(path) if misfit else None)
            problems = [] if why else check(path)
        except Exception as exc:  # a damaged file fails to open in many ways
            why, problems = None, [f"it cannot be read ({type(exc).__name__})"]
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
        yield path, attrs
    noun, _, where = what.partition(" in ")
    for why, n in other.items():
        notes.append(f"{n} {noun}{'s' if n != 1 else ''} in {where} not reused, removed: {why}")


def find_results(
    study: Study, archive: Path, archive_usable: bool = True
) -> tuple[Found, list[str]]:
    """Where the study's cases already are, and notes on files set aside.

    Batch files first, then the archive (when ``archive_usable``: it passed its checks). A
    file is used only if it has this layout, record and engine (:func:`mismatch`) and its
    checksums verify; a batch file that fails them is removed (its cases are computed again)
    and named in the notes.
    """
    wanted = {c.case_id for c in study.cases}
    found: Found = {}
    notes: list[str] = []
    parts = parts_directory(archive)
    files = sorted(parts.glob(f"batch-*{batch_file.SUFFIX}")) if parts.is_dir() else []
    checked = checked_files(
        files, batch_file.read_attrs, batch_file.verify, study.record, notes,
        f"batch file in {parts}",
    )  # fmt: skip
    for path, _ in checked:
        try:
            _index_of(path, found, wanted)
        except (ArchiveFileError, OSError, RuntimeError, ValueError, KeyError) as exc:
            notes.append(f"{path} cannot be read ({exc}): its cases are computed again")
    if archive_usable and archive.is_file():
        try:
            why = mismatch(read_attrs(archive), study.record)
        except Exception:  # not an archive at all (replaced with --overwrite)
            why = "it is not a campipe archive"
        if why:
            log.info("not reusing %s: %s", archive, why)
        elif problems := verify(archive):
            notes.append(f"{archive} failed its checks ({'; '.join(problems)}): not reused")
        else:
            _index_of(archive, found, wanted)
    return found, notes


def earlier_cases(archive: Path) -> list[str]:
    """The case ids an archive (a file, or a parts archive's index) at ``archive`` holds
    before a run replaces it; [] where there is none or it cannot be read."""
    try:
        if archive.is_dir():
            from campipe.io.parts import read_index as read_parts_index

            return [str(c) for c in read_parts_index(archive).get("case", [])]
        if archive.is_file():
            return [str(c) for c in read_index(archive, CASE_ID)[0]]
    except Exception:  # damaged, or not an archive: its checks say so
        return []
    return []


def dropped_cases(archive: Path, before: list[str], study: Study, overwrite: bool) -> list[str]:
    """Refuse a run that would remove cases the archive at ``archive`` held before it
    (``before``, their ids) and this run's spec does not make, unless ``overwrite``; then the
    note that says how many it removed. A narrower sweep or an edited key would replace them,
    and nothing else keeps them (a helper lost 28 of 32 cluster cases to a rerun with one
    speed while the run only noted it).

    Raises
    ------
    ArchiveExistsError
        If cases would be removed and ``overwrite`` is False; nothing has been changed.
    """
    if not before:  # (a first run: no pass over the study's cases)
        return []
    wanted = {c.case_id for c in study.cases}
    dropped = sum(c not in wanted for c in before)
    if not dropped:
        return []
    held = f"{dropped} of the {len(before)} cases it holds are not in this run's spec"
    if not overwrite:
        raise ArchiveExistsError.at(
            str(archive),
            f"{held} (a narrower sweep, or an edited key), and this run would remove them; "
            "write it to another path (-o) to keep them, or remove them with --overwrite",
            found=f"{dropped} cases this spec does not make",
            expected="an archive holding only this spec's cases",
        )
    return [f"{archive}: {held} (a narrower sweep, or an edited key): removed (--overwrite)"]


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
        return ArchiveState(True, False, "a folder", False, kept=True)
    if not stat.S_ISREG(info.st_mode):
        return ArchiveState(True, False, "not a regular file", False)
    own = _inputs(study).get(archive.resolve())
    if own is not None:
        return ArchiveState(True, False, own, False, kept=True)
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
    same = attrs.get("study_key") == study_key(study)  # moved or copied with its spec: ours
    if mine and theirs and mine != theirs and not same:
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


def _inputs(study: Study) -> dict[Path, str]:
    """The files the study reads, resolved → what each is, in words: its spec and the lift
    tables its profiles read (``profile.file``, relative to the spec's folder)."""
    from campipe.study.spec.resolve import distinct_but_speed

    if study.spec.path is None:
        return {}
    spec = Path(study.spec.path).resolve()
    out = {spec: "the spec itself"}
    for case in distinct_but_speed(study.cases)[0]:
        table = case.values.get("profile.file")
        if table is not None:
            out.setdefault((spec.parent / str(table)).resolve(), f"the lift table {table}, "
                           "which the study reads (profile.file)")  # fmt: skip
    return out


def refuse(archive: Path, state: ArchiveState) -> ArchiveExistsError:
    fix = (
        "choose another archive path (-o): the study's own inputs and a folder are never "
        "replaced, not even with --overwrite"
        if state.kept
        else "choose another archive path (-o), or replace it with --overwrite"
    )
    return ArchiveExistsError.at(
        str(archive),
        f"exists and is {state.what}, not this study's archive; {fix}",
        found=state.what,
        expected="no file, or this study's archive",
    )


def clean_temporaries(archive: Path) -> None:
    """Remove temporary files a killed run left (this study's only)."""
    parts = parts_directory(archive)
    leftovers = [*parts.glob(".*.tmp"), *parts.glob(".reach-*")] if parts.is_dir() else []
    leftovers += [p for p in archive.parent.glob(f".{archive.name}.*.tmp") if is_temporary(p)]
    for p in leftovers:
        log.info("removing %s, left by an interrupted run", p)
        p.unlink(missing_ok=True)


def case_statuses(archive: Path) -> dict[str, str]:
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
    statuses = case_statuses(archive)
    total = len(read_variable(archive, CASE_ID))
    return StudyReport(
        archive, total, total, 0, 0, True, time.monotonic() - started, statuses=statuses
    )


def up_to_date(archive: Path, total: int, started: float) -> StudyReport:
    return StudyReport(
        archive,
        total,
        total,
        0,
        0,
        True,
        time.monotonic() - started,
        statuses=case_statuses(archive),
    )
