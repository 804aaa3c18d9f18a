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
