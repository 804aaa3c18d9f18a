"""netCDF files of a study, the archive above all, written atomically (its batch files are
:mod:`campipe.io.batch_file`'s).

Every file is written at a temporary path in its final folder and renamed into place
(``os.replace``) only once complete and flushed, so a reader (or a rerun after a crash) sees
either the whole file or none. Files are netCDF-4 (HDF5): variables along ``case`` are chunked
``CASE_CHUNK`` cases per chunk and compressed (:data:`COMPRESSIONS`); ``xarray.open_dataset``
reads them as they are.

Rows are written a block at a time, so a writer holds no more than the rows it is given: the
archive is assembled by streaming batch after batch into it. A variable written in row order
(whole, or block after block from its first row) is checksummed as it is written; only one
written out of order is read back for its checksum when the file is committed.

netCDF-C and HDF5 are not thread-safe: every call into netCDF4 here holds :data:`LOCK`.
"""

from __future__ import annotations

import errno
import hashlib
import itertools
import json
import logging
import os
import platform
import shutil
import socket
import threading
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from campipe import __version__
from campipe.errors import CampipeError
from campipe.io import NETCDF_MAGIC
from campipe.io.compression import COMPRESSION, COMPRESSIONS
from campipe.io.digests import (
    ATTRIBUTES_ENTRY,
    CHECKSUM_ATTR,
    RunningDigest,
    attributes_digest,
    checksums,
    variable_digest,
)
from campipe.io.lock import ArchiveBusyError, lock_path, writing
from campipe.io.watch import NETCDF_LOCK, progress, watched

__all__ = [
    "COMPRESSION",
    "COMPRESSIONS",
    "ArchiveBusyError",
    "ArchiveFileError",
    "NetCDFWriter",
    "VariableSpec",
    "lock_path",
    "writing",
]

log = logging.getLogger(__name__)

#: Serialises netCDF4 calls from this process's threads (``campipe.io.watch``'s, which a
#: watched read holds while it reads).
LOCK = NETCDF_LOCK
#: Cases per chunk of a variable along case and samples (a history): eight cases' histories
#: compress a third better than one case's alone and cost HDF5 an eighth of the chunks; reading
#: one case decompresses eight cases' rows of a variable (46 kB of a 721-sample history).
CASE_CHUNK = 8
#: Cases per chunk of a 1-D per-case variable, events per chunk of an event variable.
ROW_CHUNK = 4096
#: Chunk cache of each such variable in an archive [bytes] and its hash slots.
VECTOR_CACHE = 2**20
VECTOR_CACHE_SLOTS = 101
#: Packages whose versions an archive records.
DEPENDENCIES = ("numpy", "scipy", "numba", "xarray", "netCDF4", "dask", "distributed", "pint")
_counter = itertools.count()


@dataclass(frozen=True)
class VariableSpec:
    """A variable to create: name, dimensions, type and attributes."""

    name: str  # variable name
    dims: tuple[str, ...]  # dimensions, case first where present
    dtype: str  # numpy dtype string ("f8", "i1", "i4", "i8") or "str"
    attrs: Mapping[str, object]  # netCDF attributes


class ArchiveFileError(CampipeError, RuntimeError):
    """A file that is not a campipe archive or batch file (``key`` the file)."""


class NotNetcdfError(ArchiveFileError, ValueError):
    """A path given as an archive that is not a netCDF file at all (the user's input)."""


class ArchiveDamagedError(ArchiveFileError):
    """A file whose variables differ from the checksums stored when it was written, or
    cannot be read (``key`` the file, ``found`` the variables: ``attributes`` for the global
    attributes)."""


class ArchiveWriteError(CampipeError, RuntimeError):
    """A file that cannot be written: a full disk, a read-only folder (``key`` the file,
    ``found`` the errno where the system gave one)."""


@contextmanager
def _writes(path: Path) -> Iterator[None]:
    """netCDF-C's and the system's write failures as ArchiveWriteError naming the file, the
    cause where known, and the free space of its folder (netCDF-C says only 'HDF error')."""
    try:
        yield
    except ArchiveWriteError:
        raise
    except (OSError, RuntimeError) as exc:
        raise write_error(path, exc) from None


def missing_filter(exc: BaseException) -> str | None:
    """What to do about netCDF-C's "Filter error" (the HDF5 plugin of a compression not
    found, as when ``HDF5_PLUGIN_PATH`` names a folder without it), or None for another
    error."""
    if not isinstance(exc, RuntimeError) or "Filter error" not in str(exc):
        return None
    where = os.environ.get("HDF5_PLUGIN_PATH")
    return (
        "netCDF-C found no HDF5 plugin for the compression (HDF5_PLUGIN_PATH "
        f"{'is ' + repr(where) if where else 'is unset'}); unset HDF5_PLUGIN_PATH to use "
        "the plugins the netCDF4 package installs, or add their folder to it; for archives "
        "that need no plugin, set run.compression: zlib"
    )


def not_netcdf(path: str | Path) -> bool:
    """``path`` is a file that does not begin as a netCDF file does (a folder, a missing or
    unreadable file: False, its reader says why)."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        return False
    return not head.startswith(NETCDF_MAGIC)


#: What a file that is not netCDF at all is told.
NOT_NETCDF = "not a netCDF file (an archive campipe writes is one): check the path"


def unreadable(exc: BaseException, path: str | Path | None = None) -> str:
    """Why a file cannot be read as an archive, from the exception its reader raised (not
    netCDF, damaged, or a compression without its plugin: each reader fails its own way);
    given the file's ``path``, one that is not netCDF at all is said to be so."""
    if path is not None and not_netcdf(path):
        return NOT_NETCDF
    why = f"cannot read as an archive ({type(exc).__name__}: {str(exc)[:200]})"
    plugin = missing_filter(exc)
    if plugin is not None:
        return f"{why}: {plugin}"
    return (
        f"{why}: its structure is damaged (a changed byte, a cut copy); restore it from a "
        "copy, or run the study again to write it anew (campipe study)"
    )


def unreadable_error(path: str | Path, exc: BaseException) -> ArchiveFileError:
    """The error for ``path``, which its reader refused with ``exc``: a NotNetcdfError (the
    user's input) for a file that is not netCDF at all, else an ArchiveFileError saying why
    (``unreadable``)."""
    if not_netcdf(path):
        return NotNetcdfError.at(str(path), NOT_NETCDF)
    return ArchiveFileError.at(str(path), unreadable(exc))


def write_error(path: Path, exc: BaseException) -> ArchiveWriteError:
    """An ArchiveWriteError for ``exc`` raised while writing ``path``."""
    code = getattr(exc, "errno", None)
    why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    if (plugin := missing_filter(exc)) is not None:
        return ArchiveWriteError.at(str(path), f"cannot write ({why}): {plugin}")
    try:
        free = shutil.disk_usage(path.parent).free
        shown = f"{free / 1e9:.3g} GB" if free >= 1e9 else f"{free / 1e6:.3g} MB"
        space = f"; {shown} free in {path.parent}"
        full = free < 64 * 2**20
    except OSError:
        space, full = "", False
    if code in (errno.ENOSPC, errno.EDQUOT) or (code is None and full):
        hint = "the disk is full: free some space"
    elif code in (errno.EACCES, errno.EPERM, errno.EROFS):
        hint = "the folder is not writable: choose another archive path (-o)"
    elif code == errno.ENAMETOOLONG:
        hint = "the file name is too long: choose a shorter archive path (-o)"
    elif code == errno.EFBIG:
        hint = "the file is larger than this system allows"
    else:
        hint = "check the disk"
    return ArchiveWriteError.at(
        str(path),
        f"cannot write ({why}){space}; {hint}, then rerun the same command to resume",
        found=code,
    )


def temporary_path(path: Path) -> Path:
    """A unique hidden name beside ``path`` (same file system, so the rename is atomic)."""
    tag = f"{os.getpid()}-{threading.get_ident()}-{next(_counter)}"
    return path.with_name(f".{path.name}.{tag}.tmp")


def is_temporary(path: Path) -> bool:
    return path.name.startswith(".") and path.name.endswith(".tmp")


class NetCDFWriter:
    """Creates a netCDF file at a temporary path; :meth:`commit` renames it into place.

    ``sizes`` maps each dimension to its length, or to None for an unlimited dimension that
    :meth:`append` extends (the archive's ``event``: its length is known only at the end).
    Use as a context manager: leaving the block by an exception removes the temporary file.
    """

    def __init__(
        self,
        path: str | Path,
        sizes: Mapping[str, int | None],
        variables: Iterable[VariableSpec],
        attrs: Mapping[str, object],
        compression: str = COMPRESSION,
    ):
        import netCDF4

        self.path = Path(path)
        self.filters = COMPRESSIONS[compression]
        if compression == "zstd" and not getattr(netCDF4, "__has_zstandard_support__", False):
            raise ArchiveWriteError.at(
                str(self.path),
                f"cannot write zstd: this netCDF4 (netCDF-C {netCDF4.__netcdf4libversion__}) "
                "was built without it; set run.compression: zlib, or install netCDF4's wheel "
                "(pip install netCDF4), which has it",
            )
        self.tmp = temporary_path(self.path)
        self.variables = {v.name: v for v in variables}
        #: the stored checksums' text (:data:`CHECKSUM_ATTR`), once committed
        self.checksum_text = ""
        #: name → the running checksum of a variable written in row order so far
        self._digests: dict[str, RunningDigest] = {}
        #: the checksums' updates, computed in order on a thread of their own beside the
        #: writes (SHA-256 of an archive's rows is a tenth of what compressing them takes)
        self._hashing: ThreadPoolExecutor | None = None
        self._hashed: list[Future] = []
        with LOCK, _writes(self.path):
            cache = netCDF4.get_chunk_cache()
            if self.filters:
                # No chunk cache for the histories: each chunk is compressed as its rows are
                # written (they come in whole chunks), while later batches are computed,
                # not all at once when the file is closed. netCDF-C gives the variables the
                # process's setting when it creates them, at the end of define mode.
                netCDF4.set_chunk_cache(0, 0, 1.0)
            try:
                self._ds = netCDF4.Dataset(self.tmp, "w", format="NETCDF4")
                try:
                    for dim, size in sizes.items():
                        self._ds.createDimension(dim, size)
                    for v in self.variables.values():
                        self._create(v, sizes)
                    self._ds.setncatts({k: _attr(val) for k, val in attrs.items()})
                    self._ds.sync()  # the end of define mode: the variables are created
                except BaseException:
                    self.abort()
                    raise
            finally:
                netCDF4.set_chunk_cache(*cache)

    def _create(self, v: VariableSpec, sizes: Mapping[str, int | None]) -> None:
        # an unlimited dimension (None) is chunked as if ROW_CHUNK long
        shape = [ROW_CHUNK if (n := sizes[d]) is None else n for d in v.dims]
        kwargs: dict[str, Any] = {"fill_value": False}
        if v.dtype != "str" and all(shape):
            chunks = [
                min(CASE_CHUNK, n) if d == "case" and len(v.dims) > 1 else n
                for d, n in zip(v.dims, shape, strict=True)
            ]
            if len(v.dims) == 1:
                chunks = [min(shape[0], ROW_CHUNK)]
            kwargs["chunksizes"] = chunks
            kwargs.update(self.filters)
            # HDF5's Fletcher-32 of each chunk as stored: every reader (xarray's too) finds a
            # damaged chunk when it reads it, for a few bytes a chunk and no value changed
            kwargs["fletcher32"] = True
        dtype = str if v.dtype == "str" else np.dtype(v.dtype)
        if v.dtype == "str":
            kwargs.pop("fill_value")
        var = self._ds.createVariable(v.name, dtype, v.dims, **kwargs)
        if self.filters and not (v.dims[0] == "case" and len(v.dims) > 1):
            # Rows along event or a 1-D case axis come in parts of a chunk: keep a cache.
            var.set_var_chunk_cache(size=VECTOR_CACHE, nelems=VECTOR_CACHE_SLOTS)
        attrs = dict(v.attrs)
        if "flag_values" in attrs:
            attrs["flag_values"] = np.asarray(attrs["flag_values"], dtype=np.dtype(v.dtype))
        var.setncatts({k: _attr(val) for k, val in attrs.items()})
        self._digests[v.name] = RunningDigest(var)

    def write(self, name: str, values: np.ndarray, index: object = slice(None)) -> None:
        """Write ``values`` at ``index`` (a slice, an int, or a tuple of them). ``values``
        must stay as they are until :meth:`commit`: they are checksummed in the background."""
        with LOCK, _writes(self.path):
            var = self._ds.variables[name]
            if self.variables[name].dtype == "str":
                values = np.asarray(values, dtype=object)
                if isinstance(index, int | np.integer):
                    var[int(index)] = str(values[()])
                    self._digests.pop(name, None)
                    return
            var[index] = values
        self._track(name, values, index)  # outside the lock: other threads may write

    def append(self, name: str, values: np.ndarray) -> None:
        """Extend a variable along its unlimited first dimension by ``values``' rows (kept as
        they are until :meth:`commit`, as :meth:`write`'s)."""
        start = self._rows_written(name)
        if len(values):
            with LOCK, _writes(self.path):
                self._ds.variables[name][start : start + len(values)] = values
        self._track(name, values, slice(start, start + len(values)))

    def _rows_written(self, name: str) -> int:
        digest = self._digests.get(name)
        if digest is not None:
            return digest.rows
        with LOCK:
            return len(self._ds.variables[name])

    def _track(self, name: str, values: np.ndarray, index: object) -> None:
        """Extend the variable's running checksum by ``values`` if they continue its rows, or
        give it up (the variable is then read back at :meth:`commit`)."""
        digest = self._digests.get(name)
        if digest is None:
            return
        # a slice from the next row on (a whole variable: from row 0) continues it
        if isinstance(index, slice) and index.step in (None, 1):
            start = index.start or 0
        else:
            start = -1
        if start != digest.rows or np.ndim(values) == 0:
            del self._digests[name]
            return
        digest.rows += len(values)
        if self._hashing is None:
            self._hashing = ThreadPoolExecutor(1, thread_name_prefix="campipe-checksum")
        self._hashed.append(self._hashing.submit(digest.update, values))

    def _stop_hashing(self, wait: bool) -> None:
        """Wait for the checksums' updates (``wait``; their errors raised), or drop them."""
        hashed, self._hashed = self._hashed, []
        if wait:
            for update in hashed:
                update.result()
        if self._hashing is not None:
            self._hashing.shutdown(wait=wait, cancel_futures=not wait)
            self._hashing = None

    def write_rows(self, name: str, positions: np.ndarray, values: np.ndarray) -> None:
        """Row ``k`` of ``values`` to row ``positions[k]`` along the first dimension; runs of
        consecutive positions are written in one call."""
        positions = np.asarray(positions, dtype=np.int64)
        string = self.variables[name].dtype == "str"
        for start, stop in runs(positions):
            p0 = int(positions[start])
            block = values[start:stop]
            if string:
                block = np.array([str(v) for v in block], dtype=object)
            self.write(name, block, slice(p0, p0 + (stop - start)))

    def checksums(self) -> dict[str, str]:
        """Every variable's checksum (:func:`variable_digest`): the running one of a variable
        written whole in row order, else read back from the file; and the attributes'."""
        self._stop_hashing(wait=True)
        out = {}
        for name, var in self._ds.variables.items():
            digest = self._digests.get(name)
            if digest is not None and digest.rows == (var.shape[0] if var.shape else 0):
                out[name] = digest.hexdigest()
            else:
                out[name] = variable_digest(var)
        h = hashlib.sha256()
        attributes_digest(self._ds, h)
        out[ATTRIBUTES_ENTRY] = h.hexdigest()
        return out

    def commit(self) -> Path:
        """Checksum every variable and the attributes (:data:`CHECKSUM_ATTR`), close, flush
        to disk and rename into place; returns the final path."""
        with LOCK, _writes(self.path):
            self._ds.set_auto_mask(False)
            self.checksum_text = json.dumps(self.checksums(), sort_keys=True)
            self._ds.setncattr(CHECKSUM_ATTR, self.checksum_text)
            self._ds.close()
        with _writes(self.path):
            with open(self.tmp, "rb") as f:
                os.fsync(f.fileno())
            os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Close and remove the temporary file."""
        self._stop_hashing(wait=False)
        with LOCK:
            try:
                if self._ds.isopen():
                    self._ds.close()
            except (AttributeError, RuntimeError):
                pass
        self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> NetCDFWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


def runs(positions: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` index ranges of ``positions`` that step by exactly 1."""
    if positions.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(positions) != 1) + 1
    edges = [0, *breaks.tolist(), positions.size]
    return list(zip(edges[:-1], edges[1:], strict=True))


def _attr(value: object) -> object:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, list | tuple):
        return np.asarray(value)
    return value


def write_file(
    path: str | Path,
    sizes: Mapping[str, int],
    variables: Iterable[VariableSpec],
    arrays: Mapping[str, np.ndarray],
    attrs: Mapping[str, object],
    compression: str = COMPRESSION,
) -> Path:
    """Write a whole small file atomically: every variable from ``arrays``."""
    variables = list(variables)
    with NetCDFWriter(path, sizes, variables, attrs, compression) as w:
        for v in variables:
            w.write(v.name, arrays[v.name])
        return w.commit()


# -- reading ---------------------------------------------------------------------------------

#: Largest file read into memory when it is already open elsewhere in this process [bytes].
MAX_IN_MEMORY = 2**30


def open_elsewhere(path: str | Path) -> bool:
    """``path`` is open through another file descriptor of this process (an xarray Dataset
    left open, say); False where that cannot be told (not Linux)."""
    target = os.path.realpath(path)
    try:
        fds = os.listdir("/proc/self/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/self/fd/{fd}") == target:
                return True
        except OSError:
            continue
    return False


def open_dataset(path: str | Path):
    """A netCDF4 Dataset of ``path`` for reading.

    A file already open elsewhere in this process is read from an in-memory copy: netCDF-C
    4.10 with HDF5 2.2 crashes (a segmentation fault) when a file held open is opened, read
    (variable-length strings) and closed a few more times. A larger file than
    :data:`MAX_IN_MEMORY` is then refused with ArchiveFileError.
    """
    import netCDF4

    if not open_elsewhere(path):
        return netCDF4.Dataset(path, "r")
    size = os.path.getsize(path)
    if size > MAX_IN_MEMORY:
        raise ArchiveFileError.at(
            str(path),
            f"is open elsewhere in this process and too large ({size / 1e9:.3g} GB) to read "
            "from a copy; close it (xarray: ds.close()) and try again",
        )
    with open(path, "rb") as f:
        return netCDF4.Dataset(str(path), "r", memory=f.read())


@watched
def verify(path: str | Path) -> list[str]:
    """Check a file against its stored checksums: ``[]`` if every variable and attribute is as
    written, else what differs (or why the file cannot be read). Reads the whole file."""

    try:
        with LOCK, open_dataset(path) as ds:
            ds.set_auto_mask(False)
            if CHECKSUM_ATTR not in ds.ncattrs():
                return ["it holds no checksums (written by an older campipe)"]
            stored = json.loads(ds.getncattr(CHECKSUM_ATTR))
            if not isinstance(stored, dict):
                return ["its checksums cannot be read"]
            found = checksums(ds)
    except ArchiveFileError:
        raise  # open elsewhere in this process and too large to copy: not damage
    except Exception as exc:  # a damaged HDF5 file fails in many ways; each means the same
        return [f"it cannot be read ({type(exc).__name__}: {str(exc)[:200]})"]
    bad = sorted(k for k in set(stored) | set(found) if stored.get(k) != found.get(k))
    if not bad:
        return []
    names = ", ".join(("attributes" if k == ATTRIBUTES_ENTRY else k) for k in bad[:5])
    more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
    return [f"its checksums differ ({names}{more})"]


@watched
def damaged(
    path: str | Path,
    names: Iterable[str] | None = None,
    layout: str | None = None,
    skip_dims: Iterable[str] = (),
) -> list[str]:
    """The variables of ``path`` (those ``names``, default all, and the global attributes)
    that differ from the file's stored checksums or fail to read (as HDF5 fails a chunk whose
    Fletcher-32 differs), in name order; ``attributes`` for the global attributes,
    ``checksums`` for stored checksums that cannot be read. ``[]`` for a file that holds no
    checksums (written before campipe stored them) or, given ``layout``, whose
    ``campipe_layout`` is another (its reader refuses it as such). Variables along any of
    ``skip_dims`` are left out (those a reader does not read). Reads those variables whole,
    each without a chunk cache: memory stays a block of rows.
    """
    with LOCK, open_dataset(path) as ds:
        ds.set_auto_mask(False)
        try:
            attrs = ds.ncattrs()
        except Exception:  # HDF5 cannot open an attribute: the header is damaged
            return ["attributes"]
        if CHECKSUM_ATTR not in attrs:
            log.info("%s holds no checksums (an older campipe wrote it): not verified", path)
            return []
        if layout is not None and (
            "campipe_layout" not in attrs or ds.getncattr("campipe_layout") != layout
        ):
            return []
        try:
            stored = json.loads(ds.getncattr(CHECKSUM_ATTR))
        except ValueError:
            stored = None
        if not isinstance(stored, dict):
            return ["checksums"]
        wanted = sorted(ds.variables if names is None else set(names) & set(ds.variables))
        skipped = set(skip_dims)
        bad = []
        for name in wanted:
            var = ds.variables[name]
            if skipped & set(var.dimensions):
                continue
            try:
                var.set_var_chunk_cache(0, 0, 1.0)  # each chunk read once, then dropped
                found = variable_digest(var)
            except Exception as exc:  # a damaged chunk fails in HDF5 (Fletcher-32, a filter)
                if missing_filter(exc) is not None:
                    raise  # not damage: this machine lacks the compression's plugin
                found = None
            if found is None or found != stored.get(name):
                bad.append(name)
        h = hashlib.sha256()
        attributes_digest(ds, h)
        if h.hexdigest() != stored.get(ATTRIBUTES_ENTRY):
            bad.append("attributes")
    return bad


def check(
    path: str | Path,
    names: Iterable[str] | None = None,
    layout: str | None = None,
    skip_dims: Iterable[str] = (),
) -> None:
    """Raise ArchiveDamagedError naming what :func:`damaged` finds in ``path``: what a
    reader checks before it reads (``--no-verify`` skips it)."""
    bad = damaged(path, names, layout, skip_dims)
    if not bad:
        return
    what = ", ".join(bad[:5]) + (f" and {len(bad) - 5} more" if len(bad) > 5 else "")
    raise ArchiveDamagedError.at(
        str(path),
        f"damaged: {what} {'differs' if len(bad) == 1 else 'differ'} from the checksums "
        "stored when it was written (a changed byte, a bad disk or copy); run the study "
        "again to write it anew (campipe study), or read it as it is with --no-verify",
        found=bad,
        expected="the values written",
    )


@watched
def read_attrs(path: str | Path) -> dict[str, object]:

    with LOCK, open_dataset(path) as ds:
        return {k: ds.getncattr(k) for k in ds.ncattrs()}


@watched
def read_index(
    path: str | Path, ids: str = "case"
) -> tuple[np.ndarray, np.ndarray, dict[str, object]]:
    """An archive's case ids (the variable ``ids``) and ``event_count`` per
    row, and its global attributes: what a rerun needs to know which cases a file can supply.

    Raises
    ------
    ArchiveFileError
        If the file cannot be read or lacks those variables.
    """

    try:
        with LOCK, open_dataset(path) as ds:
            for name in (ids, "event_count"):
                if name not in ds.variables:
                    raise ArchiveFileError(f"{path}: no {name} variable", key=str(path))
            values = np.asarray(ds.variables[ids][:], dtype=object)
            counts = np.asarray(ds.variables["event_count"][:], dtype=np.int64)
            return values, counts, {k: ds.getncattr(k) for k in ds.ncattrs()}
    except OSError as exc:
        raise ArchiveFileError(f"{path}: cannot read ({exc})", key=str(path)) from None


@watched
def read_variable(path: str | Path, name: str) -> np.ndarray:
    """One whole variable (an axis such as ``cam_angle``)."""

    with LOCK, open_dataset(path) as ds:
        ds.set_auto_mask(False)
        return np.asarray(ds.variables[name][:])


@watched
def read_rows(
    path: str | Path, rows: np.ndarray, case_names: Iterable[str], event_names: Iterable[str]
) -> dict[str, np.ndarray]:
    """Some cases' rows of an archive, with their events.

    Parameters
    ----------
    rows : np.ndarray
        Increasing row indices along ``case``.
    case_names, event_names : iterable of str
        Variables along ``case`` and along ``event`` to read.

    Returns
    -------
    dict
        name → array, rows in the order given; event variables hold the given cases' events
        case by case, ``event_count`` their counts.
    """

    rows = np.asarray(rows, dtype=np.int64)
    out: dict[str, np.ndarray] = {}
    with LOCK, open_dataset(path) as ds:
        ds.set_auto_mask(False)
        lo, hi = int(rows.min()), int(rows.max()) + 1
        local = rows - lo
        for name in case_names:
            out[name] = np.asarray(ds.variables[name][lo:hi])[local]
            progress()
        counts = np.asarray(ds.variables["event_count"][:], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)])
        span = slice(int(starts[lo]), int(starts[hi]))
        pick = (
            np.concatenate(
                [np.arange(starts[r], starts[r + 1]) for r in rows] or [np.zeros(0, np.int64)]
            ).astype(np.int64)
            - span.start
        )
        for name in event_names:
            out[name] = np.asarray(ds.variables[name][span])[pick]
        out["event_count"] = counts[rows].astype(np.int32)
    return out


def provenance(command: str) -> dict[str, str]:
    """Global attributes naming who wrote an archive, when and with what."""
    import netCDF4

    now = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    versions = []
    for name in DEPENDENCIES:
        try:
            versions.append(f"{name}=={metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pass
    versions.append(f"netcdf-c=={netCDF4.__netcdf4libversion__}")
    versions.append(f"hdf5=={netCDF4.__hdf5libversion__}")
    versions.append(f"python=={platform.python_version()}")
    return {
        "Conventions": "CF-1.10",
        "campipe_version": __version__,
        "dependency_versions": ", ".join(versions),
        "host": socket.gethostname(),
        "date_created": now,
        "history": f"{now} {command}",
    }
