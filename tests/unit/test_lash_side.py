"""Lash where a designer sets it (issue 32): ``model.lash_side`` (valve, the default, or cam),
the cam-side gap a valve-side lash is, the seat it places, valve lift 0 on that seat, and the
refusal of a seat beside a lash in the spec's units."""

import math
from pathlib import Path

import numpy as np
import pytest
from study_helpers import write_spec

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import (
    cam_gap,
    lash_ratio,
    lash_seat,
    reference_preload,
    system_matrices,
    thesis_train,
)
from campipe.profiles import Ramp, polydyne
from campipe.study import load_study
from campipe.study.spec.check import SpecError
from campipe.vocabulary import CAM_AND_SEAT, SEATED

INCH = 0.0254
PROFILE = polydyne(
    "4567", 0.3 * INCH, *np.radians([100, 20, 100]), ramp=Ramp(0.3e-3, math.radians(30))
)
STUDIES = Path(__file__).parents[2] / "studies"

TRAINS = {
    "thesis": {},
    "refined rocker and spring": {"rocker_valve_arm_elements": 4, "spring_elements": 4},
    "a longer valve arm, a stiffer spring": {
        "rocker_valve_arm_length": 1.8 * INCH,
        "spring_rate": 600 / 0.2248089 / INCH,  # 600 lbf/in
    },
}


def _stem_stiffness(train) -> float:
    """EA/L of the valve stem, from its parameters [N/m]."""
    return (
        train.elastic_modulus * math.pi * train.valve_stem_diameter**2 / 4 / train.valve_stem_length
    )


@pytest.mark.parametrize("changes", TRAINS.values(), ids=TRAINS.keys())
def test_a_valve_lash_is_the_rockers_valve_end_travel(changes):
    """Seated, the pushrod and the rocker carry no load, so the rocker turns as a rigid lever
    as the cam takes a gap up: its valve end travels the geometric ratio L3/L2 (from the arm
    lengths, independent of the assembled stiffness) times the follower's, whatever the
    members' give or refinement. A valve-side lash δ_v is then the cam-side gap δ_v·L2/L3; a
    cam-side lash is that gap itself. Fails on a copy converting through the loaded static
    ratio (``engine.batch.valve_ratio``, 1.4929 for the thesis's train) or through the valve
    (q7: 1.5·(1 + k_spring/k_stem)), both off by more than 1e-9."""
    train = thesis_train().replace(**changes)
    sm = system_matrices(train)
    geometric = train.rocker_valve_arm_length / train.rocker_pushrod_arm_length
    assert lash_ratio(sm) == pytest.approx(geometric, rel=1e-9)
    assert cam_gap(sm, 0.3e-3, "valve") == pytest.approx(0.3e-3 / geometric, rel=1e-9)
    assert cam_gap(sm, 0.3e-3, "cam") == 0.3e-3


@pytest.mark.parametrize("changes", TRAINS.values(), ids=TRAINS.keys())
def test_a_valve_lash_raises_the_seat_by_itself_and_the_stems_give(changes):
    """Seated off its cam, the rocker's valve end q4 balances the spring (rate k_s, preload
    F) against the stem (k_st = EA/L): −k_s·q4 + F = k_st·(q4 + q7), so raising the seat
    moves q4 by −k_st/(k_s + k_st) of it. A valve-side lash δ_v (q4's travel) therefore
    raises the seat by δ_v·(1 + k_s/k_st) over a lash of zero: a hand calculation from three
    parameters. A cam-side lash raises it by L3/L2 times that. Fails on a copy reading the
    valve-side lash as cam-side (1.5 δ_v), or measuring it at the valve (δ_v exactly: off by
    k_s/k_st = 3.5e-4 for the thesis's train)."""
    train = thesis_train().replace(**changes)
    sm = system_matrices(train)
    stem = _stem_stiffness(train) if train.valve_stem_elements == 1 else None
    lash = 0.3e-3
    raised = lash_seat(sm, lash, "valve") - lash_seat(sm, 0.0, "valve")
    if stem is not None:
        assert raised == pytest.approx(lash * (1 + train.spring_rate / stem), rel=1e-9)
    geometric = train.rocker_valve_arm_length / train.rocker_pushrod_arm_length
    by_cam = lash_seat(sm, lash / geometric, "cam") - lash_seat(sm, 0.0, "cam")
    assert by_cam == pytest.approx(raised, rel=1e-9)
    assert lash_seat(sm, 0.0, "valve") == lash_seat(sm, 0.0, "cam")  # no lash: one seat


def test_the_default_side_is_the_valve_and_a_case_places_its_seat():
    """``lash_side`` defaults to the valve; a case with lash sits on the seat that lash
    places: for the thesis's train 0.3 mm at the valve is 0.2 mm at the cam (the 1.5 rocker
    ratio), here against the seat of the cam-side 0.2 mm to 1e-12. Fails on a copy whose
    default is the cam (a seat 1.5× the lash farther) or that drops the side in ``Case``."""
    train = thesis_train()
    assert train.lash_side == "valve"
    case = Case(train.replace(lash=0.3e-3), PROFILE, 100.0)
    cam = Case(train.replace(lash=0.2e-3, lash_side="cam"), PROFILE, 100.0)
    assert case.seat == pytest.approx(cam.seat, rel=1e-12)
    assert case.lift_zero == case.seat and Case(train, PROFILE, 1.0).lift_zero == 0.0


def test_valve_lift_reads_zero_on_the_seat():
    """With lash the valve lift is measured from the seat: it reads exactly 0 in every
    sample the valve sits on its seat (configurations III, IV), and at the nose, long after
    the lash is taken up (300 rpm, quasi-static), the valve lift of the lash-free train with
    the same load at its reference (its preload the lashed train's ``reference_preload``)
    less the seat the lash places (within 1 nm, against a seat of 0.38 mm: the lash and the
    give of the 148.1 lbf the model takes for the installed 151). Fails on a copy that
    leaves the reference at the base circle's static position (0.38 mm on the seat) or
    shifts it by the lash (0.3 mm) instead of the seat."""
    omega = 300 * math.pi / 30
    lashed = Case(thesis_train().replace(lash=0.3e-3), PROFILE, omega)
    free = thesis_train().replace(spring_preload=reference_preload(lashed.train))
    res = run_batch([lashed, Case(free, PROFILE, omega)], RunSettings(revolutions=3))
    seated = np.isin(res.contact_state[0], (CAM_AND_SEAT, SEATED))
    assert seated.sum() > 300  # about 160° of each turn on the base circle
    assert np.all(res.valve_lift[0][seated] == 0.0)
    assert lashed.seat == pytest.approx(0.3780e-3, abs=1e-7)
    last = res.cam_angle >= 4 * math.pi
    peaks = res.valve_lift[:, last].max(axis=1)
    assert peaks[1] - peaks[0] == pytest.approx(lashed.seat, abs=1e-9)


SPEC = """
name: lash
model: {preset: thesis-1971, elastic_modulus: 3e13 lbf/in**2, lash: LASH}
profile: {kind: polydyne-4567, lift: 0.3 in, rise: 100 deg, dwell: 20 deg, fall: 100 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg}
speed: 1000 rpm
"""


@pytest.mark.parametrize(
    ("lash", "seat", "words"),
    [
        ("0.2 mm", "0.01 in", "places the seat at 0.2 mm"),
        ("0.2 mm, lash_side: cam", "0.01 in", "places the seat at 0.3 mm"),
        ("0.008 in", "0.3 mm", "places the seat at 0.008 in"),
        ("0.008 in", "none", None),
    ],
)
def test_a_seat_beside_a_lash_is_refused_with_the_seat_in_the_specs_units(
    tmp_path, lash, seat, words
):
    """A train a million times stiffer than the thesis's is rigid: its valve-side lash places
    the seat at the lash itself, a cam-side one at 1.5 times it (the rocker ratio): the
    refusal names that seat in the units the lash was written in. Beside no seat, the case
    records its seat as 0 (valve lift 0 on the seat) and runs on the seat the lash places.
    Fails on a copy that states the seat in inches (0.007874 in), names the cam gap
    (0.1333 mm) or records the seat on the lash-free scale (0.2 mm)."""
    text = SPEC.replace("LASH", lash) + f"seat: {seat}\n"
    if words is None:
        case = load_study(write_spec(tmp_path, text)).cases[0]
        assert case.values["seat"] == 0.0
        assert case.case.seat == pytest.approx(0.008 * INCH, rel=1e-6)
        return
    with pytest.raises(SpecError) as exc:
        load_study(write_spec(tmp_path, text))
    assert "seat: found" in str(exc.value) and words in str(exc.value)


def test_the_lash_ramp_study_keeps_its_physical_lash():
    """studies/lash-ramp.yaml gives its lash at the valve, 0.3 mm: the follower stands
    0.2 mm off the cam (what the study said before the side existed), so its cases sit on the
    seat of a 0.2 mm cam-side lash, to 1e-12. Fails on a copy of the study left at 0.2 mm
    (valve side: a seat 0.1 mm lower)."""
    study = load_study(STUDIES / "lash-ramp.yaml")
    sm = system_matrices(thesis_train().replace(lash=0.2e-3, lash_side="cam"))
    expected = lash_seat(sm, 0.2e-3, "cam")
    assert [c.case.seat for c in study.cases] == pytest.approx(
        [expected] * len(study.cases), rel=1e-12
    )
    assert {c.values["seat"] for c in study.cases} == {0.0}
