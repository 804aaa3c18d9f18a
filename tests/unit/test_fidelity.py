"""The steady fidelity level (``run.fidelity: steady``) against the full engine, and the level
a run that names a tolerance gets (``run.fidelity_tolerance``)."""

import math

import numpy as np
import pytest
from study_helpers import write_spec

from campipe.engine import Case, RunSettings, RunSettingsError, run_at_fidelity, run_batch
from campipe.engine.periodic import (
    SteadyExtremes,
    break_events,
    steady_cases,
    steady_extremes,
)
from campipe.engine.settings import FIDELITY_ERRORS, STEADY_MIN_TURNS
from campipe.model import thesis_train
from campipe.profiles import Ramp, flat, harmonic, polydyne
from campipe.study import load_study
from campipe.study.run.execute import run_study

INCH = 0.0254
RPM = math.pi / 30
TRAIN = thesis_train()
CAM = harmonic(INCH)
POLY = polydyne("4567", 0.3 * INCH, *np.radians([100, 20, 100]))
#: The thesis's machining error: a flat from 268° to 272° across the harmonic cam's nose.
FLAT = flat(CAM, math.radians(268), math.radians(272))
RAMP = Ramp(0.3e-3, math.radians(30))  # constant-velocity: 0.3 mm over 30°
RAMPED = polydyne("4567", 0.3 * INCH, *np.radians([100, 20, 100]), ramp=RAMP)
SMOOTH_RAMPED = polydyne(
    "4567", 0.3 * INCH, *np.radians([100, 20, 100]), ramp=Ramp(0.3e-3, math.radians(30), "smooth")
)


def cases():
    """Following cases (harmonic below the onset, a polydyne, a seat the valve never
    reaches) and cases that do not follow (above the onset, a valve that seats)."""
    follow = [
        Case(TRAIN, CAM, 3000 * RPM),
        Case(TRAIN, CAM, 9000 * RPM),
        Case(TRAIN, POLY, 4000 * RPM),
        Case(TRAIN, CAM, 6000 * RPM, seat=-0.5 * INCH),  # a seat below the valve's travel
        Case(TRAIN, CAM, 6000 * RPM, closure="form"),
    ]
    other = [
        Case(TRAIN, CAM, 11000 * RPM),
        Case(TRAIN, CAM, 6000 * RPM, seat=0.1 * INCH),
    ]
    return follow, other


def test_the_steady_level_is_the_full_run_where_it_holds():
    """Below the onset the full run starts on configuration I's periodic steady state and
    stays there, so its turns repeat the closed form: valve lift and velocity, cam lift and
    force agree within the level's stated error (1e-9 in; the closed form's own sampling and
    the integrator differ by rounding), no events, the per-turn metrics the same (the peak
    cam force located exactly by the steady path, on the grid by the integrator: 1e-4). The
    cases that do not follow run in full, bit for bit as alone. Broken copy: a steady turn
    shifted by one sample differs by 1e-3 in."""
    follow, other = cases()
    batch = follow + other
    settings = RunSettings(revolutions=3, fidelity="steady")
    steady = run_at_fidelity(batch, settings)
    full = run_batch(batch, RunSettings(revolutions=3))
    n = len(follow)
    bound = FIDELITY_ERRORS["steady"]
    assert np.abs(steady.valve_lift[:n] - full.valve_lift[:n]).max() < bound
    assert np.abs(steady.cam_lift[:n] - full.cam_lift[:n]).max() < bound
    assert np.abs(steady.valve_velocity[:n] - full.valve_velocity[:n]).max() < 1e-6
    assert np.abs(steady.cam_force[:n] - full.cam_force[:n]).max() < 1e-4  # N, of ~3000 N
    assert np.all(steady.contact_state[:n] == 1) and np.all(full.contact_state[:n] == 1)
    assert [len(e) for e in steady.events[:n]] == [0] * n == [len(e) for e in full.events[:n]]
    for name in ("separation_per_rev", "seated_off_cam_per_rev", "cam_impacts_per_rev"):
        assert np.array_equal(getattr(steady, name)[:n], getattr(full, name)[:n])
    peak, ref = steady.max_cam_force_per_rev[:n], full.max_cam_force_per_rev[:n]
    assert np.abs(peak / ref - 1).max() < 1e-4
    assert np.all(steady.steps[:n] == 0)
    alone = run_batch(other, RunSettings(revolutions=3))
    assert np.array_equal(steady.valve_lift[n:], alone.valve_lift, equal_nan=True)
    assert [e.tolist() for e in steady.events[n:]] == [e.tolist() for e in alone.events]
    shifted = np.roll(steady.valve_lift[0], 1)
    assert np.abs(shifted - full.valve_lift[0]).max() > 1e3 * bound


@pytest.mark.parametrize(
    ("fields", "level"),
    [
        ({}, "full"),
        ({"fidelity": "steady"}, "steady"),
        ({"fidelity_tolerance": 1e-6 * INCH}, "steady"),
        ({"fidelity_tolerance": 1e-12 * INCH}, "full"),  # tighter than the steady level's
        ({"fidelity_tolerance": 1e-6 * INCH, "revolutions": STEADY_MIN_TURNS - 1}, "full"),
        ({"fidelity_tolerance": 1e-6 * INCH, "start": "quasi-static"}, "full"),
        ({"fidelity_tolerance": 1e-6 * INCH, "integrator": "newmark-linear"}, "full"),
    ],
)
def test_a_tolerance_takes_the_cheapest_level_within_it(fields, level):
    settings = RunSettings(**{"revolutions": STEADY_MIN_TURNS, **fields})
    assert settings.level == level


@pytest.mark.parametrize(
    ("fields", "key"),
    [
        ({"fidelity": "steady", "start": "quasi-static"}, "run.fidelity"),
        ({"fidelity": "steady", "integrator": "newmark-linear"}, "run.fidelity"),
        ({"fidelity_tolerance": -1.0}, "run.fidelity_tolerance"),
        ({"fidelity": "reduced"}, "run.fidelity"),
    ],
)
def test_a_level_without_what_it_stands_for_is_refused(fields, key):
    with pytest.raises(RunSettingsError) as exc:
        _ = RunSettings(**fields).level
    assert exc.value.key == key


SPEC = """
name: levels
model: {preset: thesis-1971}
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 6, output_every: 2 deg, fidelity_tolerance: 1e-6 in}
sweep:
  speed: [3000 rpm, 9000 rpm, 11000 rpm]
  seat: [none, 0.1 in]
"""


def test_a_study_that_names_a_tolerance(tmp_path):
    """The archive of a study run at a tolerance against the same study in full: within the
    steady level's stated error where it holds, equal elsewhere (3000 and 9000 rpm without a
    seat follow; 11000 rpm and the seated cases run in full)."""
    import xarray as xr

    tol = load_study(write_spec(tmp_path, SPEC))
    full = load_study(write_spec(tmp_path, SPEC.replace("fidelity_tolerance: 1e-6 in", "")))
    run_study(tol, tmp_path / "tol.nc", scheduler="synchronous")
    run_study(full, tmp_path / "full.nc", scheduler="synchronous")
    a, b = xr.load_dataset(tmp_path / "tol.nc"), xr.load_dataset(tmp_path / "full.nc")
    assert np.abs(a.valve_lift.values - b.valve_lift.values).max() < 1e-9 * INCH
    assert np.array_equal(a.separation_deg_per_rev.values, b.separation_deg_per_rev.values)
    assert np.array_equal(a.seat_impacts.values, b.seat_impacts.values)
    steps = a.steps.values.reshape(3, 2)  # speed × seat (none first)
    assert list(steps[:, 0] == 0) == [True, True, False] and np.all(steps[:, 1] > 0)
    assert np.array_equal(steps[2], b.steps.values.reshape(3, 2)[2])


def hops():
    """Cases whose profile has velocity jumps, each below its margin's onset: the thesis's flat
    at 6000 rpm (issue 32), constant-velocity ramps force- and form-closed at 4000 rpm."""
    return [
        Case(TRAIN, FLAT, 6000 * RPM),
        Case(TRAIN, RAMPED, 4000 * RPM),
        Case(TRAIN, RAMPED, 4000 * RPM, closure="form"),
    ]


def test_velocity_jumps_keep_their_hops_at_the_steady_level():
    """The flat and constant-velocity ramps with ``fidelity: steady`` equal the full engine
    (issue 32): the flat's release and landing, 0.336° of no-follow and two impacts at
    10.3 in/s a turn (the issue's figures), the ramps' two impacts a turn at the rate the cam
    steps to, ω·height/duration = 9.449 in/s at 4000 rpm (a closed form), every turn (the
    first turn starts before the opening ramp's step at θ = 0 and crosses it: before the
    start convention of ``common.start_piece`` it had one). Their margin is positive
    (the closed form alone would take them), so only the profile's breaks send them to the
    full engine. Broken copy: ``run_at_fidelity`` deciding by ``SteadyExtremes.holds`` alone
    (the code before issue 32) gives 0 no-follow and 0 impacts for all three."""
    batch = hops()
    settings = RunSettings(revolutions=3, fidelity="steady")
    steady = run_at_fidelity(batch, settings)
    full = run_batch(batch, RunSettings(revolutions=3))
    assert np.all(steady_extremes(batch).min_cam_force > 500.0)  # N: the margin holds
    for name in (
        "separation_per_rev",
        "cam_impacts_per_rev",
        "max_cam_impact_velocity_per_rev",
        "seat_impacts_per_rev",
    ):
        assert np.array_equal(getattr(steady, name), getattr(full, name)), name
    bound = FIDELITY_ERRORS["steady"]
    assert np.abs(steady.valve_lift - full.valve_lift).max() < bound
    assert np.abs(steady.cam_lift - full.cam_lift).max() < bound
    assert np.all(steady.steps > 0)
    np.testing.assert_allclose(np.degrees(steady.separation_per_rev[0]), 0.336, atol=5e-4)
    assert steady.cam_impacts_per_rev.tolist() == [[2, 2, 2]] * 3
    np.testing.assert_allclose(steady.max_cam_impact_velocity_per_rev[0] / INCH, 10.3, atol=0.05)
    ramp = 4000 * RPM * RAMP.height / RAMP.duration
    np.testing.assert_allclose(steady.max_cam_impact_velocity_per_rev[1:], ramp, rtol=1e-9)
    np.testing.assert_allclose(ramp / INCH, 9.449, atol=5e-4)


def test_break_events_are_the_integrators_rate_jumps():
    """``break_events`` against the profiles' rate jumps in closed form: the flat's edges step
    the rate by ω·h/2·|cos 268°| (0.278 m/s at 6000 rpm, a release), a constant-velocity
    ramp's base-circle ends by ω·height/duration (0.240 m/s at 4000 rpm, an impact); a jump
    below the capture velocity is crossed held, one above it is not. The harmonic cam, the
    thesis's polydyne and smooth ramps have none at any speed. Broken copies: a check of the
    rate jumping into the follower only (JUMP) misses the flat; one without the capture
    velocity keeps the ramp at a capture of 0.25 m/s."""
    w_flat, w_ramp = 6000 * RPM, 4000 * RPM
    flat_jump = w_flat * 0.5 * INCH * abs(math.cos(math.radians(268)))
    ramp_jump = w_ramp * RAMP.height / RAMP.duration
    np.testing.assert_allclose([flat_jump, ramp_jump], [0.2785, 0.2400], atol=5e-5)
    flat_case, ramp_case = Case(TRAIN, FLAT, w_flat), Case(TRAIN, RAMPED, w_ramp)
    for case, jump in ((flat_case, flat_jump), (ramp_case, ramp_jump)):
        assert break_events([case], 0.99 * jump).tolist() == [True]
        assert break_events([case], 1.01 * jump).tolist() == [False]
    smooth = [Case(TRAIN, p, s * RPM) for p in (CAM, POLY, SMOOTH_RAMPED) for s in (500, 12000)]
    assert not break_events(smooth, 1e-9).any()
    form = Case(TRAIN, FLAT, w_flat, closure="form")  # the flat drags a form-closed follower
    assert break_events([form], 0.99 * flat_jump).tolist() == [True]


def test_a_smooth_profile_below_its_onset_takes_the_steady_path():
    """The fast path is kept where it holds: ``steady_cases`` takes the harmonic cam below its
    onset (9383 rpm at the preset's 151 lbf: the thesis notes, from the constrained train's
    frequency response) and leaves it above; takes the thesis's polydyne and smooth ramps;
    leaves the flat and constant-velocity ramps; and ``run_at_fidelity`` integrates no step
    for exactly the cases it takes (the steps a counter of the full engine's work), their
    valve lift within the level's error. Below the capture velocity a ramp's step is crossed
    held, by the integrators too, so the ramp takes the steady path again. Broken copies: a
    level turned off (``steady_cases`` all False) fails the first, one ignoring the margin
    takes 9450 rpm."""
    batch = [
        Case(TRAIN, CAM, 9300 * RPM),
        Case(TRAIN, CAM, 9450 * RPM),
        Case(TRAIN, POLY, 4000 * RPM),
        Case(TRAIN, SMOOTH_RAMPED, 4000 * RPM),
        *hops(),
    ]
    settings = RunSettings(revolutions=2, fidelity="steady")
    take = steady_cases(batch, settings)
    assert take.tolist() == [True, False, True, True, False, False, False]
    result = run_at_fidelity(batch, settings)
    assert ((result.steps == 0) == take).all()
    full = run_batch(batch, RunSettings(revolutions=2))
    assert np.abs(result.valve_lift - full.valve_lift)[take].max() < FIDELITY_ERRORS["steady"]
    loose = RunSettings(revolutions=2, fidelity="steady", capture_velocity=0.25)  # > 0.240 m/s
    ramp = [Case(TRAIN, RAMPED, 4000 * RPM)]
    assert steady_cases(ramp, loose).tolist() == [True]
    a, b = (
        run_at_fidelity(ramp, loose),
        run_batch(ramp, RunSettings(revolutions=2, capture_velocity=0.25)),
    )
    assert a.steps[0] == 0 and b.cam_impacts_per_rev.sum() == 0
    assert np.abs(a.valve_lift - b.valve_lift).max() < FIDELITY_ERRORS["steady"]


def test_a_least_force_of_zero_does_not_hold():
    """Configuration I holds all turn only with the least cam force (and seat height) above
    zero: at zero the follower is at the edge of a separation. Broken copy: ``>=`` (the code
    before issue 32) holds at zero."""
    one = np.ones(3)
    ext = SteadyExtremes(np.array([1.0, 0.0, np.inf]), one, one, np.array([1.0, 1.0, 0.0]), one)
    assert ext.holds.tolist() == [True, False, False]


def test_the_steady_peak_force_just_before_a_break():
    """A bucket tappet (Rayleigh damping) on a polydyne with smooth ramps at 3000 rpm: its
    largest cam force falls 0.2° before the rise's end, a break, where the scan's least
    sample ties across the break and took the dwell's side. The steady closed form's peak
    equals the full engine's (modal-exact follows the force to its peaks between its
    samples: a second method) to 1e-9. Broken copy: the refinement on the least sample's
    own piece alone (7e-5 low, 535.2605 against 535.2980 N)."""
    from campipe.model import valve_train

    bucket = valve_train(
        "thesis-1971",
        {"layout": "direct-acting", "tappet_mass": "45 g", "valve_mass": "65 g",
         "stem_stiffness": "30000 N/mm", "tappet_contact_stiffness": "60000 N/mm",
         "spring_rate": "35 N/mm", "spring_preload": "220 N", "damping_kind": "rayleigh",
         "rayleigh_alpha": "40 s**-1", "rayleigh_beta": "2e-6 s"},
    )  # fmt: skip
    ramp = Ramp(0.3e-3, math.radians(30), "smooth")
    cam = polydyne("4567", 9e-3, *np.radians([110, 20, 110]), ramp=ramp)
    case = Case(bucket, cam, 3000 * RPM)
    steady = run_at_fidelity([case], RunSettings(revolutions=2, fidelity="steady"))
    full = run_batch([case], RunSettings(revolutions=2))
    assert np.all(steady.steps == 0)
    peak = full.max_cam_force_per_rev[0]
    assert peak[0] == pytest.approx(535.298, abs=1e-3)
    np.testing.assert_allclose(steady.max_cam_force_per_rev[0], peak, rtol=1e-9)
