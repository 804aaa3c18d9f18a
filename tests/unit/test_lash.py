"""Lash (``model.lash``) measured at the cam (``lash_side: cam``): the clearance a seated train
stands off its cam, taken up by the opening ramp; the seat it places; how a spec refuses it
beside a seat. The valve side, the default, is tests/unit/test_lash_side.py."""

import math

import numpy as np
import pytest
from study_helpers import write_spec

from campipe.engine import Case, CaseError, RunSettings, run_batch
from campipe.model import lash_seat, system_matrices, thesis_train, valve_train
from campipe.profiles import Ramp, evaluate, harmonic, polydyne
from campipe.study import load_study
from campipe.study.spec.check import SpecError
from campipe.vocabulary import CAM_IMPACT, EV_KIND, EV_TIME, EV_VELOCITY, SEAT_IMPACT, SEATED

INCH = 0.0254
RAMP = Ramp(0.3e-3, math.radians(30))
PROFILE = polydyne("4567", 0.3 * INCH, *np.radians([100, 20, 100]), ramp=RAMP)
LASH = 0.2e-3
RPM = math.pi / 30


def test_the_lash_places_the_seat():
    """Seated, the train sheds the preload that compressed it: the seat is the rocker ratio
    times the lash plus the preload's give at the valve (all members but the stem). Checks:
    a train a million times stiffer seats at exactly 1.5 × lash (rigid kinematics); the
    thesis train's give is the preload over its stiffness seen from the valve, here against
    the two-spring hand estimate F·(1/k_train) within 5 %; the engine's Case places it."""
    train = thesis_train().replace(lash=LASH, lash_side="cam")
    ratio = train.rocker_valve_arm_length / train.rocker_pushrod_arm_length
    assert ratio == pytest.approx(1.5)
    stiff = train.replace(elastic_modulus=train.elastic_modulus * 1e6)
    assert lash_seat(system_matrices(stiff), LASH, "cam") == pytest.approx(1.5 * LASH, rel=1e-6)
    give = lash_seat(system_matrices(train), LASH, "cam") - 1.5 * LASH
    assert 0.05e-3 < give < 0.1e-3
    case = Case(train, PROFILE, 300 * math.pi / 30)
    assert case.seat == lash_seat(system_matrices(train), LASH, "cam")
    with pytest.raises(CaseError, match="give one of them") as exc:
        Case(train, PROFILE, 300 * math.pi / 30, seat=1e-3)
    assert exc.value.key == "seat"
    assert math.isnan(Case(thesis_train(), PROFILE, 1.0).seat)  # no lash: no seat


@pytest.mark.parametrize("rpm", [300, 1000])
def test_the_cam_takes_the_lash_up_where_its_lift_equals_the_lash(rpm):
    """With the valve at rest on its seat the train carries no load, so the follower stands
    exactly ``lash`` off the base circle: the cam meets it where the opening ramp's lift
    equals the lash (here 2/3 of the way up a 0.3 mm ramp over 30°: at 20°), at the ramp's
    velocity height/duration·ω, the follower being at rest. Hand calculation, independent
    of the engine: θ = lash / height · duration."""
    omega = rpm * math.pi / 30
    case = Case(thesis_train().replace(lash=LASH, lash_side="cam"), PROFILE, omega)
    res = run_batch([case], RunSettings(revolutions=3))
    ev = res.events[0]
    cam = ev[ev[:, EV_KIND] == CAM_IMPACT]
    late = cam[cam[:, EV_TIME] * omega > 4 * math.pi]  # the third turn, long after seating
    assert len(late) == 1
    theta = late[0, EV_TIME] * omega - 4 * math.pi
    assert math.degrees(theta) == pytest.approx(LASH / RAMP.height * 30, abs=1e-6)
    assert float(evaluate(PROFILE, theta)[0]) == pytest.approx(LASH, abs=1e-12)
    closing = RAMP.height / RAMP.duration * omega
    assert late[0, EV_VELOCITY] == pytest.approx(closing, rel=1e-6)
    seats = ev[ev[:, EV_KIND] == SEAT_IMPACT]
    assert len(seats) >= 2  # the valve seats on the closing ramp every turn


SPEC = """
name: lash
model: {preset: thesis-1971, lash: 0.2 mm, lash_side: cam}
profile: {kind: polydyne-4567, lift: 0.3 in, rise: 100 deg, dwell: 20 deg, fall: 100 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg}
speed: 1000 rpm
"""


BUCKET = {
    "layout": "direct-acting",
    "tappet_mass": "30 g",
    "valve_mass": "50 g",
    "tappet_contact_stiffness": "200 N/um",
    "stem_stiffness": "100 N/um",
    "spring_rate": "35 N/mm",
    "spring_preload": "220 N",
    "damping_ratios": [0.05, 0.05],
}


@pytest.mark.parametrize("lash_mm", [0.1, 0.25])
def test_the_seated_spring_pushes_with_its_installed_force_whatever_the_lash(lash_mm):
    """``spring_preload`` is the installed force, the valve closed on its seat. A bucket tappet
    (35 N/mm, 220 N) at a crawl: resting on its seat off the cam (configuration IV) its seat
    force is 220 N; at the cam's nose the cam force is 220 N plus the rate times the valve
    lift, less the masses' deceleration (hand statics). Fails if the model's reference load
    were ``spring_preload`` itself (the seat force 220 N + rate × lash: 223.5 N, 228.75 N)."""
    train = valve_train("thesis-1971", {**BUCKET, "lash": f"{lash_mm} mm"})
    rate, preload, mass = 35e3, 220.0, 0.08
    w = 100.0 * RPM
    run = run_batch([Case(train, harmonic(0.009), w)], RunSettings(revolutions=2))
    # Seated from 78° to 102° of each turn (the base circle at 90°): from 85° on, the
    # tappet's ring on its stem since it left the cam has decayed.
    turn = np.degrees(run.cam_angle) % 360.0
    rest = (turn >= 85.0) & (turn <= 100.0)
    assert np.all(run.contact_state[0][rest] == SEATED) and rest.sum() == 32
    np.testing.assert_allclose(run.seat_force[0][rest], preload, rtol=1e-6)
    nose = int(np.argmax(run.cam_lift[0]))
    lift = run.valve_lift[0, nose]
    assert lift == pytest.approx(0.009 - lash_mm * 1e-3, rel=2e-3)  # less the link's give
    # q at the nose: −ω²·h/2 of deceleration on both masses (the cam's and the valve's).
    expected = preload + rate * lift - mass * w**2 * 0.009 / 2
    assert run.cam_force[0, nose] == pytest.approx(expected, rel=1e-6)


def test_a_spec_with_lash(tmp_path):
    study = load_study(write_spec(tmp_path, SPEC + "sweep: {model.lash: [0.1 mm, 0.2 mm]}\n"))
    seats = [
        lash_seat(system_matrices(thesis_train().replace(lash=lash, lash_side="cam")), lash, "cam")
        for lash in (1e-4, 2e-4)
    ]
    assert [c.case.seat for c in study.cases] == pytest.approx(seats, rel=1e-12)
    assert seats[1] - seats[0] == pytest.approx(1.5e-4, rel=0.01)  # the rocker ratio
    assert [c.values["model.lash"] for c in study.cases] == pytest.approx([1e-4, 2e-4])
    none = load_study(write_spec(tmp_path, SPEC), {"model.lash": "none", "seat": "0.1 in"})
    assert none.cases[0].case.seat == pytest.approx(0.1 * INCH)
    assert valve_train(overrides={"lash": "none"}) == thesis_train()


@pytest.mark.parametrize(
    ("extra", "key", "words"),
    [
        ("seat: 0.1 in\n", "seat", "give one of them"),
        ("", "model.lash", "below the full valve lift"),
    ],
)
def test_bad_lash_names_its_key(tmp_path, extra, key, words):
    text = SPEC + extra
    if not extra:
        text = text.replace("lash: 0.2 mm", "lash: 0.4 in")
    with pytest.raises(SpecError) as exc:
        load_study(write_spec(tmp_path, text))
    assert key in str(exc.value) and words in str(exc.value)


@pytest.mark.parametrize("lash", [0.1e-3, 0.5e-3])
def test_the_coil_clash_margin_counts_from_the_installed_length_with_lash(lash):
    """``spring_travel_to_solid`` is the installed length less the solid length, and with
    lash the installed force (``spring_preload``) is the seated spring's: the margin is the
    travel less the spring's compression from there, travel − (F − P)/k, at every sample of a
    crawl over the lift (F the spring's force, tested against the seat force above), and the
    travel itself on the seat. A helper read 9.9 and 9.5 mm on the seat of a 10 mm travel (the
    lash's travel taken off). Broken copy: the margin counted from the unstressed reference."""
    from campipe.model import spring_clash_margin, spring_element_forces

    chain = {"layout": "lumped", "masses": ["0.05 kg", "0.06 kg"], "stiffnesses": ["20000 N/mm"],
             "spring_rate": "40 N/mm", "spring_preload": "250 N", "damping_ratios": [0.05],
             "spring_travel_to_solid": "10 mm", "lash": f"{lash * 1e3} mm"}  # fmt: skip
    train = valve_train("thesis-1971", chain)
    run = run_batch([Case(train, PROFILE, 10 * RPM)], RunSettings(revolutions=1))
    q = run.q[0]
    force = spring_element_forces(train, q)[:, -1]
    margin = spring_clash_margin(train, q)
    np.testing.assert_allclose(margin, 10e-3 - (force - 250.0) / 40e3, rtol=0, atol=1e-12)
    seated = np.asarray(run.contact_state[0]) == SEATED
    assert seated.any() and np.abs(force[seated] - 250.0).max() < 1e-6
    np.testing.assert_allclose(margin[seated], 10e-3, rtol=0, atol=1e-10)
    assert margin.min() < 10e-3 - 0.007  # the cam's 7.6 mm (0.3 in) lift, less the lash
