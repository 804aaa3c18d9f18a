"""The output rule: what a command may replace at a path it writes.

One rule for every command that writes a file beside the archive (``campipe study`` decides
about the archive itself in ``campipe.study.run.resume``, by the same words):

- **Nothing there**: written.
- **The command's own input** (the spec it reads, the archive it draws or replays from):
  never replaced, not even with ``--overwrite``.
- **A folder, or not a regular file** (a FIFO, a device): never replaced.
- **A file this command writes** (``Kind.ours``: a netCDF file whose attributes say campipe
  wrote it for the same command and study; a recording or a figure of the format the
  command writes, told by its first bytes): replaced, as a rerun expects.
- **Anything else** (another study's archive, a netCDF or HDF5 file campipe did not write,
  a spec, a text file, a symbolic link to a missing file): refused unless ``overwrite``.

A path a spec gives (``plots[].output``), and whatever a command writes into a folder it
was given (``campipe init``), stays inside that folder once symbolic links are followed:
``../x.pdf``, an absolute path elsewhere or a link out of the folder are refused, naming the
key. Files are written at a temporary path and renamed into place, so a symbolic link at the
path is replaced, never followed.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from campipe.errors import CampipeError
from campipe.io import NETCDF_MAGIC

#: Bytes read from the start of a file to tell its format.
HEAD_BYTES = 64
#: First bytes of the formats campipe writes beside an archive, by suffix.
MAGIC = {
    ".png": (b"\x89PNG\r\n\x1a\n",),
    ".pdf": (b"%PDF-",),
    ".svg": (b"<?xml", b"<svg"),
    ".rrd": (b"RRF",),  # rerun's recordings: RRF2 today
}


class OutputExistsError(CampipeError, ValueError):
    """A file at an output path that the command may not replace (``key`` the option or spec
    key naming the path, ``found`` what the file is)."""


class OutputPathError(CampipeError, ValueError):
    """An output path outside the folder it must stay in (``key`` the option or spec key,
    ``found`` the path)."""


@dataclass(frozen=True)
class Kind:
    """What a command writes: ``what`` in words, and ``ours(path)``: the file at ``path`` is
    one the command wrote itself (for the same study), which a rerun may replace."""

    what: str
    ours: Callable[[Path], bool]


def head(path: Path) -> bytes:
    """The first bytes of a file (empty if it cannot be read)."""
    try:
        with open(path, "rb") as f:
            return f.read(HEAD_BYTES)
    except OSError:
        return b""


def is_netcdf(path: Path) -> bool:
    """A netCDF or HDF5 file, by its first bytes."""
    return head(path).startswith(NETCDF_MAGIC)


def same_format(path: Path) -> bool:
    """The file at ``path`` is of the format its suffix names (a PNG in ``x.png``...)."""
    magic = MAGIC.get(path.suffix.lower())
    return magic is not None and head(path).lstrip().startswith(magic)


#: A figure or a recording: replaced when it is a file of the format written.
FIGURE = Kind("a figure", same_format)
RECORDING = Kind("a rerun recording", same_format)


def check_output(
    path: str | Path,
    key: str,
    kind: Kind,
    *,
    overwrite: bool = False,
    inputs: Iterable[tuple[str | Path | None, str]] = (),
    inside: str | Path | None = None,
    describe: Callable[[Path], str] | None = None,
) -> Path:
    """Refuse to write ``path`` where the output rule (the module's) says no.

    Parameters
    ----------
    path : str or Path
        The file the command is about to write.
    key : str
        The option or spec key that named it (``-o``, ``plots[0].output``), named by the error.
    kind : Kind
        What the command writes, and how it tells a file it wrote.
    overwrite : bool
        ``--overwrite`` given: replace any regular file but the command's inputs.
    inputs : iterable of (path or None, words)
        The command's own inputs, never replaced: (the spec, "the spec"), ...
    inside : str or Path, optional
        The folder the path must stay in once links are followed.
    describe : callable, optional
        What a netCDF file is, in words (from its attributes), for the message.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputPathError
        If ``path`` leaves ``inside``.
    OutputExistsError
        If a file there may not be replaced.
    """
    path = Path(path)
    if inside is not None:
        _check_inside(path, key, Path(inside))
    try:
        info = path.lstat()
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise _refused(path, key, f"a path that cannot be read ({exc.strerror})", False) from None
    if stat.S_ISLNK(info.st_mode) and not path.exists():
        what = "a symbolic link to a missing file"
        if overwrite:
            return path
        raise _refused(path, key, what, True)
    info = path.stat()
    if stat.S_ISDIR(info.st_mode):
        raise _refused(path, key, "a folder", False)
    if not stat.S_ISREG(info.st_mode):
        raise _refused(path, key, "not a regular file", False)
    for given, words in inputs:
        if given is not None and _same_file(path, Path(given)):
            raise _refused(path, key, f"{words}, which this command reads", False)
    if kind.ours(path) or overwrite:
        return path
    raise _refused(path, key, _what(path, kind, describe), True)


def _check_inside(path: Path, key: str, folder: Path) -> None:
    resolved = Path(os.path.realpath(path))
    home = Path(os.path.realpath(folder))
    if resolved != home and home not in resolved.parents:
        raise OutputPathError.at(
            key,
            f"{path} is outside the folder {folder} (at {resolved}); write a path inside it, "
            f"such as {path.name}",
            found=str(path),
            expected=f"a path inside {folder}",
        )


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _what(path: Path, kind: Kind, describe: Callable[[Path], str] | None) -> str:
    if is_netcdf(path):
        words = describe(path) if describe is not None else ""
        return words or "a netCDF or HDF5 file campipe did not write for this command"
    if path.suffix.lower() in MAGIC:
        return f"a file that is not {kind.what} (not a {path.suffix.lower()[1:]} file)"
    wrote = "" if "campipe" in kind.what else " campipe wrote"  # (export's names itself)
    return f"a file that is not {kind.what}{wrote}"


def _refused(path: Path, key: str, what: str, overwrite_helps: bool) -> OutputExistsError:
    fix = (
        f"choose another path ({key}), or replace it with --overwrite"
        if overwrite_helps
        else f"choose another path ({key})"
    )
    return OutputExistsError.at(
        key,
        f"{path} exists and is {what}; {fix}",
        found=what,
        expected="no file, or one this command wrote (with --overwrite: a regular file)",
    )


def describe_netcdf(path: Path) -> str:
    """What a netCDF file is, from its attributes: a campipe study's archive, an onset
    archive, or a file campipe did not write ("" when its attributes cannot be read)."""
    attrs = netcdf_attrs(path)
    if attrs is None:
        return ""
    name = str(attrs.get("study_name", ""))[:60]
    if str(attrs.get("campipe_layout", "")).startswith("campipe-archive"):
        return f"the archive of the study {name}"
    if attrs.get("campipe_file") == ONSET_FILE or "speed_range_rpm" in attrs:
        return f"the onset archive of {name} ({str(attrs.get('spec_file', ''))[:200]})"
    return "a netCDF file campipe did not write"


def netcdf_attrs(path: Path) -> dict | None:
    """A netCDF file's global attributes, or None for a file that is not one (or unreadable)."""
    from campipe.io.archive import read_attrs

    if not is_netcdf(path):
        return None
    try:
        return read_attrs(path)
    except Exception:  # damaged, or not netCDF after all
        return None


#: The ``campipe_file`` attribute of an onset archive (``campipe onset``, a spec's ``search``).
ONSET_FILE = "onset"


def onset_kind(study_name: str, spec_file: str) -> Kind:
    """An onset archive of the study ``study_name`` whose spec is ``spec_file`` (relative to
    the archive's folder): one written for another spec of the same name is not ours. An
    onset archive from before ``campipe_file`` was written is told by its speed range."""

    def ours(path: Path) -> bool:
        attrs = netcdf_attrs(path)
        if attrs is None or attrs.get("study_name") != study_name:
            return False
        if attrs.get("campipe_file") == ONSET_FILE:
            theirs = str(attrs.get("spec_file", ""))
            return not theirs or not spec_file or theirs == spec_file
        return "speed_range_rpm" in attrs and "campipe_layout" not in attrs

    return Kind("an onset archive of this spec", ours)
