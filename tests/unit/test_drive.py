"""The drive (issue 37): a speed given as the engine's with ``drive: {cam_per_crank}``, read
as the cam's by its ratio wherever a speed goes; refused where it cannot be read."""

from __future__ import annotations

import math

import jsonschema
import pytest

from campipe.study import SpecError, check_spec, expand
from campipe.study.spec.coordinates import coordinate_values
from campipe.study.spec.schema import study_schema

RPM = 2 * math.pi / 60
BASE = {
    "name": "t",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "run": {"revolutions": 1},
    "drive": {"cam_per_crank": 0.5},
}


def _study(**keys):
    return expand(check_spec({**BASE, **keys}))


def test_an_engine_speed_gives_the_cam_speed_by_the_drive_s_ratio():
    """engine_speed 12000 rpm at cam_per_crank 0.5 is a cam at 6000 rpm, and the same case
    (its id) as a spec giving speed: 6000 rpm. Fails on a copy that multiplies by the
    inverse ratio (24000 rpm) or ignores the drive."""
    engine = _study(engine_speed="12000 rpm")
    cam = expand(
        check_spec({k: v for k, v in BASE.items() if k != "drive"} | {"speed": "6000 rpm"})
    )
    assert engine.cases[0].case.speed == pytest.approx(6000 * RPM, rel=1e-15)
    assert engine.cases[0].case_id == cam.cases[0].case_id
    assert coordinate_values(engine.cases, engine)["engine_speed_rpm"].tolist() == [12000.0]
    assert "engine_speed_rpm" not in coordinate_values(cam.cases, cam)
    assert engine.spec.drive == 0.5 and cam.spec.drive is None
    assert "engine_speed" in engine.varied and "engine_speed" not in cam.varied


@pytest.mark.parametrize("units", ["rpm", "rev/min", "r/min"])
def test_an_engine_speed_sweep_is_the_cam_s_speed_sweep_in_its_order(units):
    """A sweep of engine speeds (in rpm, rev/min or r/min) is a speed sweep of the cam at
    half of each, its place among the axes kept (the first key outermost), each case's
    engine speed beside it. Fails on a copy that moves the key to the end of the sweep, or
    whose speed sweep's fast path keeps the first engine speed for every case."""
    study = _study(
        sweep={"engine_speed": [f"12000 {units}", f"19048 {units}"], "seat": ["none", "0.1 in"]}
    )
    assert [a.key for a in study.axes] == ["speed", "seat"]
    speeds = [c.case.speed / RPM for c in study.cases]
    engines = coordinate_values(study.cases, study)["engine_speed_rpm"].tolist()
    assert speeds == pytest.approx([6000, 6000, 9524, 9524], rel=1e-13)
    assert engines == [12000, 12000, 19048, 19048]


def test_a_range_and_a_case_entry_of_engine_speeds():
    """A range's ends and a case entry's engine speed are scaled too. Fails on a copy that
    scales only lists."""
    ranged = _study(sweep={"engine_speed": {"from": "8000 rpm", "to": "12000 rpm", "num": 3}})
    assert [c.case.speed / RPM for c in ranged.cases] == pytest.approx([4000, 5000, 6000])
    entries = _study(cases=[{"engine_speed": "10000 rpm"}, {"engine_speed": "14000 rpm"}])
    assert [c.case.speed / RPM for c in entries.cases] == pytest.approx([5000, 7000])


@pytest.mark.parametrize(
    ("keys", "path", "words"),
    [
        ({"engine_speed": "6000 rpm", "drive": None}, "engine_speed", "drive's ratio"),
        ({"engine_speed": "6000 rpm", "speed": "3000 rpm"}, "engine_speed", "not both"),
        ({"engine_speed": "6000"}, "engine_speed", "units name an angle"),
        ({"engine_speed": "6000 rpm", "drive": {"cam_per_crank": -1}}, "drive.cam_per_crank", ""),
        ({"engine_speed": "6000 rpm", "drive": {"ratio": 0.5}}, "drive.ratio", "cam_per_crank"),
        ({"sweep": {"engine_speed": ["6000 rpm", "6 m"]}}, "sweep.engine_speed[1]", "angle"),
    ],
)
def test_a_bad_drive_or_engine_speed_is_refused_at_its_key(keys, path, words):
    """Fails on a copy that reports the engine's problems at ``speed`` (where they are
    written to) or accepts an engine speed without a drive."""
    raw = {**BASE, **keys}
    if raw.get("drive") is None:
        raw.pop("drive")
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw))
    assert path in info.value.paths, str(info.value)
    assert words in str(info.value)


def test_the_schema_takes_a_drive_and_an_engine_speed():
    """The generated schema accepts the spec above and refuses a drive without its ratio."""
    validator = jsonschema.Draft202012Validator(study_schema())
    good = {**BASE, "sweep": {"engine_speed": ["12000 rpm"]}, "cases": [{"engine_speed": "1 rpm"}]}
    assert list(validator.iter_errors(good)) == []
    assert list(validator.iter_errors({**BASE, "drive": {}}))
