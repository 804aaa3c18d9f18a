"""One design evaluated: the spec's base case with the design's values, its no-follow onset
(``campipe.engine.onset.onset_speeds``, as ``campipe onset`` finds it) and its metrics at
the requirements' speeds (the engine, as a study's batch runs), and the margin on each
requirement.

A margin is in the requirement's units, positive where it holds: the value less the minimum,
the maximum less the value (a metric's value the worst over its speeds). The search compares
requirements by their *relative* margins (the margin over the bound, or over 1 for a bound of
0): the least of them is the design's, and names the requirement that binds.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe import engine
from campipe.constants import RPM
from campipe.engine import onset as engine_onset
from campipe.engine.levers import at_the_cam
from campipe.engine.metrics import archived_metrics
from campipe.errors import CampipeError
from campipe.study.spec.design import ONSET, Design, Requirement, bound_label, onset_required
from campipe.study.spec.expand import Study
from campipe.study.spec.resolve import ResolvedCase
from campipe.vocabulary import FAILURES


class DesignError(CampipeError, ValueError):
    """A design section the spec's cases cannot serve (``key`` the spec key)."""


@dataclass(frozen=True)
class Bound:
    """One bound of a requirement: ``onset_speed_rpm ≥ 9500 rpm``."""

    requirement: Requirement
    side: str  # "min" or "max"

    @property
    def value(self) -> float:
        r = self.requirement
        return r.minimum if self.side == "min" else r.maximum

    @property
    def name(self) -> str:
        """The margin's column: ``margin_onset_speed_rpm_min`` (with the bound written at
        the engine's speed, ``margin_onset_engine_speed_rpm_min``)."""
        return f"margin_{self.requirement.written_key}_{self.side}"

    @property
    def label(self) -> str:
        return bound_label(self.requirement, self.side)

    def margin(self, value: float) -> float:
        """The margin of ``value`` (the requirement's units); -inf for a value not found."""
        if math.isnan(value):
            return -math.inf
        margin = value - self.value if self.side == "min" else self.value - value
        return self.requirement.as_written(margin)  # an engine-speed onset's: the engine's rpm

    def relative(self, margin: float) -> float:
        """A :meth:`margin` over the bound, each in the units it was written in."""
        value = self.requirement.as_written(self.value)
        return margin / (abs(value) if value != 0 else 1.0)


def bounds_of(design: Design) -> tuple[Bound, ...]:
    return tuple(
        Bound(r, side)
        for r in design.require
        for side, v in (("min", r.minimum), ("max", r.maximum))
        if not math.isnan(v)
    )


@dataclass
class Evaluation:
    """A design and what it gives."""

    x: np.ndarray  # the varied keys' values (SI), in design.vary's order
    onset: float = math.nan  # the no-follow onset [rpm]; NaN: not asked for, or none
    onset_status: str = ""  # engine.onset.Onset's: found, below, none ("" not asked for)
    onset_proven: bool = True  # its search proven (``Computed.onset_proven``)
    #: (metric, speed [rad/s]) → the metric's summary (the archive's units); NaN: failed run
    metrics: dict[tuple[str, float], float] = field(default_factory=dict)
    values: dict[str, float] = field(default_factory=dict)  # requirement → worst value
    margins: dict[str, float] = field(default_factory=dict)  # Bound.name → margin
    relative: float = math.inf  # the least relative margin (inf: no bound)
    binding: str = ""  # the Bound.label of the least
    #: every bound the design fails, (Bound.label, relative margin), the worst first
    failing: tuple[tuple[str, float], ...] = ()
    objectives: tuple[float, ...] = ()  # each objective's value (its units; NaN: not found)

    @property
    def objective(self) -> float:
        """The (first) objective's value."""
        return self.objectives[0] if self.objectives else math.nan

    @property
    def feasible(self) -> bool:
        return self.relative >= 0.0


@dataclass(frozen=True)
class Computed:
    """What a worker computes of a design (:func:`compute_design`); judged by this process."""

    onset: float = math.nan  # the no-follow onset [rpm]; NaN: not asked for, or none
    onset_status: str = ""  # engine.onset.Onset's status ("" not asked for)
    #: (metric summary, speed [rad/s]) → its value (the archive's units); NaN: none
    values: dict[tuple[str, float], float] = field(default_factory=dict)
    failed: tuple[bool, ...] = ()  # the run at each speed failed (a failure status)
    #: the onset's search proven free of missed windows (engine.onset.Onset.proven); False
    #: where it passed speeds on the chords' estimate (a seated steady state, a lift's step)
    onset_proven: bool = True


def compute_design(
    low: float,
    high: float,
    needs_onset: bool,
    speeds: tuple[float, ...],
    wanted: tuple[str, ...],
    level: float,
    first: ResolvedCase,
) -> Computed:
    """A design's case evaluated (on a worker): its no-follow onset between ``low`` and
    ``high`` [rad/s] if ``needs_onset`` (at ``level`` a turn with a seat; NaN: the onset's
    default), and the metrics ``wanted`` (their summaries) of one run of the case at each
    of ``speeds``, as a study's batch runs them."""
    onset, status = math.nan, ""
    if needs_onset:
        at = engine_onset.DEFAULT_ONSET_LEVEL if math.isnan(level) else level
        on = engine_onset.onset_speeds([first.case], low, high, level=at)
        onset, status = float(on.speed[0] / RPM), str(on.status[0])
        proven = on.proven is None or bool(on.proven[0])
    else:
        proven = True
    if not speeds:
        return Computed(onset, status, onset_proven=proven)
    metrics = {m.summary: m for m in archived_metrics()}
    chosen = [metrics[w] for w in wanted]
    cases = [dataclasses.replace(first.case, speed=s) for s in speeds]
    result = engine.run_at_fidelity(
        cases,
        first.settings,
        full_state=any(m.record for m in chosen),
        on_failure="record",
    )
    # a lever layout's cam force and impacts at the cam, as archived (and the cam's radius)
    pressure = any(m.key == "max_cam_pressure" for m in chosen)
    result = at_the_cam(result, cases, first.settings.capture_velocity, pressure)
    failed = np.isin(np.asarray(result.status), FAILURES)
    values = {}
    for m in chosen:
        summary = m.summarise(m.to_archive(result.metric_per_rev(m.key)), result.measured)
        for i, s in enumerate(speeds):
            values[m.summary, s] = float(summary[i])
    return Computed(onset, status, values, tuple(bool(f) for f in failed), proven)


def _in_order(items: Sequence, task: Callable) -> list:
    """The default map: each item in this thread."""
    return [task(item) for item in items]


def _reachable(r: Requirement, low: float, high: float, drive: float | None) -> None:
    """Refuse an onset bound no design can meet: the onset is searched within the spec's
    speeds [``low``, ``high``] rpm (the cam's), so a ``min`` above their top or a ``max``
    below their bottom is never met, whatever the design (``drive``: cam per crank). A bound
    written at the engine's speed (``onset_engine_speed_rpm``) is refused at that key, in the
    engine's rpm as written."""
    engine = r.engine_onset

    def shown(rpm: float) -> str:
        if engine:
            return f"{r.as_written(rpm):g} rpm (the cam's {rpm:g} rpm)"
        return f"{rpm:g} rpm" + (f" (the engine's {rpm / drive:g} rpm)" if drive else "")

    for bound, value, edge, side in (("min", r.minimum, high, "top"), ("max", r.maximum, low,
                                                                      "bottom")):  # fmt: skip
        if math.isnan(value) or (value <= edge if bound == "min" else value >= edge):
            continue
        raise DesignError.at(
            f"design.require.{r.written_key}.{bound}",
            f"found {shown(value)}, {'above' if bound == 'min' else 'below'} the {side} of "
            f"the spec's speed range, {shown(edge)}: the onset is searched within it (as "
            "campipe onset's), so no design can meet the bound; widen the speed range or "
            "move the bound" + ("" if engine else " (design's speeds are the cam's)"),
            found=r.as_written(value),
            expected=f"{'≤' if bound == 'min' else '≥'} {shown(edge)}",
        )


class Evaluator:
    """Evaluates designs of a spec's ``design`` section.

    Parameters
    ----------
    study : Study
        The spec expanded (its speeds the onset's range).
    cases_at : callable
        x (SI values of design.vary's keys) → the spec's expanded study with those values
        (``campipe.study.design.search.design_study``).
    on_evaluation : callable, optional
        Given each new evaluation (a progress line).
    mapped : callable, optional
        ``mapped(items, task)`` → the results in order: where the designs of a batch
        (:meth:`many`) are computed (``campipe.study.run.workers.task_map``: a study's
        scheduler); default: one after another in this thread.
    """

    def __init__(
        self,
        study: Study,
        cases_at: Callable[[np.ndarray], Study],
        on_evaluation: Callable[[Evaluation], None] | None = None,
        mapped: Callable[[Sequence, Callable], list] | None = None,
    ) -> None:
        design = study.spec.design
        assert design is not None
        self.design = design
        self.cases_at = cases_at
        self.on_evaluation = on_evaluation  # told of each new evaluation (a progress line)
        self.bounds = bounds_of(design)
        self.evaluations: list[Evaluation] = []
        self._seen: dict[bytes, Evaluation] = {}
        speeds = np.array([c.case.speed for c in study.cases])
        self.low, self.high = float(speeds.min()), float(speeds.max())
        self.needs_onset = onset_required(design)
        if self.needs_onset and not self.high > self.low:
            raise DesignError.at(
                "speed",
                f"the spec runs one speed ({self.low / RPM:g} rpm); the onset requirement is "
                "searched over the spec's speed range: sweep it, e.g. sweep: {speed: {from: "
                "3000 rpm, to: 20000 rpm, num: 2}}",
                found=self.low,
                expected="a speed range",
            )
        for r in design.require if self.needs_onset else ():
            if r.key == ONSET:
                _reachable(r, self.low / RPM, self.high / RPM, study.spec.drive)
        refusal = self.needs_onset and engine_onset.adjuster_refusal([study.cases[0].case])
        if refusal:
            raise DesignError.at(engine_onset.ADJUSTER_KEY, refusal, found="an adjuster")
        self.metrics = {m.summary: m for m in archived_metrics()}
        self.speeds = sorted({s for r in design.require for s in r.speeds})
        self.mapped = mapped or _in_order
        wanted = tuple(dict.fromkeys(r.key for r in design.require if r.speeds))
        #: what a worker runs for one design's case (picklable: processes, a cluster)
        level = next((r.level for r in design.require if r.key == ONSET), math.nan)
        self.task = functools.partial(
            compute_design, self.low, self.high, self.needs_onset, tuple(self.speeds), wanted,
            level,
        )  # fmt: skip

    def __call__(self, values: Sequence[float] | np.ndarray) -> Evaluation:
        """Evaluate the design ``x`` (kept in :attr:`evaluations`; a design evaluated
        before is not evaluated again)."""
        return self.many([values])[0]

    def many(self, designs: Sequence[Sequence[float] | np.ndarray]) -> list[Evaluation]:
        """Evaluate ``designs`` as one batch on the workers (those not evaluated before),
        kept in :attr:`evaluations` in the order given; their evaluations in that order."""
        xs = [np.array(values, float) for values in designs]
        new: dict[bytes, np.ndarray] = {}
        for x in xs:
            if x.tobytes() not in self._seen:
                new.setdefault(x.tobytes(), x)
        firsts = [self.cases_at(x).cases[0] for x in new.values()]
        computed = self.mapped(firsts, self.task) if firsts else []
        for x, c in zip(new.values(), computed, strict=True):
            ev = Evaluation(x, c.onset, c.onset_status, onset_proven=c.onset_proven)
            ev.metrics = self._metrics(c)
            self._judge(ev)
            self.evaluations.append(ev)
            self._seen[x.tobytes()] = ev
            if self.on_evaluation is not None:
                self.on_evaluation(ev)
        return [self._seen[x.tobytes()] for x in xs]

    def seen(self, x: Sequence[float] | np.ndarray) -> Evaluation | None:
        """The evaluation of ``x`` if it was evaluated."""
        return self._seen.get(np.array(x, float).tobytes())

    def _metrics(self, c: Computed) -> dict[tuple[str, float], float]:
        """A computed design's metrics, NaN where its run failed; a NaN of a run that did
        not fail is a metric the model lacks: refused."""
        out = {}
        for (summary, s), value in c.values.items():
            failed = c.failed[self.speeds.index(s)]
            if not failed and math.isnan(value):
                raise DesignError.at(
                    f"design.require.{summary}",
                    f"the run at {s / RPM:g} rpm gives no value of {summary} (NaN): the "
                    "model lacks what it needs (a Hertz pressure: the contact's radii "
                    "and modulus, docs/model.md); require another metric",
                    found="NaN",
                    expected="a metric the model defines",
                )
            out[summary, s] = math.nan if failed else value
        return out

    def onset_value(self, ev: Evaluation) -> float:
        """The onset a requirement compares [rpm]: none in the range reads as its top, no-follow
        already at its bottom as its bottom."""
        if ev.onset_status == "none":
            return self.high / RPM
        if ev.onset_status == "below":
            return self.low / RPM
        return ev.onset

    def _judge(self, ev: Evaluation) -> None:
        for r in self.design.require:
            if r.key == ONSET:
                ev.values[r.key] = self.onset_value(ev)
        for b in self.bounds:
            r = b.requirement
            if r.key == ONSET:
                value = ev.values[r.key]
            else:
                per_speed = [ev.metrics[r.key, s] for s in r.speeds]
                value = math.nan if any(map(math.isnan, per_speed)) else (
                    min(per_speed) if b.side == "min" else max(per_speed))  # fmt: skip
            ev.margins[b.name] = b.margin(value)
            rel = b.relative(ev.margins[b.name])
            if rel < ev.relative:
                ev.relative, ev.binding = rel, b.label
            if rel < 0.0:
                ev.failing += ((b.label, rel),)
        ev.failing = tuple(sorted(ev.failing, key=lambda f: f[1]))
        ev.objectives = tuple(self.objective_value(ev, k, s) for k, s in self.design.objectives)

    def objective_value(self, ev: Evaluation, key: str, sense: str) -> float:
        """The value of the objective ``key`` (a metric's the worst over its speeds for
        ``sense``)."""
        keys = [v.key for v in self.design.vary]
        if key in keys:
            return float(ev.x[keys.index(key)])
        if key == ONSET:
            return self.onset_value(ev)
        r = next(r for r in self.design.require if r.key == key)
        values = [ev.metrics[r.key, s] for s in r.speeds]
        if any(map(math.isnan, values)):
            return math.nan
        return max(values) if sense == "minimize" else min(values)

    def better(self, a: Evaluation, b: Evaluation) -> bool:
        """``a``'s objective is better than ``b``'s (NaN never is)."""
        if math.isnan(a.objective):
            return False
        if math.isnan(b.objective):
            return True
        if self.design.sense == "minimize":
            return a.objective < b.objective
        return a.objective > b.objective


def margin_columns(bounds: Sequence[Bound]) -> Mapping[str, str]:
    """Bound.name → its units."""
    return {b.name: b.requirement.units for b in bounds}
