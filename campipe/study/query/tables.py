"""Selecting and printing an archive's cases: tables, the summary, the replay selection.

Rows are chosen with the ``--where`` language of :mod:`campipe.study.where` (never evaluated
as Python) and ordered with ``--sort``.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe.engine.metrics import UNCERTAINTY
from campipe.errors import did_you_mean, excerpt
from campipe.study.query.display import display_units, format_value, label, to_display
from campipe.study.spec.coordinates import coordinate_values
from campipe.study.spec.drive import ENGINE_SPEED_NAME
from campipe.study.spec.variables import NONE_WORD, VARIABLES, case_coordinates, data_variables
from campipe.study.where import QueryError, Where, evaluate, parse_where, unordered_none
from campipe.units import degree_speed
from campipe.vocabulary import EVENTS_TRUNCATED, FAILURES, STATUS

__all__ = [
    "CaseTable",
    "QueryError",
    "displayed",
    "Where",
    "case_table",
    "evaluate",
    "format_rows",
    "onset_table",
    "parse_where",
    "replay_mask",
    "select",
    "summary",
]

# -- the case table --------------------------------------------------------------------------


@dataclass
class CaseTable:
    """An archive's per-case columns."""

    columns: dict[str, np.ndarray]  # name → (n,) or (n, k) values
    units: dict[str, str]  # name → units ("" for none)
    default: list[str]  # columns printed when --columns is not given
    n: int  # cases
    study: str = ""  # the study's name
    #: name → its CF flags, meaning → value (``status``: ok 0, …), for ``--where``
    flags: dict[str, dict[str, int]] = field(default_factory=dict)


#: An impact's metric → the count of those impacts: a case without one has no impact
#: velocity, and reads ``none`` (as no seat does) where the archive stores 0.
OF_IMPACTS = {"max_seating_velocity": "seat_impacts", "max_cam_impact_velocity": "cam_impacts"}


def case_table(ds) -> CaseTable:
    """Per-case columns of an archive (an ``xarray.Dataset``), as stored: its case coordinates
    (``case``, the ids, first), then its per-case data variables; the default columns are the
    coordinates and the metrics, each mean followed by its uncertainty where the archive has
    one (a run of automatic length: :func:`format_rows` shows the pair as ``145.9 ± 0.6``).
    An impact's velocity where the case had no such impact is none (``-inf``,
    :data:`OF_IMPACTS`): a valve that never seats has no seating velocity, not a soft one."""
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    flags: dict[str, dict[str, int]] = {}
    coords = [k for k, v in ds.coords.items() if v.dims[:1] == ("case",) and v.ndim <= 2]
    data = [k for k, v in ds.data_vars.items() if v.dims == ("case",)]
    for name in coords + data:
        v = ds[name]
        values = v.values
        if values.dtype.kind in "OUS":
            values = values.astype(object)
        columns[name] = values
        units[name] = str(v.attrs.get("units", ""))
        if "flag_meanings" in v.attrs and "flag_values" in v.attrs:
            flags[name] = _flags(v.attrs["flag_meanings"], v.attrs["flag_values"])
    for name, count in OF_IMPACTS.items():
        if name in columns and count in columns:
            columns[name] = np.where(columns[count] == 0, -np.inf, columns[name])
    metrics = [
        k
        for k in data
        if VARIABLES.get(k) is None
        or VARIABLES[k].role == "metric"
        or (VARIABLES[k].role == "uncertainty" and k.removesuffix(UNCERTAINTY) in data)
    ]
    name = str(ds.attrs.get("study_name", ""))
    return CaseTable(columns, units, coords + metrics, ds.sizes.get("case", 0), name, flags)


def _flags(meanings, values) -> dict[str, int]:
    """CF flags as meaning → value; none where the attributes do not read as words and whole
    numbers (an archive edited by hand)."""
    try:
        numbers = [int(x) for x in np.atleast_1d(values).tolist()]
    except (TypeError, ValueError, OverflowError):
        return {}
    return dict(zip(str(meanings).split(), numbers, strict=False))


def displayed(table: CaseTable, shown: dict[str, str]) -> CaseTable:
    """The table with each column in the units ``shown`` names (see
    :func:`campipe.study.query.display.display_units`); columns not named stay as they are."""
    # the cam's speed for units per degree of cam angle, the engine's per degree of crank angle
    speed = table.columns.get(degree_speed(shown.values()))
    columns = {
        k: without_noise(to_display(v, table.units[k], shown.get(k, table.units[k]), speed))
        if shown.get(k, table.units[k]) != table.units[k]
        else v
        for k, v in table.columns.items()
    }
    units = {k: shown.get(k, u) for k, u in table.units.items()}
    return CaseTable(columns, units, table.default, table.n, table.study, table.flags)


#: Significant digits a converted value keeps: a double holds 15 to 17, and the last one or
#: two of a value converted there and back are the conversion's rounding (200 lbf stored in
#: newtons reads back as 200.00000000000009 lbf).
DISPLAY_DIGITS = 15


def without_noise(values: np.ndarray) -> np.ndarray:
    """Converted floats rounded to DISPLAY_DIGITS significant digits (others as they are)."""
    if values.dtype.kind != "f":
        return values
    flat = [float(f"{v:.{DISPLAY_DIGITS}g}") for v in values.ravel().tolist()]
    return np.array(flat, dtype=values.dtype).reshape(values.shape)


def display_table(ds, system: str = "spec") -> CaseTable:
    """The archive's case table in the units of ``system`` (``spec``, ``si``, ``in-lbf`` or
    ``mm-deg``)."""
    table = case_table(ds)
    return displayed(table, display_units(table.units, ds.attrs, system))


def select(table: CaseTable, where: str | None = None, sort: str | None = None) -> np.ndarray:
    """Row indices matching ``where``, ordered by ``sort`` (``"col"``, ``"-col"`` descending;
    several keys separated by commas, first key first). ``table`` holds stored values: a
    ``--where`` quantity is converted to each column's stored units."""
    rows = np.arange(table.n)
    if where is not None:
        rows = rows[evaluate(parse_where(where), table.columns, table.n, table.units, table.flags)]
    if sort is not None:
        keys = [k.strip() for k in sort.split(",") if k.strip()]
        if not keys:
            raise QueryError.at(
                "--sort", f"found no column in {sort!r}; e.g. -max_cam_force (descending)"
            )
        for key in reversed(keys):
            descending = key.startswith("-")
            name = key[1:] if key[0] in "+-" else key  # one sign: "--x" names no column
            if name not in table.columns:
                raise QueryError.at(
                    "--sort", f"unknown column {excerpt(name)}{did_you_mean(name, table.columns)}"
                )
            values = unordered_none(name, table.columns[name][rows])  # (no impact: last)
            if values.ndim != 1:
                raise QueryError.at("--sort", f"{name} holds several values per case")
            rows = rows[_order(values, descending)]
    return rows


def _order(values: np.ndarray, descending: bool) -> np.ndarray:
    """Stable order; NaN last either way (no seat, -inf, first ascending; another column's
    none, no value, last: ``where.unordered_none``)."""
    if values.dtype.kind in "iuf":
        v = values.astype(float)
        key = -v if descending else v
        return np.argsort(key, kind="stable")
    _, rank = np.unique(values.astype(str), return_inverse=True)
    return np.argsort(-rank if descending else rank, kind="stable")


def _cell(value, fmt: str) -> object:
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f":  # a list padded to the longest of its column: its own
            finite = np.flatnonzero(~np.isnan(value))
            value = value[: finite[-1] + 1 if finite.size else 0]
        return [_cell(v, fmt) for v in value]
    if isinstance(value, np.integer | int) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, np.floating | float):
        v = float(value)
        if fmt == "json":
            return v if math.isfinite(v) else None
        if fmt == "csv":
            return format_value(v) if v == -math.inf else repr(v)
        return format_value(v)
    return str(value)


def format_rows(table: CaseTable, rows: np.ndarray, names: Sequence[str], fmt: str) -> str:
    """The selected rows as ``table`` (aligned text, units under the names), ``csv`` (units in
    the header: ``seat [in]``) or ``json`` (``{"study", "units", "cases": [row objects]}``).
    No seat reads ``none`` (JSON: null, as NaN)."""
    for name in names:
        if name not in table.columns:
            raise QueryError.at(
                "--columns",
                f"unknown column {excerpt(name)}"
                f"{did_you_mean(name, table.columns)} (columns: "
                f"{', '.join(table.columns)})",
            )
    cells = [[_cell(table.columns[n][r], fmt) for n in names] for r in rows]
    if fmt == "json":
        return json.dumps(
            {
                "study": table.study,
                "units": {n: table.units[n] for n in names},
                "cases": [dict(zip(names, row, strict=True)) for row in cells],
            },
            indent=1,
        )
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([label(n, table.units[n]) for n in names])
        for r, row in zip(rows, cells, strict=True):
            writer.writerow(
                [
                    json.dumps(_cell(table.columns[n][r], "json")) if isinstance(c, list) else c
                    for n, c in zip(names, row, strict=True)
                ]
            )
        return buf.getvalue().rstrip("\n")
    if fmt != "table":
        raise QueryError.at("--format", f"found {excerpt(fmt)}, expected table, csv or json")
    names, cells = _with_uncertainties(table, rows, list(names), cells)
    text = [
        [", ".join(map(str, c)) if isinstance(c, list) else str(c) for c in row] for row in cells
    ]
    head = [
        list(names),
        [f"[{table.units[n]}]" if table.units[n] not in ("", "1") else "" for n in names],
    ]
    numeric = [table.columns[n].dtype.kind in "iuf" for n in names]
    widths = [max(len(r[j]) for r in head + text) for j in range(len(names))]
    lines = []
    for line in head + text:
        lines.append(
            "  ".join(
                (c.rjust(w) if num else c.ljust(w))
                for c, w, num in zip(line, widths, numeric, strict=True)
            ).rstrip()
        )
    lines.append(f"({len(rows)} of {table.n} cases)")
    return "\n".join(lines)


def plus_minus(value: float, error: float) -> str:
    """``145.9 ± 0.6``: the error to one significant digit (two if the first is 1) and the
    value to the same decimal place; the value alone (``format_value``) if the error is NaN.
    A value below 1e-3 or from 1e6 up reads with a power of ten, ``(9.85 ± 0.09)e-07``."""
    if not math.isfinite(error) or not math.isfinite(value):
        return format_value(value)
    if error == 0:
        return f"{format_value(value)} ± 0"
    size = abs(value) or error
    if size < 1e-3 or size >= 1e6:
        power = math.floor(math.log10(size))
        scaled = plus_minus(value / 10.0**power, error / 10.0**power)
        return f"({scaled})e{power:+03d}"
    exponent = math.floor(math.log10(error))
    digits = 2 if f"{error:.1e}".startswith("1") else 1
    places = max(digits - 1 - exponent, 0)
    scale = 10.0 ** (exponent - digits + 1)
    rounded = round(error / scale) * scale
    return f"{value:.{places}f} ± {rounded:.{places}f}"


def _with_uncertainties(
    table: CaseTable, rows: np.ndarray, names: list[str], cells: list[list]
) -> tuple[list[str], list[list]]:
    """The table format's columns: a mean shown with its uncertainty (``<name>_uncertainty``,
    also shown) reads ``145.9 ± 0.6`` in the mean's column, where the uncertainty is a
    number, and the uncertainty's own column goes."""
    pairs = {
        j: names.index(n + UNCERTAINTY)
        for j, n in enumerate(names)
        if n + UNCERTAINTY in names and table.columns[n].ndim == 1
    }
    if not pairs:
        return names, cells
    dropped = set(pairs.values())
    out = []
    for r, row in zip(rows, cells, strict=True):
        row = list(row)
        for j, k in pairs.items():
            row[j] = plus_minus(
                float(table.columns[names[j]][r]), float(table.columns[names[k]][r])
            )
        out.append([c for j, c in enumerate(row) if j not in dropped])
    return [n for j, n in enumerate(names) if j not in dropped], out


# -- the summary -------------------------------------------------------------------------------


def summary(ds, where: str | None = None, system: str = "spec") -> str:
    """The study's axes, the cases that failed or kept only part of their events (by case
    id) and, for a speed sweep, the separation onset speed (first speed with
    ``separation_deg_per_rev > 0``) for each combination of the other varying parameters,
    values in the units of ``system`` (:mod:`campipe.study.query.display`).

    With ``where``, only the cases it selects are summarised (the axes' values among them,
    their failures, their onsets)."""
    stored = case_table(ds)
    table = displayed(stored, display_units(stored.units, ds.attrs, system))
    name = ds.attrs.get("study_name", "study")
    selected = ""
    if where is not None:
        total = table.n
        table = subset(table, select(stored, where))
        selected = f" (of {total}, where {where})"
    revolutions = ds.attrs.get("revolutions", "?")
    length = (
        f"revolutions until settled (at most {ds.attrs.get('max_revolutions', '?')})"
        if revolutions == "auto"
        else f"{revolutions} revolutions"
    )
    record = ", ".join(r for r in str(ds.attrs.get("record", "")).split(", ") if r != "settling")
    lines = [f"{name}: {table.n} cases{selected}, {length}, record: {record or '-'}"]
    if ds.attrs.get("campipe_file") == "design":  # no runs of a length, nothing recorded
        lines = [f"{name}: {table.n} designs evaluated by campipe design{selected}"]
    try:
        axes = json.loads(ds.attrs.get("study_axes", "[]"))
    except json.JSONDecodeError:
        axes = []
    lines.append("axes:" if axes else "axes: none (a single case)")
    for a in axes:
        col = table.columns.get(a["name"])
        every = stored.columns.get(a["name"])
        if "size" not in a and every is not None and every.ndim == 1:  # a design's varied key
            a["size"] = len(dict.fromkeys(_cell(v, "table") for v in every))
        size = f"{a.get('size', '?')} values"
        if where is not None and col is not None and col.ndim == 1:  # the selection's values
            size = f"{len(dict.fromkeys(_cell(v, 'table') for v in col))} of {size}"
        engine = table.columns.get(ENGINE_SPEED_NAME) if a["name"] == "speed_rpm" else None
        lines.append(
            f"  {a['name']:<24} {a.get('kind', 'varied'):<7} {size}"
            + (f": {_values_text(col, table.units.get(a['name'], ''))}" if col is not None else "")
            + (f" (the cam's); engine {_values_text(engine, 'rpm')}" if engine is not None else "")
        )
    lines += design_lines(ds.attrs, table)
    lines += status_lines(table)
    lines += settling_lines(table, ds.attrs.get("max_revolutions", "?"))
    lines += tension_lines(table)
    lines += clash_lines(table)
    onset = onset_table(table)
    if onset:
        lines.append("")
        which = "cam speed" if ENGINE_SPEED_NAME in table.columns else "speed"
        lines.append(f"separation onset (first {which} with separation_deg_per_rev > 0):")
        lines += onset
    return "\n".join(lines)


def design_lines(attrs, table: CaseTable) -> list[str]:
    """A design file's outcome (``campipe design``'s attributes): whether a design meets the
    requirements, what binds, the objective, the chosen design's case id; [] for a study."""
    if attrs.get("campipe_file") != "design":
        return []
    chosen = table.columns.get("chosen")
    ids = table.columns.get("case", np.arange(table.n).astype(str))
    picked = [str(ids[i]) for i in range(table.n) if chosen is not None and chosen[i] == "yes"]
    return [
        f"design ({attrs.get('design_method', '?')}): feasible {attrs.get('design_feasible', '?')}"
        f"; {attrs.get('design_objective', '-')}; binding {attrs.get('design_binding', '-')}",
        f"chosen: {', '.join(picked) if picked else 'none among these cases'}",
    ]


def subset(table: CaseTable, rows: np.ndarray) -> CaseTable:
    """The table's rows ``rows``, in that order."""
    return CaseTable(
        {k: v[rows] for k, v in table.columns.items()},
        table.units,
        table.default,
        rows.size,
        table.study,
        table.flags,
    )


#: Case ids listed at most per status in the summary.
MAX_LISTED = 20


def status_lines(table: CaseTable) -> list[str]:
    """``failed: <id> (chatter), ...`` and ``events truncated: ...`` lines, by case id."""
    status = table.columns.get("status")
    if status is None:
        return []
    ids = table.columns.get("case", np.arange(table.n).astype(str))
    out = []
    failed = np.flatnonzero(np.isin(status, FAILURES))
    if failed.size:
        shown = ", ".join(
            f"{ids[i]} ({STATUS.get(int(status[i]), status[i])})" for i in failed[:MAX_LISTED]
        )
        more = f" and {failed.size - MAX_LISTED} more" if failed.size > MAX_LISTED else ""
        out.append(f"failed: {shown}{more} (histories and metrics NaN)")
    truncated = np.flatnonzero(status == EVENTS_TRUNCATED)
    if truncated.size:
        shown = ", ".join(str(ids[i]) for i in truncated[:MAX_LISTED])
        more = f" and {truncated.size - MAX_LISTED} more" if truncated.size > MAX_LISTED else ""
        out.append(f"events truncated (run.max_events reached): {shown}{more}")
    return out


def settling_lines(table: CaseTable, cap: object) -> list[str]:
    """How a run of automatic length's cases settled: how many repeat with each period, and
    the ids of those that did not repeat (their metrics are statistics over their window)."""
    period = table.columns.get("period_turns")
    if period is None:
        return []
    period = np.asarray(period, int)
    counts = ", ".join(
        f"{np.count_nonzero(period == p)} every {'turn' if p == 1 else f'{p} turns'}"
        for p in np.unique(period[period > 0])
    )
    out = [f"settled: {counts or 'none'}"]
    never = np.flatnonzero(period == 0)
    if never.size:
        ids = table.columns.get("case", np.arange(table.n).astype(str))
        shown = ", ".join(f"{ids[i]}{_separation(table, i)}" for i in never[:MAX_LISTED])
        more = f" and {never.size - MAX_LISTED} more" if never.size > MAX_LISTED else ""
        out.append(
            f"not repeating within {cap} revolutions: {shown}{more} (metrics over the run's "
            "second half: means ± standard error, largest)"
        )
    return out


#: The least force through the joints that only push (``run.record: member_loads``).
JOINT = "min_joint_force"


def tension_lines(table: CaseTable) -> list[str]:
    """The cases where a joint that only pushes in the hardware pulled (``min_joint_force``
    below 0): the model's two-sided joint held what the hardware would let go (docs/model.md,
    "Joints that pull")."""
    return _below_zero(
        table, JOINT, "a joint pulled",
        "the hardware's (a pushrod in its cups, a rocker, finger or tappet on the valve's tip) "
        "only push, the model's hold on, so past the pull these cases' forces and bounces are "
        'the model\'s (docs/model.md, "Joints that pull")',
    )  # fmt: skip


#: The spring's coil-clash margin (``record: [spring]``): below 0, coils went solid.
CLASH = "min_spring_clash_margin"


def clash_lines(table: CaseTable) -> list[str]:
    """The cases whose valve spring's coils clashed (``min_spring_clash_margin`` below 0: an
    element went solid, which the model has no stop for). The run notes the valve lifting past
    the spring's travel as it computes the cases; this reads any archive that records the
    spring, an up-to-date one too, and sees an element of a surging spring go solid first."""
    return _below_zero(
        table, CLASH, "the valve spring's coils clashed",
        "the model has no stop at solid, so past it these cases' motion is not a real train's "
        "(model.spring_travel_to_solid)",
    )  # fmt: skip


def _below_zero(table: CaseTable, column: str, what: str, why: str) -> list[str]:
    """``<what> (<column> below 0) in n of N cases, least <v> <units> (<id>): <why>``, or
    nothing where the column is absent or never below 0."""
    values = table.columns.get(column)
    if values is None:
        return []
    values = np.asarray(values, float)
    below = np.flatnonzero(values < 0)
    if not below.size:
        return []
    ids = table.columns.get("case", np.arange(table.n).astype(str))
    least = below[np.argmin(values[below])]
    units = table.units.get(column, "")
    return [
        f"{what} ({column} below 0) in {below.size} of {table.n} cases, least "
        f"{_cell(values[least], 'table')} {units} ({ids[least]}): {why}"
    ]


#: The metric the summary shows with its uncertainty for a case that never repeats.
SEPARATION = "separation_deg_per_rev"


def _separation(table: CaseTable, i: int) -> str:
    """`` (separation_deg_per_rev 145.9 ± 0.6 deg)`` for case i, or "" without the columns."""
    value = table.columns.get(SEPARATION)
    error = table.columns.get(SEPARATION + UNCERTAINTY)
    if value is None or error is None:
        return ""
    units = table.units.get(SEPARATION, "")
    units = f" {units}" if units and units != "1" else ""
    return f" ({SEPARATION} {plus_minus(float(value[i]), float(error[i]))}{units})"


def _values_text(col: np.ndarray, units: str) -> str:
    if col.ndim != 1:
        return f"{len({tuple(r) for r in col})} distinct"
    uniq = list(dict.fromkeys(_cell(v, "table") for v in col))
    numbers = any(u != NONE_WORD for u in uniq)  # ("none" alone takes no unit)
    unit = f" {units}" if units and units != "1" and numbers else ""
    if col.dtype.kind in "iuf" and len(uniq) > 6:
        values = col.astype(float)
        finite = values[np.isfinite(values)]
        extra = (" and none" if np.any(values == -math.inf) else "") + (
            " and nan" if np.any(np.isnan(values)) else ""
        )
        return f"{finite.min():.6g} … {finite.max():.6g}{unit}{extra}"
    return ", ".join(str(u) for u in uniq) + unit


def onset_table(table: CaseTable) -> list[str]:
    """Lines of the onset table, or [] when speed does not vary."""
    cols = table.columns
    if "speed_rpm" not in cols or "separation_deg_per_rev" not in cols:
        return []
    speed = cols["speed_rpm"].astype(float)
    if np.unique(speed).size < 2:
        return []
    engine = cols.get(ENGINE_SPEED_NAME)  # a drive's: the onset at the engine's speed too
    others = [
        n
        for n, v in cols.items()
        if n not in ("speed_rpm", "case", ENGINE_SPEED_NAME)
        and n in table.default
        and n not in _metric_names(table)
        and len({_key(x) for x in v}) > 1
    ]
    groups: dict[tuple, list[int]] = {}
    usable = (
        ~np.isin(cols["status"], FAILURES) if "status" in cols else np.ones(table.n, dtype=bool)
    )
    for i in np.flatnonzero(usable).tolist():
        groups.setdefault(tuple(_key(cols[n][i]) for n in others), []).append(i)
    head = [*(label(n, table.units.get(n, "")) for n in others), "onset_rpm"]
    head += ["onset_engine_rpm"] if engine is not None else []
    rows = []
    for members in groups.values():
        idx = np.array(members)
        order = idx[np.argsort(speed[idx], kind="stable")]
        sep = cols["separation_deg_per_rev"][order]
        hit = np.flatnonzero(sep > 0)
        onsets = [_onset(speed[order], hit)]
        if engine is not None:
            onsets.append(_onset(np.asarray(engine, float)[order], hit))
        rows.append([_cell(cols[n][idx[0]], "table") for n in others] + onsets)
    text = [[", ".join(map(str, c)) if isinstance(c, list) else str(c) for c in r] for r in rows]
    widths = [max(len(r[j]) for r in [head, *text]) for j in range(len(head))]
    return [
        "  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
        for r in [head, *text]
    ]


def _onset(speed: np.ndarray, hit: np.ndarray) -> str:
    """The onset among ``speed`` (ascending) where the cases ``hit`` leave the cam."""
    if hit.size == 0:
        return f"none up to {speed[-1]:.6g}"
    if hit[0] == 0:
        return f"at or below {speed[0]:.6g}"
    return f"{speed[hit[0]]:.6g}"


def _metric_names(table: CaseTable) -> set[str]:
    return {n for n in table.columns if n in VARIABLES and VARIABLES[n].role != "parameter"}


def _key(x) -> object:
    if isinstance(x, np.ndarray):
        return tuple(x.tolist())
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    return x.item() if isinstance(x, np.generic) else x


# -- replay selection ---------------------------------------------------------------------------


def replay_mask(study, plan, data) -> np.ndarray:
    """(n,) bool: which cases of a computed batch the spec's ``replay.where`` selects.

    The expression sees the cases' archive coordinates and per-case metrics, as
    ``campipe query`` would; this is what a replay logger (the study's
    :data:`~campipe.study.run.execute.BatchHook`) calls to pick the cases to log.
    """
    n = plan.size
    if not study.spec.replay:
        return np.zeros(n, dtype=bool)
    columns = dict(coordinate_values(list(plan.cases), study))
    columns.update(
        {
            k: v
            for k, v in data.arrays.items()
            if v.shape[:1] == (n,) and v.ndim == 1 and k != "event_count"
        }
    )
    return evaluate(parse_where(study.spec.replay), columns, n, stored_units(study.varied))


def stored_units(varied: Sequence[str], record: Sequence[str] = ()) -> dict[str, str]:
    """Per-case column → its stored units, for a study varying ``varied``: what a
    ``--where`` converts its quantities to before the archive exists."""
    out = {"case": ""}
    for name, var, _ in case_coordinates(varied).values():
        out[name] = var.units or ""
    for name, var in data_variables(record).items():
        if var.dims == ("case",):
            out[name] = var.units or ""
    return out
