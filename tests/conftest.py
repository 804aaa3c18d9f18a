from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

# The thesis's printed figures live beside the tests as plain data.
sys.path.insert(0, str(Path(__file__).parent))

if TYPE_CHECKING:
    from study_helpers import SmallArchive

# The session's archives are built once and only read: each test that takes one fails at its
# teardown, named, if a file of the archive's folder changed (chmod would not stop a test
# run as root). A test that changes files takes a copy.
CHANGED = "the session's {} was changed by this test: take a copy (small_archive_copy)"


@pytest.fixture(scope="session")
def _small_archive_once(tmp_path_factory: pytest.TempPathFactory) -> SmallArchive:
    from study_helpers import SmallArchive  # imported here: unit tests need no xarray

    return SmallArchive.build(tmp_path_factory.mktemp("small-archive"))


@pytest.fixture
def small_archive(_small_archive_once: SmallArchive) -> Iterator[SmallArchive]:
    """The small study (``study_helpers.SMALL_SPEC``, 3 speeds × 2 seats) run once a session:
    its spec, archive, batch files, study and run report, to be read only."""
    from study_helpers import snapshot

    before = snapshot(_small_archive_once.directory)
    yield _small_archive_once
    assert snapshot(_small_archive_once.directory) == before, CHANGED.format("small archive")


@pytest.fixture
def small_archive_copy(_small_archive_once: SmallArchive, tmp_path: Path) -> SmallArchive:
    """A copy of the small study's spec, archive and batch files in ``tmp_path``, to change."""
    return _small_archive_once.copy_to(tmp_path)


@pytest.fixture(scope="session")
def _quickstart_once(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from study_helpers import STUDIES

    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    archive = tmp_path_factory.mktemp("readme") / "studies" / "quickstart.nc"
    archive.parent.mkdir()
    run_study(load_study(STUDIES / "quickstart.yaml"), archive, scheduler="threads")
    return archive


@pytest.fixture
def quickstart_archive(_quickstart_once: Path) -> Iterator[Path]:
    """``studies/quickstart.yaml`` run once a session as the README's first command runs it:
    the archive ``<folder>/studies/quickstart.nc`` (4 speeds × 2 seats, three turns), to be
    read only."""
    from study_helpers import snapshot

    folder = _quickstart_once.parents[1]
    before = snapshot(folder)
    yield _quickstart_once
    assert snapshot(folder) == before, CHANGED.format("quickstart archive")
