"""The force maxima on a lift table (a break every half degree): every turn's largest cam
force is the profile's, whatever the breaks."""

import numpy as np

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.profiles.pieces import evaluate
from campipe.profiles.shapes import table

INCH = 0.0254
RPM = 2 * np.pi / 60


def test_a_lift_table_s_cam_force_maxima_are_every_turn_s():
    """The thesis train at 8000 rpm (it follows the cam) on its harmonic cam and on a 0.5°
    lift table of it: modal-exact's largest cam force a turn is the smooth profile's on every
    one of 4 turns, to the table's own difference (its spline against the cosine: 5e-4 N of
    3863 N), and newmark-linear's at 1 µs to 0.05 N. Broken copy: the grid's points alone
    count for the maxima (the table's breaks end nearly every step before it reaches one, as
    before): 3751, 3205, 3260 and 2216 N."""
    cam = harmonic(INCH)
    angles = np.radians(np.arange(0.0, 360.0, 0.5))
    lifts = table(angles, evaluate(cam, angles)[0])
    cases = [Case(thesis_train(), p, 8000 * RPM) for p in (cam, lifts)]
    exact = run_batch(cases, RunSettings(revolutions=4)).max_cam_force_per_rev
    assert np.ptp(exact[0]) < 1e-6 and exact[0, 0] > 3800.0
    assert np.max(np.abs(exact[1] - exact[0])) < 1e-3
    newmark = run_batch(
        cases[1:], RunSettings(revolutions=4, integrator="newmark-linear", dt=1e-6)
    ).max_cam_force_per_rev
    assert np.max(np.abs(newmark[0] - exact[0])) < 0.05
