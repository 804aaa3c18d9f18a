"""Helpers shared by the study tests: writing specs, opening archives for comparison."""

from __future__ import annotations

import json
import shutil
import textwrap
from pathlib import Path

import xarray as xr

from campipe.study.spec.variables import VOLATILE_ATTRS

ROOT = Path(__file__).parents[1]
STUDIES = ROOT / "studies"
INCH = 0.0254
LBF = 4.4482216152605


def write_spec(directory: Path, text: str, name: str = "spec.yaml") -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path


def load(path: Path) -> xr.Dataset:
    """An archive read into memory, without the provenance attributes that legitimately
    differ between two runs (host, UTC time, history)."""
    ds = xr.load_dataset(path)
    for name in VOLATILE_ATTRS:
        ds.attrs.pop(name, None)
    return ds


def die(plan):
    """A batch whose worker process dies (tests of a killed worker)."""
    import os

    os._exit(9)


def changed(base: dict, **changes: object) -> dict:
    """A deep copy of a raw spec with ``a__b=value`` setting ``raw["a"]["b"]``."""
    raw = json.loads(json.dumps(base))
    for key, value in changes.items():
        node = raw
        *parents, last = key.split("__")
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return raw


#: The small study the integration tests share (``small_archive`` in conftest.py): the thesis's
#: harmonic cam at three speeds across the separation onset, without a seat and with one at
#: 0.1 in (six cases, the speed outermost), two turns, with q and the member loads recorded.
#: An undamped bucket tappet with 0.1 mm of lash on a polydyne cam's constant-velocity ramps:
#: seated, its tappet swings on its stem (test_joint_tension, test_force_peaks: tappet 45 g,
#: stem and contact 30000 and 60000 N/mm in series, seated spring 220 N, ramp 0.3 mm over
#: 30°). A spec without its run and sweep.
BUCKET_RING = """\
name: bucket-ring
model: {layout: direct-acting, tappet_mass: 0.045 kg, valve_mass: 0.065 kg,
        stem_stiffness: 30000 N/mm, tappet_contact_stiffness: 60000 N/mm,
        spring_rate: 35 N/mm, spring_preload: 220 N, damping_ratios: [0], lash: 0.1 mm}
profile: {kind: polydyne-4567, lift: 9 mm, rise: 110 deg, dwell: 20 deg, fall: 110 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg, ramp_shape: constant-velocity}
closure: force
"""

SMALL_SPEC = """
name: small
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 2, record: [q, member_loads]}
sweep:
  speed: [6000 rpm, 9524 rpm, 11000 rpm]
  seat: [none, 0.1 in]
"""


class SmallArchive:
    """The small study run into ``directory``: ``spec.yaml``, ``small.nc`` and the batch
    files the run kept (``small.nc.parts``), in batches of two cases on the synchronous
    scheduler."""

    def __init__(self, directory: Path, study=None, report=None) -> None:
        self.directory = directory
        self.spec = directory / "spec.yaml"
        self.archive = directory / "small.nc"
        self._study = study
        #: the run that built the archive (None for a copy)
        self.report = report

    @property
    def study(self):
        """The study loaded from this folder's spec."""
        if self._study is None:
            from campipe.study import load_study

            self._study = load_study(self.spec)
        return self._study

    @property
    def parts(self) -> Path:
        """The folder of the run's batch files."""
        from campipe.study.run.batches import parts_directory

        return parts_directory(self.archive)

    @classmethod
    def build(cls, directory: Path) -> SmallArchive:
        from campipe.study import load_study
        from campipe.study.run.execute import run_study

        study = load_study(write_spec(directory, SMALL_SPEC))
        archive = directory / "small.nc"
        report = run_study(study, archive, scheduler="synchronous", batch_size=2, keep_parts=True)
        return cls(directory, study, report)

    def copy_to(self, directory: Path) -> SmallArchive:
        """A copy of the spec, the archive and its batch files in ``directory``, for a test
        that changes or deletes them."""
        shutil.copy(self.spec, directory / self.spec.name)
        shutil.copy(self.archive, directory / self.archive.name)
        copy = SmallArchive(directory)
        shutil.copytree(self.parts, copy.parts)
        return copy


def snapshot(directory: Path) -> list[tuple[str, int, int]]:
    """Every file under ``directory`` with its size and modification time."""
    return sorted(
        (str(p.relative_to(directory)), p.stat().st_size, p.stat().st_mtime_ns)
        for p in directory.rglob("*")
        if p.is_file()
    )
