"""A spec's ``design:`` section (``campipe design``): the keys to vary and their bounds, the
requirements a design must meet, the objective; checked like the rest of the spec, every
problem at its key path.

Grammar::

    design:
      vary: {<key>: {from: <value>, to: <value>, tolerance: <value>}, ...}   # tolerance optional
      require:
        onset_speed_rpm: {min: <speed>, max: <speed>, level: <angle>}  # a bound or both;
                                            # level: campipe onset's --level (with a seat)
        <metric>: {min: <value>, max: <value>, at: <speed> | [<speed>, ...]}
      minimize: <key> | maximize: <key>     # a varied key, onset_speed_rpm or a required metric
                                            # (two objectives: a list, or one of each: Pareto)
      method: local | global                # several keys: SciPy's bounded local or global
      max_evaluations: <integer>

``<metric>`` is any per-case metric of a study's archive (``campipe query``'s column, e.g.
``max_seating_velocity``), its bounds in its units; ``at`` the speeds it is run at (its value
the worst over them). A metric required with ``at`` and no bound is only computed (for the
objective, or to be shown).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from campipe.constants import DEFAULT_ONSET_LEVEL_DEG, RPM
from campipe.engine.metrics import archived_metrics
from campipe.errors import did_you_mean, excerpt
from campipe.study.spec.blocks import Problems, as_mapping, show, unknown_key
from campipe.study.spec.fields import CASE_FIELDS, SpecProblem, sample_keys, varied_fields
from campipe.units import QuantityError, convert, parse_quantity, written_units

#: The requirement on the no-follow onset (``campipe onset``'s column, the value in rpm).
ONSET = "onset_speed_rpm"
#: The onset at the engine's speed: a requirement or objective of a spec with a drive, read
#: as the cam's onset (:data:`ONSET`) at the engine's speed times cam_per_crank.
ENGINE_ONSET = "onset_engine_speed_rpm"
#: The keys of ``design`` and what they hold.
DESIGN_KEYS: dict[str, str] = {
    "vary": "keys to vary and their bounds: {<key>: {from, to, tolerance}} (tolerance: the "
    "root search's, one key; default 1e-4 of the range)",
    "require": "bounds a design must meet: {onset_speed_rpm: {min, max, level}} (level: the "
    "no-follow a turn that counts with a seat, campipe onset's --level) and per-case metrics "
    "at stated speeds {<metric>: {min, max, at}}",
    "minimize": "a varied key, onset_speed_rpm or a required metric, made as small as the "
    "requirements allow; two (a list, or one here and one in maximize): the Pareto front",
    "maximize": "likewise, made as large as they allow",
    "method": "with several keys (or an objective other than the one varied key): local "
    "(SciPy's COBYQA, bounded, from the middle of the bounds, the default) or global "
    "(differential evolution)",
    "max_evaluations": "designs evaluated at most (default 200)",
}
METHODS = ("local", "global")
DEFAULT_MAX_EVALUATIONS = 200
MAX_EVALUATIONS = 100_000
#: The root search's tolerance by default, a fraction of the varied key's range.
DEFAULT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class Vary:
    """A varied key and its bounds (SI)."""

    key: str  # the spec key, e.g. "model.spring_preload"
    low: float
    high: float
    tolerance: float  # the root search's bracket width (SI)
    units: str  # its SI units (pint spelling; "" for a number)
    written: str  # the units its bounds were written in ("" for a number)


@dataclass(frozen=True)
class Requirement:
    """Bounds on the onset or on a metric, in ``units``; NaN: no bound."""

    key: str  # ONSET or a metric's archive name
    minimum: float
    maximum: float
    units: str  # units of the bounds and the values (the archive's; rpm for the onset)
    speeds: tuple[float, ...] = ()  # a metric's speeds [rad/s] (the worst over them counts)
    written: str = ""  # the units the bounds were written in
    #: the onset's level [rad of no-follow a turn, with a seat] (``campipe onset --level``);
    #: NaN: its default
    level: float = math.nan
    #: the drive's cam_per_crank where the spec wrote the bounds or the speeds at the
    #: engine's speed (``onset_engine_speed_rpm``, ``at_engine``); NaN: the cam's
    engine: float = math.nan

    @property
    def bounded(self) -> bool:
        return not (math.isnan(self.minimum) and math.isnan(self.maximum))

    @property
    def engine_onset(self) -> bool:
        """An onset bound the spec wrote at the engine's speed (``onset_engine_speed_rpm``)."""
        return self.key == ONSET and not math.isnan(self.engine)

    @property
    def written_key(self) -> str:
        """The key as the spec wrote it: ``onset_engine_speed_rpm`` for an engine-speed onset."""
        return ENGINE_ONSET if self.engine_onset else self.key

    def as_written(self, value: float) -> float:
        """``value`` in the requirement's units (the cam's rpm for the onset) at the speed the
        bound was written at: the engine's rpm for an engine-speed onset (a bound, a margin)."""
        return value / self.engine if self.engine_onset else value


def bound_label(r: Requirement, side: str) -> str:
    """One bound in words, in the units it was written in: ``onset_speed_rpm ≥ 9500 rpm``."""
    sign, value = ("≥", r.minimum) if side == "min" else ("≤", r.maximum)
    units = r.units
    key, value = r.written_key, r.as_written(value)
    if r.written and units and r.written != units:
        value, units = convert(value, units, r.written), r.written
    return f"{key} {sign} {value:.6g}{' ' + units if units else ''}"


def section_text(design: Design) -> list[str]:
    """The checked section in words (``campipe validate``): what varies, what is required
    (a metric's speeds, the onset's level), what is optimised, by which search."""
    root = design.search == "root"  # the tolerance is the root search's
    vary = "; ".join(
        f"{v.key} from {_shown(v.low, v)} to {_shown(v.high, v)}"
        + (f" (tolerance {_shown(v.tolerance, v)})" if root else "")
        for v in design.vary
    )
    required = []
    for r in design.require:
        sides = [bound_label(r, side) for side, v in (("min", r.minimum), ("max", r.maximum))
                 if not math.isnan(v)] or [f"{r.key} computed"]  # fmt: skip
        engine = not math.isnan(r.engine)
        at = f" at {', '.join(f'{s / RPM:g}' for s in r.speeds)} rpm" if r.speeds else ""
        if at and engine:
            engine_at = ", ".join(f"{s / RPM / r.engine:g}" for s in r.speeds)
            at += f" (the cam's; the engine's {engine_at})"
        level = ""
        if r.key == ONSET:
            shown = f"{math.degrees(r.level):g} deg a turn"
            if math.isnan(r.level):
                shown = f"{DEFAULT_ONSET_LEVEL_DEG:g} deg a turn, the default"
            speed = "the engine's speed" if engine else "the cam's speed"
            level = f" ({speed}; with a seat, from no-follow of {shown})"
        required.append(" and ".join(sides) + at + level)
    goals = ", ".join(f"{sense} {key}" for key, sense in design.objectives)
    return [
        f"design: vary {vary}",
        f"  require {'; '.join(required) or 'nothing'}",
        f"  {goals}; a {design.search} search: campipe design runs it (the lines above are "
        "campipe study's run of the spec's own cases)",
    ]


def _shown(value: float, v: Vary) -> str:
    return written_value(value, v.units, v.written)


def written_value(value: float, units: str, written: str) -> str:
    """A varied key's value in the units its bounds were written in."""
    if units and written:
        return f"{convert(value, units, written):.7g} {written}"
    return f"{value:.7g}{' ' + units if units else ''}"


@dataclass(frozen=True)
class Design:
    """A checked ``design:`` section."""

    vary: tuple[Vary, ...]
    require: tuple[Requirement, ...]
    #: (key, "minimize" | "maximize") each: a varied key, ONSET or a required metric; two:
    #: the Pareto front of the designs evaluated
    objectives: tuple[tuple[str, str], ...]
    method: str = "local"
    max_evaluations: int = DEFAULT_MAX_EVALUATIONS

    @property
    def objective(self) -> str:
        """The (first) objective's key."""
        return self.objectives[0][0]

    @property
    def sense(self) -> str:
        return self.objectives[0][1]

    @property
    def pareto(self) -> bool:
        return len(self.objectives) == 2

    @property
    def search(self) -> str:
        """The search campipe design runs: "pareto" (two objectives), "root" (one varied key
        that is the objective), else ``method``."""
        if self.pareto:
            return "pareto"
        one = len(self.vary) == 1 and self.objective == self.vary[0].key
        return "root" if one else self.method


def metric_units() -> dict[str, str]:
    """A metric's archive name → its units (pint spelling; "" for a count)."""
    return {m.summary: m.units or "" for m in archived_metrics()}


def check_design(value: object, problems: Problems, drive: float | None = None) -> Design | None:
    """``design:`` → a :class:`Design`, or None with its problems added; ``drive`` the spec's
    cam_per_crank (its speeds at the engine's then read too)."""
    block = problems.check(as_mapping, value, "design", "{vary, require, minimize | maximize}")
    if block is None:
        return None
    before = len(problems.items)
    for k in block:
        if k not in DESIGN_KEYS:
            problems.items.append(unknown_key("design", str(k), DESIGN_KEYS))
    vary = _vary(block.get("vary"), problems)
    require = _require(block.get("require"), problems, drive)
    objectives = _objectives(block, vary, require, problems, drive)
    method = block.get("method", "local")
    if method not in METHODS:
        problems.add(
            "design.method",
            f"found {show(method)}, expected one of: {', '.join(METHODS)}"
            + (did_you_mean(method, METHODS) if isinstance(method, str) else ""),
        )
    most = block.get("max_evaluations", DEFAULT_MAX_EVALUATIONS)
    if isinstance(most, bool) or not isinstance(most, int) or not 2 <= most <= MAX_EVALUATIONS:
        problems.add(
            "design.max_evaluations",
            f"found {show(most)}, expected an integer from 2 to {MAX_EVALUATIONS}",
        )
    if len(problems.items) > before or vary is None or require is None:
        return None
    return Design(vary, require, objectives, str(method), int(most))


def _block(
    value: object, key: str, missing: str, expected: str, empty: str, problems: Problems
) -> Mapping | None:
    """The mapping a section's ``key`` holds, or None with its problem noted: ``missing``
    when absent, ``expected`` when not a mapping, ``empty`` when it holds nothing."""
    if value is None:
        problems.add(key, f"missing: {missing}")
        return None
    block = problems.check(as_mapping, value, key, expected)
    if block is None:
        return None
    if not block:
        problems.add(key, f"empty; expected {empty}")
        return None
    return block


def _vary(value: object, problems: Problems) -> tuple[Vary, ...] | None:
    block = _block(
        value,
        "design.vary",
        "the keys to vary, {<key>: {from, to}}",
        "{<key>: {from, to}}",
        "at least one key → {from, to}",
        problems,
    )
    if block is None:
        return None
    keys = tuple(k for k in sample_keys() if k != "speed")
    out = []
    for key, r in block.items():
        path = f"design.vary.{key}"
        if key not in keys:
            problems.items.append(unknown_key("design.vary", str(key), keys))
            continue
        got = _bounds(key, r, path, problems)
        if got is not None:
            out.append(got)
    return tuple(out) if len(out) == len(block) else None


def _bounds(key: str, r: object, path: str, problems: Problems) -> Vary | None:
    entry = problems.check(as_mapping, r, path, "{from, to, tolerance}")
    if entry is None:
        return None
    field = varied_fields()[key]
    bad = False
    for k in entry:
        if k not in ("from", "to", "tolerance"):
            problems.items.append(unknown_key(path, str(k), ("from", "to", "tolerance")))
            bad = True
    for k in ("from", "to"):
        if k not in entry:
            problems.add(f"{path}.{k}", "missing; a varied key needs from and to")
            bad = True
    if bad:
        return None
    low = problems.check(field.parse, entry["from"], f"{path}.from")
    high = problems.check(field.parse, entry["to"], f"{path}.to")
    if not isinstance(low, float) or not isinstance(high, float):
        if low is not None and high is not None:
            problems.add(path, f"found {excerpt(r)}, expected numbers or quantities")
        return None
    if not high > low:
        problems.add(path, f"found from {show(entry['from'])} to {show(entry['to'])}, expected "
                     "to greater than from")  # fmt: skip
        return None
    tolerance = DEFAULT_TOLERANCE * (high - low)
    if "tolerance" in entry:
        t = _quantity(entry["tolerance"], field.units, f"{path}.tolerance", problems)
        if t is None:
            return None
        if not 0 < t < high - low:
            problems.add(f"{path}.tolerance", f"found {show(entry['tolerance'])}, expected a "
                         "value greater than 0 and less than the range")  # fmt: skip
            return None
        tolerance = t
    written = written_units(entry["from"]) or written_units(entry["to"])
    return Vary(key, low, high, tolerance, field.units, written)


def _quantity(value: object, units: str, path: str, problems: Problems) -> float | None:
    if isinstance(value, bool):
        problems.add(path, f"found {show(value)}, expected a quantity")
        return None
    try:
        v = parse_quantity(value, units, path)
    except QuantityError as exc:
        problems.items.append(SpecProblem.from_error(exc, path))
        return None
    if not math.isfinite(v):
        problems.add(path, f"found {show(value)}, expected a finite value")
        return None
    return v


def _require(
    value: object, problems: Problems, drive: float | None = None
) -> tuple[Requirement, ...] | None:
    block = _block(
        value,
        "design.require",
        "the bounds a design must meet, e.g. {onset_speed_rpm: {min: 9500 rpm}}",
        "{<requirement>: {min, max}}",
        "onset_speed_rpm or a metric",
        problems,
    )
    if block is None:
        return None
    units = metric_units()
    names = (ONSET, ENGINE_ONSET, *units)
    out = []
    for key, entry in block.items():
        path = f"design.require.{key}"
        if key not in names:
            problems.items.append(unknown_key("design.require", str(key), names))
            continue
        if key == ENGINE_ONSET and ONSET in block:
            problems.add(path, f"found {ONSET} as well: require the onset once, at the cam's "
                         "speed or at the engine's")  # fmt: skip
            continue
        if key == ENGINE_ONSET and drive is None:
            problems.add(path, f"the onset at the engine's speed needs a drive (drive: "
                         f"{{cam_per_crank: 0.5}}); without one, require {ONSET}")  # fmt: skip
            continue
        got = _requirement(str(key), entry, units.get(key, ""), path, problems, drive)
        if got is not None:
            out.append(got)
    return tuple(out) if len(out) == len(block) else None


def _requirement(
    key: str, value: object, units: str, path: str, problems: Problems, drive: float | None
) -> Requirement | None:
    onset = key in (ONSET, ENGINE_ONSET)
    allowed = ("min", "max", "level") if onset else ("min", "max", "at", "at_engine")
    entry = problems.check(as_mapping, value, path, "{" + ", ".join(allowed) + "}")
    if entry is None:
        return None
    before = len(problems.items)
    for k in entry:
        if k not in allowed:
            problems.items.append(unknown_key(path, str(k), allowed))
    bounds = {}
    for k in ("min", "max"):
        bounds[k] = math.nan
        if k in entry:
            v = _quantity(entry[k], "rpm" if onset else units, f"{path}.{k}", problems)
            bounds[k] = math.nan if v is None else v
    if onset and not ("min" in entry or "max" in entry):
        problems.add(path, "expected a bound: min, max or both")
    if bounds["min"] > bounds["max"]:
        problems.add(path, f"found min {show(entry['min'])} above max {show(entry['max'])}")
    speeds: tuple[float, ...] = ()
    engine = drive if key == ENGINE_ONSET and drive is not None else math.nan
    if not onset and "at_engine" in entry:
        if drive is None:
            problems.add(f"{path}.at_engine", "speeds at the engine's need a drive (drive: "
                         "{cam_per_crank: 0.5}); without one, give the cam's with at")  # fmt: skip
        elif "at" in entry:
            problems.add(path, "found at and at_engine: give the speeds once, the cam's (at) "
                         "or the engine's (at_engine)")  # fmt: skip
        else:
            engine = drive
            speeds = tuple(v * drive for v in _speeds(entry["at_engine"], f"{path}.at_engine",
                                                      problems))  # fmt: skip
    elif not onset:
        speeds = _speeds(entry.get("at"), f"{path}.at", problems)
    level = math.nan
    if "level" in entry:
        got = _quantity(entry["level"], "rad", f"{path}.level", problems)
        if got is not None and got < 0.0:
            problems.add(f"{path}.level", f"found {show(entry['level'])}, expected ≥ 0 deg")
        level = math.nan if got is None else got
    if len(problems.items) > before:
        return None
    written = written_units(entry.get("min")) or written_units(entry.get("max"))
    if key == ENGINE_ONSET:  # the cam's onset, its bounds at the cam's speed
        key = ONSET
        bounds = {k: v * engine for k, v in bounds.items()}
    return Requirement(key, bounds["min"], bounds["max"], "rpm" if onset else units, speeds,
                       written, level, engine)  # fmt: skip


def _speeds(value: object, path: str, problems: Problems) -> tuple[float, ...]:
    if value is None:
        problems.add(path, "missing: the speeds the metric is run at, e.g. at: 7000 rpm")
        return ()
    values = value if isinstance(value, list) else [value]
    if not values:
        problems.add(path, "empty; expected a speed or a list of speeds")
    field = CASE_FIELDS["speed"]
    out = [problems.check(field.parse, v, f"{path}[{i}]" if isinstance(value, list) else path)
           for i, v in enumerate(values)]  # fmt: skip
    return tuple(float(v) for v in out if v is not None)


def _objectives(
    block: Mapping,
    vary: tuple[Vary, ...] | None,
    require: tuple[Requirement, ...] | None,
    problems: Problems,
    drive: float | None = None,
) -> tuple[tuple[str, str], ...]:
    given = [
        (sense, ONSET if key == ENGINE_ONSET and drive is not None else key)
        for sense in ("minimize", "maximize")
        if sense in block
        for key in (block[sense] if isinstance(block[sense], list) else [block[sense]])
    ]
    if not given or len(given) > 2:
        problems.add(
            "design.minimize",
            "missing: minimize or maximize, e.g. minimize: model.spring_preload"
            if not given
            else f"found {len(given)} objectives, expected one, or two for a Pareto front",
        )
        return ()
    choices = [
        *(v.key for v in vary or ()),
        *(r.key for r in require or () if r.key != ONSET),
        ONSET,
    ]
    out = []
    for sense, key in given:
        if not isinstance(key, str) or key not in choices:
            problems.add(
                f"design.{sense}",
                f"found {show(key)}, expected a varied key, onset_speed_rpm or a required "
                f"metric (one of: {', '.join(choices)})"
                + (did_you_mean(key, choices) if isinstance(key, str) else ""),
            )
        else:
            out.append((key, sense))
    if len(out) == 2 and out[0][0] == out[1][0]:
        problems.add(f"design.{given[1][0]}", f"found {out[0][0]} twice, expected two objectives")
    return tuple(out)


def check_design_axes(axes: Mapping[str, str], design: Design, problems: Problems) -> None:
    """A design varies its keys over the spec's base case: the spec's axes may vary the
    speed only (the onset's range), never a design key. ``axes`` is key → where it is
    varied (``sweep``, ``zip``, ``sample.ranges``, ``cases``)."""
    for key, where in axes.items():
        if key != "speed":
            problems.add(
                f"{where}.{key}" if where != "cases" else "cases",
                f"campipe design varies design.vary's keys over one base case: the spec's "
                f"axes may vary speed only (its range is the onset's), found {key}",
            )


def onset_required(design: Design) -> bool:
    return any(k == ONSET for k, _ in design.objectives) or any(
        r.key == ONSET for r in design.require
    )
