"""The periodic start of a profile whose rate jumps (constant-velocity ramps): the cam's
jump into the held follower is an impact (``common.classify_break``) whose impulse the turn's
closed form carries (``steady._break_impulse``), and a run starting at θ = 0 starts after the
turn's break, where the cam's rate already is."""

import math

import numpy as np

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import polydyne
from campipe.profiles.shapes import Ramp
from campipe.vocabulary import SEAT

INCH = 0.0254
DEG = math.pi / 180
RPM = 2 * math.pi / 60
#: Ramps of 0.01 in over 20° at constant velocity: a rate step of 0.23 m/s at 3000 rpm where
#: each starts or ends (θ = 0 and 310°), the follower held on the cam all turn.
PROFILE = polydyne("345", INCH, 90 * DEG, 90 * DEG, 90 * DEG, ramp=Ramp(0.01 * INCH, 20 * DEG))


def test_the_periodic_start_is_where_a_long_run_settles_through_the_ramps_impacts():
    """At 3000 rpm the run from the periodic start has the valve lift of the 30th turn of a
    run from the quasi-static start (its transient long decayed) to 1e-12 m at every degree,
    and its second turn repeats its first to 1e-14 m; the two ramp impacts a turn are there.
    Fails without the impulse in the turn's closed form (1.7e-6 m, free velocities 0.02 m/s
    off at the turn's end), or starting before the break at θ = 0 (1.7e-6 m in the first
    degrees)."""
    case = Case(thesis_train(), PROFILE, 3000.0 * RPM)
    periodic = run_batch([case], RunSettings(revolutions=2, output_every=DEG))
    settled = run_batch([case], RunSettings(revolutions=30, output_every=DEG, start="quasi-static"))
    first = periodic.q[0, :361, SEAT]
    assert np.ptp(first) > 0.02
    assert np.max(np.abs(settled.q[0, -361:, SEAT] - first)) < 1e-12
    assert np.max(np.abs(periodic.q[0, 361:, SEAT] - periodic.q[0, 1:361, SEAT])) < 1e-14
    assert len(periodic.events[0]) == 4
    assert np.all(periodic.separation_per_rev[0] == 0.0)
