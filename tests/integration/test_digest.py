"""Bit identity: the archive of a mixed study against a stored digest.

Refactoring commits must leave every number of this archive unchanged. A commit that means to
change results updates ``tests/data/mixed-study.sha256`` (run this file with
``CAMPIPE_UPDATE_DIGEST=1``) and says so in its message.

The bits are a platform's: LAPACK's kernels (OpenBLAS picks them by CPU: Haswell, SkylakeX, …)
round the modes differently in the last bit, and every number after follows. The file records
one digest per platform (``tests.references.numerical_platform``), and the archive must be
bit-identical to one of them. On a platform not recorded, the study runs again in a process on
the kernels every digest is recorded on (``tests.references.on_reference_kernels``: OpenBLAS's
Haswell, where the processor runs them) and that must be bit-identical to one; the platform
may add its own with
``CAMPIPE_ADD_PLATFORM_DIGEST=1``, on code whose digest matches a recorded one on a recorded
platform (nothing checks that: the commit says where it was); a change of results
(``CAMPIPE_UPDATE_DIGEST=1``) replaces them all with the platform's it was run on and the
reference kernels'.
"""

import hashlib
import os
import tempfile
from pathlib import Path

import netCDF4
import numpy as np

from campipe.study import load_study
from campipe.study.run.execute import run_study
from tests.references import (
    add_platform_digest,
    assert_recorded,
    record_digest,
    recorded_digests,
)

DATA = Path(__file__).parents[1] / "data"
DIGEST = DATA / "mixed-study.sha256"


def archive_digest(path: Path) -> str:
    """SHA-256 over every variable's name, dimensions, type, attributes and raw values, in
    name order; the global attributes (provenance, the spec's text) are left out."""
    h = hashlib.sha256()
    with netCDF4.Dataset(path) as ds:
        ds.set_auto_mask(False)
        for name in sorted(ds.variables):
            var = ds.variables[name]
            h.update(f"{name}|{var.dimensions}|{var.dtype}|".encode())
            for key in sorted(var.ncattrs()):
                h.update(f"{key}={var.getncattr(key)!r};".encode())
            values = np.asarray(var[...])
            h.update(values.tobytes() if values.dtype != object else repr(values.tolist()).encode())
    return h.hexdigest()


def mixed_archive_digest() -> str:
    """:func:`archive_digest` of the mixed study's archive, run in a folder of its own."""
    with tempfile.TemporaryDirectory() as folder:
        archive = Path(folder) / "mixed.nc"
        run_study(load_study(DATA / "mixed-study.yaml"), archive, scheduler="synchronous")
        return archive_digest(archive)


def test_the_mixed_study_archive_is_bit_identical_to_the_stored_digest():
    digest = mixed_archive_digest()
    if os.environ.get("CAMPIPE_UPDATE_DIGEST"):
        record_digest(DIGEST, digest, __file__, "mixed_archive_digest()")
    if os.environ.get("CAMPIPE_ADD_PLATFORM_DIGEST"):
        add_platform_digest(DIGEST, digest)
    assert_recorded(digest, recorded_digests(DIGEST), __file__, "mixed_archive_digest()")
