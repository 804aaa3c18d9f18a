"""``campipe design``'s estimate, printed before the search: one design timed on this
machine, through the code every evaluation runs, times the rounds the search takes at most.

A round is what the workers compute side by side: a batch of designs (a root search's two
bounds, then its scan; a global method's generation; a Pareto sample) takes as many rounds
as it has designs for each worker; a step of a sequential method (the root's brentq and
bisection, COBYQA) one round each. The designs a search evaluates at most
(:func:`~campipe.study.design.search.most_evaluations`) bound it; a search that stops early
takes less. Not included: compiling the kernels (said before, when it happens) and the
process's own start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from campipe.study.design.evaluate import Evaluator
from campipe.study.design.search import GLOBAL_POPSIZE, SCAN, most_evaluations, root_halvings
from campipe.study.spec.design import Design
from campipe.study.spec.expand import Study


@dataclass(frozen=True)
class DesignEstimate:
    """What ``campipe design`` prints about its cost before the search."""

    seconds: float  # the search's wall time at most [s]
    each: float  # one design's evaluation, timed here [s]
    designs: int  # designs evaluated at most
    rounds: int  # rounds of the workers at most (see the module)
    workers: int  # workers assumed
    method: str  # root, local, global or pareto

    def text(self) -> str:
        """``design time: about 12 s on 2 workers ...``, with its basis."""
        from campipe.study.run.progress import format_seconds

        def say(s: float) -> str:
            return f"{s:.2g} s" if s < 10 else format_seconds(s)

        w = f"{self.workers} worker{'s' if self.workers != 1 else ''}"
        return (
            f"design time: at most about {say(self.seconds)} on {w} ({self.method} search: "
            f"at most {self.designs} designs in {self.rounds} rounds of the workers; one "
            f"design timed here at {say(self.each)} (the spec's own values); compiling and "
            "the process's own start not included)"
        )


def search_rounds(design: Design, workers: int) -> tuple[str, int]:
    """The search's method and the rounds of ``workers`` it takes at most (the module)."""
    workers = max(int(workers), 1)
    most = most_evaluations(design)
    n = len(design.vary)
    if design.pareto:
        return "pareto", math.ceil(most / workers)
    if n == 1 and design.objective == design.vary[0].key:
        rounds = math.ceil(2 / workers) + math.ceil(SCAN / workers) + 2 * root_halvings(design)
        return "root", min(rounds, most)
    if design.method == "local":
        return "local", most
    population = GLOBAL_POPSIZE * n
    # the population and its generations: about the first half, as search._global runs it
    generations = min(max(2, (most // 2) // population), math.ceil(most / population))
    batched = generations * population
    return "global", generations * math.ceil(population / workers) + max(most - batched, 0)


def time_design(evaluate: Evaluator, study: Study) -> float:
    """One design's evaluation, the spec's own values (its first case), timed in this
    process and not kept: the faster of two, the first paying what a process's first
    evaluation pays (a worker pays it once) [s]."""
    times = []
    for _ in range(2):
        t = time.perf_counter()
        evaluate.task(study.cases[0])
        times.append(time.perf_counter() - t)
    return min(times)


def estimate_design(evaluate: Evaluator, study: Study, workers: int) -> DesignEstimate:
    """The estimate of ``campipe design`` on ``workers`` workers (see the module)."""
    design = evaluate.design
    each = time_design(evaluate, study)
    method, rounds = search_rounds(design, workers)
    return DesignEstimate(
        rounds * each, each, most_evaluations(design), rounds, max(int(workers), 1), method
    )
