"""Bit identity: the archive of a mixed study against a stored digest.

Refactoring commits must leave every number of this archive unchanged. A commit that means to
change results updates ``tests/data/mixed-study.sha256`` (run this file with
``CAMPIPE_UPDATE_DIGEST=1``) and says so in its message.

The bits are a platform's: LAPACK's kernels (OpenBLAS picks them by CPU: Haswell, SkylakeX, …)
round the modes differently in the last bit, and every number after follows. The file records
one digest per platform (``tests.references.numerical_platform``), and the archive must be
bit-identical to one of them. A platform not recorded yet adds its own with
``CAMPIPE_ADD_PLATFORM_DIGEST=1``, on code whose digest matches a recorded one on a recorded
platform (nothing checks that: the commit says where it was); a change of results
(``CAMPIPE_UPDATE_DIGEST=1``) replaces them all with the platform's it was run on.
"""

import hashlib
import os
from pathlib import Path

import netCDF4
import numpy as np

from campipe.study import load_study
from campipe.study.run.execute import run_study
from tests.references import (
    add_platform_digest,
    numerical_platform,
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


def test_the_mixed_study_archive_is_bit_identical_to_the_stored_digest(tmp_path):
    study = load_study(DATA / "mixed-study.yaml")
    archive = tmp_path / "mixed.nc"
    run_study(study, archive, scheduler="synchronous")
    digest = archive_digest(archive)
    if os.environ.get("CAMPIPE_UPDATE_DIGEST"):
        record_digest(DIGEST, digest)
    if os.environ.get("CAMPIPE_ADD_PLATFORM_DIGEST"):
        add_platform_digest(DIGEST, digest)
    recorded = recorded_digests(DIGEST)
    assert digest in recorded, (
        f"the archive's digest {digest} on platform {numerical_platform()} is none of those "
        f"recorded ({recorded}): results changed, or this platform's is not recorded yet"
    )
