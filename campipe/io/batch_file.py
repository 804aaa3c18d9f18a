"""Batch files: one finished batch of a study, kept until the archive holds its cases.

A batch file is a NumPy ``.npz`` (an uncompressed zip of ``.npy`` arrays, written by
``numpy.savez`` and read with ``allow_pickle=False``) holding the batch's arrays and, as the
member :data:`ATTRS`, its attributes as JSON. It is written at a temporary path and renamed
into place (``os.replace``), so a rerun after a killed run sees a whole file or none; every
member carries the zip's CRC-32, and the member :data:`HASH` a BLAKE2b of every other
member's name, type, shape and bytes, which :func:`verify` checks: a CRC alone is
recomputed by whatever saves the file again, so an edited and re-saved batch passed. It
is not synced to the disk (``fsync``): a killed process leaves its writes to the system,
and what a system crash leaves of a file not yet on the disk fails those checks, so a rerun
computes its cases again. A batch file is scratch, no copy of anything else; the archive,
the product, is synced before it is renamed into place. Syncing each batch file cost the
worker that wrote it a wait for the disk, batch after batch.

Not netCDF: HDF5 is not thread-safe, so every netCDF call of a process is serialised
(``campipe.io.archive.LOCK``), and a worker storing its batch waited while the archive's
compression held that lock. A batch file involves no HDF5: a worker stores it in a few
milliseconds, beside the archive being written. Its members are the names the archive gives
the same variables; the case ids are the member ``case``.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from campipe.io.archive import temporary_path, write_error

#: The member holding a batch file's attributes (JSON text).
ATTRS = "attributes"
#: The member holding the BLAKE2b of the others' content (hex text, :func:`content_hash`).
HASH = "content_hash"
#: How a batch file's name ends.
SUFFIX = ".npz"
#: Members that are not arrays of the batch.
_META = (ATTRS, HASH)


def content_hash(members: Mapping[str, np.ndarray]) -> str:
    """BLAKE2b (32 bytes, hex) of ``members`` (but :data:`HASH`) in name order: each name,
    dtype, shape and bytes."""
    h = hashlib.blake2b(digest_size=32)
    for name in sorted(members):
        if name == HASH:
            continue
        a = np.ascontiguousarray(members[name])
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.reshape(-1).view(np.uint8).data)
    return h.hexdigest()


def write(path: Path, arrays: Mapping[str, np.ndarray], attrs: Mapping[str, object]) -> Path:
    """Write ``arrays`` (text arrays as fixed-width unicode) and ``attrs`` to ``path``
    atomically; returns the path.

    Raises
    ------
    campipe.io.archive.ArchiveWriteError
        If the file cannot be written; nothing is left at ``path`` then.
    """
    members: dict[str, Any] = {name: np.asarray(a) for name, a in arrays.items()}
    for name, a in members.items():
        if a.dtype == object:
            members[name] = a.astype(str)
    members[ATTRS] = np.array(json.dumps(dict(attrs), sort_keys=True))
    members[HASH] = np.array(content_hash(members))
    tmp = temporary_path(path)
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **members)  # no object arrays: nothing is pickled
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise write_error(path, exc) from None
    return path


def read(path: Path, names: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """The arrays ``names`` of a batch file (default: all but its attributes; text arrays as
    object arrays of str). Reading a member whole checks its CRC-32."""
    with np.load(path, allow_pickle=False) as z:
        wanted = [n for n in z.files if n not in _META] if names is None else list(names)
        out = {name: z[name] for name in wanted}
    return {k: v.astype(object) if v.dtype.kind == "U" else v for k, v in out.items()}


def read_attrs(path: Path) -> dict[str, object]:
    """A batch file's attributes."""
    with np.load(path, allow_pickle=False) as z:
        attrs = json.loads(str(z[ATTRS][()]))
    if not isinstance(attrs, dict):
        raise ValueError(f"{path}: its attributes are not a mapping")
    return attrs


def verify(path: Path) -> list[str]:
    """``[]`` if every member of the file reads back as written (the zip's CRC-32 of each,
    then their content against the file's :data:`HASH`) and its attributes read, else why
    not. Reads the whole file twice (the CRCs, then the arrays)."""
    try:
        with zipfile.ZipFile(path) as z:
            bad = z.testzip()
        if bad is not None:
            return [f"its member {bad} differs from its checksum"]
        read_attrs(path)
        with np.load(path, allow_pickle=False) as npz:
            members = {name: npz[name] for name in npz.files}
    except Exception as exc:  # a damaged zip fails in many ways; each means the same
        return [f"it cannot be read ({type(exc).__name__}: {str(exc)[:200]})"]
    if HASH not in members:
        return ["it holds no content hash (an older campipe wrote it)"]
    if str(members[HASH][()]) != content_hash(members):
        return ["its content differs from its hash (edited and saved again?)"]
    return []
