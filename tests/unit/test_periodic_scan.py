"""The periodic start's scan for the latest angle where configuration I holds
(``steady._latest_hold``, its samples stepped by ``steady._scan_piece``), against the equation
of motion in NumPy and the steady state's own samples.

A start that does not hold at θ = 0 begins where the cam's compression (or the valve's height
above its seat) has just come back to zero: the start's state must give F1 ≈ 0 (or q7 at the
seat) through M·a + C·v + K·q, and no sample of the scan's grid after it may hold.
"""

import math

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import Case, RunSettings
from campipe.engine.batch import start_states, train_matrices, valve_reference
from campipe.engine.periodic import _as_extremes, _samples, prepare_steady
from campipe.engine.steady import SEARCH_SAMPLES
from campipe.model import thesis_train
from campipe.profiles import harmonic, polydyne
from campipe.vocabulary import CAM, SEAT

INCH = 0.0254
RPM = math.pi / 30
TRAIN = thesis_train()
HARMONIC = harmonic(INCH)
POLY = polydyne("345", 0.4 * INCH, *np.radians([120, 20, 120]))


def _contact_force(case, q, v, a):
    """F1 from the equation of motion M·a + C·v + K·q = preload + F, F on the cam only."""
    sm = train_matrices(case.train)
    k = sm.mass.shape[0]
    residual = sm.mass @ a[:k] + sm.damping @ v[:k] + sm.stiffness @ q[:k] - sm.preload
    return residual[CAM], float(np.abs(sm.preload).max())


def test_harmonic_start_is_the_latest_hold():
    """Above the onset (12000–20000 rpm) the harmonic cam's periodic state pulls at θ = 0:
    the start is where the compression comes back to zero, the latest on the scan's grid.

    Fails on a copy of ``_latest_hold`` that brackets the boundary a sample late (θ_a at
    sample i − 1, which does not hold): the bisection ends where the cam pulls by 2 N.
    """
    speeds = np.array([12000.0, 13000.0, 15000.0, 17500.0, 20000.0]) * RPM
    cases = [Case(TRAIN, HARMONIC, w) for w in speeds]
    start = start_states(cases, RunSettings(revolutions=1))
    assert (start.t0 < 0).all()  # each start needed the scan
    theta_s = TWO_PI + speeds * start.t0
    batch = prepare_steady(cases)
    ext = _as_extremes(batch.extremes(batch.cases.omega.copy()))
    for i, case in enumerate(cases):
        f1, scale = _contact_force(case, start.q0[i], start.v0[i], start.a0[i])
        assert abs(f1) < 1e-6 * scale  # on the boundary: the compression is zero
        # No sample of the grid after the start holds (the steady state's compression,
        # another kernel's closed form).
        d = TWO_PI / SEARCH_SAMPLES
        later = TWO_PI - d * np.arange(0, int((TWO_PI - theta_s[i]) / d))
        active = np.zeros(len(cases), np.bool_)
        active[i] = True
        force = _samples(batch, ext, np.sort(later), active).cam_force[i]
        assert (force < 0).all()


def test_seated_polydyne_start_on_its_boundary():
    """A polydyne with a seat the valve reaches: the start is where configuration I has just
    come to hold again, the valve at its seat height or the cam's compression at zero.

    Fails on a copy of ``_scan_piece`` that steps the blocks back with ``block_basis`` at −h
    (which takes its series branch there for a fast mode): it stops at a sample too early,
    and the start is 1e-3 of the preload away from its boundary. Fails on the off-by-one
    copy of the test above too.
    """
    seats = [0.02 * INCH, 0.1 * INCH, 0.3 * INCH]
    speeds = np.array([3000.0, 8000.0, 14000.0]) * RPM
    cases = [Case(TRAIN, POLY, w, seat=s) for s in seats for w in speeds]
    start = start_states(cases, RunSettings(revolutions=1))
    scanned = 0
    for i, case in enumerate(cases):
        if start.t0[i] >= 0:
            continue
        scanned += 1
        f1, scale = _contact_force(case, start.q0[i], start.v0[i], start.a0[i])
        height = start.q0[i, SEAT] - (valve_reference(train_matrices(TRAIN)) + case.seat)
        assert -f1 >= -1e-6 * scale and height >= -1e-12  # configuration I holds there
        assert min(abs(f1) / scale, abs(height) / INCH) < 1e-6  # and is on its boundary
    assert scanned >= 3
