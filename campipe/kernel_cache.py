"""Where numba keeps campipe's compiled kernels: one user-wide folder per version of their
source, so that a fresh install or clone of a campipe this machine has run before loads its
kernels instead of compiling them again.

numba's own cache sits beside each source file (``__pycache__``): every new clone or venv
starts it empty and compiles every kernel again. Here a kernel is cached under
``<root>/<kernel source>/<package folder>``, where

- ``root`` is ``$NUMBA_CACHE_DIR/campipe`` when the environment sets numba's cache folder,
  else campipe's user cache folder (``~/.cache/campipe/numba`` on Linux);
- ``kernel source`` is the first hex digits of a SHA-256 over every file the kernels compile
  from (:data:`SOURCES`) and the numba and numpy versions. An edit anywhere in them moves
  every kernel to a new folder: numba's per-file stamp would keep a caller whose callee, in
  another file, changed.

Installing campipe's cache locator (:func:`locator`; :func:`install`, called by every module
that defines kernels before it defines them: numba picks a kernel's cache when it is
decorated) puts it ahead of numba's locators for campipe's files only. Any other function
keeps numba's behaviour, and so does everything when ``NUMBA_CACHE_LOCATOR_CLASSES`` is set
or the folder cannot be written (numba then falls back to ``__pycache__``). When a new kernel-source
folder is made, those beyond the :data:`KEEP` used last are removed; with them go the other
files a process keeps there for the next (``campipe.disk_cache``, :func:`ensure_folder`).

A process that loads its kernels does not set numba up to compile (:func:`_load_overload`);
one that compiles inlines campipe's helpers without numba's copies of their IR
(:func:`_inline_without_copies`). numba itself is imported only by those and the locator:
finding the folder does not import it, so the commands that only read the disk cache kept
there (``campipe query``, ``model``, ``validate``) do not.
"""

from __future__ import annotations

import functools
import logging
import os
import shutil
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from campipe.sources import PACKAGE, source_digest

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
    """The folder holding one folder per kernel source: numba's cache folder (the environment's
    ``NUMBA_CACHE_DIR``, read here without importing numba) or campipe's user cache folder."""
    numba_folder = os.environ.get("NUMBA_CACHE_DIR")
    if numba_folder:
        return Path(numba_folder) / "campipe"
    import platformdirs

    return Path(platformdirs.user_cache_dir("campipe", appauthor=False)) / "numba"


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
    """Make ``path``, this source's folder or one in it, for files other than kernels
    (``campipe.disk_cache``): made as numba makes a kernel's, so that making this source's
    folder prunes the others all the same (:func:`prune`)."""
    new = not cache_folder().exists()
    path.mkdir(parents=True, exist_ok=True)
    _made(new)


def _made(new: bool) -> None:
    """This source's folder exists: mark it used; prune the others if it is ``new``."""
    mark_used()
    if new:
        log.debug("new kernel cache folder %s", cache_folder())
        try:
            prune(cache_root())
        except OSError as exc:  # never fail a kernel over the clean-up
            log.debug("kernel cache folders not pruned: %s", exc)


def _is_source_folder(name: str) -> bool:
    return len(name) == 16 and all(c in "0123456789abcdef" for c in name)


@functools.cache
def locator() -> type:
    """numba's cache locator for campipe's kernels (see the module's docstring): a class made
    once numba is imported, so that reading this module (for the folder) does not import it."""
    from numba.core import caching

    class KernelCacheLocator(caching._CacheLocator):
        def __init__(self, py_func, py_file: str):
            self._py_file = py_file  # numba names it when it warns that a kernel cannot be cached
            self._lineno = py_func.__code__.co_firstlineno
            package = Path(py_file).resolve().parent.relative_to(ROOT)
            self._cache_path = str(cache_folder().joinpath(*package.parts))

        def ensure_cache_path(self) -> None:
            new = not cache_folder().exists()
            super().ensure_cache_path()
            _made(new)

        def get_cache_path(self) -> str:
            return self._cache_path

        def get_source_stamp(self) -> str:
            return source_hash()

        def get_disambiguator(self) -> str:
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                Path(py_file).resolve().relative_to(ROOT)
            except (ValueError, OSError):
                return None  # not campipe's: numba's own locators
            if getattr(sys, "frozen", False):
                return None
            try:
                self = cls(py_func, py_file)
                self.ensure_cache_path()
            except OSError as exc:  # not writable: numba's own locators
                log.debug("kernel cache folder unusable (%s); numba's __pycache__ instead", exc)
                return None
            return self

    return KernelCacheLocator


def install() -> None:
    """Put :func:`locator`'s class first among numba's cache locators (once), and load
    campipe's kernels without preparing numba to compile (:func:`_load_overload`). numba's
    locator list is internal (``CacheImpl``, ``_CacheImpl`` before 0.68): if it is not found,
    numba's own caching stays."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    if not isinstance(classes, list):
        log.debug("numba's cache locators not found: kernels cached in __pycache__")
        return
    if locator() not in classes:
        classes.insert(0, locator())
    cache = caching.Cache
    if getattr(cache.load_overload, "__wrapped__", None) is None and all(
        hasattr(cache, name) for name in ("_load_overload", "_guard_against_spurious_io_errors")
    ):
        _load_overload.__wrapped__ = cache.load_overload  # type: ignore[attr-defined]
        cache.load_overload = _load_overload


def _load_overload(self, sig, target_context):
    """numba's ``Cache.load_overload`` (which this replaces), without its
    ``target_context.refresh()`` for campipe's kernels.

    That refresh imports and registers every implementation numba compiles from (numba.np,
    numba.cpython, ...; and through them ``scipy.linalg``): 0.2 s of a study's start that
    loading compiled code does not use. What loading does use is set up here: numba's runtime
    (NRT: the kernels that allocate call it). Anything that compiles (a kernel of a new
    signature) refreshes the context itself, as numba's compiler always does."""
    if not isinstance(self._impl.locator, locator()):
        return _load_overload.__wrapped__(self, sig, target_context)  # type: ignore[attr-defined]
    from numba.core.runtime import rtsys

    rtsys.initialize(target_context)
    loaded = None  # stays None when the guard swallows an error: not cached
    with self._guard_against_spurious_io_errors():
        loaded = self._load_overload(sig, target_context)
    if loaded is None:  # numba compiles the kernel next
        _inline_without_copies()
    return loaded


@functools.cache
def _inline_without_copies() -> None:
    """Let numba inline campipe's ``inline="always"`` helpers without copying their IR (once a
    process, before the first of campipe's kernels compiles).

    For each call site, numba's ``InlineWorker.inline_function`` builds the helper's IR afresh
    (the untyped passes) and hands it to ``inline_ir``, which deep-copies it twice before
    splicing it into the caller: once to mutate, once to return unmutated; block by block, so
    each block copies the helper's whole scope again. No one else holds that fresh IR, and
    ``inline_function``'s caller (the ``InlineInlinables`` pass) drops the unmutated copy, so
    neither copy is needed; they were a sixth of a first run's compiling (numba/numba#8989).
    Here the fresh blocks copy as themselves while they are spliced in; the IR, and so the
    compiled code, is what numba's copies give. Only campipe's helpers are inlined this way,
    and only while numba's inliner has the shape this was written for (``inline_ir`` copies
    through a nested ``copy_ir`` alone); otherwise numba's own method stays."""
    from numba.core import inline_closurecall, ir

    worker = inline_closurecall.InlineWorker
    original = getattr(worker, "inline_function", None)
    code = getattr(getattr(worker, "inline_ir", None), "__code__", None)
    nested = [c.co_name for c in code.co_consts if hasattr(c, "co_name")] if code else []
    if original is None or nested != ["copy_ir"] or not hasattr(worker, "run_untyped_passes"):
        log.debug("numba's inliner has changed: helpers inlined with numba's copies")
        return

    class Fresh(ir.Block):
        def __deepcopy__(self, memo):
            return self

    def inline_function(self, caller_ir, block, i, function, arg_typs=None):
        if not (getattr(function, "__module__", None) or "").startswith("campipe."):
            return original(self, caller_ir, block, i, function, arg_typs)
        callee_ir = self.run_untyped_passes(function)
        fresh = list(callee_ir.blocks.values())
        for one in fresh:
            one.__class__ = Fresh
        try:
            freevars = function.__code__.co_freevars
            return self.inline_ir(caller_ir, block, i, callee_ir, freevars, arg_typs=arg_typs)
        finally:
            for one in fresh:
                one.__class__ = ir.Block

    inline_function.__wrapped__ = original  # type: ignore[attr-defined]
    worker.inline_function = inline_function
