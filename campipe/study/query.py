"""Selecting and printing an archive's cases: the ``--where`` language, tables, the summary.

``--where`` takes comparisons of per-case columns joined by ``and``, ``or``, ``not`` and
parentheses::

    speed_rpm > 9000 and seat > 0
    closure == "form" or not (cam_impacts >= 2)
    9000 <= speed_rpm < 12000
    seat is nan                  # no seat (also: seat is none, seat is not nan)
    profile in ["harmonic 1 in", "polydyne-4567 1 in 90/90/90/90 deg"]

The text is parsed with Python's ``ast`` module and every node is checked against a short
whitelist (comparisons, boolean operators, names of columns, numbers, strings, lists of
them); nothing is ever evaluated as Python. Attribute access, calls, subscripts, arithmetic,
lambdas and names that are not columns are refused. Numbers compare equal within a relative
1e-9 (so ``speed_rpm == 11000`` finds 11000 rpm however it was converted).
"""

from __future__ import annotations

import ast
import csv
import io
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from campipe.errors import CampipeError, did_you_mean

#: Longest ``--where`` accepted [characters]; keeps the parser's recursion shallow.
MAX_WHERE_LENGTH = 2000
#: Relative tolerance of ``==`` between numbers.
EQUAL_RTOL = 1e-9
#: Words that are values, not columns.
WORDS = {"nan": math.nan, "none": math.nan, "inf": math.inf, "true": True, "false": False}

_COMPARE = {
    ast.Eq: "==",
    ast.NotEq: "!=",
    ast.Lt: "<",
    ast.LtE: "<=",
    ast.Gt: ">",
    ast.GtE: ">=",
    ast.In: "in",
    ast.NotIn: "not in",
    ast.Is: "is",
    ast.IsNot: "is not",
}
_ALLOWED = (
    ast.Expression,
    ast.BoolOp,
    ast.And,
    ast.Or,
    ast.UnaryOp,
    ast.Not,
    ast.USub,
    ast.UAdd,
    ast.Compare,
    ast.Name,
    ast.Load,
    ast.Constant,
    ast.List,
    ast.Tuple,
    *_COMPARE,
)


class QueryError(CampipeError, ValueError):
    """A ``--where`` expression, column or sort key that is refused; ``key`` is the option
    (``--where``, ``--columns``, ``--sort``, ``--format``)."""


@dataclass(frozen=True)
class Where:
    """A parsed, checked ``--where`` expression."""

    text: str  # as written
    tree: ast.Expression  # checked against the whitelist
    names: frozenset[str]  # the columns it reads


def parse_where(text: str) -> Where:
    """Parse and check a ``--where`` expression.

    Raises
    ------
    QueryError
        For a syntax error or anything outside the language above (a call, an attribute,
        a subscript, arithmetic, a name starting with an underscore), naming what was found.
    """
    if not isinstance(text, str) or not text.strip():
        raise QueryError.at("--where", "empty; expected a condition such as 'speed_rpm > 9000'")
    if len(text) > MAX_WHERE_LENGTH:
        raise QueryError.at(
            "--where", f"{len(text)} characters, expected at most {MAX_WHERE_LENGTH}"
        )
    try:
        with warnings.catch_warnings():  # e.g. "invalid decimal literal": refused below anyway
            warnings.simplefilter("ignore", SyntaxWarning)
            tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError) as exc:
        raise QueryError.at(
            "--where",
            f"cannot parse {text!r} ({exc.msg}); expected comparisons joined by and, or, not",
        ) from None
    names: set[str] = set()
    # A list (or tuple) stands only on the right of 'in' / 'not in', holding plain values.
    lists = {
        id(right)
        for node in ast.walk(tree)
        if isinstance(node, ast.Compare)
        for op, right in zip(node.ops, node.comparators, strict=True)
        if isinstance(op, ast.In | ast.NotIn) and isinstance(right, ast.List | ast.Tuple)
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.List | ast.Tuple):
            if id(node) not in lists:
                raise QueryError.at(
                    "--where",
                    "a list stands only after 'in', e.g. 'speed_rpm in "
                    "[9000, 9524]'; join conditions with and, or, not",
                )
            if not all(
                isinstance(e, ast.Constant)
                or (isinstance(e, ast.UnaryOp) and isinstance(e.operand, ast.Constant))
                for e in node.elts
            ):
                raise QueryError.at("--where", "the list after 'in' holds numbers or strings only")
        if not isinstance(node, _ALLOWED):
            raise QueryError.at(
                "--where",
                f"{_describe(node)} is not allowed; expected comparisons "
                "of columns with numbers or strings, joined by and, or, not",
            )
        if isinstance(node, ast.Name):
            if node.id.startswith("_"):
                raise QueryError.at("--where", f"the name {node.id!r} is not allowed")
            if node.id.lower() not in WORDS:
                names.add(node.id)
        if isinstance(node, ast.Constant) and not isinstance(node.value, int | float | str):
            raise QueryError.at("--where", f"the constant {node.value!r} is not allowed")
        if (
            isinstance(node, ast.UnaryOp)
            and isinstance(node.op, ast.USub | ast.UAdd)
            and not isinstance(node.operand, ast.Constant | ast.Name)
        ):
            raise QueryError.at("--where", "a sign applies to a number only")
        if isinstance(node, ast.Compare):
            for op, right in zip(node.ops, node.comparators, strict=True):
                if isinstance(op, ast.Is | ast.IsNot) and not (
                    isinstance(right, ast.Name) and right.id.lower() in ("nan", "none")
                ):
                    raise QueryError.at(
                        "--where",
                        "'is' and 'is not' compare with nan (or none) only, e.g. 'seat is nan'",
                    )
                if isinstance(op, ast.In | ast.NotIn) and not isinstance(
                    right, ast.List | ast.Tuple
                ):
                    raise QueryError.at(
                        "--where", "'in' takes a list, e.g. 'speed_rpm in [9000, 9524]'"
                    )
    return Where(text, tree, frozenset(names))


def _describe(node: ast.AST) -> str:
    kinds = {
        ast.Call: "a call",
        ast.Attribute: "attribute access",
        ast.Subscript: "a subscript",
        ast.BinOp: "arithmetic",
        ast.Lambda: "a lambda",
        ast.IfExp: "an if-expression",
        ast.NamedExpr: "an assignment",
        ast.Starred: "unpacking",
    }
    for kind, text in kinds.items():
        if isinstance(node, kind):
            return text
    return f"'{type(node).__name__}'"


def check_names(where: Where, columns: Sequence[str]) -> None:
    """Refuse a name that is not a column, suggesting the nearest."""
    for name in sorted(where.names):
        if name not in columns:
            raise QueryError.at(
                "--where",
                f"unknown column {name!r}{did_you_mean(name, columns)} "
                f"(columns: {', '.join(columns)})",
            )


def evaluate(where: Where, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) bool: the rows where the expression holds."""
    check_names(where, list(columns))
    out = _eval(where.tree.body, columns)
    return np.broadcast_to(np.asarray(out, dtype=bool), (n,)).copy()


def _eval(node: ast.AST, cols: Mapping[str, np.ndarray]):
    if isinstance(node, ast.BoolOp):
        values = [np.asarray(_eval(v, cols), dtype=bool) for v in node.values]
        reduce = np.logical_and.reduce if isinstance(node.op, ast.And) else np.logical_or.reduce
        return reduce(values)
    if isinstance(node, ast.UnaryOp):
        value = _eval(node.operand, cols)
        if isinstance(node.op, ast.Not):
            return ~np.asarray(value, dtype=bool)
        if not _is_number(value):
            raise QueryError.at("--where", "a sign applies to a number only")
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Compare):
        result = None
        left = _eval(node.left, cols)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = _eval(right_node, cols)
            one = _compare(_COMPARE[type(op)], left, right, node.left, right_node)
            result = one if result is None else result & one
            left = right
        return result
    if isinstance(node, ast.Name):
        if node.id.lower() in WORDS:
            return WORDS[node.id.lower()]
        col = cols[node.id]
        if col.ndim != 1:
            raise QueryError.at(
                "--where", f"{node.id} holds {col.shape[1]} values per case and cannot be compared"
            )
        return col
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.List | ast.Tuple):
        return [_eval(e, cols) for e in node.elts]
    raise QueryError.at("--where", f"{_describe(node)} is not allowed")


def _is_text(v) -> bool:
    return isinstance(v, str) or (isinstance(v, np.ndarray) and v.dtype.kind in "OUS")


def _is_number(v) -> bool:
    return (isinstance(v, int | float) and not isinstance(v, bool)) or (
        isinstance(v, np.ndarray) and v.dtype.kind in "iuf"
    )


def _name(node: ast.AST) -> str:
    return node.id if isinstance(node, ast.Name) else ast.unparse(node)


def _compare(op: str, a, b, a_node, b_node) -> np.ndarray:
    if op in ("is", "is not"):
        if _is_text(a):
            nan = np.zeros(np.shape(a), dtype=bool)
        else:
            nan = np.isnan(np.asarray(a, dtype=float))
        return nan if op == "is" else ~nan
    if op in ("in", "not in"):
        hit = np.zeros(np.shape(a), dtype=bool)
        for item in b:
            hit |= _compare("==", a, item, a_node, b_node)
        return hit if op == "in" else ~hit
    if _is_text(a) != _is_text(b) or isinstance(a, bool) or isinstance(b, bool):
        text, other = (a_node, b_node) if _is_text(a) else (b_node, a_node)
        raise QueryError.at(
            "--where",
            f"{_name(text)} is text and {_name(other)} is not; "
            'compare text with a quoted string, e.g. closure == "form"',
        )
    if _is_text(a):
        if op not in ("==", "!="):
            raise QueryError.at(
                "--where",
                f"text compares with == and != only (found {op} "
                f"between {_name(a_node)} and {_name(b_node)})",
            )
        eq = np.asarray(a, dtype=object) == np.asarray(b, dtype=object)
        return eq if op == "==" else ~eq
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if op in ("==", "!="):
        eq = np.isclose(a, b, rtol=EQUAL_RTOL, atol=0.0)
        return eq if op == "==" else ~eq
    with np.errstate(invalid="ignore"):
        return {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal}[op](
            a, b
        )


# -- the case table --------------------------------------------------------------------------


@dataclass
class CaseTable:
    """An archive's per-case columns."""

    columns: dict[str, np.ndarray]  # name → (n,) or (n, k) values
    units: dict[str, str]  # name → units ("" for none)
    default: list[str]  # columns printed when --columns is not given
    n: int  # cases


def case_table(ds) -> CaseTable:
    """Per-case columns of an archive (an ``xarray.Dataset``): its case coordinates, then its
    per-case data variables; the default columns are the coordinates and the metrics."""
    from campipe.study.variables import VARIABLES

    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    coords = [k for k, v in ds.coords.items() if v.dims[:1] == ("case",) and v.ndim <= 2]
    data = [k for k, v in ds.data_vars.items() if v.dims == ("case",)]
    for name in coords + data:
        v = ds[name]
        values = v.values
        if values.dtype.kind in "OUS":
            values = values.astype(object)
        columns[name] = values
        units[name] = str(v.attrs.get("units", ""))
    metrics = [k for k in data if VARIABLES.get(k) is None or VARIABLES[k].role == "metric"]
    return CaseTable(columns, units, coords + metrics, ds.sizes.get("case", 0))


def select(table: CaseTable, where: str | None = None, sort: str | None = None) -> np.ndarray:
    """Row indices matching ``where``, ordered by ``sort`` (``"col"``, ``"-col"`` descending;
    several keys separated by commas, first key first)."""
    rows = np.arange(table.n)
    if where is not None:
        rows = rows[evaluate(parse_where(where), table.columns, table.n)]
    if sort:
        for key in reversed([k.strip() for k in sort.split(",") if k.strip()]):
            descending = key.startswith("-")
            name = key.lstrip("-+")
            if name not in table.columns:
                raise QueryError.at(
                    "--sort", f"unknown column {name!r}{did_you_mean(name, table.columns)}"
                )
            values = table.columns[name][rows]
            if values.ndim != 1:
                raise QueryError.at("--sort", f"{name} holds several values per case")
            rows = rows[_order(values, descending)]
    return rows


def _order(values: np.ndarray, descending: bool) -> np.ndarray:
    """Stable order; NaN last either way."""
    if values.dtype.kind in "iuf":
        v = values.astype(float)
        key = -v if descending else v
        return np.argsort(key, kind="stable")
    _, rank = np.unique(values.astype(str), return_inverse=True)
    return np.argsort(-rank if descending else rank, kind="stable")


def _cell(value, fmt: str) -> object:
    if isinstance(value, np.ndarray):
        return [_cell(v, fmt) for v in value]
    if isinstance(value, np.integer | int) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, np.floating | float):
        v = float(value)
        if fmt == "json":
            return None if math.isnan(v) else v
        if fmt == "csv":
            return repr(v)
        return f"{v:.6g}"
    return str(value)


def format_rows(table: CaseTable, rows: np.ndarray, names: Sequence[str], fmt: str) -> str:
    """The selected rows as ``table`` (aligned text with units), ``csv`` or ``json`` (an
    array of row objects)."""
    for name in names:
        if name not in table.columns:
            raise QueryError.at(
                "--columns",
                f"unknown column {name!r}"
                f"{did_you_mean(name, table.columns)} (columns: "
                f"{', '.join(table.columns)})",
            )
    cells = [[_cell(table.columns[n][r], fmt) for n in names] for r in rows]
    if fmt == "json":
        return json.dumps([dict(zip(names, row, strict=True)) for row in cells], indent=1)
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(names)
        for r, row in zip(rows, cells, strict=True):
            writer.writerow(
                [
                    json.dumps(_cell(table.columns[n][r], "json")) if isinstance(c, list) else c
                    for n, c in zip(names, row, strict=True)
                ]
            )
        return buf.getvalue().rstrip("\n")
    if fmt != "table":
        raise QueryError.at("--format", f"found {fmt!r}, expected table, csv or json")
    text = [
        [", ".join(map(str, c)) if isinstance(c, list) else str(c) for c in row] for row in cells
    ]
    head = [list(names), [f"[{table.units[n]}]" if table.units[n] else "" for n in names]]
    numeric = [table.columns[n].dtype.kind in "iuf" for n in names]
    widths = [max(len(r[j]) for r in head + text) for j in range(len(names))]
    lines = []
    for row in head + text:
        lines.append(
            "  ".join(
                (c.rjust(w) if num else c.ljust(w))
                for c, w, num in zip(row, widths, numeric, strict=True)
            ).rstrip()
        )
    lines.append(f"({len(rows)} of {table.n} cases)")
    return "\n".join(lines)


# -- the summary -------------------------------------------------------------------------------


def summary(ds) -> str:
    """The study's axes and, for a speed sweep, the separation onset speed (first speed with
    ``separation_deg_per_rev > 0``) for each combination of the other varying parameters."""
    table = case_table(ds)
    name = ds.attrs.get("study_name", "study")
    lines = [
        f"{name}: {table.n} cases, {ds.attrs.get('revolutions', '?')} revolutions, "
        f"record: {ds.attrs.get('record', '-')}"
    ]
    try:
        axes = json.loads(ds.attrs.get("study_axes", "[]"))
    except json.JSONDecodeError:
        axes = []
    lines.append("axes:" if axes else "axes: none (a single case)")
    for a in axes:
        col = table.columns.get(a["name"])
        lines.append(
            f"  {a['name']:<24} {a['kind']:<7} {a['size']} values"
            + (f": {_values_text(col, table.units.get(a['name'], ''))}" if col is not None else "")
        )
    onset = onset_table(table)
    if onset:
        lines.append("")
        lines.append("separation onset (first speed with separation_deg_per_rev > 0):")
        lines += onset
    return "\n".join(lines)


def _values_text(col: np.ndarray, units: str) -> str:
    if col.ndim != 1:
        return f"{len({tuple(r) for r in col})} distinct"
    uniq = list(dict.fromkeys(_cell(v, "table") for v in col))
    unit = f" {units}" if units else ""
    if col.dtype.kind in "iuf" and len(uniq) > 6:
        finite = col[np.isfinite(col.astype(float))]
        nan = " and nan" if finite.size < col.size else ""
        return f"{finite.min():.6g} … {finite.max():.6g}{unit}{nan}"
    return ", ".join(str(u) for u in uniq) + unit


def onset_table(table: CaseTable) -> list[str]:
    """Lines of the onset table, or [] when speed does not vary."""
    cols = table.columns
    if "speed_rpm" not in cols or "separation_deg_per_rev" not in cols:
        return []
    speed = cols["speed_rpm"].astype(float)
    if np.unique(speed).size < 2:
        return []
    others = [
        n
        for n, v in cols.items()
        if n not in ("speed_rpm", "case_id")
        and n in table.default
        and n not in _metric_names(table)
        and len({_key(x) for x in v}) > 1
    ]
    groups: dict[tuple, list[int]] = {}
    for i in range(table.n):
        groups.setdefault(tuple(_key(cols[n][i]) for n in others), []).append(i)
    head = [*others, "onset_rpm"]
    rows = []
    for idx in groups.values():
        idx = np.array(idx)
        order = idx[np.argsort(speed[idx], kind="stable")]
        sep = cols["separation_deg_per_rev"][order]
        hit = np.flatnonzero(sep > 0)
        if hit.size == 0:
            text = f"none up to {speed[order[-1]]:.6g}"
        elif hit[0] == 0:
            text = f"at or below {speed[order[0]]:.6g}"
        else:
            text = f"{speed[order[hit[0]]]:.6g}"
        rows.append([_cell(cols[n][idx[0]], "table") for n in others] + [text])
    text = [[", ".join(map(str, c)) if isinstance(c, list) else str(c) for c in r] for r in rows]
    widths = [max(len(r[j]) for r in [head, *text]) for j in range(len(head))]
    return [
        "  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
        for r in [head, *text]
    ]


def _metric_names(table: CaseTable) -> set[str]:
    from campipe.study.variables import VARIABLES

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
    :data:`~campipe.study.execute.BatchHook`) calls to pick the cases to log.
    """
    from campipe.study.layout import coordinate_values

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
    return evaluate(parse_where(study.spec.replay), columns, n)
