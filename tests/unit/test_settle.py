"""The settling check of a run of automatic length (``campipe.engine.settle.repeats``) on
turn-boundary states of known behaviour: a geometric transient, a period of two, a response
that never repeats."""

from __future__ import annotations

import numpy as np

from campipe.engine.settle import Boundary, metrics_repeat, repeats, settled_from

TOL = 1e-5


def boundary(states: np.ndarray) -> Boundary:
    """One case whose single coordinate takes ``states`` at the turn boundaries (its
    velocity zero), ranging over 1 in a turn."""
    k = states.size
    q = states.reshape(1, k, 1)
    return Boundary(q, np.zeros_like(q), np.ones((1, 2, 1)))


def first_settled(states: np.ndarray, p: int) -> int | None:
    b = boundary(states)
    for k in range(1, states.size):
        if repeats(b, 0, k, p, TOL):
            return k
    return None


def test_a_slow_transient_is_not_settled_while_its_distance_left_exceeds_the_tolerance():
    """x_k = r^k with r = 0.99: the turn-to-turn change, 0.01·r^(k−1), falls below the
    tolerance at k ≈ 688, but the distance left to the periodic response, r^k, only at
    k ≈ 1146. The check waits for the latter (d·r/(1 − r) ≤ tol). Fails on a copy that
    accepts a small change alone (it settles about 460 turns early, 1e-3 away)."""
    r = 0.99
    states = r ** np.arange(2000.0)
    k = first_settled(states, 1)
    assert k is not None
    assert states[k] <= TOL * 1.01  # the distance left is within the tolerance
    assert states[k - 5] > TOL  # and not long after it was
    change_small = np.flatnonzero(np.abs(np.diff(states)) <= TOL)[0] + 1
    assert k > change_small + 400


def test_a_period_of_two_is_found_with_p_two_and_not_with_p_one():
    """Alternating states settle with p = 2 (at once: they repeat exactly) and never with
    p = 1. Fails on a copy that compares every state with the one before whatever p."""
    states = np.tile([0.0, 1.0], 10)
    assert first_settled(states, 1) is None
    assert first_settled(states, 2) == 2
    b = boundary(states)
    assert settled_from(b, 0, 19, 2, TOL) == 1  # back to the start: the window is all of it


def test_a_response_that_never_repeats_is_never_settled():
    """A logistic map in its chaotic regime never repeats within 1e-5 for p = 1 … 4."""
    x = np.empty(200)
    x[0] = 0.3
    for k in range(1, x.size):
        x[k] = 3.9 * x[k - 1] * (1 - x[k - 1])
    assert all(first_settled(x, p) is None for p in (1, 2, 3, 4))


def test_the_window_starts_where_the_turns_metrics_repeat_too():
    """States that repeat exactly from the start, and a first turn whose metric (its
    no-follow) differs from the next's by 4e-3 of its largest: the window starts at turn 1,
    not 0; metrics equal to the tolerance, or NaN in both turns, repeat; a count that
    differs by one does not. Fails on a copy that walks back on the states alone."""
    b = boundary(np.zeros(8))
    per_rev = np.array([[6.068, 2.0, np.nan]] + [[6.0436, 2.0, np.nan]] * 7)
    assert settled_from(b, 0, 7, 1, TOL) == 0  # the states alone: all of it
    assert settled_from(b, 0, 7, 1, TOL, per_rev) == 1
    assert metrics_repeat(per_rev, 1, 1, TOL)
    assert not metrics_repeat(np.array([[6.0, 2.0], [6.0, 3.0]]), 0, 1, TOL)
    assert metrics_repeat(np.array([[6.0, 2.0], [6.0 * (1 + 0.9 * TOL), 2.0]]), 0, 1, TOL)
