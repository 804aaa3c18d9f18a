"""A run of automatic length does not take a chaotic response's passage near an unstable
periodic one for a settled response (``campipe.engine.settle.confirmed``), and still settles
the cases it settled before, as soon.

The case: the README quickstart's 9524 rpm case with the seat at 0.1 in (thesis train,
harmonic cam 1 in), whose response never repeats. Run for up to 96 turns, its boundary states
4 turns apart came within the tolerance at turn 95 (a difference of 5.6e-6, a twentieth of
the one before) and the single check took it for period 4 (146.86° a turn); the next
differences grow again (1.7e-5, 2.7e-5, 1.0e-4, 6.0e-4, 3.1e-3 at turns 96–100).
"""

from __future__ import annotations

import numpy as np
import pytest

from campipe.constants import INCH, RPM
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.metrics import batch_means_error
from campipe.engine.settings import SETTLE_CONFIRM
from campipe.model import thesis_train, valve_train
from campipe.profiles import harmonic


def seated_9524() -> Case:
    return Case(thesis_train(), harmonic(1.0 * INCH), 9524 * RPM, 0.1 * INCH)


def test_the_quickstart_chaotic_case_is_not_reported_settled_over_96_turns():
    """Over up to 96 turns it never repeats (period_turns 0, all 96 turns run), and its
    no-follow per turn, a mean over its window (turns 49–96), agrees with an independent
    long fixed run (one piece of 400 turns, no restarts at turn boundaries; mean over turns
    101–400, 145.80°) within 3 % and within 3 standard errors of the two means (batch
    means). Fails on a copy with SETTLE_CONFIRM 0 (the single check: period 4 from turn 91,
    146.86°, no uncertainty)."""
    case = seated_9524()
    auto = run_batch([case], RunSettings(revolutions=None, max_revolutions=96))
    assert auto.period_turns[0] == 0
    assert auto.turns_run[0] == 96
    window = np.flatnonzero(auto.measured[0])
    assert window[0] == 48 and window[-1] == 95  # the second half: turns 49–96
    ours = float(np.degrees(auto.separation[0]))
    ours_error = float(batch_means_error(np.degrees(auto.separation_per_rev), auto.measured)[0])

    fixed = run_batch([case], RunSettings(revolutions=400, warmup=100, max_events=16384))
    per_turn = np.degrees(fixed.separation_per_rev[0, 100:])
    theirs = float(per_turn.mean())
    theirs_error = float(batch_means_error(per_turn[None], np.ones((1, 300), np.bool_))[0])
    assert np.ptp(per_turn[-8:]) > 1.0  # the long run does not repeat either
    assert abs(ours / theirs - 1.0) <= 0.03, (ours, theirs)
    assert np.isfinite(ours_error) and 0 < ours_error < 2.0
    assert abs(ours - theirs) <= 3.0 * np.hypot(ours_error, theirs_error), (
        ours,
        ours_error,
        theirs,
        theirs_error,
    )


@pytest.mark.parametrize(
    ("speed_rpm", "seat_in", "period"),
    [(11000.0, None, 1), (12000.0, None, 2), (12000.0, 0.1, 1), (13500.0, None, 1)],
)
def test_true_periods_are_found_and_agree_with_a_long_run(speed_rpm, seat_in, period):
    """Without a seat, 11000 rpm repeats every turn and 12000 rpm every second turn; with the
    seat at 0.1 in 12000 rpm repeats every turn, and so does 13500 rpm without one. The rule
    finds these periods, and the settled window's no-follow per turn agrees with a fixed run
    of 60 turns' last 20 (in one piece) within 0.5 %, whose own per-turn values repeat with
    the same period. Fails on a copy that checks period 1 only (12000 rpm without a seat then
    never repeats: period 0) and on one that reports the period it confirmed rather than its
    least divisor that the response heads to (12000 rpm with the seat and 13500 rpm without:
    period 2, their transients alternating)."""
    seat = np.nan if seat_in is None else seat_in * INCH
    case = Case(thesis_train(), harmonic(1.0 * INCH), speed_rpm * RPM, seat)
    auto = run_batch([case], RunSettings(revolutions=None))
    assert auto.period_turns[0] == period
    fixed = run_batch([case], RunSettings(revolutions=60, warmup=40))
    last = np.degrees(fixed.separation_per_rev[0, 40:])
    assert np.allclose(last[period:], last[:-period], rtol=2e-3)
    if period == 2:
        assert abs(last[1] - last[0]) > 10.0  # two different turns: the period is two
    assert abs(auto.separation[0] / fixed.separation[0] - 1.0) < 5e-3


def test_cases_that_follow_the_cam_still_settle_in_their_first_turn():
    """From the periodic start a case that follows the cam (3000, 6000 and 9000 rpm without a
    seat) repeats it at once: one turn run, period 1, no-follow 0, its valve lift that of a
    fixed run's second turn. Fails on a copy that asks the first comparison to be confirmed
    too (three turns run)."""
    cases = [Case(thesis_train(), harmonic(1.0 * INCH), s * RPM) for s in (3000, 6000, 9000)]
    auto = run_batch(cases, RunSettings(revolutions=None))
    assert np.all(auto.turns_run == 1) and np.all(auto.period_turns == 1)
    assert np.all(auto.settled_turn == 0)
    assert np.all(auto.separation == 0.0)
    fixed = run_batch(cases, RunSettings(revolutions=2, warmup=1))
    second = fixed.valve_lift[:, 360:]
    assert np.allclose(auto.valve_lift, second, rtol=0, atol=1e-9 * np.ptp(second))


def test_a_seated_case_that_repeats_exactly_later_is_confirmed_first():
    """With the seat at 0.1 in the 6000 rpm case leaves the cam at seating (44.7° a turn) and
    repeats exactly from its second turn; the rule confirms that repetition over
    SETTLE_CONFIRM further turns before it stops: 2 + SETTLE_CONFIRM turns run, the window
    from turn 2, its no-follow that of a fixed 8-turn run's last turns. Fails on a copy that
    takes a rounding-level repetition at once anywhere in the run (2 turns run)."""
    case = Case(thesis_train(), harmonic(1.0 * INCH), 6000 * RPM, 0.1 * INCH)
    auto = run_batch([case], RunSettings(revolutions=None))
    assert auto.period_turns[0] == 1
    assert auto.turns_run[0] == 2 + SETTLE_CONFIRM
    assert auto.settled_turn[0] == 1
    fixed = run_batch([case], RunSettings(revolutions=8, warmup=4))
    assert abs(np.degrees(fixed.separation[0]) - 44.69) < 0.01
    assert abs(auto.separation[0] / fixed.separation[0] - 1.0) < 1e-6


def test_a_grazing_first_turn_is_left_out_of_the_settled_window():
    """A two-mass chain 1.4 rpm past its onset (10360.58 rpm) leaves the periodic start for
    6.068° its first turn and 6.0436° every turn after, its state at the first turn's end
    within the tolerance of the next (the no-follow of a grazing landing moves with the start
    state without bound). The window starts after it: no-follow that of a fixed 30-turn run's
    last turn to 2e-5, where a helper's own solve_ivp run read 6.04355°. Fails on a copy
    that walks the window back on the states alone (6.0497°: turn 1 averaged in)."""
    chain = {
        "layout": "lumped",
        "masses": ["0.05 kg", "0.06 kg"],
        "stiffnesses": ["20000 N/mm"],
        "spring_rate": "40 N/mm",
        "spring_preload": "250 N",
        "damping_ratios": [0.05, 0.05],
    }
    case = Case(valve_train("thesis-1971", chain), harmonic(0.01), 10362 * RPM)
    auto = run_batch([case], RunSettings(revolutions=None))
    assert auto.period_turns[0] == 1 and auto.settled_turn[0] >= 1
    fixed = run_batch([case], RunSettings(revolutions=30, warmup=29))
    sep = np.degrees(auto.separation[0])
    assert abs(sep / np.degrees(fixed.separation[0]) - 1.0) < 2e-5
    assert abs(sep - 6.04355) < 1e-4
