"""The periodic start of a profile whose rate jumps (constant-velocity ramps): the cam's
jump into the held follower is an impact (``common.classify_break``) whose impulse the turn's
closed form carries (``steady._break_impulse``); a run starts on the state before a break at
its start and crosses it, and ends before a break at its end (``common.start_piece``,
``ends_on_a_break``), so a run continued from another's last state, turn by turn, has every
turn's impacts."""

import math

import numpy as np
import pytest

from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.batch import start_states
from campipe.model import thesis_train, valve_train
from campipe.profiles import flat, harmonic, polydyne
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
    off at the turn's end), or starting on the state before the break at θ = 0 without
    crossing it (1.7e-6 m in the first degrees)."""
    case = Case(thesis_train(), PROFILE, 3000.0 * RPM)
    periodic = run_batch([case], RunSettings(revolutions=2, output_every=DEG))
    settled = run_batch([case], RunSettings(revolutions=30, output_every=DEG, start="quasi-static"))
    first = periodic.q[0, :361, SEAT]
    assert np.ptp(first) > 0.02
    assert np.max(np.abs(settled.q[0, -361:, SEAT] - first)) < 1e-12
    assert np.max(np.abs(periodic.q[0, 361:, SEAT] - periodic.q[0, 1:361, SEAT])) < 1e-14
    assert len(periodic.events[0]) == 4  # 0°, 310°, 360°, 670°: the break at 720° is the next run's
    assert np.all(periodic.separation_per_rev[0] == 0.0)


#: The polydyne with 0.3 mm ramps over 30° at constant velocity (studies/lash-ramp.yaml's
#: profile): rate steps at θ = 0 (into the follower) and at 280°.
RAMPED = polydyne("4567", 0.3 * INCH, *np.radians([100, 20, 100]), ramp=Ramp(0.3e-3, 30 * DEG))


@pytest.mark.parametrize("integrator, agree", [("default", 1e-12), ("newmark-linear", 1e-7)])
def test_a_run_continued_turn_by_turn_keeps_the_impact_at_each_turn_s_start(integrator, agree):
    """A run of automatic length runs turn by turn, each turn from the last one's end state
    (``settle.run_settled``): at 1000, 3000 and 5000 rpm its settled turn's valve lift equals
    the last of 8 fixed turns of one run to 1e-12 m (modal-exact; newmark-linear at 1 µs to
    1e-7 m: its impulses fall on differently placed steps), and every turn of both has the
    two ramp impacts. Broken copies: a run that starts on the piece holding its start angle
    (the break there not crossed: the state a turn ended in is the one before it) loses the
    impact at θ = 0 of every turn, 1.4e-6 m off at 3000 rpm and one impact a turn;
    newmark-linear's start keeping the end sample's cam velocity (after the step): no
    impulse, 2.5e-6 m off."""
    cases = [Case(thesis_train(), RAMPED, rpm * RPM) for rpm in (1000, 3000, 5000)]
    dt = 1e-6 if integrator == "newmark-linear" else None
    auto = run_batch(cases, RunSettings(revolutions=None, integrator=integrator, dt=dt))
    fixed = run_batch(cases, RunSettings(revolutions=8, integrator=integrator, dt=dt))
    assert np.all(auto.period_turns == 1)
    settled = auto.valve_lift
    assert np.max(np.abs(settled - fixed.valve_lift[:, -settled.shape[1] :])) < agree
    assert np.all(fixed.cam_impacts_per_rev == 2)
    for i in range(len(cases)):
        assert np.all(auto.cam_impacts_per_rev[i, : auto.turns_run[i]] == 2)


def test_a_release_in_the_held_orbit_carries_its_impulse_share_too():
    """The thesis's flat (268–272°) under force closure releases the follower at its edges,
    where the held orbit the run starts on drags it with the cam: the free coordinates take
    the impulse's share there as at an impact, so the force-closed start is the form-closed
    one (whose run holds the follower through the same breaks and repeats its first turn),
    to rounding. A one-mass chain's valve (its mirror, q7 = −q1) is then the follower from
    its first sample: its valve read 1.46 mm off the follower in its first turn at 6000 rpm,
    the mirror set ringing by the releases. Fails on a copy that skips a release's impulse
    (the free velocities 1e-4 off; the mirror 1.5e-3 m)."""
    cam = flat(harmonic(INCH), 268 * DEG, 272 * DEG)
    force, form = (
        Case(thesis_train(), cam, 6000 * RPM, closure=closure) for closure in ("force", "form")
    )
    settings = RunSettings(revolutions=1, output_every=DEG)
    start = start_states([force, form], settings)
    q0, v0 = start.q0, start.v0
    np.testing.assert_allclose(q0[0], q0[1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(v0[0], v0[1], rtol=0, atol=1e-11 * np.abs(v0[1]).max())
    held = run_batch([form], RunSettings(revolutions=2, output_every=DEG))
    np.testing.assert_allclose(held.q[0, 360], held.q[0, 0], rtol=1e-12, atol=1e-14)
    chain = {"layout": "lumped", "masses": ["0.1 kg"], "stiffnesses": []}
    chain |= {"spring_rate": "40 N/mm", "spring_preload": "300 N", "damping_ratios": [0.05]}
    one = Case(valve_train("thesis-1971", chain), flat(harmonic(0.01), 268 * DEG, 272 * DEG),
               6000 * RPM)  # fmt: skip
    run = run_batch([one], RunSettings(revolutions=3, output_every=0.1 * DEG))
    assert np.any(np.asarray(run.contact_state[0]) != 1)  # it leaves the cam each turn
    assert np.max(np.abs(run.q[0, :, SEAT] + run.q[0, :, 0])) < 1e-12
