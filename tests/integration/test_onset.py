"""The steady-state path: the periodic state in closed form against the time-domain engine,
its margin against the frequency response, and ``campipe onset`` against a time-domain
bisection."""

import json
import math

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_allclose
from references import steady_state_cam_force
from study_helpers import write_spec

from campipe.cli import main
from campipe.constants import INCH, LBF, RPM
from campipe.engine import Case, CaseError, RunSettings, run_batch
from campipe.engine import onset as O
from campipe.engine import periodic as P
from campipe.model import thesis_train
from campipe.profiles import harmonic, polydyne

TRAIN = thesis_train()
CAM = harmonic(INCH)
POLY = polydyne("4567", INCH, math.radians(90), math.radians(90), math.radians(90))
LAST = slice(-361, None)


def test_the_margin_is_the_least_of_the_frequency_response():
    """The closed form's least cam force against the frequency response of the constrained
    train (tests/unit/test_accuracy.py, written from M, C, K alone), minimised on a 0.001° grid."""
    speeds = [RPM * r for r in (3000, 8000, 9383, 10000)]
    ext = P.steady_extremes([Case(TRAIN, CAM, w) for w in speeds])
    theta = np.radians(np.arange(0, 360, 1e-3))
    for k, w in enumerate(speeds):
        force = -steady_state_cam_force(TRAIN, w, INCH, theta)
        assert abs(ext.min_cam_force[k] - force.min()) < 1e-6 * LBF
        assert abs(ext.max_cam_force[k] - force.max()) < 1e-6 * LBF
        assert abs(ext.min_cam_force_angle[k] - theta[force.argmin()]) < math.radians(2e-3)
    assert ext.min_cam_force[2] == pytest.approx(0.0, abs=0.01 * LBF)  # the onset, 9383 rpm


@pytest.mark.parametrize(
    "case, start, revolutions",
    [
        (Case(TRAIN, CAM, RPM * 8000), "periodic", 4),
        (Case(TRAIN, CAM, RPM * 8000), "quasi-static", 8),
        (Case(TRAIN, POLY, RPM * 3000), "quasi-static", 8),
        (Case(TRAIN, POLY, RPM * 12000, closure="form"), "quasi-static", 8),
    ],
    ids=["harmonic-periodic", "harmonic-quasi-static", "polydyne", "polydyne-form"],
)
def test_steady_histories_equal_the_engines_last_turn(case, start, revolutions):
    """One turn of closed form against the last of several integrated turns: from the
    periodic start, and from the thesis's quasi-static start, whose transient has decayed."""
    ss = P.steady_state([case])
    res = run_batch([case], RunSettings(revolutions=revolutions, start=start))
    assert np.abs(ss.valve_lift - res.valve_lift[:, LAST]).max() < 1e-9 * INCH
    assert np.abs(ss.follower_lift - res.follower_lift[:, LAST]).max() < 1e-9 * INCH
    assert_allclose(ss.cam_force, res.cam_force[:, LAST], rtol=0, atol=1e-6 * LBF)
    # q7's acceleration from M⁻¹(f − Kq − Cv − M_f1·q̈1): cancellation costs a few digits.
    assert_allclose(ss.acc, res.acc[:, LAST], rtol=0, atol=1e-8 * np.abs(res.acc).max())
    assert ss.q.shape == (1, 361, 7) and ss.cam_angle[-1] == pytest.approx(2 * math.pi)


def test_the_steady_state_refuses_a_case_that_leaves_the_cam_or_seats():
    with pytest.raises(CaseError) as info:
        P.steady_state([Case(TRAIN, CAM, RPM * 8000), Case(TRAIN, CAM, RPM * 9500)])
    assert (info.value.key, info.value.found) == ("speed", [1])
    with pytest.raises(CaseError) as info:
        P.steady_state([Case(TRAIN, CAM, RPM * 3000, seat=0.1 * INCH)])
    assert info.value.key == "seat"


def time_domain_onsets(designs, low, high, tolerance):
    """Bisection on the time-domain engine alone (periodic start, 4 turns): no-follow in some
    turn above (the archive's separation_deg_per_rev > 0), in none below."""
    a = np.full(len(designs), low)
    b = np.full(len(designs), high)
    while (b - a).max() > tolerance:
        x = 0.5 * (a + b)
        cases = [Case(d.train, d.profile, s, d.seat) for d, s in zip(designs, x, strict=True)]
        res = run_batch(cases, RunSettings(revolutions=4), full_state=False)
        off = res.separation > 0
        a = np.where(off, a, x)
        b = np.where(off, x, b)
    return 0.5 * (a + b)


SPEC = """
name: onsets
model: {preset: thesis-1971}
profile: {kind: harmonic, lift: 1 in}
closure: force
sweep:
  speed: {from: LOW rpm, to: HIGH rpm, num: 2}
  AXIS
"""


def onset_cli(tmp_path, low, high, axis, *options):
    spec = SPEC.replace("LOW", str(low)).replace("HIGH", str(high)).replace("AXIS", axis)
    path = write_spec(tmp_path, spec)
    out = CliRunner().invoke(main, ["onset", str(path), "--format", "json", *options])
    assert out.exit_code == 0, out.output
    printed = json.loads(out.stdout)
    assert printed["units"]["onset_speed_rpm"] == "rpm"
    return printed["cases"], tmp_path / "onsets-onset.nc"


def test_onset_agrees_with_a_time_domain_bisection_at_three_preloads(tmp_path):
    rows, nc = onset_cli(tmp_path, 6000, 14000, "model.spring_preload: [120 lbf, 151 lbf, 180 lbf]")
    found = np.array([r["onset_speed_rpm"] for r in rows])
    assert [r["confirmed"] for r in rows] == ["yes"] * 3
    designs = [Case(TRAIN.replace(spring_preload=p * LBF), CAM, 1.0) for p in (120, 151, 180)]
    bisected = time_domain_onsets(designs, RPM * 6000, RPM * 14000, RPM * 0.05) / RPM
    assert np.abs(found - bisected).max() < 1.0
    # The onsets the thesis notes give (frequency response of the constrained train).
    assert_allclose(found, [8939, 9383, 9769], atol=1.0)
    with xr.open_dataset(nc) as ds:
        assert ds.onset_speed_rpm.attrs["units"] == "rpm"
        assert ds.spring_preload.attrs["units"] == "N"
        assert_allclose(ds.spring_preload.values, np.array([120, 151, 180]) * LBF)
        assert ds.margin.dims == ("combination", "scan") and ds.margin.attrs["units"] == "N"
        # The margin falls through zero at the onset: positive at the range's low end.
        assert (ds.margin.values[:, 0] > 0).all() and (ds.margin.values[:, -1] < 0).all()


def test_onset_with_the_seat_agrees_with_a_time_domain_bisection(tmp_path):
    """Seat at 0.1 in: the valve seats on every turn, so the steady state is piecewise
    (I, III, IV); the seat's impact throws the train off the cam with the valve off its
    seat (configuration II) from about 560 rpm up: the first separation, ``--level 0 deg``
    (the default level, 0.5° a turn, is tests/integration/test_onset_windows.py's)."""
    rows, _ = onset_cli(tmp_path, 200, 3000, "seat: [0.1 in, none]", "--level", "0 deg")
    assert [r["seat"] for r in rows] == [pytest.approx(0.1), None]  # the spec's units, in
    assert rows[1]["onset_status"] == "none"  # no seat: follows up to 3000 rpm
    assert rows[1]["onset_speed_rpm"] is None
    design = Case(TRAIN, CAM, 1.0, seat=0.1 * INCH)
    bisected = time_domain_onsets([design], RPM * 200, RPM * 3000, RPM * 0.05) / RPM
    assert rows[0]["confirmed"] == "yes"
    assert abs(rows[0]["onset_speed_rpm"] - bisected[0]) < 1.0


def test_onset_statuses_and_refusals(tmp_path):
    on = O.onset_speeds([Case(TRAIN, CAM, 1.0), Case(TRAIN, POLY, 1.0, closure="form")],
                        RPM * 9500, RPM * 12000)  # fmt: skip
    assert list(on.status) == ["below", "none"] and np.isnan(on.speed).all()
    with pytest.raises(CaseError) as info:
        O.onset_speeds([Case(TRAIN, CAM, 1.0)], RPM * 9000, RPM * 8000)
    assert info.value.key == "speed"
    one_speed = SPEC.replace("speed: {from: LOW rpm, to: HIGH rpm, num: 2}", "seat: [none]")
    path = write_spec(tmp_path, one_speed.replace("AXIS", "") + "speed: 9000 rpm\n")
    out = CliRunner().invoke(main, ["onset", str(path)])
    assert out.exit_code == 2 and "speed: the spec runs one speed (9000 rpm)" in out.output


def test_a_study_with_a_search_runs_the_onset(tmp_path):
    """``search: {onset: no-follow, axis: speed}``: ``campipe study`` writes the onset file at
    the archive's path; a bad value is refused at its key."""
    spec = SPEC.replace("LOW", "6000").replace("HIGH", "14000").replace("AXIS", "")
    path = write_spec(tmp_path, spec + "search: {onset: no-follow, axis: speed}\n")
    out = CliRunner().invoke(main, ["study", str(path)])
    assert out.exit_code == 0, out.output
    with xr.open_dataset(tmp_path / "onsets.nc") as ds:
        assert_allclose(ds.onset_speed_rpm.values, [9383], atol=0.1)
    path = write_spec(tmp_path, spec + "search: {onset: follow}\n")
    out = CliRunner().invoke(main, ["study", str(path)])
    assert out.exit_code == 2 and "search.onset: found 'follow', expected no-follow" in out.output


def test_the_onset_says_what_it_compiles_and_compiles_the_check_ahead(tmp_path, monkeypatch):
    """Before numba compiles the search's kernels (and, with the check, the time-domain
    engine's) ``campipe onset`` says which on the terminal, as ``campipe study`` does, and
    compiles the check's beside the search's in two processes; with every kernel cached it
    says nothing. (The cache is made to look empty; the compiling itself is recorded, not
    run.) Broken copy, run: onset_study without ``_compile_first``: no notice."""
    import campipe.engine.kernels as kernels

    compiled = []
    monkeypatch.setattr(kernels, "_missing", lambda named: list(named))
    monkeypatch.setattr(kernels, "compile_kernels", lambda *a, **k: compiled.append(k))
    spec = SPEC.replace("LOW", "6000").replace("HIGH", "14000").replace("AXIS", "")
    path = write_spec(tmp_path, spec)
    out = CliRunner().invoke(main, ["onset", str(path)])
    assert out.exit_code == 0, out.output
    first = out.stderr.splitlines()[0]
    assert first.startswith("campipe onset: compiling steady extremes, periodic start, ")
    assert "modal-exact" in first and compiled == [{"search": True}]
    out = CliRunner().invoke(main, ["onset", str(path), "--no-check"])
    assert "compiling steady extremes with numba" in out.stderr
    assert "modal-exact" not in out.stderr and len(compiled) == 1
    monkeypatch.setattr(kernels, "_missing", lambda named: [])
    out = CliRunner().invoke(main, ["onset", str(path)])
    assert out.exit_code == 0 and "compiling" not in out.stderr


def test_a_train_with_a_lash_adjuster_is_refused_before_any_search(tmp_path):
    """A lash adjuster's plunger moves turn by turn, so its train has no one-turn steady state
    to search: campipe onset and campipe design's onset requirement refuse it naming
    model.hla_leak_down, at once and writing nothing (campipe before: a 93 s search read the
    train with its plunger leaked down, gave 6143 engine rpm, and its time-domain check,
    pumping up, said NO; found by a fresh pair of eyes)."""
    from pathlib import Path

    import yaml

    bundled = Path(__file__).parents[2] / "studies" / "finger-follower-hla.yaml"
    raw = yaml.safe_load(bundled.read_text())
    raw["sweep"] = {"engine_speed": ["4000 rpm", "9000 rpm"]}
    raw.pop("plots", None)
    path = tmp_path / "hla.yaml"
    path.write_text(yaml.safe_dump(raw))
    out = CliRunner().invoke(main, ["onset", str(path), "-o", str(tmp_path / "on.nc")])
    assert out.exit_code == 2, out.output
    refused = "model.hla_leak_down: found a hydraulic lash adjuster (model.hla_*) in 1 of 1"
    assert f"{refused} combination:" in out.output  # (campipe onset's word for a row)
    assert "run.revolutions: auto" in out.output and not (tmp_path / "on.nc").exists()
    raw["design"] = {
        "vary": {"model.spring_preload": {"from": "150 N", "to": "300 N"}},
        "require": {"onset_speed_rpm": {"min": "4000 rpm"}},
        "minimize": "model.spring_preload",
    }
    path.write_text(yaml.safe_dump(raw))
    out = CliRunner().invoke(main, ["design", str(path), "-o", str(tmp_path / "d.nc")])
    assert out.exit_code == 2, out.output
    assert f"{refused} design:" in out.output
    assert not (tmp_path / "d.nc").exists()
