"""A compliant case whose contact switch cannot be located fails alone (issue 39, item 8):
its status says so, its batch's other cases are stored."""

import math

import numpy as np
import xarray as xr
from study_helpers import write_spec

import campipe.engine.compliant as compliant
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.vocabulary import NONFINITE, OK

SPEC = """
name: stiff
model:
  preset: thesis-1971
  cam_contact: kelvin-voigt
  cam_contact_stiffness: 1e6 lbf/in
  cam_contact_damping: 10 lbf*s/in
profile: {kind: harmonic, lift: 1 in}
closure: force
run: {revolutions: 1, output_every: 4 deg}
sweep:
  speed: [6000 rpm, 11000 rpm]
"""
#: The case whose switch is made unlocatable [rad/s].
FAILING = 11000 * 2 * math.pi / 60


def _lost_bracket():
    """A terminal monitor that is negative at its segment's start and positive at every later
    call: the step sees a crossing, the root search then finds no sign change (brentq's
    ValueError), as rounding or non-finite states make it in a stiff undamped contact."""
    calls = []

    def monitor(t, z):
        calls.append(t)
        return -1.0 if len(calls) == 1 else 1.0

    monitor.terminal, monitor.direction, monitor.contact = True, 1.0, 0
    return monitor


def test_a_switch_that_cannot_be_located_fails_its_case_alone(tmp_path, monkeypatch):
    """Both cases in one batch; the 11000 rpm case's monitor loses its bracket: it ends with
    status nonfinite and NaN metrics, the 6000 rpm case finishes and the archive is written.
    Broken copy, exact_segment: brentq's ValueError not turned into UnresolvedSwitch: the
    study dies with SciPy's traceback and no archive."""
    real = compliant._Run.monitors

    def monitors(self, t_a, z_a):
        out = real(self, t_a, z_a)
        if math.isclose(self.s.lift.w, FAILING, rel_tol=1e-9):
            out.append(_lost_bracket())
        return out

    monkeypatch.setattr(compliant._Run, "monitors", monitors)
    spec = write_spec(tmp_path, SPEC)
    report = run_study(load_study(spec), tmp_path / "stiff.nc", scheduler="synchronous")
    assert report.computed == 2 and report.batches == 1
    with xr.open_dataset(tmp_path / "stiff.nc") as ds:
        assert ds["speed_rpm"].values.tolist() == [6000.0, 11000.0]
        assert ds["status"].values.tolist() == [OK, NONFINITE]
        force = ds["max_cam_force"].values
        assert np.isfinite(force[0]) and force[0] > 100.0 and np.isnan(force[1])


HERTZ = """
name: hertz
model:
  preset: thesis-1971
  cam_contact: hertz
  cam_hertz_constant: 1e10 N/m^1.5
  seat_contact: hertz
profile: {kind: harmonic, lift: 1 in}
seat: 0.02 in
closure: force
run: {revolutions: 1, output_every: 4 deg}
speed: 6000 rpm
sweep:
  model.seat_hertz_constant: [1e9 N/m^1.5, 1e11 N/m^1.5, 1e12 N/m^1.5]
"""


def test_max_steps_stops_a_stiff_undamped_hertz_case_alone(tmp_path):
    """Hertz contacts without damping, one batch of three seats of rising stiffness (about
    4900, 8200 and 12100 adaptive steps for the turn): with --max-steps 6000 (Limits.steps,
    run.max_steps) the two stiffer cases stop at exactly 6000 steps with status step_limit
    and NaN metrics, and the first is stored as a run without the cap gives it, to the bit.
    Broken copies: the step counter left out of _segment's events (every case runs to the
    end, status ok); the cap read as NONFINITE; or counted across the batch rather than a
    case (the first case stopped too)."""
    from campipe.engine import run_at_fidelity
    from campipe.study.spec.limits import Limits
    from campipe.vocabulary import STEP_LIMIT

    spec = write_spec(tmp_path, HERTZ)
    free = load_study(spec).cases[0]
    alone = run_at_fidelity([free.case], free.settings, on_failure="record")
    assert int(alone.status[0]) == OK and 0 < int(alone.steps[0]) < 6000
    study = load_study(spec, limits=Limits(steps=6000))
    assert [c.settings.max_steps for c in study.cases] == [6000.0] * 3
    report = run_study(study, tmp_path / "hertz.nc", scheduler="synchronous")
    assert report.batches == 1
    with xr.open_dataset(tmp_path / "hertz.nc") as ds:
        assert ds["status"].values.tolist() == [OK, STEP_LIMIT, STEP_LIMIT]
        assert ds["steps"].values.tolist() == [int(alone.steps[0]), 6000, 6000]
        force = ds["max_cam_force"].values
        assert np.isnan(force[1:]).all()
        assert force[0] == float(np.nanmax(alone.metric_per_rev("max_cam_force")))  # [N]
        assert force[0] > 1000.0


def test_validate_names_the_step_cap_of_compliant_cases(tmp_path):
    """campipe validate --max-steps 2000 on the stiffest case: its estimate says each
    compliant case stops at 2000 steps, with the status, and the timed sample run stops
    there too (the study is not refused). Fails if the cap were left out of the estimate."""
    from click.testing import CliRunner

    from campipe.cli import main

    spec = write_spec(tmp_path, HERTZ.replace("1e9 N/m^1.5, 1e11 N/m^1.5, ", ""))
    out = CliRunner().invoke(main, ["validate", str(spec), "--max-steps", "2000"])
    assert out.exit_code == 0, out.output
    line = next(t for t in out.output.splitlines() if t.startswith("run time: about"))
    assert "each compliant case stops at 2e+03 steps (run.max_steps, --max-steps)" in line
    assert "status step_limit" in line
