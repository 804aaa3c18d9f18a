"""Checking a study spec's structure and values, every problem named by its key path.

The spec arrives as plain data (parsed by :mod:`campipe.io.spec_yaml`); this module refuses
anything it does not declare (:mod:`campipe.study.spec.fields`) with the key's path, what was
found and what is expected, and returns a :class:`Spec`: the base case with the run defaults
filled in, and the axes (sweep, zip, cases, sample) with ranges expanded into value lists.
Checks that need a whole case (a seat above full lift, a step beyond the stability limit)
run when the cases are resolved (:mod:`campipe.study.spec.expand`).

Grammar (all keys optional except ``name``; each case must end up with a ``speed`` and a
``profile`` from the base or an axis)::

    name: separation-map
    description: free text
    model: {preset: thesis-1971, <parameter>: <quantity>, ...}
    profile: {kind: harmonic, lift: 1 in}
           | {kind: polydyne-345 | polydyne-4567, lift, rise, dwell, fall}
           | {kind: table, file: lift.csv}
    defects: [{kind: flat, from: 268 deg, to: 272 deg}, {kind: bump, center, height, width}]
    closure: force | form
    seat: none | <length>
    speed: <angular speed>
    drive: {cam_per_crank: <number>}                   # campipe.study.spec.drive
    engine_speed: <angular speed>                      # instead of speed, with a drive
    run: {revolutions, integrator, dt, output_every, tolerance, max_events, record: [...]}
    sweep: {<key>: [values] | {from, to, num}, ...}     # full grid
    zip: {<key>: [values] | {from, to, num}, ...}       # varied together
    cases: [{<case keys>}, ...]                          # deep-merged over the base
    sample: {method: latin-hypercube, n, seed, ranges: {<key>: {from, to}}}
    replay: {where: EXPR}
    plots: [{kind: histories | metric | map | events, ...}, ...]   # campipe.study.spec.plots
    design: {vary, require, minimize | maximize, ...}   # campipe.study.spec.design
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from campipe.errors import CampipeError, excerpt
from campipe.study.spec.blocks import (
    MAX_AXIS_LENGTH,
    Problems,
    Sample,
    as_mapping,
    check_axes,
    check_case_block,
    check_cases,
    check_sample,
    leaf_keys,
    show,
    unknown_key,
)
from campipe.study.spec.design import Design, check_design, check_design_axes
from campipe.study.spec.drive import apply_drive
from campipe.study.spec.fields import (
    CASE_FIELDS,
    CASE_KEYS,
    RUN_DEFAULTS,
    SEARCHES,
    TOP_LEVEL,
    SpecProblem,
)
from campipe.study.spec.plots import PlotError, PlotRequest, check_plot
from campipe.study.where import QueryError, parse_where

#: A study name: it names the archive file.
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"
#: Containers whose keys are dotted case keys (so ``--set`` takes the rest of a path whole).
_KEYED_BY_CASE_KEY = ("sweep", "zip", "ranges")
#: Problems reported at most, so a large bad grid stays readable.
MAX_PROBLEMS = 20


class SpecError(CampipeError, ValueError):
    """A spec refused before anything runs: one or more problems (``problems``), each with
    its key path."""

    def __init__(self, problems: list[SpecProblem], source: str = "spec"):
        self.problems = problems
        self.source = source
        head = f"{source}: {len(problems)} problem{'s' if len(problems) != 1 else ''}"
        super().__init__("\n".join([head, *(f"  {p}" for p in problems)]))

    @property
    def paths(self) -> list[str]:
        return [p.path for p in self.problems]


@dataclass
class Spec:
    """A checked spec: the base case and its axes, values still in spec spelling."""

    name: str  # study name
    description: str  # free text
    text: str  # the spec's text as read (kept in the archive)
    directory: Path  # where relative paths (lift tables) are resolved
    base: dict  # the base case: CASE_KEYS, run defaults filled in
    sweep: dict[str, list]  # key → values; full grid, first key outermost
    zip: dict[str, list]  # key → values, all the same length
    cases: list[dict]  # case entries, deep-merged over the base
    sample: Sample | None  # sampled design
    replay: str | None  # replay selection expression
    search: str | None = None  # "onset": search the speed axis instead (campipe onset)
    drive: float | None = None  # camshaft turns per crankshaft turn (drive.cam_per_crank)
    overrides: dict[str, object] = field(default_factory=dict)  # --set KEY=VALUE applied
    path: Path | None = None  # the spec file, when read from one
    plots: list[PlotRequest] = field(default_factory=list)  # figures to write at the end
    design: Design | None = None  # what campipe design searches for

    @property
    def record(self) -> tuple[str, ...]:
        return tuple(self.base["run"]["record"])


def check_conflicts(spec: Spec, problems: Problems) -> None:
    """A key may be varied by one axis only, and not also set by a case entry."""
    owners: dict[str, str] = {}
    axes = [("sweep", k) for k in spec.sweep] + [("zip", k) for k in spec.zip]
    if spec.sample:
        axes += [("sample.ranges", k) for k in spec.sample.ranges]
    for where, key in axes:
        for other, owner in owners.items():
            if key == other or key.startswith(other + ".") or other.startswith(key + "."):
                problems.add(
                    f"{where}.{key}",
                    f"{other} is already varied by {owner}.{other}; vary each key in one place",
                )
        owners[key] = where
    for i, entry in enumerate(spec.cases):
        for key in leaf_keys(entry):
            for other, owner in owners.items():
                if key == other or key.startswith(other + "."):
                    problems.add(
                        f"cases[{i}].{key}", f"also varied by {owner}.{other}; vary it in one place"
                    )


def _axis_keys(spec: Spec) -> dict[str, str]:
    """Key → where the spec varies it (its axes and case entries)."""
    out = {k: "sweep" for k in spec.sweep} | {k: "zip" for k in spec.zip}
    out |= {k: "sample.ranges" for k in (spec.sample.ranges if spec.sample else {})}
    for entry in spec.cases:
        out |= {k: "cases" for k in leaf_keys(entry)}
    return out


def check_replay(value: object, problems: Problems) -> str | None:
    block = problems.check(as_mapping, value, "replay", "{where: EXPR}")
    if block is None:
        return None
    for k in block:
        if k != "where":
            problems.items.append(unknown_key("replay", k, ["where"]))
    where = block.get("where")
    if not isinstance(where, str) or not where.strip():
        problems.add(
            "replay.where",
            f'found {show(where)}, expected an expression such as "speed_rpm == 11000"',
        )
        return None
    try:
        parse_where(where)
    except QueryError as exc:
        problems.add("replay.where", str(exc))
        return None
    return where


def check_plot_list(value: object, problems: Problems) -> list[PlotRequest]:
    """``plots:``: a list of plots (:func:`campipe.study.spec.plots.check_plot`), each problem at
    its entry's key."""
    if not isinstance(value, list):
        problems.add("plots", f"found {show(value)}, expected a list such as [{{kind: metric}}]")
        return []
    out = []
    for i, entry in enumerate(value):
        if not isinstance(entry, Mapping):
            problems.add(
                f"plots[{i}]", f"found {show(entry)}, expected a mapping such as {{kind: map}}"
            )
            continue
        try:
            out.append(check_plot(entry, f"plots[{i}]"))
        except PlotError as exc:
            problems.add(str(exc.key), exc.reason)
    return out


def check_search(value: object, problems: Problems) -> str | None:
    """``search: {onset: no-follow, axis: speed}`` → "onset"."""
    block = problems.check(as_mapping, value, "search", "{onset: no-follow, axis: speed}")
    if block is None:
        return None
    ok = True
    for k, v in block.items():
        if k not in SEARCHES:
            problems.items.append(unknown_key("search", k, list(SEARCHES)))
            ok = False
        elif v not in SEARCHES[k]:
            problems.add(f"search.{k}", f"found {show(v)}, expected {' or '.join(SEARCHES[k])}")
            ok = False
    if "onset" not in block:
        problems.add("search.onset", "missing: what to search for (no-follow)")
        ok = False
    return "onset" if ok else None


# -- the spec -------------------------------------------------------------------------------


def check_spec(
    raw: object,
    text: str = "",
    directory: str | Path = ".",
    source: str = "spec",
    overrides: Mapping[str, object] | None = None,
    max_axis: int = MAX_AXIS_LENGTH,
) -> Spec:
    """Check a parsed spec and return it with defaults filled in and ranges expanded.

    Parameters
    ----------
    raw : object
        The parsed YAML (see :func:`campipe.io.spec_yaml.read_spec`).
    text : str
        The spec's text, kept in the archive.
    directory : str or Path
        The spec's folder: lift-table files are relative to it.
    source : str
        The spec's name in error messages.
    overrides : mapping, optional
        ``{"run.revolutions": 1}``: applied over ``raw`` first (``campipe study --set``).
    max_axis : int
        Longest axis (a range's num, a sample's n): refused beyond it, before any value is
        made (the case count is checked by :func:`campipe.study.spec.limits.check_limits`).

    Raises
    ------
    SpecError
        Listing every problem found, each with its key path.
    """
    problems = Problems()
    overrides = dict(overrides or {})
    if overrides:
        raw = copy.deepcopy(raw)
        for key, value in overrides.items():
            try:
                raw = apply_override(raw, key, value)
            except SpecProblem as exc:
                problems.items.append(exc)
    if not isinstance(raw, Mapping):
        found = "nothing (the file is empty, or only comments)" if raw is None else show(raw)
        raise SpecError(
            [
                SpecProblem(
                    "", f"found {found}, expected a mapping of the keys: " + ", ".join(TOP_LEVEL)
                )
            ],
            source,
        )
    raw, drive = apply_drive(raw, problems)
    for k in raw:
        if k not in TOP_LEVEL:
            problems.items.append(unknown_key("", str(k), TOP_LEVEL))
    name = raw.get("name")
    if name is None:
        problems.add(
            "name", "missing; expected a study name such as 'separation-map' (it names the archive)"
        )
    elif not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        quote = f"; YAML read it as a number: quote it, name: '{name}'"
        problems.add(
            "name",
            f"found {show(name)}, expected letters, digits, '-', '_' or '.', "
            "starting with a letter or digit (it names the archive file)"
            + (quote if isinstance(name, int | float) and not isinstance(name, bool) else ""),
        )
    description = raw.get("description", "")
    if not isinstance(description, str):
        problems.add("description", f"found {show(description)}, expected text")
    base = check_case_block({k: raw[k] for k in CASE_KEYS if k in raw}, "", False, problems)
    base.setdefault("model", {})
    base["model"] = {"preset": "thesis-1971", **(base["model"] or {})}
    base.setdefault("defects", [])
    base.setdefault("closure", "force")
    base.setdefault("seat", "none")
    base["run"] = {**RUN_DEFAULTS, **(base.get("run") or {})}
    problems.check(check_output_every, base["run"])
    sweep = check_axes(raw["sweep"], "sweep", False, problems, max_axis) if "sweep" in raw else {}
    zipped = check_axes(raw["zip"], "zip", True, problems, max_axis) if "zip" in raw else {}
    cases = check_cases(raw["cases"], problems) if "cases" in raw else []
    sample = check_sample(raw["sample"], problems, max_axis) if "sample" in raw else None
    replay = check_replay(raw["replay"], problems) if "replay" in raw else None
    plots = check_plot_list(raw["plots"], problems) if "plots" in raw else []
    search = check_search(raw["search"], problems) if "search" in raw else None
    design = check_design(raw["design"], problems, drive) if "design" in raw else None
    spec = Spec(
        name=name if isinstance(name, str) else "",
        description=str(description),
        text=text,
        directory=Path(directory),
        base=base,
        sweep=sweep,
        zip=zipped,
        cases=cases,
        sample=sample,
        replay=replay,
        search=search,
        drive=drive,
        overrides=overrides,
        plots=plots,
        design=design,
    )
    check_conflicts(spec, problems)
    if design is not None:
        check_design_axes(_axis_keys(spec), design, problems)
    if problems.items:
        raise SpecError(problems.items[:MAX_PROBLEMS], source)
    return spec


def check_output_every(run: Mapping) -> None:
    """The stored histories need at least two samples: ``output_every`` within the run."""
    try:
        revolutions = CASE_FIELDS["run.revolutions"].parse(run["revolutions"], "run.revolutions")
        if revolutions is None:  # auto: the recorded turns'
            revolutions = CASE_FIELDS["run.history_turns"].parse(
                run["history_turns"], "run.history_turns"
            )
        every = CASE_FIELDS["run.output_every"].parse(run["output_every"], "run.output_every")
    except SpecProblem:
        return  # refused where the run block is checked
    if every > revolutions * 2 * math.pi:
        raise SpecProblem(
            "run.output_every",
            f"found {excerpt(run['output_every'])}, longer than the run "
            f"({revolutions:g} revolutions = {revolutions * 360:g} deg): the histories would "
            "hold the start alone",
            found=run["output_every"],
            expected=f"at most {revolutions * 360:g} deg",
        )


def apply_override(raw: object, key: str, value: object) -> object:
    """Set ``key`` (a dotted path, list indices as numbers) in a copy of ``raw``.

    Inside ``sweep``, ``zip`` and ``sample.ranges`` the rest of the path is one key:
    ``sweep.model.spring_preload`` sets the sweep's ``model.spring_preload``.
    """
    if not isinstance(raw, dict):
        raise SpecProblem(key, "the spec is not a mapping")
    parts = key.split(".")
    node: object = raw
    i = 0
    while i < len(parts) - 1:
        part = parts[i]
        if isinstance(node, list):
            idx = _index(part, node, key)
            node = node[idx]
            i += 1
            continue
        if not isinstance(node, dict):
            raise SpecProblem(key, f"{'.'.join(parts[:i])} is not a mapping")
        if part in _KEYED_BY_CASE_KEY:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise SpecProblem(key, f"{'.'.join(parts[: i + 1])} is not a mapping")
            node[".".join(parts[i + 1 :])] = value
            return raw
        node = node.setdefault(part, {})
        i += 1
    last = parts[-1]
    if isinstance(node, list):
        node[_index(last, node, key)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise SpecProblem(key, f"{'.'.join(parts[:-1])} is not a mapping")
    return raw


def _index(part: str, node: list, key: str) -> int:
    if not part.isdigit() or int(part) >= len(node):
        raise SpecProblem(key, f"found {excerpt(part)}, expected a list index below {len(node)}")
    return int(part)
