"""Checksums of a netCDF file's variables and attributes, as campipe stores them (the
archive's ``campipe_checksums``): SHA-256 of each variable's name, dimensions, type,
attributes and values, read a block of rows at a time; the global attributes' under
:data:`ATTRIBUTES_ENTRY`. Pure functions over an open ``netCDF4.Dataset`` (the caller holds
the netCDF lock)."""

from __future__ import annotations

import hashlib

import numpy as np

from campipe.io.watch import progress

#: The checksum entry of the global attributes (no variable has this name).
ATTRIBUTES_ENTRY = "/attributes"
#: Bytes read at a time when a variable is checksummed.
CHECKSUM_BLOCK = 8 * 2**20
#: Global attribute holding the checksums of a file's variables and attributes (JSON), left
#: out of the attributes' own.
CHECKSUM_ATTR = "campipe_checksums"


def _attribute_bytes(value: object) -> bytes:
    """An attribute's value as bytes that do not depend on numpy's repr."""
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    a = np.asarray(value)
    return b"a" + f"{a.dtype.str}{a.shape}".encode() + a.tobytes()


def attributes_digest(owner, h) -> None:
    for key in sorted(owner.ncattrs()):
        if key == CHECKSUM_ATTR:
            continue
        h.update(key.encode() + b"=")
        h.update(_attribute_bytes(owner.getncattr(key)))
        h.update(b";")


def _values_bytes(values: np.ndarray) -> bytes:
    if values.dtype == object or values.dtype.kind in "US":
        parts = [str(v).encode("utf-8", "surrogatepass") for v in values.ravel()]
        return b"".join(len(p).to_bytes(8, "little") + p for p in parts)
    return np.ascontiguousarray(values).tobytes()


def header_digest(var):
    """A variable's checksum so far: its name, dimensions, type and attributes."""
    h = hashlib.sha256()
    h.update(f"{var.name}|{var.dimensions}|{var.dtype}|".encode())
    attributes_digest(var, h)
    return h


class RunningDigest:
    """:func:`variable_digest` of a variable computed from the values as they are written,
    in row order: the same bytes the file gives back, without reading them."""

    def __init__(self, var) -> None:
        self.hash = header_digest(var)
        self.dtype = None if var.dtype is str else np.dtype(var.dtype)
        self.rows = 0  # rows written so far, hashed or to be (``NetCDFWriter._track``)

    def update(self, values) -> None:
        """Hash the next rows (at least one dimension: a scalar is not rows)."""
        a = np.asarray(values, dtype=object if self.dtype is None else self.dtype)
        self.hash.update(_values_bytes(a))

    def hexdigest(self) -> str:
        return self.hash.hexdigest()


def variable_digest(var) -> str:
    """SHA-256 of a netCDF4 variable: name, dimensions, type, attributes and values (read a
    block of rows at a time, so memory stays bounded)."""
    h = header_digest(var)
    shape = var.shape
    if not shape or shape[0] == 0:
        h.update(_values_bytes(np.asarray(var[...])))
        return h.hexdigest()
    itemsize = 64 if var.dtype is str else np.dtype(var.dtype).itemsize
    row = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    step = max(1, CHECKSUM_BLOCK // max(row, 1))
    for start in range(0, shape[0], step):
        h.update(_values_bytes(np.asarray(var[start : start + step])))
        progress()
    return h.hexdigest()


def checksums(ds) -> dict[str, str]:
    """Variable name → SHA-256 (:func:`variable_digest`) for an open netCDF4 Dataset, and the
    digest of its global attributes under :data:`ATTRIBUTES_ENTRY`."""
    out = {name: variable_digest(var) for name, var in ds.variables.items()}
    h = hashlib.sha256()
    attributes_digest(ds, h)
    out[ATTRIBUTES_ENTRY] = h.hexdigest()
    return out
