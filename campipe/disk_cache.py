"""Files a process leaves for the next, beside the compiled kernels: the SI values of the
quantity texts it read (``campipe.units``), so that a run whose quantities were all read
before never imports pint (0.1 s of a one-case study's start); and the results of the
model's LAPACK calls (:func:`arrays`: a train's modes and its configurations' block forms),
so that a run of trains solved before never imports ``scipy.linalg`` (0.12 s).

They are kept in this source's folder of the kernel cache (``campipe.kernel_cache``: one
folder per version of the engine, the profiles, the model, numba and numpy, pruned with the
kernels), one file per kind and key; the caller's key names what else the content depends on
(LAPACK's results: the libraries' versions and :func:`processor_kind`, since OpenBLAS picks
its kernels by the processor and their last bits differ: numba keys its kernels on the
processor too, and a cache on a cluster's shared home is read by machines of many kinds).
A file holds a SHA-256 of its kind and key and one of its content, and is read back only when
both match: a file that is missing, damaged or another key's is a miss, and the caller
computes. A folder that cannot be written keeps nothing, silently.
"""

from __future__ import annotations

import functools
import hashlib
import io
import logging
import os
import platform
import tempfile
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: The first line of every file: its format.
MAGIC = b"campipe disk cache 1\n"
#: Files kept per kind, those written last (another key's, such as an older pint's, are left
#: behind by an upgrade).
KEEP = 8

_written: dict[str, int] = {}  # files of each kind :func:`arrays` wrote in this process
_written_lock = threading.Lock()


def cpu_info() -> dict[str, str]:
    """The first processor's fields in Linux's ``/proc/cpuinfo`` ("model name", "flags", …);
    empty elsewhere."""
    fields: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                if not line.strip():
                    break  # the first processor's block ends
                name, _, value = line.partition(":")
                fields.setdefault(name.strip(), value.strip())
    except OSError:
        pass
    return fields


@functools.cache
def processor_kind() -> str:
    """What a LAPACK result's last bits depend on beyond the libraries' versions: the
    processor's model and instruction sets (OpenBLAS picks its kernels by them: Haswell's and
    SkylakeX's round differently) and an ``OPENBLAS_CORETYPE`` that overrides its choice."""
    info = cpu_info()
    features = info.get("flags", info.get("Features", ""))
    model = info.get("model name", "") or platform.processor() or platform.machine()
    flags = hashlib.sha256(" ".join(sorted(features.split())).encode()).hexdigest()[:16]
    return f"{model}; flags {flags}; OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '')}"


def folder(kind: str) -> Path:
    """The folder of ``kind``'s files, in this source's folder of the kernel cache."""
    from campipe import kernel_cache  # the folder only: numba is not imported

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


def arrays(
    kind: str,
    inputs: Sequence[np.ndarray],
    version: str,
    compute: Callable[[], Sequence[np.ndarray]],
) -> list[np.ndarray]:
    """``compute()``'s arrays, a pure function of ``inputs`` and of the library versions
    named in ``version``: read back if kept for exactly these inputs (dtype, shape and every
    bit), else computed and kept. The arrays are stored in numpy's ``.npy`` format and read
    back bit for bit, never unpickled; each is returned contiguous, in the order it was
    computed in (C or Fortran), whether computed or read, so that what is done with it next
    cannot depend on where it came from.

    A process writes at most :data:`KEEP` files of a kind: a study of hundreds of trains
    computes every one as before, without a write each; a study of a few reads them all."""
    digest = hashlib.sha256(version.encode())
    for a in inputs:
        digest.update(f"{a.dtype.str} {a.shape}\n".encode())
        digest.update(np.ascontiguousarray(a).tobytes())
    key = digest.hexdigest()
    content = read(kind, key)
    if content is not None:
        try:
            f = io.BytesIO(content)
            count = int(np.load(f, allow_pickle=False))
            return [np.load(f, allow_pickle=False) for _ in range(count)]
        except (ValueError, OSError, EOFError):
            log.debug("%s: unreadable arrays, computed again", kind)
    out = [
        a if a.flags.c_contiguous or a.flags.f_contiguous else np.ascontiguousarray(a)
        for a in map(np.asarray, compute())
    ]
    with _written_lock:
        if _written.get(kind, 0) >= KEEP:
            return out
        _written[kind] = _written.get(kind, 0) + 1
    f = io.BytesIO()
    np.save(f, np.int64(len(out)), allow_pickle=False)
    for a in out:
        np.save(f, a, allow_pickle=False)
    write(kind, key, f.getvalue())
    return out
