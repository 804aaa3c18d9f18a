"""campipe design's search on closed-form stand-ins for a design's evaluation: the root search's
bracket and its answer, the scan where neither bound is feasible, maximize, the budget, the
Pareto front."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from campipe.study.design.evaluate import Bound, Evaluation
from campipe.study.design.search import pareto_front, run_design
from campipe.study.spec.design import Design, Requirement, Vary


class Stub:
    """An Evaluator of a closed form: ``margin(x)`` the requirement's (relative) margin,
    ``objective(x)`` the objectives' values (default: the first key)."""

    def __init__(self, design, margin, objective=None):
        self.design = design
        self.margin = margin
        self.objective = objective or (lambda x: (float(x[0]),))
        req = Requirement("onset_speed_rpm", 1.0, math.nan, "rpm")
        self.bounds = (Bound(req, "min"),)
        self.evaluations = []
        self._seen = {}
        self.needs_onset = False
        self.batches = []  # the designs of each call of many, as evaluated (new ones)

    def seen(self, x):
        return self._seen.get(np.array(x, float).tobytes())

    def __call__(self, x):
        x = np.array(x, float)
        if x.tobytes() in self._seen:
            return self._seen[x.tobytes()]
        m = float(self.margin(x))
        e = Evaluation(x, margins={self.bounds[0].name: m}, relative=m,
                       binding=self.bounds[0].label, objectives=self.objective(x))  # fmt: skip
        self.evaluations.append(e)
        self._seen[x.tobytes()] = e
        return e

    def many(self, xs):
        before = len(self.evaluations)
        out = [self(x) for x in xs]
        self.batches.append([float(e.x[0]) for e in self.evaluations[before:]])
        return out

    def better(self, a, b):
        sign = 1.0 if self.design.sense == "minimize" else -1.0
        return sign * a.objective < sign * b.objective


def design(*objectives, keys=1, tolerance=1e-3, most=200, method="local"):
    vary = tuple(Vary(f"model.k{i}", 0.0, 10.0, tolerance, "", "") for i in range(keys))
    req = (Requirement("onset_speed_rpm", 1.0, math.nan, "rpm"),)
    return Design(vary, req, tuple(objectives), method, most)


def search(d, margin, objective=None):
    study = SimpleNamespace(spec=SimpleNamespace(design=d), name="stub")
    stub = Stub(d, margin, objective)
    return run_design(study, stub), stub


def test_the_least_feasible_value_to_the_tolerance_and_never_the_infeasible_end():
    """Feasible from x = π: the answer meets the requirement, lies within the tolerance above
    π, and an evaluation within the tolerance below it does not meet it. Fails if the search
    answered brentq's root estimate (which may lie below π) or the bracket's middle."""
    result, stub = search(design(("model.k0", "minimize")), lambda x: x[0] - math.pi)
    best = result.best
    assert result.feasible and result.method == "root"
    assert math.pi <= best.x[0] <= math.pi + 1e-3
    below = [e.x[0] for e in stub.evaluations if not e.feasible]
    assert best.x[0] - max(below) <= 1e-3
    assert len(stub.evaluations) < 20  # brentq, not 14 bisections after a scan


def test_maximize_finds_the_largest_feasible_value():
    """Feasible up to x = e: maximize returns e from below. Fails if maximize were searched
    as minimize (the lower bound, 0, feasible, would be returned)."""
    result, _ = search(design(("model.k0", "maximize")), lambda x: math.e - x[0])
    assert result.feasible and math.e - 1e-3 <= result.best.x[0] <= math.e


def test_a_better_bound_that_is_feasible_is_the_answer_at_once():
    """Both bounds go out as one batch (the bracketing evaluations, side by side on the
    workers) and the feasible better one is the answer with nothing more evaluated. Fails if
    the bounds were evaluated one call at a time or the search went on."""
    result, stub = search(design(("model.k0", "minimize")), lambda x: 1.0)
    assert result.best.x[0] == 0.0 and len(stub.evaluations) == 2
    assert stub.batches == [[0.0, 10.0]]


def test_neither_bound_feasible_scans_and_searches_the_window():
    """Feasible only on [4, 6] (a requirement each way): the scan finds the window and the
    root search its lower edge. Fails without the scan (both bounds infeasible read as no
    answer)."""
    result, stub = search(design(("model.k0", "minimize")), lambda x: 1.0 - abs(x[0] - 5.0))
    assert result.feasible and 4.0 <= result.best.x[0] <= 4.0 + 1e-3
    # the bounds one batch, the scan's nine values (1, 2, ..., 9) the next, then one at a time
    assert stub.batches[0] == [0.0, 10.0]
    assert stub.batches[1] == pytest.approx(list(np.linspace(0.0, 10.0, 11)[1:-1]))
    assert all(len(b) <= 1 for b in stub.batches[2:])


def test_no_feasible_value_reports_the_closest():
    """The margin peaks at x = 7 below zero: infeasible, the closest evaluation (the largest
    margin) chosen, never the objective's best. Fails if the least x were returned."""
    result, _ = search(design(("model.k0", "minimize")), lambda x: -1.0 - abs(x[0] - 7.0))
    assert not result.feasible
    assert result.best.relative == max(e.relative for e in result.evaluations)
    assert abs(result.best.x[0] - 7.0) < 1.0


def test_the_budget_stops_the_search_and_it_answers_from_what_it_has():
    result, stub = search(design(("model.k0", "minimize"), most=3), lambda x: x[0] - math.pi)
    assert result.stopped and len(stub.evaluations) == 3
    assert result.feasible and result.best.x[0] >= math.pi


@pytest.mark.parametrize("method", ["local", "global"])
def test_two_keys_reach_the_constrained_optimum(method):
    """Minimize x0 + x1 with x0·x1 ≥ 9 on [0, 10]²: the optimum is (3, 3), 6. Both
    methods come within 1 % and answer a feasible design. Fails if an infeasible last point
    were answered."""
    result, _ = search(
        design(("model.k0", "minimize"), keys=2, method=method, most=400),
        lambda x: x[0] * x[1] / 9.0 - 1.0,
        lambda x: (float(x[0] + x[1]),),
    )
    assert result.feasible and result.best.x[0] * result.best.x[1] >= 9.0
    assert result.best.objective == pytest.approx(6.0, rel=0.01)


def test_the_pareto_front_is_the_non_dominated_feasible_set():
    """Two objectives, minimize x0 and maximize x1, feasible where x1 ≤ x0: the front of a
    Latin hypercube is every feasible sample no other feasible one beats in both, checked
    by brute force, sorted by the first objective. Fails on a dominated point kept or a
    non-dominated one dropped."""
    d = design(("model.k0", "minimize"), ("model.k1", "maximize"), keys=2, most=80)
    result, stub = search(d, lambda x: x[0] - x[1], lambda x: (float(x[0]), float(x[1])))
    assert result.method == "pareto" and len(stub.evaluations) == 80
    ok = [i for i, e in enumerate(stub.evaluations) if e.feasible]
    expected = [
        i for i in ok
        if not any(stub.evaluations[j].x[0] <= stub.evaluations[i].x[0]
                   and stub.evaluations[j].x[1] >= stub.evaluations[i].x[1]
                   and j != i
                   and tuple(stub.evaluations[j].x) != tuple(stub.evaluations[i].x)
                   for j in ok)
    ]  # fmt: skip
    assert sorted(result.front) == sorted(expected) and len(expected) >= 3
    xs = [stub.evaluations[i].x[0] for i in result.front]
    assert xs == sorted(xs) and result.order[: len(expected)] == result.front
    assert pareto_front(stub.evaluations, d) == result.front


def test_the_global_method_evaluates_each_generation_as_one_batch():
    """differential_evolution's population (8 a key: 16 for two) goes to the workers as one
    batch (SciPy's probe of the constraint's shape the one design before it), and each later
    generation's trials too; COBYQA's steps one at a time. The answer
    still reaches the optimum (3, 3). Fails if the population were evaluated one design a
    call (every batch of one)."""
    result, stub = search(
        design(("model.k0", "minimize"), keys=2, method="global", most=400),
        lambda x: x[0] * x[1] / 9.0 - 1.0,
        lambda x: (float(x[0] + x[1]),),
    )
    sizes = [len(b) for b in stub.batches]
    # SciPy probes the constraint's shape at one point first (a point of the population)
    assert sizes[0] == 1 and sizes[0] + sizes[1] == 16
    assert sum(s >= 15 for s in sizes) >= 5 and sizes[-1] == 1
    assert result.feasible and result.best.objective == pytest.approx(6.0, rel=0.01)
