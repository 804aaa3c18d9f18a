"""A parts archive: a folder holding one compressed netCDF file per batch (its *parts*, each
written atomically by the worker that computed the batch, each with its checksums) and a
small JSON index, written last by the run, that names the parts and the study's case order.

Layout of a parts archive ``PATH/``::

    PATH/index.json          the index (:data:`INDEX`), written atomically once every part is
    PATH/part-<key>.nc       one batch's cases, a CF netCDF file as the single-file archive
                             (same variables and attributes), ``event_case`` its own rows

The index holds the archive's global attributes (``attrs``), the case ids in the study's
order (``case``), the compression of its parts and, for each part, its file name, cases,
events and the SHA-256 of its stored checksums (``checksum``): a reader finds a replaced
part without reading it. Only what the index names belongs to the archive.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path

from campipe.errors import CampipeError
from campipe.io.archive import CHECKSUM_ATTR, read_attrs, temporary_path, write_error

#: The index's file name inside a parts archive.
INDEX = "index.json"
#: How a part's file name begins and ends.
PART_PREFIX = "part-"
PART_SUFFIX = ".nc"
#: The index's format; an index of another format is not read.
INDEX_FORMAT = "campipe-parts-1"


class PartsIndexError(CampipeError, RuntimeError):
    """A parts archive whose index is missing or cannot be read (``key`` the archive)."""


def index_path(archive: Path) -> Path:
    return Path(archive) / INDEX


def part_name(key: str) -> str:
    """A part's file name from its batch key."""
    return f"{PART_PREFIX}{key}{PART_SUFFIX}"


def part_files(archive: Path) -> list[Path]:
    """The part files in a parts archive's folder, by name (the index's or not)."""
    return sorted(Path(archive).glob(f"{PART_PREFIX}*{PART_SUFFIX}"))


def is_parts_archive(path: str | Path) -> bool:
    """``path`` is a folder holding a parts archive's index."""
    return index_path(Path(path)).is_file()


def checksum_digest(checksums: str) -> str:
    """The index's checksum of a part: SHA-256 of the text of its stored checksums (the
    attribute :data:`~campipe.io.archive.CHECKSUM_ATTR`), 16 hex digits."""
    return hashlib.sha256(checksums.encode()).hexdigest()[:16]


def part_checksum(path: Path) -> str:
    """:func:`checksum_digest` of a part's stored checksums, read from its attributes."""
    return checksum_digest(str(read_attrs(path).get(CHECKSUM_ATTR, "")))


def write_index(
    archive: Path,
    attrs: Mapping[str, object],
    case_ids: list[str],
    parts: list[dict[str, object]],
    compression: str,
) -> Path:
    """Write the index atomically; returns its path.

    Parameters
    ----------
    attrs : mapping
        The archive's global attributes (text and numbers).
    case_ids : list of str
        The study's case ids, in its order.
    parts : list of dict
        Each part's ``file`` (name in the folder), ``cases``, ``events`` and ``checksum``.
    """
    path = index_path(archive)
    content = {
        "format": INDEX_FORMAT,
        "attrs": dict(attrs),
        "compression": compression,
        "parts": parts,
        "case": case_ids,
    }
    tmp = temporary_path(path)
    try:
        tmp.write_text(json.dumps(content, default=_plain))
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise write_error(path, exc) from None
    return path


def _plain(value: object) -> object:
    """numpy numbers and arrays in the attributes as JSON."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"cannot write {type(value).__name__} to the index")


def read_index(archive: str | Path) -> dict:
    """A parts archive's index (see the module).

    Raises
    ------
    PartsIndexError
        If the folder holds no index (a run not finished) or it cannot be read.
    """
    path = index_path(Path(archive))
    try:
        content = json.loads(path.read_text())
    except FileNotFoundError:
        raise PartsIndexError.at(
            str(archive),
            f"no {INDEX}: not a parts archive, or its run has not finished (rerun the same "
            "command to finish it)",
        ) from None
    except (OSError, ValueError) as exc:
        raise PartsIndexError.at(str(archive), f"its {INDEX} cannot be read ({exc})") from None
    if not isinstance(content, dict) or content.get("format") != INDEX_FORMAT:
        raise PartsIndexError.at(
            str(archive), f"its {INDEX} is not a campipe parts index ({INDEX_FORMAT})"
        )
    return content
