"""Files a process leaves for the next, beside the compiled kernels: the SI values of the
quantity texts it read (``campipe.units``), so that a run whose quantities were all read
before never imports pint (0.1 s of a one-case study's start).

They are kept in this source's folder of the kernel cache (``campipe.kernel_cache``: one
folder per version of the engine, the profiles, the model, numba and numpy, pruned with the
kernels), one file per kind and key; the caller's key names what else the content depends on.
A file holds a SHA-256 of its kind and key and one of its content, and is read back only when
both match: a file that is missing, damaged or another key's is a miss, and the caller
computes. A folder that cannot be written keeps nothing, silently.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

#: The first line of every file: its format.
MAGIC = b"campipe disk cache 1\n"
#: Files kept per kind, those written last (another key's, such as an older pint's, are left
#: behind by an upgrade).
KEEP = 8


def folder(kind: str) -> Path:
    """The folder of ``kind``'s files, in this source's folder of the kernel cache."""
    from campipe import kernel_cache  # numba: a run loads it for its kernels anyway

    return kernel_cache.cache_folder() / kind


def _digest(kind: str, key: str) -> str:
    return hashlib.sha256(f"{kind}\n{key}".encode()).hexdigest()


def read(kind: str, key: str) -> bytes | None:
    """The content kept for ``kind`` and ``key``; None if there is none, or if its file is
    damaged or another key's."""
    digest = _digest(kind, key)
    try:
        data = (folder(kind) / digest[:32]).read_bytes()
    except OSError:
        return None
    head = MAGIC + digest.encode() + b"\n"
    check, _, content = data[len(head) :].partition(b"\n")
    if not data.startswith(head) or check != hashlib.sha256(content).hexdigest().encode():
        log.debug("%s/%s: damaged or another key's, passed over", kind, digest[:32])
        return None
    return content


def write(kind: str, key: str, content: bytes) -> None:
    """Keep ``content`` for ``kind`` and ``key``, written whole or not at all (another process
    reads the old file or the new); nothing is kept where the folder cannot be written."""
    from campipe import kernel_cache

    digest = _digest(kind, key)
    where = folder(kind)
    check = hashlib.sha256(content).hexdigest().encode()
    tmp = None
    try:
        kernel_cache.ensure_folder(where)
        fd, tmp = tempfile.mkstemp(dir=where, prefix=".", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(MAGIC + digest.encode() + b"\n" + check + b"\n" + content)
        os.replace(tmp, where / digest[:32])
        tmp = None
        prune(where)
    except OSError as exc:
        log.debug("%s not kept: %s", kind, exc)
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)


def prune(where: Path, keep: int = KEEP) -> None:
    """Remove the files in ``where`` beyond the ``keep`` written last (not those being
    written); a file another process removes meanwhile is passed over."""
    written = []
    for p in where.iterdir():
        if p.name.startswith("."):
            continue
        try:
            written.append((p.stat().st_mtime, p))
        except OSError:
            continue
    written.sort(reverse=True)
    for _, old in written[keep:]:
        old.unlink(missing_ok=True)
