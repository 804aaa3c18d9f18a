"""How an archive's variables may be compressed: the spec's ``run.compression`` names one
(:mod:`campipe.study.spec.fields`), :mod:`campipe.io.archive` writes with it. Apart, so a spec
is checked without the archive's module."""

from __future__ import annotations

from typing import Any

#: How an archive's variables may be compressed (the spec's ``run.compression``) → the
#: keywords netCDF4 takes for it. zstd (HDF5 filter 32015, netCDF-C 4.9 and later, built into
#: the netCDF4 wheels): written and read faster than zlib, the file somewhat larger (``campipe
#: bench`` measures both); netCDF4 applies no byte shuffle before it. zlib with the byte
#: shuffle: read by every netCDF-4 reader. Level 1 of either compresses these histories
#: nearly as well as higher levels in less time.
COMPRESSIONS: dict[str, dict[str, Any]] = {
    "zstd": {"compression": "zstd", "complevel": 1},
    "zlib": {"compression": "zlib", "complevel": 1, "shuffle": True},
    "none": {},
}
#: The default compression.
COMPRESSION = "zstd"
