"""``campipe design``'s search: the design that meets a spec's requirements best.

- **One varied key that is also the objective**: a root search. Both bounds are evaluated;
  if the better one (the lower for ``minimize``) meets the requirements it is the answer;
  else, where the other does, the requirements' least relative margin is a function whose
  sign changes between them: ``scipy.optimize.brentq`` brackets its root, then bisection
  until the bracket is no wider than the key's tolerance, and the answer is the bracket's
  end that meets them (never the root's estimate, which may not). Where neither bound meets
  them, :data:`SCAN` values across the bounds are looked at, and the root is
  searched between the best feasible one and its neighbour towards the better bound.
- **Two objectives**: a Latin hypercube of ``max_evaluations`` designs over the bounds
  (``scipy.stats.qmc``, seeded), and the Pareto front of those that meet the requirements:
  the designs no other feasible design is at least as good as in both objectives and better
  in one.
- **Otherwise**: SciPy's optimisers on the keys scaled to [0, 1] with the relative margins
  as inequality constraints: ``minimize(method="COBYQA")`` from the middle of the bounds
  (``method: local``), or ``differential_evolution`` (``method: global``, seeded, then
  COBYQA from its best).

Every evaluation is kept; the answer is the best evaluation that meets every requirement,
so an optimiser's last point never stands in for it. Where none does, the result says so and
names the closest (the largest least relative margin) and the requirement it fails.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe.errors import CampipeError
from campipe.io.spec_yaml import parse_spec_text
from campipe.study.design.evaluate import DesignError, Evaluation, Evaluator
from campipe.study.spec.check import SpecError, check_spec
from campipe.study.spec.design import Design
from campipe.study.spec.expand import Study, expand

#: Values across the bounds looked at when neither bound meets the requirements (one key).
SCAN = 9
#: differential_evolution's population for each varied key (``method: global``).
GLOBAL_POPSIZE = 8


class _Spent(CampipeError, RuntimeError):
    """The evaluations allowed are spent (stops an optimiser; never leaves the search)."""


@dataclass
class DesignResult:
    """The search's outcome."""

    study: Study  # the spec expanded
    evaluations: list[Evaluation]  # in the order evaluated
    chosen: int  # index of the answer (feasible) or of the closest design (infeasible)
    feasible: bool  # whether any design meets every requirement
    method: str  # "root", "local", "global" or "pareto"
    seconds: float  # wall time of the search
    stopped: bool = False  # the search ran out of evaluations (design.max_evaluations)
    #: two objectives: the Pareto front's indices, by the first objective (chosen: its first)
    front: list[int] = field(default_factory=list)

    @property
    def design(self) -> Design:
        d = self.study.spec.design
        assert d is not None
        return d

    @property
    def best(self) -> Evaluation:
        return self.evaluations[self.chosen]

    @property
    def order(self) -> list[int]:
        """The rows shown: the answer first (the Pareto front, with two objectives), then every
        other evaluation in order."""
        first = self.front or [self.chosen]
        shown = set(first)
        return [*first, *(i for i in range(len(self.evaluations)) if i not in shown)]


def design_study(study: Study) -> Callable[[np.ndarray], Study]:
    """x → the spec checked again and expanded with the design's values set (the same
    checks a spec's values pass; its ``--set`` overrides kept)."""
    spec = study.spec
    design = spec.design
    assert design is not None
    source = str(spec.path) if spec.path else "spec"
    raw = parse_spec_text(spec.text, source)

    def cases_at(x: np.ndarray) -> Study:
        overrides = dict(spec.overrides)
        for v, value in zip(design.vary, x, strict=True):
            overrides[v.key] = f"{float(value)!r} {v.units}" if v.units else float(value)
        try:
            checked = check_spec(raw, spec.text, spec.directory, source, overrides)
            checked.path = spec.path
            return expand(checked, source)
        except SpecError as exc:
            values = ", ".join(f"{v.key} = {value:.6g} {v.units}".rstrip()
                               for v, value in zip(design.vary, x, strict=True))  # fmt: skip
            raise DesignError.at(
                "design.vary",
                f"the design {values} (SI) is refused: {exc.problems[0]}; narrow the bounds",
                found=values,
                expected="bounds whose every value the spec accepts",
            ) from None

    return cases_at


def run_design(
    study: Study,
    evaluate: Evaluator | None = None,
    *,
    notice: Callable[[str], None] | None = None,
    on_evaluation: Callable[[Evaluation], None] | None = None,
    mapped: Callable[[Sequence, Callable], list] | None = None,
    before: Callable[[Evaluator], None] | None = None,
) -> DesignResult:
    """Search the design ``study.spec.design`` asks for (see the module's description).

    Parameters
    ----------
    study : Study
        The spec expanded, with its ``design`` section.
    evaluate : Evaluator, optional
        What evaluates a design (default: the spec's onset and engine,
        :class:`~campipe.study.design.evaluate.Evaluator`).
    notice : callable, optional
        Given a line to show before numba compiles the kernels the evaluations need (the
        onset's search, the run's integrator; not called when they are cached); they are
        compiled first, as ``campipe onset`` does.
    on_evaluation : callable, optional
        Given each new evaluation (a progress line).
    mapped : callable, optional
        Where a batch of designs is computed (``campipe.study.run.workers.task_map``, a
        study's scheduler); default: one after another in this thread. The search and its
        answer are the same on every scheduler.
    before : callable, optional
        Given the evaluator once the kernels are compiled, before the search (the
        estimate: :func:`campipe.study.design.estimate.estimate_design`).
    """
    design = study.spec.design
    if design is None:
        raise DesignError.at("design", "missing: the spec has no design section")
    if evaluate is None:
        evaluate = Evaluator(study, design_study(study), on_evaluation, mapped)
        _compile(study, evaluate, notice)
    if before is not None:
        before(evaluate)
    t0 = time.perf_counter()
    method = design.search
    stopped = False
    try:
        if design.pareto:
            _sample(evaluate, design)
        elif method == "root":
            _root(evaluate, design)
        elif design.method == "global":
            _global(evaluate, design)
        else:
            _local(evaluate, design)
    except _Spent:
        stopped = True
    if evaluate.needs_onset and evaluate.evaluations:
        from campipe.engine.kernels import record_loaded, search_kernels

        record_loaded(search_kernels())  # the search's kernels, compiled ahead or not
    evals = evaluate.evaluations
    feasible = [i for i, e in enumerate(evals) if e.feasible]
    if feasible:
        chosen = feasible[0]
        for i in feasible[1:]:
            if evaluate.better(evals[i], evals[chosen]):
                chosen = i
    else:
        chosen = max(range(len(evals)), key=lambda i: evals[i].relative)
    front = pareto_front(evals, design) if design.pareto else []
    if front:
        chosen = front[0]
    return DesignResult(study, evals, chosen, bool(feasible), method,
                        time.perf_counter() - t0, stopped, front)  # fmt: skip


def _compile(study: Study, evaluate: Evaluator, notice: Callable[[str], None] | None) -> None:
    from campipe.engine.kernels import compile_first

    first = study.cases[0]
    compile_first({first.settings: first.case} if evaluate.speeds else {}, notice,
                  search=evaluate.needs_onset)  # fmt: skip


def most_evaluations(design: Design) -> int:
    """The evaluations a search takes at most: the budget, or for a root search its scan and
    a bisection to the tolerance at worst (brentq takes fewer)."""
    if design.search != "root":
        return design.max_evaluations
    return min(design.max_evaluations, 2 + SCAN + 2 * root_halvings(design))


def root_halvings(design: Design) -> int:
    """The halvings of the one key's bounds down to its tolerance."""
    v = design.vary[0]
    return math.ceil(math.log2(max((v.high - v.low) / v.tolerance, 2.0)))


def pareto_front(evals: list[Evaluation], design: Design) -> list[int]:
    """The feasible evaluations no other feasible one dominates (at least as good in both
    objectives, better in one; a NaN objective is never on the front), by the first
    objective."""
    signs = np.array([1.0 if s == "minimize" else -1.0 for _, s in design.objectives])
    idx = [i for i, e in enumerate(evals) if e.feasible and np.isfinite(e.objectives).all()]
    values = np.array([np.array(evals[i].objectives) * signs for i in idx]).reshape(-1, 2)
    front = []
    for a, v in zip(idx, values, strict=True):
        dominated = np.any(np.all(values <= v, axis=1) & np.any(values < v, axis=1))
        if not dominated:
            front.append(a)
    return sorted(front, key=lambda i: signs[0] * evals[i].objectives[0])


def _sample(evaluate: Evaluator, design: Design) -> None:
    from scipy.stats import qmc

    call = _budget_many(evaluate, design)
    low = np.array([v.low for v in design.vary])
    high = np.array([v.high for v in design.vary])
    points = qmc.LatinHypercube(d=len(design.vary), seed=0).random(design.max_evaluations)
    call([low + u * (high - low) for u in points])  # one batch


def _budget_many(
    evaluate: Evaluator, design: Design
) -> Callable[[Sequence[np.ndarray]], list[Evaluation]]:
    """``evaluate.many`` within the budget: of a batch that would exceed it, the designs it
    allows are evaluated, then the search stops (:class:`_Spent`)."""

    def call(xs: Sequence[np.ndarray]) -> list[Evaluation]:
        new = list(
            {x.tobytes(): x for x in map(np.asarray, xs) if evaluate.seen(x) is None}.values()
        )
        room = design.max_evaluations - len(evaluate.evaluations)
        if len(new) > room:
            if room > 0:
                evaluate.many(new[:room])
            raise _Spent.at("design.max_evaluations", f"{design.max_evaluations} designs evaluated")
        return evaluate.many(xs)

    return call


def _budget(evaluate: Evaluator, design: Design) -> Callable[[np.ndarray], Evaluation]:
    many = _budget_many(evaluate, design)
    return lambda x: many([x])[0]


# -- one key: a root search ----------------------------------------------------------------


def _root(evaluate: Evaluator, design: Design) -> None:
    from scipy.optimize import brentq

    v = design.vary[0]
    many = _budget_many(evaluate, design)
    call = _budget(evaluate, design)
    good, far = (v.low, v.high) if design.sense == "minimize" else (v.high, v.low)
    at_good, at_far = many([np.array([good]), np.array([far])])  # one batch
    if at_good.feasible:
        return
    if not at_far.feasible:
        scan = many([np.array([x]) for x in np.linspace(good, far, SCAN + 2)[1:-1]])
        found = next((float(e.x[0]) for e in scan if e.feasible), None)
        if found is None:
            return
        far = found
    a, b = _bracket(evaluate, good, far)

    def g(x: float) -> float:
        e = call(np.array([x]))
        return max(e.relative, -1e300) if e.feasible else min(e.relative, -1e-300)

    if abs(b - a) > v.tolerance:
        try:
            brentq(g, a, b, xtol=v.tolerance / 4, maxiter=200)
        except _Spent:
            raise
        except (ValueError, RuntimeError):
            pass  # a margin without a sign change (-inf: a failed run): bisection below
    a, b = _bracket(evaluate, good, far)
    while abs(b - a) > v.tolerance:
        m = 0.5 * (a + b)
        if call(np.array([m])).feasible:
            b = m
        else:
            a = m


def _bracket(evaluate: Evaluator, good: float, far: float) -> tuple[float, float]:
    """The tightest bracket the evaluations give between ``good`` and ``far``: the feasible
    value nearest ``good`` and the infeasible one nearest it on ``good``'s side."""
    sign = 1.0 if far > good else -1.0
    xs = [(float(e.x[0]), e.feasible) for e in evaluate.evaluations]
    inside = [(x, ok) for x, ok in xs if 0.0 <= sign * (x - good) <= sign * (far - good)]
    b = min((x for x, ok in inside if ok), key=lambda x: sign * (x - good))
    a = max((x for x, ok in inside if not ok and sign * (x - b) < 0), key=lambda x: sign * x)
    return a, b


# -- several keys: SciPy's optimisers ---------------------------------------------------------


class _Scaled:
    """The design on [0, 1]ⁿ: the objective and the relative margins, one evaluation per
    point (the optimisers ask for both). Given the points as columns (N, S), as
    ``differential_evolution(vectorized=True)`` does, they are evaluated as one batch."""

    def __init__(self, evaluate: Evaluator, design: Design) -> None:
        self.many = _budget_many(evaluate, design)
        self.evaluate = evaluate
        self.low = np.array([v.low for v in design.vary])
        self.span = np.array([v.high - v.low for v in design.vary])
        self.sign = 1.0 if design.sense == "minimize" else -1.0
        self.cache: dict[bytes, Evaluation] = {}
        self.scale = math.nan

    def at(self, us: np.ndarray) -> list[Evaluation]:
        """The evaluations of the points ``us`` (S, N), those not seen as one batch."""
        us = np.clip(np.atleast_2d(np.asarray(us, float)), 0.0, 1.0)
        missing = list({u.tobytes(): u for u in us if u.tobytes() not in self.cache}.values())
        if missing:
            evals = self.many([self.low + u * self.span for u in missing])
            self.cache.update((u.tobytes(), e) for u, e in zip(missing, evals, strict=True))
        return [self.cache[u.tobytes()] for u in us]

    def objective(self, u: np.ndarray) -> float | np.ndarray:
        """The scaled objective of a point (N,), or of each column of (N, S)."""
        u = np.asarray(u, float)
        values = np.array([self._objective(e) for e in self.at(u.T if u.ndim == 2 else u)])
        return values if u.ndim == 2 else float(values[0])

    def _objective(self, e: Evaluation) -> float:
        if math.isnan(self.scale) and math.isfinite(e.objective):
            self.scale = abs(e.objective) or 1.0
        if not math.isfinite(e.objective):
            return 1e6
        return self.sign * e.objective / self.scale

    def margins(self, u: np.ndarray) -> np.ndarray:
        """The relative margins (M,) of a point (N,), or (M, S) of the columns of (N, S)."""
        u = np.asarray(u, float)
        out = np.array(
            [
                [b.relative(e.margins[b.name]) for b in self.evaluate.bounds]
                for e in self.at(u.T if u.ndim == 2 else u)
            ]
        )
        out = np.maximum(out, -1e6)
        return out.T if u.ndim == 2 else out[0]


def _constraints(scaled: _Scaled):
    from scipy.optimize import NonlinearConstraint

    if not scaled.evaluate.bounds:
        return []
    return [NonlinearConstraint(scaled.margins, 0.0, np.inf)]


def _cobyqa(scaled: _Scaled, design: Design, start: np.ndarray) -> None:
    from scipy.optimize import Bounds, minimize

    span = np.array([v.high - v.low for v in design.vary])
    final = float(min(v.tolerance for v in design.vary) / span.max())
    left = design.max_evaluations - len(scaled.evaluate.evaluations)
    if left < 2:
        return
    minimize(
        scaled.objective,
        start,
        method="COBYQA",
        bounds=Bounds(0.0, 1.0),
        constraints=_constraints(scaled),
        options={"maxfev": left, "initial_tr_radius": 0.25, "final_tr_radius": max(final, 1e-8)},
    )


def _local(evaluate: Evaluator, design: Design) -> None:
    scaled = _Scaled(evaluate, design)
    _cobyqa(scaled, design, np.full(len(design.vary), 0.5))


def _global(evaluate: Evaluator, design: Design) -> None:
    from scipy.optimize import differential_evolution

    scaled = _Scaled(evaluate, design)
    n = len(design.vary)
    popsize = GLOBAL_POPSIZE
    rounds = max(1, (design.max_evaluations // 2) // (popsize * n) - 1)
    differential_evolution(
        scaled.objective,
        [(0.0, 1.0)] * n,
        constraints=_constraints(scaled),
        popsize=popsize,
        maxiter=rounds,
        seed=0,
        polish=False,
        tol=1e-6,
        vectorized=True,  # each generation one batch of designs on the workers
        updating="deferred",
    )
    evals = evaluate.evaluations
    feasible = [e for e in evals if e.feasible]
    pool = feasible or evals
    best = pool[0]
    for e in pool[1:]:
        if evaluate.better(e, best) if feasible else e.relative > best.relative:
            best = e
    _cobyqa(scaled, design, (best.x - scaled.low) / scaled.span)
