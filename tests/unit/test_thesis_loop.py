"""The bench's scalar loop of the thesis's algorithm (``campipe.bench.thesis_loop``), the
reference of the speed sweep's goal, against campipe's newmark-linear at the same step: the
same method written twice (a Gaussian elimination a step there, a step map per train here)."""

import math

import numpy as np

from campipe.bench import thesis_loop
from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.vocabulary import SEAT

INCH = 0.0254
RPM = math.pi / 30
EVERY = math.radians(1.0)


def _both(speed_rpm, revolutions):
    cases = [Case(thesis_train(), harmonic(INCH), speed_rpm * RPM)]
    loop = thesis_loop.run_cases(cases, revolutions, EVERY)[0]
    settings = RunSettings(
        revolutions=revolutions, integrator="newmark-linear", dt=thesis_loop.STEP,
        output_every=EVERY,
    )  # fmt: skip
    return loop, run_batch(cases, settings).q[0, :, SEAT]


def test_the_loop_is_newmark_linear_below_the_onset():
    """At 6000 rpm the follower stays on the cam: the two codes of one method agree to
    rounding (1e-12 in over 1.5 turns, the valve lifting 1.5 in).

    Fails on a copy of the loop whose step matrix takes ΔT²/3 for ΔT²/6 (thesis Eq. 67), or
    whose samples take the step's end instead of its cubic (Eq. 57): they differ by 5e-8 in
    and 5e-4 in.
    """
    loop, newmark = _both(6000.0, 1.5)
    assert np.isfinite(loop).all()
    assert np.ptp(loop) > 1.4 * INCH
    assert np.abs(loop - newmark).max() < 1e-12 * INCH


def test_the_loop_separates_and_strikes_like_newmark_linear():
    """At 11000 rpm the follower leaves the cam and strikes it again: the loop follows
    newmark-linear's valve to a thousandth of an inch (the two place an impact's velocity
    change a step apart).

    Fails on a copy that never releases the cam (F1 > 0 ignored): the valve then follows the
    cam's motion, 0.14 in away from newmark-linear's.
    """
    loop, newmark = _both(11000.0, 2.0)
    assert np.abs(loop - newmark).max() < 1e-3 * INCH
