from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

# The thesis's printed figures live beside the tests as plain data.
sys.path.insert(0, str(Path(__file__).parent))

if TYPE_CHECKING:
    from study_helpers import SmallArchive


@pytest.fixture(scope="session")
def _small_archive_once(tmp_path_factory: pytest.TempPathFactory) -> SmallArchive:
    from study_helpers import SmallArchive  # imported here: unit tests need no xarray

    return SmallArchive.build(tmp_path_factory.mktemp("small-archive"))


@pytest.fixture
def small_archive(_small_archive_once: SmallArchive):
    """The small study (``study_helpers.SMALL_SPEC``) run once a session: its spec, archive,
    batch files, study and run report, to be read only. A test that changes or deletes any
    of its files fails here, named; it takes ``small_archive_copy`` instead."""
    before = _small_archive_once.snapshot()
    yield _small_archive_once
    assert _small_archive_once.snapshot() == before, (
        "the session's small archive was changed: a test that writes takes small_archive_copy"
    )


@pytest.fixture
def small_archive_copy(_small_archive_once: SmallArchive, tmp_path: Path) -> SmallArchive:
    """A copy of the small study's spec, archive and batch files in ``tmp_path``, to change."""
    return _small_archive_once.copy_to(tmp_path)
