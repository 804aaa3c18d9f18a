"""modal-exact repeats a first turn that closes on its own start: a case that follows the cam
from the periodic start is computed for one turn and its later turns are that turn
(``exact.state._repeat_first_turn``); anything else is integrated turn by turn."""

import math

import numpy as np

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.vocabulary import SEAT

INCH = 0.0254
RPM = 2 * math.pi / 60
EVERY = math.radians(1.0)
PER_TURN = 360


def _case(rpm, seat=math.nan):
    return Case(thesis_train(), harmonic(INCH), rpm * RPM, seat=seat)


def test_a_following_case_repeats_its_first_turn_as_newmark_linear_integrates_them():
    """6000 rpm (below the onset, no seat), 4 turns from the periodic start: every turn's
    valve lift agrees with newmark-linear at 0.25 µs integrated through all four turns to
    2e-9 m (its own error there is about 1e-10 m), the later turns equal the first, the
    per-turn metrics too, and only the first turn's grid was walked (steps within one turn's
    samples and a few). Fails if the copy misplaces a sample by one (1e-4 m off), leaves a
    turn's metrics unset, or copies a turn that had not repeated."""
    settings = RunSettings(revolutions=4, output_every=EVERY)
    default = run_batch([_case(6000.0)], settings)
    newmark = run_batch(
        [_case(6000.0)], RunSettings(revolutions=4, output_every=EVERY,
                                    integrator="newmark-linear", dt=0.25e-6)
    )  # fmt: skip
    valve = default.q[0, :, SEAT]
    assert np.max(np.abs(valve - newmark.q[0, :, SEAT])) < 2e-9
    turns = valve[1:].reshape(4, PER_TURN)
    assert np.all(turns == turns[0])
    assert np.ptp(valve) > 0.02  # the valve moves (a full lift of about an inch)
    assert np.all(default.per_rev[0] == default.per_rev[0, 0])
    assert default.per_rev[0, :, 0].size == 4
    assert default.steps[0] <= PER_TURN + 8


def test_a_case_whose_first_turn_does_not_repeat_is_integrated_turn_by_turn():
    """From the quasi-static start the first turn carries a transient: the turns differ
    (by more than 1e-7 m of valve lift), and the run walks every turn's grid. Fails if a
    turn is copied without checking that it repeated."""
    res = run_batch(
        [_case(6000.0)], RunSettings(revolutions=4, output_every=EVERY, start="quasi-static")
    )
    turns = res.q[0, 1:, SEAT].reshape(4, PER_TURN)
    assert np.max(np.abs(turns[1] - turns[0])) > 1e-7
    assert res.steps[0] >= 4 * PER_TURN


def test_cases_with_events_or_partial_turns_are_integrated_turn_by_turn():
    """A seated case (seat impacts every turn), a case past the onset and a run of 2.5 turns
    walk every turn; the seated case's two turns agree with newmark-linear at 0.25 µs to
    2e-7 m (its impacts bound newmark-linear's error). Fails if an event-bearing or partial
    run is repeated."""
    settings = RunSettings(revolutions=2, output_every=EVERY)
    res = run_batch([_case(6000.0, seat=0.0), _case(11000.0)], settings)
    assert np.all(res.steps >= 2 * PER_TURN)
    nm = run_batch(
        [_case(6000.0, seat=0.0)],
        RunSettings(revolutions=2, output_every=EVERY, integrator="newmark-linear", dt=0.25e-6),
    )
    assert np.max(np.abs(res.q[0, :, SEAT] - nm.q[0, :, SEAT])) < 2e-7
    partial = run_batch([_case(6000.0)], RunSettings(revolutions=2.5, output_every=EVERY))
    assert partial.steps[0] >= 2.5 * PER_TURN
