"""Opening and closing ramps on a polydyne cam, and a valve seating on its closing ramp."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from study_helpers import write_spec

from campipe.engine import INTEGRATORS, Case, RunSettings, run_batch
from campipe.engine.batch import train_matrices, valve_ratio
from campipe.model import thesis_train
from campipe.profiles import RAMP_SHAPES, Ramp, evaluate, polydyne
from campipe.study import load_study
from campipe.study.spec.check import SpecError
from campipe.vocabulary import EV_KIND, EV_TIME, EV_VELOCITY, SEAT_IMPACT

INCH = 0.0254
SCHEDULE = np.radians([70, 20, 70])
RAMP = Ramp(0.3e-3, math.radians(30))


def jumps(profile):
    """(break angles [deg], lift, rate and acceleration jumps across each break)."""
    b = profile.breaks[:-1]
    left = np.array(evaluate(profile, b, "left"))
    right = np.array(evaluate(profile, b, "right"))
    return np.degrees(b), right - left


@pytest.mark.parametrize("kind", ["345", "4567"])
def test_smooth_ramps_leave_lift_velocity_and_acceleration_continuous(kind):
    """The smooth shape's velocity 3u² − 2u³ of the end velocity starts and ends with zero
    acceleration, and the rise starts at the ramp's velocity (P'(0) solved for): no break
    jumps in lift, velocity or acceleration (a rise left with P'(0) = 0 would jump the rate
    by the ramp's velocity at 30° and 310°)."""
    ramp = Ramp(0.3e-3, math.radians(30), "smooth")
    profile = polydyne(kind, 0.4 * INCH, *SCHEDULE, ramp=ramp)
    angles, jump = jumps(profile)
    assert_allclose(angles, [0, 30, 100, 120, 190, 220], atol=1e-9)
    assert np.abs(jump).max() < 1e-12
    lift, rate, _ = evaluate(profile, np.radians([0, 15, 30, 110, 190, 205, 220, 300]))
    h, r = 0.4 * INCH, ramp.height
    assert_allclose(lift[[0, 2, 3, 4, 6, 7]], [0, r, h, r, 0, 0], rtol=1e-12, atol=1e-15)
    # halfway: 2·r·(u³ − u⁴/2) at u = 1/2, the closing ramp the opening one run backwards
    assert_allclose(lift[[1, 5]], 3 / 16 * r, rtol=1e-12)
    assert_allclose(rate[[2, 4]], [ramp.velocity(), -ramp.velocity()], rtol=1e-12)
    assert_allclose(ramp.velocity(), 2 * ramp.height / ramp.duration)


def test_constant_velocity_ramps_step_only_at_the_base_circle():
    """The constant-velocity ramp climbs at height/duration: the rate steps from 0 to it where
    the opening ramp leaves the base circle and back where the closing ramp reaches it, and
    nowhere else."""
    profile = polydyne("4567", 0.4 * INCH, *SCHEDULE, ramp=RAMP)
    angles, jump = jumps(profile)
    v = RAMP.height / RAMP.duration
    assert_allclose(jump[1], [v, 0, 0, 0, 0, v], atol=1e-12)  # rate; 0° is the wrap
    assert np.abs(jump[[0, 2]]).max() < 1e-12
    assert np.abs(np.delete(jump[1], [0, 5])).max() < 1e-12
    assert "constant-velocity ramps" in profile.label


def test_without_a_ramp_the_polydyne_is_the_thesis_s():
    """The rise polynomial solved with P'(0) = 0 is the thesis's (Eqs. 29–34), exactly."""
    from campipe.profiles.shapes import POLYDYNE_POLYNOMIALS, _rise_polynomial

    for kind, coefficients in POLYDYNE_POLYNOMIALS.items():
        assert_allclose(_rise_polynomial(kind, 0.0), coefficients, atol=1e-9)


@pytest.mark.parametrize(
    ("ramp", "message"),
    [
        (Ramp(0.0, 0.5), "ramp height"),
        (Ramp(0.02, 0.5), "ramp height"),  # above the 0.4 in lift
        (Ramp(1e-4, 0.0), "ramp duration"),
        (Ramp(1e-4, 0.5, "linear"), "ramp shape"),
        (Ramp(1e-4, 2.0), "one turn"),
    ],
)
def test_bad_ramps_are_refused(ramp, message):
    with pytest.raises(ValueError, match=message):
        polydyne("4567", 0.4 * INCH, *SCHEDULE, ramp=ramp)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_valve_seats_at_the_ramp_s_velocity_at_low_speed(integrator):
    """A seat halfway up the closing ramp (the valve's lash): at 300 rpm the train follows
    the cam quasi-statically, so the valve lands at the closing ramp's velocity, the static
    valve ratio times ω times height/duration (to 1 %); at 1000 and 2000 rpm still within
    0.1 %. At 3000 rpm the train's own vibration left by the fall adds to it (4 % slower):
    the ramp no longer sets the seating alone. Broken copy: seating on the steep flank (no
    ramp) lands ten times faster."""
    train = thesis_train()
    ratio = valve_ratio(train_matrices(train))
    profile = polydyne("4567", 0.4 * INCH, *SCHEDULE, ramp=RAMP)
    speeds = [300, 1000, 2000, 3000]
    cases = [Case(train, profile, r * math.pi / 30, seat=ratio * RAMP.height / 2) for r in speeds]
    res = run_batch(cases, RunSettings(revolutions=2, integrator=integrator))
    error = []
    for i, case in enumerate(cases):
        ev = res.events[i]
        first = ev[ev[:, EV_KIND] == SEAT_IMPACT][0]
        angle = math.degrees(first[EV_TIME] * case.speed)
        assert 190 < angle < 220  # on the closing ramp
        ramp_speed = ratio * case.speed * RAMP.height / RAMP.duration
        error.append(first[EV_VELOCITY] / ramp_speed - 1)
    assert abs(error[0]) < 0.01
    assert max(abs(error[1]), abs(error[2])) < 1e-3
    assert 0.01 < abs(error[3]) < 0.1
    steep = polydyne("4567", 0.4 * INCH, *SCHEDULE)
    flank = Case(train, steep, 300 * math.pi / 30, seat=ratio * RAMP.height / 2)
    ev = run_batch([flank], RunSettings(revolutions=2, integrator=integrator)).events[0]
    assert ev[ev[:, EV_KIND] == SEAT_IMPACT][0, EV_VELOCITY] > 3 * res.events[0][0, EV_VELOCITY]


def test_ramps_in_a_spec(tmp_path):
    """profile.ramp_height and ramp_duration go together and sweep like any key; the shape is
    a choice; a harmonic cam has no ramps."""
    base = """
name: ramps
profile: {kind: polydyne-4567, lift: 0.4 in, rise: 70 deg, dwell: 20 deg, fall: 70 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg, ramp_shape: smooth}
speed: 1000 rpm
sweep: {profile.ramp_height: [0.2 mm, 0.3 mm]}
"""
    study = load_study(write_spec(tmp_path, base))
    assert [round(c.case.profile.poly[0, 3] * 1e6, 6) for c in study.cases] != [0, 0]
    heights = [float(evaluate(c.case.profile, math.radians(30))[0]) for c in study.cases]
    assert_allclose(heights, [0.2e-3, 0.3e-3], rtol=1e-12)
    for bad, key in [
        (base.replace(", ramp_duration: 30 deg", ""), "profile.ramp_duration"),
        (base.replace("ramp_shape: smooth", "ramp_shape: linear"), "profile.ramp_shape"),
        (
            "name: h\nprofile: {kind: harmonic, lift: 1 in, ramp_height: 1 mm}\nspeed: 1 rpm\n",
            "profile.ramp_height",
        ),
    ]:
        with pytest.raises(SpecError, match=key.replace(".", r"\.")):
            load_study(write_spec(tmp_path, bad))
    assert set(RAMP_SHAPES) == {"constant-velocity", "smooth"}
