"""The steady fidelity level (``run.fidelity: steady``) against the full engine, and the level
a run that names a tolerance gets (``run.fidelity_tolerance``)."""

import math

import numpy as np
import pytest
from study_helpers import write_spec

from campipe.engine import Case, RunSettings, RunSettingsError, run_at_fidelity, run_batch
from campipe.engine.settings import FIDELITY_ERRORS, STEADY_MIN_TURNS
from campipe.model import thesis_train
from campipe.profiles import harmonic, polydyne
from campipe.study import load_study
from campipe.study.run.execute import run_study

INCH = 0.0254
RPM = math.pi / 30
TRAIN = thesis_train()
CAM = harmonic(INCH)
POLY = polydyne("4567", 0.3 * INCH, *np.radians([100, 20, 100]))


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
