"""``campipe design``'s table and file: one row per design evaluated, the answer first.

The table is a :class:`~campipe.study.query.tables.CaseTable` (``campipe query``'s
formatting: aligned text, CSV, ``{study, units, cases}`` JSON); the file a small netCDF
dataset along ``case`` (SI, ``units`` attributes; the onset in rpm as ``campipe onset``'s)
that ``campipe query`` and ``campipe plot metric`` read.
"""

from __future__ import annotations

import json
import math

import numpy as np

from campipe.constants import RPM
from campipe.io.archive import VariableSpec
from campipe.study.design.evaluate import bounds_of
from campipe.study.design.search import DesignResult
from campipe.study.query.tables import CaseTable
from campipe.study.spec.design import DEFAULT_ONSET_LEVEL_DEG, ONSET, written_value
from campipe.study.spec.fields import varied_fields

#: The ``campipe_file`` attribute of a design's file.
DESIGN_FILE = "design"


def key_column(key: str) -> str:
    """A varied key's column: its archive name (``model.spring_preload`` → ``spring_preload``)."""
    f = varied_fields()[key]
    return f.archive_name or key.replace(".", "_")


def metric_column(metric: str, speed: float) -> str:
    """``max_seating_velocity_at_7000rpm`` (a fraction's point written p)."""
    return f"{metric}_at_{speed / RPM:g}rpm".replace(".", "p")


def design_table(result: DesignResult) -> CaseTable:
    """Every evaluation, the answer first (stored units: SI, the onset in rpm)."""
    design = result.design
    evals = [result.evaluations[i] for i in result.order]
    n = len(evals)
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}

    def add(name: str, values: list, unit: str = "") -> None:
        columns[name] = np.array(values, dtype=object if isinstance(values[0], str) else float)
        units[name] = unit

    add("case", [f"d{result.order[i]:04d}" for i in range(n)])
    add("evaluation", [float(i + 1) for i in result.order])
    answer = "yes" if result.feasible else "closest"
    on_front = len(result.front)
    add("chosen", ["front" if i < on_front else answer if i == 0 else "" for i in range(n)])
    for j, v in enumerate(design.vary):
        add(key_column(v.key), [float(e.x[j]) for e in evals], v.units)
    if any(e.onset_status for e in evals):
        add(ONSET, [e.onset for e in evals], "rpm")
        add("onset_status", [e.onset_status for e in evals])
    for r in design.require:
        for s in r.speeds:
            add(metric_column(r.key, s), [e.metrics[r.key, s] for e in evals], r.units)
    for b in bounds_of(design):
        add(b.name, [_finite(e.margins[b.name]) for e in evals], b.requirement.units)
    for name, (key, sense) in zip(objective_columns(result), design.objectives, strict=True):
        if name not in columns:  # a metric at several speeds: its worst over them
            k = design.objectives.index((key, sense))
            add(name, [e.objectives[k] for e in evals], _units_of(result, key))
    add("feasible", ["yes" if e.feasible else "no" for e in evals])
    add("binding", [answer_binding(result) or "-" if i == 0 and not on_front
                    else e.binding or "-" for i, e in enumerate(evals)])  # fmt: skip
    columns["evaluation"] = columns["evaluation"].astype(np.int64)
    return CaseTable(columns, units, list(columns), n, result.study.name)


def objective_columns(result: DesignResult) -> list[str]:
    """Each objective's column: a varied key's, the onset's, a metric's at its one speed, or
    ``<metric>_worst`` (the largest over its speeds to minimize, the least to maximize)."""
    design = result.design
    out = []
    for key, _ in design.objectives:
        if key in [v.key for v in design.vary]:
            out.append(key_column(key))
        elif key == ONSET:
            out.append(ONSET)
        else:
            r = next(r for r in design.require if r.key == key)
            out.append(metric_column(key, r.speeds[0]) if len(r.speeds) == 1 else f"{key}_worst")
    return out


def _units_of(result: DesignResult, key: str) -> str:
    return next(r.units for r in result.design.require if r.key == key)


def _finite(margin: float) -> float:
    return math.nan if math.isinf(margin) and margin < 0 else margin


def shown_units(result: DesignResult) -> dict[str, str]:
    """Column → the units the spec wrote its bounds in (the table's display units)."""
    design = result.design
    out = {key_column(v.key): v.written for v in design.vary if v.written}
    for r in design.require:
        if r.written and r.key != ONSET:
            out.update({metric_column(r.key, s): r.written for s in r.speeds})
    for b in bounds_of(design):
        if b.requirement.written and b.requirement.key != ONSET:
            out[b.name] = b.requirement.written
    return out


#: The design file's onset: the cam's speed, as campipe onset's (a drive's engine speed is
#: onset_engine_speed_rpm there, and in design's table).
ONSET_LONG_NAME = (
    "no-follow onset speed of the cam (cam rpm; with a drive, the engine's is this over "
    "drive.cam_per_crank; NaN: none inside the speed range)"
)


def file_contents(result: DesignResult, table: CaseTable) -> tuple[dict, list, dict, dict]:
    """(sizes, variables, arrays, attributes) of the design's netCDF file: ``table``'s
    columns along ``case`` (stored units), ``event_count`` 0 (no events are kept), the
    search's outcome in the attributes."""
    variables: list[VariableSpec] = []
    arrays: dict[str, np.ndarray] = {}
    for name, col in table.columns.items():
        kind = "str" if col.dtype == object else ("i4" if col.dtype.kind == "i" else "f8")
        attrs = {"units": table.units[name]} if table.units[name] else {}
        if name == ONSET:
            attrs["long_name"] = ONSET_LONG_NAME
        variables.append(VariableSpec(name, ("case",), kind, attrs))
        arrays[name] = col
    variables.append(VariableSpec("event_count", ("case",), "i4", {"long_name": "events kept "
                                  "(a design's file keeps none)"}))  # fmt: skip
    arrays["event_count"] = np.zeros(table.n, np.int32)
    spec = result.study.spec
    design = result.design
    attrs = {
        "title": f"{result.study.name}: designs evaluated by campipe design",
        "study_name": result.study.name,
        "design_feasible": "yes" if result.feasible else "no",
        "design_method": result.method,
        "design_binding": answer_binding(result),
        "design_objective": ", ".join(f"{s} {k}" for k, s in design.objectives),
        "design_objective_columns": json.dumps(objective_columns(result)),
        "study_axes": json.dumps(
            [{"name": key_column(v.key), "key": v.key} for v in design.vary]
        ),  # fmt: skip
        "spec": spec.text,
        "spec_overrides": json.dumps(spec.overrides, default=str),
    }
    return {"case": table.n}, variables, arrays, attrs


def bounds_reached(result: DesignResult) -> list[str]:
    """The varied keys the answer holds at a bound of ``design.vary`` (within the key's
    tolerance), as "design.vary.KEY's lower bound (VALUE)": there the bound stops the search,
    whatever margin the requirements have left."""
    out = []
    for j, v in enumerate(result.design.vary):
        x = float(result.best.x[j])
        for side, edge in (("lower", v.low), ("upper", v.high)):
            if abs(x - edge) <= v.tolerance:
                shown = written_value(edge, v.units, v.written)
                out.append(f"design.vary.{v.key}'s {side} bound ({shown})")
    return out


def answer_binding(result: DesignResult) -> str:
    """What binds at the chosen design: a bound of ``design.vary`` it sits on (a feasible
    answer's, :func:`bounds_reached`), else its requirement of least relative margin."""
    edges = bounds_reached(result) if result.feasible and not result.front else []
    return " and ".join(edges) or result.best.binding


def onset_level_text(result: DesignResult) -> str | None:
    """What the onset requirement reads where the train has a seat: the speed where no-follow
    reaches its level a turn (the default 0.5°, or ``level``), not its first flight; None
    where there is no onset requirement or no seat."""
    onset = next((r for r in result.design.require if r.key == ONSET), None)
    if onset is None or not any(c.case.has_seat for c in result.study.cases):
        return None
    if math.isnan(onset.level):
        shown = f"{DEFAULT_ONSET_LEVEL_DEG:g}° a turn, the default"
    else:
        shown = f"{math.degrees(onset.level):g}° a turn"
    return (
        f"the onset is where no-follow reaches {shown} (with a seat): the chosen design may "
        "leave the cam by up to that much at it; level: 0 deg requires the first flight the "
        "engine keeps"
    )


def summary_lines(result: DesignResult) -> list[str]:
    """What the command says after the table: the answer or its absence, what binds, the
    cost."""
    design = result.design
    best = result.best
    n = len(result.evaluations)
    values = ", ".join(f"{v.key} = {written_value(best.x[j], v.units, v.written)}"
                       for j, v in enumerate(design.vary))  # fmt: skip
    lines = []
    if result.front:
        names = objective_columns(result)
        ends = [result.evaluations[i] for i in (result.front[0], result.front[-1])]
        span = " to ".join(
            "(" + ", ".join(f"{n} {v:.6g}" for n, v in zip(names, e.objectives, strict=True)) + ")"
            for e in ends
        )
        lines.append(f"{result.study.name}: Pareto front of {len(result.front)} designs, "
                     f"from {span}")  # fmt: skip
    elif result.feasible:
        lines.append(f"{result.study.name}: {design.sense} {design.objective}: {values}")
        if edges := bounds_reached(result):
            least = f"; the least margin: {best.binding} (relative {best.relative:.3g})"
            lines.append(
                f"binding: {' and '.join(edges)}, not a requirement"
                f"{least if best.binding else ''}: widen design.vary to search past it"
            )
        elif best.binding:
            lines.append(f"binding: {best.binding} (relative margin {best.relative:.3g})")
    else:
        fails = " and ".join(f"{label} (relative margin {rel:.3g})" for label, rel in best.failing)
        lines.append(
            f"{result.study.name}: infeasible: no design within design.vary's bounds meets "
            f"the requirements; the closest, {values}, fails {fails}"
        )
    if level := onset_level_text(result):
        lines.append(level)
    estimated = sum(not e.onset_proven for e in result.evaluations)
    if estimated:
        lines.append(
            f"{estimated} of the {n} designs' onsets searched past speeds on the chords' "
            "estimate, not proven (a seated steady state or a profile with steps): a window of "
            "no-follow narrower than the scan may be missed, as campipe onset says"
        )
    lines.append(
        f"{n} design{'s' if n != 1 else ''} evaluated ({result.method}"
        f"{', stopped at design.max_evaluations' if result.stopped else ''}) in "
        f"{result.seconds:.3g} s"
    )
    return lines
