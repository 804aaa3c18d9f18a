"""Limits on what a spec may ask for, checked from the spec alone, before any case is built.

A few lines of YAML can ask for more than any machine has: ten million cases, a step of
1e-15 s, a history sampled every 1e-9 degree, a trillion events. Each bound below is
estimated from the spec's values without expanding a single case — the case count from the
axes' lengths, the steps from the slowest speed and the smallest step anywhere in the spec —
and refused, naming the key, what was found and the limit, with the option that raises it.
The defaults fit a machine of a few cores and some tens of GB of memory and disk.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import DEFAULT_STEPS, resolve_integrator
from campipe.engine.settings import sample_count, turn_count
from campipe.errors import CampipeError
from campipe.study.spec.blocks import MAX_AXIS_LENGTH, leaf_keys
from campipe.study.spec.check import Spec
from campipe.study.spec.fields import CASE_FIELDS, SpecProblem, varied_fields
from campipe.study.spec.variables import DOF_NAMES, data_variables


@dataclass(frozen=True)
class Limits:
    """The bounds a spec is checked against (``campipe study/validate --max-...``)."""

    cases: int = MAX_AXIS_LENGTH  # cases in the study
    steps: float = 1e9  # integration steps of one case (time step bound)
    samples: int = 100_000  # stored samples of one case's histories
    events: int = 100_000  # run.max_events: events kept per case
    archive_bytes: float = 20e9  # the archive before compression [bytes]

    #: option that raises each limit
    OPTIONS = {
        "cases": "--max-cases",
        "steps": "--max-steps",
        "samples": "--max-samples",
        "events": "--max-events",
        "archive_bytes": "--max-archive-gb",
    }


def _over(key: str, what: str, found: float, limit: float, option: str) -> SpecProblem:
    return SpecProblem(
        key,
        f"{what}: {found:.4g}, beyond the limit of {limit:.4g}; make the study smaller, "
        f"or raise the limit with {option}",
        found=found,
        expected=f"at most {limit:.4g}",
    )


def axis_lengths(spec: Spec) -> list[tuple[str, int]]:
    """(spec path, length) of every axis: its length, never its values."""
    out = [(f"sweep.{k}", len(v)) for k, v in spec.sweep.items()]
    if spec.zip:
        out.append(("zip", len(next(iter(spec.zip.values())))))
    if spec.sample:
        out.append(("sample.n", spec.sample.n))
    if spec.cases:
        out.append(("cases", len(spec.cases)))
    return out


def case_count(spec: Spec) -> int:
    """Cases the spec makes: the product of its axes' lengths."""
    return math.prod(n for _, n in axis_lengths(spec))


def values_of(spec: Spec, key: str) -> Iterator[object]:
    """Every value a dotted case key takes anywhere in the spec (in spec spelling): the base,
    the axes, the case entries, a sampled range's ends."""
    node: object = spec.base
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    if node is not None:
        yield node
    for axes in (spec.sweep, spec.zip):
        yield from axes.get(key, [])
    if spec.sample and key in spec.sample.ranges:
        yield from (f"{v!r} {varied_fields()[key].units}" for v in spec.sample.ranges[key])
    for entry in spec.cases:
        if key in leaf_keys(entry):
            node = entry
            for part in key.split("."):
                node = node.get(part) if isinstance(node, dict) else None
            if node is not None:
                yield node


def _parsed(spec: Spec, key: str) -> list:
    field = varied_fields()[key]
    out = []
    for v in values_of(spec, key):
        try:
            out.append(field.parse(v, key))
        except SpecProblem:
            continue  # refused elsewhere
    return out


def bytes_per_case(record: tuple[str, ...], samples: int, revolutions: int) -> int:
    """An archive's bytes per case before compression (events not counted)."""
    sizes = {"cam_angle": samples, "revolution": revolutions, "dof": len(DOF_NAMES)}
    total = 0
    for var in data_variables(record).values():
        if "case" not in var.dims:
            continue
        total += int(np.prod([sizes[d] for d in var.dims[1:]])) * np.dtype(var.dtype).itemsize
    return total + 16 + 8 * 8 + 64  # case id, numeric coordinates, labels (about)


def check_limits(spec: Spec, limits: Limits) -> list[SpecProblem]:
    """The problems of a checked spec against ``limits``, from the spec alone."""
    problems = []
    n = case_count(spec)
    if n > limits.cases:
        lengths = axis_lengths(spec)
        axes = " × ".join(f"{path} {length}" for path, length in lengths)
        longest = max(lengths, key=lambda a: a[1])[0]
        problems.append(_over(longest, f"cases ({axes})", n, limits.cases, Limits.OPTIONS["cases"]))
    run = spec.base["run"]
    try:
        fixed = CASE_FIELDS["run.revolutions"].parse(run["revolutions"], "run")
        # auto: its recorded turns are stored, and it runs at most max_revolutions
        stored = CASE_FIELDS["run.history_turns"].parse(run["history_turns"], "run")
        longest = CASE_FIELDS["run.max_revolutions"].parse(run["max_revolutions"], "run")
        revolutions = float(stored if fixed is None else fixed)
        run_turns = float(longest if fixed is None else fixed)
        output_every = float(CASE_FIELDS["run.output_every"].parse(run["output_every"], "run"))
    except SpecProblem:
        return problems  # refused by the spec's own checks
    samples = sample_count(revolutions, output_every)
    if samples > limits.samples:
        problems.append(
            _over(
                "run.output_every",
                f"samples per case ({revolutions:g} revolutions every "
                f"{math.degrees(output_every):.4g} deg)",
                samples,
                limits.samples,
                Limits.OPTIONS["samples"],
            )
        )
    events = max(_parsed(spec, "run.max_events") or [0])
    if events > limits.events:
        problems.append(
            _over(
                "run.max_events",
                "events kept per case",
                events,
                limits.events,
                Limits.OPTIONS["events"],
            )
        )
    steps, why = _steps(spec, run_turns)
    if steps > limits.steps:
        problems.append(_over(why[0], why[1], steps, limits.steps, Limits.OPTIONS["steps"]))
    n_rev = turn_count(revolutions) if fixed is not None else int(run_turns)
    size = n * bytes_per_case(tuple(run["record"]), samples, n_rev)
    if size > limits.archive_bytes:
        problems.append(
            _over(
                "run",
                "archive size before compression [GB]",
                size / 1e9,
                limits.archive_bytes / 1e9,
                Limits.OPTIONS["archive_bytes"],
            )
        )
    return problems


def _steps(spec: Spec, revolutions: float) -> tuple[float, tuple[str, str]]:
    """The most integration steps any case may take: the slowest speed anywhere in the spec
    with the smallest step anywhere in it (a bound, not an estimate of a real case)."""
    speeds = [s for s in _parsed(spec, "speed") if s and s > 0]
    if not speeds:
        return 0.0, ("speed", "")
    slowest = min(speeds)
    steps: list[float] = [s for s in _parsed(spec, "run.dt") if s]
    for name in _parsed(spec, "run.integrator"):
        try:
            default = DEFAULT_STEPS[resolve_integrator(name)]
        except CampipeError:
            continue
        if default is not None and (None in _parsed(spec, "run.dt") or not steps):
            steps.append(default)
    if not steps:
        return 0.0, ("run.dt", "")
    dt = min(steps)
    simulated = revolutions * TWO_PI / slowest
    return simulated / dt, (
        "run.dt",
        f"steps per case ({simulated:.4g} s simulated at the slowest speed, "
        f"{slowest * 30 / math.pi:.4g} rpm, with the smallest step, {dt:.4g} s)",
    )
