"""Bit identity: the archive of a mixed study against a stored digest.

Refactoring commits must leave every number of this archive unchanged. A commit that means to
change results updates ``tests/data/mixed-study.sha256`` (run this file with
``CAMPIPE_UPDATE_DIGEST=1``) and says so in its message.
"""

import hashlib
import os
from pathlib import Path

import netCDF4
import numpy as np

from campipe.study import load_study
from campipe.study.run.execute import run_study

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
        DIGEST.write_text(digest + "\n")
    assert digest == DIGEST.read_text().strip()
