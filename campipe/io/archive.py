"""netCDF files of a study: batch files and the archive, written atomically.

Every file is written at a temporary path in its final folder and renamed into place
(``os.replace``) only once complete and flushed, so a reader (or a rerun after a crash) sees
either the whole file or none. Files are netCDF-4 (HDF5): variables along ``case`` are chunked
``CASE_CHUNK`` cases per chunk and, in an archive, zlib-compressed; ``xarray.open_dataset``
reads them as they are.

Rows are written one case at a time, so a writer holds no more than the rows it is given:
the archive is assembled by streaming batch after batch into it.

netCDF-C and HDF5 are not thread-safe: every call into netCDF4 here holds :data:`LOCK`.
"""

from __future__ import annotations

import itertools
import logging
import os
import platform
import socket
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from campipe import __version__
from campipe.errors import CampipeError
from campipe.io.lock import ArchiveBusyError, lock_path, writing

__all__ = [
    "ArchiveBusyError",
    "ArchiveFileError",
    "NetCDFWriter",
    "VariableSpec",
    "lock_path",
    "writing",
]

log = logging.getLogger(__name__)

#: Serialises netCDF4 calls from this process's threads.
LOCK = threading.RLock()
#: zlib level of an archive's variables: level 1 compresses these histories as well as 4
#: (within 2 %) in less time. Batch files, which live only until the archive is assembled, are
#: written uncompressed (level 0).
COMPLEVEL = 1
#: Cases per chunk of a variable along case and samples (a history): eight cases' histories
#: compress a third better than one case's alone and cost HDF5 an eighth of the chunks; reading
#: one case decompresses eight cases' rows of a variable (46 kB of a 721-sample history).
CASE_CHUNK = 8
#: Cases per chunk of a 1-D per-case variable, events per chunk of an event variable.
ROW_CHUNK = 4096
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


def temporary_path(path: Path) -> Path:
    """A unique hidden name beside ``path`` (same file system, so the rename is atomic)."""
    tag = f"{os.getpid()}-{threading.get_ident()}-{next(_counter)}"
    return path.with_name(f".{path.name}.{tag}.tmp")


def is_temporary(path: Path) -> bool:
    return path.name.startswith(".") and path.name.endswith(".tmp")


class NetCDFWriter:
    """Creates a netCDF file at a temporary path; :meth:`commit` renames it into place.

    Use as a context manager: leaving the block by an exception removes the temporary file.
    """

    def __init__(
        self,
        path: str | Path,
        sizes: Mapping[str, int],
        variables: Iterable[VariableSpec],
        attrs: Mapping[str, object],
        complevel: int = COMPLEVEL,
    ):
        import netCDF4

        self.path = Path(path)
        self.complevel = complevel
        self.tmp = temporary_path(self.path)
        self.variables = {v.name: v for v in variables}
        with LOCK:
            self._ds = netCDF4.Dataset(self.tmp, "w", format="NETCDF4")
            try:
                for dim, size in sizes.items():
                    self._ds.createDimension(dim, size)
                for v in self.variables.values():
                    self._create(v, sizes)
                self._ds.setncatts({k: _attr(val) for k, val in attrs.items()})
            except BaseException:
                self.abort()
                raise

    def _create(self, v: VariableSpec, sizes: Mapping[str, int]) -> None:
        shape = [sizes[d] for d in v.dims]
        kwargs: dict[str, Any] = {"fill_value": False}
        if v.dtype != "str" and all(shape):
            chunks = [
                min(CASE_CHUNK, n) if d == "case" and len(v.dims) > 1 else n
                for d, n in zip(v.dims, shape, strict=True)
            ]
            if len(v.dims) == 1:
                chunks = [min(shape[0], ROW_CHUNK)]
            kwargs["chunksizes"] = chunks
            if self.complevel:
                kwargs.update(zlib=True, complevel=self.complevel, shuffle=True)
        dtype = str if v.dtype == "str" else np.dtype(v.dtype)
        if v.dtype == "str":
            kwargs.pop("fill_value")
        var = self._ds.createVariable(v.name, dtype, v.dims, **kwargs)
        attrs = dict(v.attrs)
        if "flag_values" in attrs:
            attrs["flag_values"] = np.asarray(attrs["flag_values"], dtype=np.dtype(v.dtype))
        var.setncatts({k: _attr(val) for k, val in attrs.items()})

    def write(self, name: str, values: np.ndarray, index: object = slice(None)) -> None:
        """Write ``values`` at ``index`` (a slice, an int, or a tuple of them)."""
        with LOCK:
            var = self._ds.variables[name]
            if self.variables[name].dtype == "str":
                values = np.asarray(values, dtype=object)
                if isinstance(index, int | np.integer):
                    var[int(index)] = str(values[()])
                    return
            var[index] = values

    def write_rows(self, name: str, positions: np.ndarray, values: np.ndarray) -> None:
        """Row ``k`` of ``values`` to row ``positions[k]`` along the first dimension; runs of
        consecutive positions are written in one call."""
        positions = np.asarray(positions, dtype=np.int64)
        string = self.variables[name].dtype == "str"
        with LOCK:
            var = self._ds.variables[name]
            for start, stop in runs(positions):
                p0 = int(positions[start])
                block = values[start:stop]
                if string:
                    block = np.array([str(v) for v in block], dtype=object)
                var[p0 : p0 + (stop - start)] = block

    def commit(self) -> Path:
        """Close, flush to disk and rename into place; returns the final path."""
        with LOCK:
            self._ds.close()
        with open(self.tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Close and remove the temporary file."""
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
    complevel: int = COMPLEVEL,
) -> Path:
    """Write a whole small file (a batch) atomically: every variable from ``arrays``."""
    variables = list(variables)
    with NetCDFWriter(path, sizes, variables, attrs, complevel) as w:
        for v in variables:
            w.write(v.name, arrays[v.name])
        return w.commit()


def read_attrs(path: str | Path) -> dict[str, object]:
    import netCDF4

    with LOCK, netCDF4.Dataset(path, "r") as ds:
        return {k: ds.getncattr(k) for k in ds.ncattrs()}


def read_index(path: str | Path) -> tuple[np.ndarray, np.ndarray, dict[str, object]]:
    """An archive's or batch file's ``case_id`` and ``event_count`` per row, and its global
    attributes: what a rerun needs to know which cases a file can supply.

    Raises
    ------
    ArchiveFileError
        If the file cannot be read or lacks those variables.
    """
    import netCDF4

    try:
        with LOCK, netCDF4.Dataset(path, "r") as ds:
            for name in ("case_id", "event_count"):
                if name not in ds.variables:
                    raise ArchiveFileError(f"{path}: no {name} variable", key=str(path))
            ids = np.asarray(ds.variables["case_id"][:], dtype=object)
            counts = np.asarray(ds.variables["event_count"][:], dtype=np.int64)
            return ids, counts, {k: ds.getncattr(k) for k in ds.ncattrs()}
    except OSError as exc:
        raise ArchiveFileError(f"{path}: cannot read ({exc})", key=str(path)) from None


def read_variable(path: str | Path, name: str) -> np.ndarray:
    """One whole variable (an axis such as ``cam_angle``)."""
    import netCDF4

    with LOCK, netCDF4.Dataset(path, "r") as ds:
        ds.set_auto_mask(False)
        return np.asarray(ds.variables[name][:])


def read_rows(
    path: str | Path, rows: np.ndarray, case_names: Iterable[str], event_names: Iterable[str]
) -> dict[str, np.ndarray]:
    """Some cases' rows of an archive or batch file, with their events.

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
    import netCDF4

    rows = np.asarray(rows, dtype=np.int64)
    out: dict[str, np.ndarray] = {}
    with LOCK, netCDF4.Dataset(path, "r") as ds:
        ds.set_auto_mask(False)
        lo, hi = int(rows.min()), int(rows.max()) + 1
        local = rows - lo
        for name in case_names:
            out[name] = np.asarray(ds.variables[name][lo:hi])[local]
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
