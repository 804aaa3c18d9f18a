"""Expansion of a spec into cases: grid, zip, cases, sampled designs, and stable case ids."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from study_helpers import INCH, LBF, write_spec

from campipe.model import thesis_train
from campipe.study import SpecError, check_spec, expand, load_study
from campipe.study.spec.expand import count_cases, deep_merge, raw_cases

BASE = {
    "name": "t",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "speed": "9000 rpm",
    "run": {"revolutions": 1, "integrator": "newmark-linear", "dt": "1 us"},
}
RPM = math.pi / 30


def study(**changes):
    return expand(check_spec({**BASE, **changes}))


def rpm(case):
    return round(case.values["speed"] / RPM, 9)


def test_a_grid_is_the_product_of_its_axes_first_key_outermost():
    s = study(sweep={"speed": ["6000 rpm", "9000 rpm", "9524 rpm"], "seat": ["none", "0.05 in"]})
    assert [(rpm(c), c.values["seat"]) for c in s.cases] == [
        (6000, pytest.approx(math.nan, nan_ok=True)),
        (6000, pytest.approx(0.05 * INCH)),
        (9000, pytest.approx(math.nan, nan_ok=True)),
        (9000, pytest.approx(0.05 * INCH)),
        (9524, pytest.approx(math.nan, nan_ok=True)),
        (9524, pytest.approx(0.05 * INCH)),
    ]
    assert [c.index for c in s.cases] == list(range(6))
    assert [(a.key, a.kind, a.size) for a in s.axes] == [
        ("speed", "sweep", 3),
        ("seat", "sweep", 2),
    ]
    assert len({c.case_id for c in s.cases}) == 6


def test_a_range_steps_in_the_units_written():
    s = study(sweep={"speed": {"from": "1000 rpm", "to": "20000 rpm", "num": 39}})
    assert [rpm(c) for c in s.cases] == [1000 + 500 * i for i in range(39)]
    s = study(sweep={"model.spring_preload": {"from": "120 lbf", "to": "180 lbf", "num": 3}})
    assert_allclose(
        [c.case.train.spring_preload for c in s.cases], np.array([120, 150, 180]) * LBF, rtol=1e-12
    )


def test_zip_varies_its_keys_together():
    s = study(
        zip={
            "speed": ["6000 rpm", "9000 rpm", "9524 rpm"],
            "model.spring_preload": ["120 lbf", "151 lbf", "180 lbf"],
        },
        sweep={"closure": ["force", "form"]},
    )
    pairs = [(c.case.closure, rpm(c), round(c.case.train.spring_preload / LBF, 9)) for c in s.cases]
    assert pairs == [
        ("force", 6000, 120),
        ("force", 9000, 151),
        ("force", 9524, 180),
        ("form", 6000, 120),
        ("form", 9000, 151),
        ("form", 9524, 180),
    ]
    assert s.varied == ("model.spring_preload",)


def test_cases_deep_merge_over_the_base_and_multiply_the_grid():
    s = study(
        model={"preset": "thesis-1971", "spring_rate": "260 lbf/in"},
        sweep={"speed": ["6000 rpm", "9000 rpm"]},
        cases=[
            {"model": {"spring_preload": "120 lbf"}},
            {
                "profile": {
                    "kind": "polydyne-4567",
                    "lift": "1 in",
                    "rise": "90 deg",
                    "dwell": "90 deg",
                    "fall": "90 deg",
                },
                "closure": "form",
            },
            {"profile": {"lift": "0.5 in"}, "run": {"dt": "0.5 us"}},
        ],
    )
    assert len(s.cases) == 6
    a, b, c = s.cases[0], s.cases[2], s.cases[4]
    thesis = thesis_train()
    # the case's preload replaces the preset's; the base's spring rate and the rest stay
    assert a.case.train.spring_preload == pytest.approx(120 * LBF)
    assert a.case.train.spring_rate == pytest.approx(260 * LBF / INCH)
    assert a.case.train.pushrod_length == thesis.pushrod_length
    # a profile of another kind replaces the base's whole; closure set by the case
    assert b.values["profile"] == "polydyne-4567 1 in 90/90/90/90 deg"
    assert b.case.closure == "form" and a.case.closure == "force"
    assert b.case.train.spring_preload == thesis.spring_preload
    # a profile of the same kind merges key by key; the run merges too
    assert c.values["profile"] == "harmonic 0.5 in"
    assert c.settings.dt == 0.5e-6 and c.settings.revolutions == 1
    # grid inside each case entry
    assert [rpm(x) for x in s.cases] == [6000, 9000] * 3
    assert ("cases", "cases", 3) in [(x.key, x.kind, x.size) for x in s.axes]
    # the archive gets a coordinate for the listed preload (dt and closure always have one)
    assert s.varied == ("model.spring_preload",)


def test_deep_merge_keeps_the_base_untouched():
    base = {"model": {"preset": "p", "a": 1}, "run": {"dt": 1}}
    merged = deep_merge(base, {"model": {"a": 2}})
    assert merged == {"model": {"preset": "p", "a": 2}, "run": {"dt": 1}}
    assert base == {"model": {"preset": "p", "a": 1}, "run": {"dt": 1}}


def test_a_latin_hypercube_puts_one_point_in_each_stratum_and_is_seeded():
    sample = {
        "method": "latin-hypercube",
        "n": 8,
        "seed": 1,
        "ranges": {
            "speed": {"from": "1000 rpm", "to": "2000 rpm"},
            "model.spring_preload": {"from": "100 lbf", "to": "200 lbf"},
        },
    }
    s = study(sample=sample)
    speeds = np.array([rpm(c) for c in s.cases])
    preloads = np.array([c.case.train.spring_preload / LBF for c in s.cases])
    assert len(s.cases) == 8
    # Latin hypercube: each of the 8 equal slices of each range holds exactly one point
    assert sorted(np.floor((speeds - 1000) / 125).astype(int)) == list(range(8))
    assert sorted(np.floor((preloads - 100) / 12.5).astype(int)) == list(range(8))
    again = study(sample=sample)
    assert [c.case_id for c in again.cases] == [c.case_id for c in s.cases]
    other = study(sample={**sample, "seed": 2})
    assert not {c.case_id for c in other.cases} & {c.case_id for c in s.cases}
    assert [(a.key, a.kind, a.size) for a in s.axes] == [
        ("speed", "sample", 8),
        ("model.spring_preload", "sample", 8),
    ]


def test_count_matches_the_expansion():
    spec = check_spec(
        {
            **BASE,
            "sweep": {"speed": ["1 rpm", "2 rpm"], "seat": ["none"]},
            "zip": {"closure": ["force", "form"], "profile.lift": ["1 in", "2 in"]},
            "cases": [{}, {"model": {"spring_preload": "100 lbf"}}],
        }
    )
    assert count_cases(spec) == 2 * 1 * 2 * 2 == len(list(raw_cases(spec)))


#: The id of BASE: a hash of its canonical parameters, the same on any machine, any run.
BASE_ID = "4f3f989d3d336d79"


def test_case_ids_are_stable_and_follow_the_parameters_not_their_spelling():
    base = study().cases[0].case_id
    assert base == study().cases[0].case_id
    assert len(base) == 16 and int(base, 16) >= 0
    # the preset's own value, written out, is the same case
    assert (
        study(model={"preset": "thesis-1971", "spring_preload": "151 lbf"}).cases[0].case_id == base
    )
    # seat "none" and null are the same case
    assert study(seat=None).cases[0].case_id == base
    # any change of a parameter is another case
    changed = [
        study(speed="9001 rpm"),
        study(seat="0.1 in"),
        study(closure="form"),
        study(model={"spring_preload": "150 lbf"}),
        study(profile={"kind": "harmonic", "lift": "0.9 in"}),
        study(defects=[{"kind": "flat", "from": "268 deg", "to": "272 deg"}]),
        study(run={"revolutions": 2, "integrator": "newmark-linear", "dt": "1 us"}),
        study(run={"revolutions": 1, "integrator": "newmark-linear", "dt": "0.5 us"}),
    ]
    ids = {s.cases[0].case_id for s in changed}
    assert len(ids) == len(changed) and base not in ids


def test_case_id_is_pinned():
    assert study().cases[0].case_id == BASE_ID


def test_a_lift_table_enters_the_id_by_its_values_not_its_path(tmp_path):
    rows = "\n".join(f"{a},{0.5 * (1 - math.cos(math.radians(a)))}" for a in range(0, 360, 10))
    (tmp_path / "cam.csv").write_text(f"angle [deg],lift [in]\n{rows}\n")
    (tmp_path / "copy.csv").write_text(f"# the same cam\nangle [deg],lift [in]\n{rows}\n")
    (tmp_path / "other.csv").write_text(
        f"angle [deg],lift [in]\n{rows}\n".replace(",0.5", ",0.6", 1)
    )
    spec = """
    name: t
    profile: {{kind: table, file: {file}}}
    speed: 6000 rpm
    """
    ids = {
        f: load_study(write_spec(tmp_path, spec.format(file=f), f"{f}.yaml")).cases[0]
        for f in ("cam.csv", "copy.csv", "other.csv")
    }
    assert ids["cam.csv"].case_id == ids["copy.csv"].case_id
    assert ids["other.csv"].case_id != ids["cam.csv"].case_id
    assert ids["cam.csv"].values["profile"] == "table cam.csv (36 points)"
    assert ids["cam.csv"].case.profile.n_pieces == 36


def test_labels_write_lengths_in_the_units_the_spec_wrote_them_in():
    """A spec in millimetres reads its profiles in millimetres (they were 0.2559 in for
    6.5 mm); each length in its own written unit, the angles as before; a spec in inches keeps
    its labels (the mixed study's digest holds them)."""
    s = study(
        profile={
            "kind": "polydyne-4567",
            "lift": "6.5 mm",
            "rise": "110 deg",
            "dwell": "20 deg",
            "fall": "110 deg",
            "ramp_height": "0.2 mm",
            "ramp_duration": "30 deg",
        },
        defects=[{"kind": "bump", "center": "200 deg", "height": "5 um", "width": "10 deg"}],
        sweep={"profile.lift": ["6.5 mm", "0.3 in"]},
    )
    mm, inch = (c.values["profile"] for c in s.cases)
    assert mm == (
        "polydyne-4567 6.5 mm 110/20/110/60 deg, constant-velocity ramps 0.2 mm over 30 deg"
    )
    assert inch.startswith("polydyne-4567 0.3 in ") and "ramps 0.007874 in" in inch
    assert s.cases[0].values["defects"] == "bump 5 um at 200 deg over 10 deg"
    harmonic = study(profile={"kind": "harmonic", "lift": "25.4 mm"}).cases[0]
    assert harmonic.values["profile"] == "harmonic 25.4 mm"
    # the refusals say the lift in the spec's units too
    with pytest.raises(SpecError, match=r"full valve lift 38\.1 mm \(cam lift 25\.4 mm × rocker"):
        study(profile={"kind": "harmonic", "lift": "25.4 mm"}, seat="40 mm")
