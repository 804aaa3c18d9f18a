"""Where numba keeps campipe's compiled kernels, through numba's public settings only: one
user-wide folder per version of the kernels' source, numba's cache folder
(``NUMBA_CACHE_DIR``) inside it.

The kernels are decorated with numba's own ``cache=True``. Where numba writes that cache is
its documented environment variable ``NUMBA_CACHE_DIR``, read once, when numba is first
imported. Before campipe's engine or profiles import numba, :func:`configure` sets it to
``<root>/<kernel source>/numba``, where

- ``root`` is campipe's user cache folder (``~/.cache/campipe/kernels`` on Linux);
- ``kernel source`` is the first hex digits of a SHA-256 over every file the kernels compile
  from (:data:`SOURCES`) and the numba and numpy versions. An edit anywhere in them moves
  every kernel to a new folder: numba's own check (the stamp of the kernel's own file) would
  keep a kernel whose callee, in another file, changed.

It does not when the environment already sets ``NUMBA_CACHE_DIR`` (numba then caches there,
and after an edit to campipe's engine that folder should be emptied), or when numba was
imported before campipe (numba's default then: ``__pycache__`` beside each source file).
numba keys a cached kernel by its file's path and time stamp as well: a new clone or venv of
the same campipe compiles its kernels again. When a new kernel-source folder is made, those
beyond the :data:`KEEP` used last are removed; with them go the other files a process keeps
there for the next (``campipe.disk_cache``, :func:`ensure_folder`) and campipe's record of
which kernels were compiled (:func:`compiled_marker`, for the first run's notice).

This module does not import numba: the commands that only read the disk cache kept here
(``campipe query``, ``model``, ``validate``) do not either.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import shutil
import sys
import time
from collections.abc import Iterable
from importlib import metadata
from pathlib import Path

import numpy as np

from campipe.sources import PACKAGE, source_digest, source_files

log = logging.getLogger(__name__)

ROOT = PACKAGE
#: What the kernels compile from: the engine, the profiles, the model and the base modules
#: they read constants from; and the two modules that compute this hash.
SOURCES = (
    "engine",
    "profiles",
    "model",
    "vocabulary.py",
    "constants.py",
    "kernel_cache.py",
    "sources.py",
)
#: numba's documented environment variable for its cache folder.
NUMBA_CACHE_DIR = "NUMBA_CACHE_DIR"
#: Kernel-source folders kept: those used last (their modification time, :func:`mark_used`).
KEEP = 3
#: A folder used this recently [s] is never removed (another process may be loading from it).
IN_USE = 3600.0


def hash_sources(root: Path) -> str:
    """SHA-256 (hex) of the numba and numpy versions and of the :data:`SOURCES` under the
    package folder ``root`` (``campipe.sources.source_digest``)."""
    numba = metadata.version("numba")  # as numba.__version__, without importing numba
    return source_digest(SOURCES, root, f"numba {numba}; numpy {np.__version__}")


@functools.cache
def source_hash() -> str:
    """:func:`hash_sources` of this campipe, once a process."""
    return hash_sources(ROOT)


def cache_root() -> Path:
    """The folder holding one folder per kernel source: in campipe's user cache folder."""
    import platformdirs

    return Path(platformdirs.user_cache_dir("campipe", appauthor=False)) / "kernels"


@functools.cache
def cache_folder() -> Path:
    """The folder of this source's kernels (once a process: every kernel asks)."""
    return cache_root() / source_hash()[:16]


def prune(root: Path, keep: int = KEEP, now: float | None = None) -> list[Path]:
    """Remove the kernel-source folders under ``root`` beyond the ``keep`` used last (a
    process marks its folder used, :func:`mark_used`) that no process used for
    :data:`IN_USE` seconds; returns those removed. A folder another process removes meanwhile
    is passed over."""
    now = time.time() if now is None else now
    used = []
    for p in root.iterdir():
        try:
            if p.is_dir() and _is_source_folder(p.name):
                used.append((p.stat().st_mtime, p))
        except OSError:
            continue
    used.sort(reverse=True)
    removed = []
    for when, old in used[keep:]:
        if now - when > IN_USE:
            shutil.rmtree(old, ignore_errors=True)
            removed.append(old)
    return removed


@functools.cache
def mark_used() -> None:
    """Set this source's folder's modification time to now, once a process: :func:`prune`
    keeps the folders used last."""
    try:
        os.utime(cache_folder())
    except OSError as exc:
        log.debug("cannot mark the kernel cache folder used: %s", exc)


def ensure_folder(path: Path) -> None:
    """Make ``path``, this source's folder or one in it; making this source's folder marks
    it used and prunes the others (:func:`prune`)."""
    new = not cache_folder().exists()
    path.mkdir(parents=True, exist_ok=True)
    mark_used()
    if new:
        log.debug("new kernel cache folder %s", cache_folder())
        try:
            prune(cache_root())
        except OSError as exc:  # never fail a run over the clean-up
            log.debug("kernel cache folders not pruned: %s", exc)


def configure() -> str | None:
    """Point numba's cache at this source's folder (``NUMBA_CACHE_DIR``, see the module's
    docstring), unless the environment sets it or numba is imported already; the folder
    numba caches in, or None for numba's default (``__pycache__`` beside the sources).
    Called by ``campipe.engine`` and ``campipe.profiles`` before any of their modules
    imports numba; the environment passes the setting on to the processes campipe starts."""
    if NUMBA_CACHE_DIR not in os.environ and "numba" not in sys.modules:
        folder = cache_folder() / "numba"
        try:
            ensure_folder(folder)
        except OSError as exc:  # not writable: numba's own default
            log.debug("kernel cache folder unusable (%s); numba's default instead", exc)
        else:
            os.environ[NUMBA_CACHE_DIR] = str(folder)
    return os.environ.get(NUMBA_CACHE_DIR) or None


def stamp_of(root: Path, numba_folder: str) -> str:
    """SHA-256 (hex) of what numba checks before it loads a cached kernel, beyond the
    source's folder: the folder it caches in (``numba_folder``, "" for its default) and the
    path, modification time and size of each of the :data:`SOURCES` under the package folder
    ``root``. A copy of campipe at another path, or the same files written again, has
    another stamp: numba compiles its kernels again."""
    h = hashlib.sha256(numba_folder.encode())
    for path in source_files(SOURCES, root):
        st = path.stat()
        h.update(f"\n{path}\0{st.st_mtime_ns}\0{st.st_size}".encode())
    return h.hexdigest()


@functools.cache
def numba_stamp() -> str:
    """:func:`stamp_of` this campipe and numba's cache folder, once a process."""
    return stamp_of(ROOT, os.environ.get(NUMBA_CACHE_DIR, ""))


def compiled_marker(name: str) -> Path:
    """The file recording that the kernels named ``name`` (``campipe.engine.kernels``) were
    compiled into numba's cache for :func:`numba_stamp`: written after they were
    (:func:`mark_compiled`), removed with this source's folder."""
    return cache_folder() / "compiled" / f"{numba_stamp()[:16]}-{name.replace(' ', '-')}"


def mark_compiled(names: Iterable[str]) -> None:
    """Record that the kernels of ``names`` are in numba's cache (:func:`compiled_marker`);
    nothing is recorded where the folder cannot be written (the next run says again that it
    compiles, and finds them cached)."""
    for name in names:
        marker = compiled_marker(name)
        try:
            ensure_folder(marker.parent)
            marker.touch()
        except OSError as exc:
            log.debug("%s not recorded as compiled: %s", name, exc)


def _is_source_folder(name: str) -> bool:
    return len(name) == 16 and all(c in "0123456789abcdef" for c in name)
