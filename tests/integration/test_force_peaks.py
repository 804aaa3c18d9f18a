"""The contact forces' maxima (``max_cam_force``, ``max_seat_force``) are the forces' peaks,
located between the grid's points (modal-exact, docs/engine.md), not the largest of the
samples: a designer reads them as the peak load whatever ``run.output_every`` is."""

import math

import numpy as np
import xarray as xr
from click.testing import CliRunner
from study_helpers import BUCKET_RING, STUDIES, write_spec

from campipe.cli import main

TAPPET, PRELOAD, RAMP, RAMP_ANGLE = 0.045, 220.0, 0.3e-3, math.radians(30.0)
STEM, CONTACT = 30000e3, 60000e3


def _run(tmp_path, text, name):
    spec = write_spec(tmp_path, text, f"{name}.yaml")
    archive = tmp_path / f"{name}.nc"
    out = CliRunner().invoke(
        main, ["study", str(spec), "-o", str(archive), "--max-samples", "1000000"]
    )
    assert out.exit_code == 0, out.output
    return xr.load_dataset(archive)


def test_a_seated_bucket_s_seat_force_peaks_at_the_closed_form_between_coarse_samples(tmp_path):
    """An undamped bucket tappet with lash (tests/integration/test_joint_tension.py has the
    motion): after the valve seats and the cam lets the tappet go, the tappet swings on its
    stem and the seat carries P₀ + m·v·ω_t at the swing's peak, v = h·ω/θ the closing ramp's
    velocity and ω_t = √(k/m). Sampled every 5° (the swing's period is 2.1° at 1000 rpm and
    6.3° at 3000 rpm), the seat force's maximum is that peak to 1e-9. Broken copy: the maxima
    read at the grid's points (273.95 N at 1000 rpm against the closed form's 276.92 N)."""
    ds = _run(
        tmp_path,
        BUCKET_RING
        + "run: {revolutions: 2, output_every: 5 deg}\nsweep: {speed: [1000 rpm, 3000 rpm]}\n",
        "ring",
    )
    k = 1.0 / (1.0 / STEM + 1.0 / CONTACT)
    for i, rpm in enumerate((1000.0, 3000.0)):
        ring = TAPPET * (RAMP * rpm * math.pi / 30.0 / RAMP_ANGLE) * math.sqrt(k / TAPPET)
        seat = ds.max_seat_force_by_rev.values[i]
        np.testing.assert_allclose(seat, PRELOAD + ring, rtol=1e-9, err_msg=f"{rpm} rpm")


def test_the_thesis_train_s_force_maxima_bound_its_finely_sampled_forces(tmp_path):
    """The thesis train with its seat at 0.1 in, at three speeds from following the cam to
    bouncing on the seat: sampled every 0.004°, each turn's largest cam and seat force is at
    least every sample's (to rounding) and exceeds their largest by no more than that
    sampling can miss (5e-5 of a peak: at 13205 rpm ω·Δt/2 is 0.027 rad for the fastest mode,
    1.06e6 rad/s, so a sample misses 3.6e-4 of that mode's share at most); sampled every 3°,
    the maxima are the same. Broken copy: the maxima read at the
    grid's points (at 5000 rpm the coarse run's first turn reads 9176.40 N of cam force, the
    fine samples reach 9178.43 N)."""
    text = """\
        name: thesis-peaks
        model: {{preset: thesis-1971}}
        profile: {{kind: harmonic, lift: 1 in}}
        seat: 0.1 in
        closure: force
        run: {{revolutions: 3, output_every: {every}}}
        sweep: {{speed: [5000 rpm, 9000 rpm, 13205 rpm]}}
        """
    coarse = _run(tmp_path, text.format(every="3 deg"), "coarse")
    fine = _run(tmp_path, text.format(every="0.004 deg"), "fine")
    assert fine.cam_angle.attrs["units"] == "degree"
    turn = np.floor(fine.cam_angle.values / 360.0 + 1e-9).astype(int)
    for force in ("cam", "seat"):
        peaks = fine[f"max_{force}_force_by_rev"].values
        # The two runs' own peaks, on grids 750 times apart, agree to what their events'
        # location allows (to run.tolerance, 1e-12 s: a stiff link's force moves by 1e-4 N).
        np.testing.assert_allclose(coarse[f"max_{force}_force_by_rev"].values, peaks, rtol=1e-7)
        history = fine[f"{force}_force"].values
        for i in range(peaks.shape[0]):
            for k in range(peaks.shape[1]):
                sampled = np.nanmax(np.where(turn == k, history[i], -np.inf))
                assert sampled <= peaks[i, k] * (1 + 1e-12), (force, i, k, sampled)
                assert peaks[i, k] - sampled <= 5e-5 * peaks[i, k], (force, i, k, sampled)


def test_a_ramp_impact_s_cam_force_peak_is_found_where_the_grid_skips_its_ringing(tmp_path):
    """The thesis train with 0.3 mm of lash on a polydyne cam's 0.25 mm ramp at 8000 rpm: the
    follower strikes the ramp and the cam force rings in modes the grid would skip (they
    cannot release the contact). Sampled every 1°, the turn's largest cam and seat forces
    are those of a run sampled every 0.01° (whose grid resolves every mode) to 1e-7, and at
    least every one of its samples. Broken copies: the maxima read at the grid's points, or
    located only where the grid already resolves the ringing (12233.6 N of cam force each,
    against 13590.9 N)."""
    text = """\
        name: ramp-impact
        model: {{preset: thesis-1971, lash: 0.3 mm, lash_side: valve}}
        profile: {{kind: polydyne-4567, lift: 0.3 in, rise: 100 deg, dwell: 20 deg,
                  fall: 100 deg, ramp_height: 0.25 mm, ramp_duration: 30 deg,
                  ramp_shape: constant-velocity}}
        closure: force
        run: {{revolutions: 1, output_every: {every}}}
        sweep: {{speed: [8000 rpm]}}
        """
    coarse = _run(tmp_path, text.format(every="1 deg"), "coarse")
    fine = _run(tmp_path, text.format(every="0.01 deg"), "fine")
    for force in ("cam", "seat"):
        peak = fine[f"max_{force}_force"].values[0]
        assert np.nanmax(fine[f"{force}_force"].values[0]) <= peak * (1 + 1e-12)
        np.testing.assert_allclose(coarse[f"max_{force}_force"].values[0], peak, rtol=1e-7)


def _bound_the_samples(peaks, fine, below, above):
    """Each turn's (case's) peak is at least every fine sample's cam force (to ``below`` of
    it) and above their largest by at most ``above`` of it."""
    peaks = np.atleast_2d(peaks)
    turn = np.floor(fine.cam_angle.values / 360.0 + 1e-9).astype(int)
    for i in range(peaks.shape[0]):
        for k in range(peaks.shape[1]):
            sampled = np.nanmax(np.where(turn == k, fine.cam_force.values[i], -np.inf))
            assert sampled <= peaks[i, k] * (1 + below), (i, k, sampled, peaks[i, k])
            assert peaks[i, k] - sampled <= above * peaks[i, k], (i, k, sampled, peaks[i, k])


FINGER = """\
name: finger
model: {layout: finger-follower, pivot_to_roller: 22 mm, pivot_to_pallet: 36 mm,
        cam_base_radius: 16 mm, cam_roller_radius: 8.75 mm, lever_rest_angle: 0 deg,
        lever_inertia: 14 kg*mm**2, roller_mass: 8 g, valve_mass: 45 g,
        lever_stiffness: 10000 N/mm, stem_stiffness: 50000 N/mm, spring_rate: 30 N/mm,
        spring_preload: 180 N, damping_ratios: [0.05], lash: 0.15 mm}
profile: {kind: polydyne-4567, lift: 5.5 mm, rise: 75 deg, dwell: 10 deg, fall: 75 deg,
          ramp_height: 0.15 mm, ramp_duration: 25 deg, ramp_shape: constant-velocity}
closure: force
drive: {cam_per_crank: 0.5}
sweep: {engine_speed: [6000 rpm, 8000 rpm]}
"""


def test_a_finger_s_roller_force_maxima_are_its_peaks_between_coarse_samples(tmp_path):
    """The bundled finger follower's train (finger-follower-hla.yaml without its adjuster)
    at 6000 and 8000 engine rpm: each turn's `max_cam_force`, the roller's normal force on
    the cam (the valve side's times the lever ratio r(θ)), is the same at 5° and 1° samples
    (to 1e-9), at least every 0.005° sample's and within 1e-5 of their largest, and
    newmark-linear's (its 1 µs steps, its own integration) within 5e-5. Broken copy: the
    valve side's peak times r where the sampled valve-side force peaks (campipe before:
    829.92 N at 6000 rpm and 1118.92 N at 8000 rpm at 5° samples against 858.13 and 1144.81
    N: at 8000 rpm the roller's largest force is on another hump of the valve-side force,
    10° from the valve side's largest)."""
    run = "run: {{revolutions: 2, output_every: {every}{integrator}}}\n"
    ds = {
        every: _run(tmp_path, FINGER + run.format(every=every, integrator=""), f"f{i}")
        for i, every in enumerate(("5 deg", "1 deg", "0.005 deg"))
    }
    peaks = ds["5 deg"].max_cam_force_by_rev.values
    np.testing.assert_allclose(ds["1 deg"].max_cam_force_by_rev.values, peaks, rtol=1e-9)
    _bound_the_samples(peaks, ds["0.005 deg"], 1e-12, 1e-5)
    newmark = _run(
        tmp_path,
        FINGER + run.format(every="5 deg", integrator=", integrator: newmark-linear"),
        "newmark",
    )
    np.testing.assert_allclose(newmark.max_cam_force_by_rev.values, peaks, rtol=5e-5)


def test_a_compliant_finger_s_roller_force_maxima_bound_its_fine_samples(tmp_path):
    """The same finger with kelvin–voigt contacts at the cam and the seat (the compliant
    integrator, its law at the roller), at 8000 engine rpm: the turn's `max_cam_force` at 5°
    samples is at least every 0.02° sample's roller force and within 1e-4 of their largest
    (found 2e-6 at 0.01°).
    Broken copy: the compliant integrator's roller-force maxima left out (its valve-side
    peak times r where the sampled valve-side force peaks)."""
    compliant = FINGER.replace(
        "lash: 0.15 mm}",
        "lash: 0.15 mm, cam_contact: kelvin-voigt, cam_contact_stiffness: 200000 N/mm,\n"
        "        cam_contact_damping: 50 N*s/m, seat_contact: kelvin-voigt,\n"
        "        seat_contact_stiffness: 200000 N/mm, seat_contact_damping: 50 N*s/m}",
    )
    run = "run: {{revolutions: 1, output_every: {every}}}\n"
    sweep = "sweep: {engine_speed: [8000 rpm]}\n"
    compliant = compliant.split("sweep:")[0]
    coarse = _run(tmp_path, compliant + run.format(every="5 deg") + sweep, "coarse")
    fine = _run(tmp_path, compliant + run.format(every="0.02 deg") + sweep, "fine")
    _bound_the_samples(coarse.max_cam_force_by_rev.values, fine, 1e-9, 1e-4)


def test_a_force_rising_into_an_impact_elsewhere_peaks_at_the_impact(tmp_path):
    """The bundled bucket with 0.25 mm of lash at 6250 rpm, past its onset: the tappet lands
    back on the cam and the cam's force rises steeply until the valve strikes its seat, where
    the impulse throws the tappet off again, so each turn's largest cam force is the held
    force at that instant, the end of its segment, with no turn of its derivative to mark it.
    Sampled at 1°, `max_cam_force` is at least every 0.002° sample's and the 0.002° run's own
    to 1e-7 (the roundoff of the fine run's 540,000 steps past the onset: its first turn's
    5468.771256 N against 5468.771301 N at 1°, on an AMD EPYC; under 1e-9 on the machine this
    was written on). Broken copy: the maxima without the held forces at an event's instant
    (5078.2 N at 1° against a 0.002° sample of 5465.9 N; found by a fresh pair of eyes, as
    was the same on a finger at 9000 rpm: 2969.4 N against 3683.3 N)."""
    text = (STUDIES / "bucket-tappet-lash.yaml").read_text().split("run:")[0]
    run = "run: {{revolutions: 3, output_every: {every}}}\n"
    sweep = "sweep: {speed: [6250 rpm], model.lash: [0.25 mm]}\n"
    coarse = _run(tmp_path, text + run.format(every="1 deg") + sweep, "coarse")
    fine = _run(tmp_path, text + run.format(every="0.002 deg") + sweep, "fine")
    peaks = coarse.max_cam_force_by_rev.values[0]
    np.testing.assert_allclose(fine.max_cam_force_by_rev.values[0], peaks, rtol=1e-7)
    _bound_the_samples(peaks, fine, 1e-12, 1e-3)
