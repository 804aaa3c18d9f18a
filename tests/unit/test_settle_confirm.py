"""The settling rule's confirmation (``campipe.engine.settle.confirmed``) on turn-boundary
states of known behaviour: a chaotic response passing near an unstable periodic one, geometric
transients of period 1 and 2, a response that repeats its start at once, and one that lands
on a repetition later in its run."""

from __future__ import annotations

import numpy as np
import pytest

from campipe.engine.settings import SETTLE_CONFIRM, RunSettings, RunSettingsError, check_settling
from campipe.engine.settle import Boundary, confirmed, least_period, repeats

TOL = 1e-5


def boundary(states: np.ndarray) -> Boundary:
    """One case whose coordinates take ``states`` (turns × coordinates) at the turn
    boundaries (its velocities zero), each ranging over 1 in a turn."""
    states = np.asarray(states, float).reshape(len(states), -1)
    q = states[None]
    return Boundary(q, np.zeros_like(q), np.ones((1, 2, states.shape[1])))


def first(check, states, p: int) -> int | None:
    """The first turn k after which ``check(boundary, 0, k, p, TOL)`` holds."""
    b = boundary(states)
    return next((k for k in range(1, len(states)) if check(b, 0, k, p, TOL)), None)


def saddle(turns: int = 30) -> np.ndarray:
    """A passage near an unstable fixed point: a stable part contracting by 0.05 a turn and
    an unstable part growing 3 times a turn from 1e-9. The differences one turn apart are
    1.2e-4, 5.9e-6, 4.9e-7 at turns 4, 5, 6 (each below the last, the last two within the
    tolerance) and 1.5e-6, 4.4e-6, 1.3e-5 … after: it comes near and leaves."""
    k = np.arange(turns, dtype=float)
    return np.stack([0.05**k, 1e-9 * 3.0**k], axis=1)


def test_a_passage_near_an_unstable_repetition_is_not_taken_for_one():
    """The single check (``repeats``) accepts the saddle passage at turn 5 (a difference
    within the tolerance, contracting 20 times, so the distance left looks 3e-7); the
    confirmed one never does, although the passage's differences stay within the tolerance
    for four turns. Independently: the states at turns 5 and 29 are far apart (the unstable
    part has grown to 7e4). Fails
    on a copy with SETTLE_CONFIRM 0 or 1 (settled at turn 5 or 6), as the engine was when the
    thesis train at 9524 rpm with the seat passed for period 4."""
    states = saddle()
    assert first(repeats, states, 1) == 5
    assert np.abs(states[29] - states[5]).max() > 1e4  # it did not repeat
    assert first(confirmed, states, 1) is None


@pytest.mark.parametrize("r", [0.5, -0.5, 0.9])
def test_a_geometric_transient_settles_confirm_periods_after_it_first_repeats(r):
    """x_k = r^k (period 1; r < 0 alternates about its limit): the single check first holds
    at some turn k0; the confirmed check at k0 + SETTLE_CONFIRM, and there the distance left
    (|x_k|, known here) is within the tolerance. Fails on a copy that makes one check fewer
    than it states (``range(1, SETTLE_CONFIRM)``: settled at k0 + 1)."""
    states = r ** np.arange(400.0)
    k0 = first(repeats, states, 1)
    k = first(confirmed, states, 1)
    assert k0 is not None and k == k0 + SETTLE_CONFIRM
    assert abs(states[k]) <= TOL


def test_a_period_of_two_is_confirmed_in_whole_periods():
    """A period-two response with a transient halving every two turns: x_k = (−1)^k +
    0.5^(k/2). The single check with p = 2 first holds at k0; the confirmed one at
    k0 + 2·SETTLE_CONFIRM (checks a period apart, not a turn); with p = 1 it never does.
    Fails on a copy that steps back one turn per check instead of one period (settled at
    k0 + SETTLE_CONFIRM, or never on the odd turns' uncontracted differences)."""
    k = np.arange(200.0)
    states = (-1.0) ** k + 0.5 ** (k / 2)
    k0 = first(repeats, states, 2)
    assert k0 is not None
    assert first(confirmed, states, 2) == k0 + 2 * SETTLE_CONFIRM
    assert first(confirmed, states, 1) is None


def test_a_repetition_of_the_start_is_settled_at_once():
    """A response that repeats its start to rounding (the periodic start of a train that
    follows the cam) settles after its first turn with p = 1, and a period-two response that
    repeats its start exactly after two turns with p = 2: nothing to confirm, the start being
    a periodic solution. Fails on a copy that confirms these too (settled at 3 and 6)."""
    assert first(confirmed, np.full(10, 0.25) + 1e-15 * np.arange(10), 1) == 1
    assert first(confirmed, np.tile([0.0, 1.0], 10), 2) == 2


def test_an_exact_repetition_later_in_the_run_is_confirmed():
    """A response that wanders and then repeats exactly from turn 4 on: the single check
    accepts it at turn 5 (a difference of 0, within AT_ONCE of the tolerance), the confirmed
    one only SETTLE_CONFIRM turns later, once the exact repetition has held for them. Fails
    on a copy that takes AT_ONCE without confirmation anywhere in the run (settled at 5)."""
    states = np.array([0.0, 0.3, 0.7, 0.2, 0.5] + [0.5] * 10)
    assert first(repeats, states, 1) == 5
    assert first(confirmed, states, 1) == 5 + SETTLE_CONFIRM


def test_a_cap_that_cannot_confirm_the_longest_period_is_refused():
    """max_period 4 needs (2 + SETTLE_CONFIRM)·4 turns before a repetition of 4 turns can be
    confirmed: one turn fewer is refused naming run.max_revolutions, that many is not. Fails
    on a copy that keeps the bound at two periods (8 turns)."""
    least = (2 + SETTLE_CONFIRM) * 4
    with pytest.raises(RunSettingsError) as info:
        check_settling(RunSettings(revolutions=None, max_revolutions=least - 1, max_period=4))
    assert info.value.key == "run.max_revolutions"
    assert f"({least} turns)" in str(info.value)
    check_settling(RunSettings(revolutions=None, max_revolutions=least, max_period=4))


def test_a_period_one_response_with_an_alternating_transient_is_reported_period_one():
    """x_k = 0.95^k·(−1)^k: it heads to one state, but its differences two turns apart
    (1 − 0.95²)·0.95^(k−2) contract 0.9 a period and pass the check with p = 2 long before
    those one turn apart (1.95·0.95^(k−1), contracting 0.95 a turn) do with p = 1. Confirmed
    with p = 2 at some turn k, the period reported is 1 (``least_period``). A true period of
    two, x_k = (−1)^k·(1 + 0.95^k), stays 2: its one-turn differences 2 + 1.95·0.95^(k−1)
    decrease too, but toward 2. Fails on a copy of least_period that returns p (2 for the
    first) or one that takes any divisor whose differences decrease (1 for the second: the
    Aitken limit, 2 here, is what tells them apart)."""
    k = np.arange(600.0)
    alternating = (-0.95) ** k
    k2 = first(confirmed, alternating, 2)
    assert k2 is not None and (first(confirmed, alternating, 1) or 10**9) > k2
    assert least_period(boundary(alternating), 0, k2, 2, TOL) == 1
    two = (-1.0) ** k * (1.0 + 0.95**k)
    k2 = first(confirmed, two, 2)
    assert k2 is not None and first(confirmed, two, 1) is None
    d = np.abs(np.diff(two))
    assert np.all(np.diff(d) < 0) and d[-1] > 2.0  # decreasing toward 2
    assert least_period(boundary(two), 0, k2, 2, TOL) == 2
