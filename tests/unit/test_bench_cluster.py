"""The bench's cluster block (campipe.bench.cluster): the client's CPU per extra case, its
table and its words, from points as bench.json keeps them."""

import pytest

from campipe.bench import cluster


def _point(workers, n, cpu, seconds=2.0, batches=8):
    return {
        "workers": workers,
        "n_cases": n,
        "seconds": seconds,
        "client_cpu": cpu,
        "batches": batches,
        "rate": n / seconds,
    }


POINTS = [
    _point(1, 1000, 0.050, 4.0),
    _point(1, 4000, 0.110, 10.0),
    _point(2, 1000, 0.052, 2.5),
    _point(2, 4000, 0.097, 5.0, 16),
]


def test_the_client_s_cpu_per_extra_case_is_the_slope_between_the_sizes():
    """(0.097 - 0.052) s over 3000 cases on two workers: 15 µs. Broken copy it fails on: the
    CPU per case of the largest study (0.097 / 4000 = 24 µs), which counts the fixed costs."""
    extra = cluster.per_extra_case(POINTS)
    assert extra == pytest.approx({1: 20e-6, 2: 15e-6})
    assert cluster.per_extra_case([POINTS[0]]) == {}  # one size: no slope


def test_the_table_and_the_goal_in_words():
    """The goal (25 µs on two workers) reached at 15 µs, not reached at 30 µs. Broken copy it
    fails on: a verdict that compares the CPU per case rather than per extra case."""
    rows = cluster.table_rows(POINTS)
    assert [r[:3] for r in rows] == [
        ["1", "1000", "8"],
        ["1", "4000", "8"],
        ["2", "1000", "8"],
        ["2", "4000", "16"],
    ]
    assert [r[-1] for r in rows] == ["", "20.0", "", "15.0"]
    assert rows[3][4] == "800" and rows[3][6] == "24"
    text = cluster.notes(POINTS)[0]
    assert "**15.0 µs** (goal: at most 25 µs, reached)" in text
    assert "66,667 cases a second" in text and "at most 800 (2 workers, 4000 cases)" in text
    slow = [*POINTS[:3], _point(2, 4000, 0.142, 5.0)]
    assert "**30.0 µs** (goal: at most 25 µs, not reached)" in cluster.notes(slow)[0]
    assert cluster.notes(POINTS[:2]) == ["Two workers not measured in this run."]


def test_the_spec_holds_the_cases_asked_for():
    """Speeds × two seats: n cases. Broken copy it fails on: a sweep of n speeds (2n cases)."""
    spec = cluster.cluster_spec(1000)
    assert spec["sweep"]["speed"]["num"] * len(spec["sweep"]["seat"]) == 1000
    assert spec["run"]["revolutions"] == 2.0
