"""The ``--where`` language: parsing a condition on per-case columns, and evaluating it.

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
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from campipe.errors import CampipeError, did_you_mean, excerpt

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
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        # ValueError: a null byte (before Python 3.12), text that is not UTF-8, an integer of
        # thousands of digits; RecursionError, MemoryError: nesting too deep for the parser
        reason = exc.msg if isinstance(exc, SyntaxError) else type(exc).__name__
        raise QueryError.at(
            "--where",
            f"cannot parse {excerpt(text)} ({excerpt(reason, 80)}); expected comparisons "
            "joined by and, or, not",
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
                raise QueryError.at("--where", f"the name {excerpt(node.id)} is not allowed")
            if node.id.lower() not in WORDS:
                names.add(node.id)
        if isinstance(node, ast.Constant) and not isinstance(node.value, int | float | str):
            raise QueryError.at("--where", f"the constant {excerpt(node.value)} is not allowed")
        if isinstance(node, ast.Constant) and isinstance(node.value, int):
            try:
                float(node.value)
            except OverflowError:
                raise QueryError.at(
                    "--where", f"the number {excerpt(node.value)} is too large to compare"
                ) from None
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
    _check_condition(tree.body)
    return Where(text, tree, frozenset(names))


def _check_condition(node: ast.AST) -> None:
    """The expression and each operand of and, or, not is a condition (a comparison, or
    conditions joined), never a bare column, number or word: ``--where "1"`` would select
    every case (the words true and false are conditions)."""
    if isinstance(node, ast.BoolOp):
        for value in node.values:
            _check_condition(value)
        return
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        _check_condition(node.operand)
        return
    if isinstance(node, ast.Name) and node.id.lower() in ("true", "false"):
        return
    if not isinstance(node, ast.Compare):
        raise QueryError.at(
            "--where",
            f"found {_source(node)} where a condition belongs; expected a "
            "comparison such as 'speed_rpm > 9000' (conditions join with and, or, not)",
        )


def _source(node: ast.AST) -> str:
    """A short excerpt of a node's text."""
    try:
        return excerpt(ast.unparse(node))
    except RecursionError:
        return f"a {type(node).__name__}"


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
                f"unknown column {excerpt(name)}{did_you_mean(name, columns)} "
                f"(columns: {', '.join(columns)})",
            )


def evaluate(where: Where, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) bool: the rows where the expression holds."""
    check_names(where, list(columns))
    out = _eval(where.tree.body, columns)
    return np.broadcast_to(np.asarray(out, dtype=bool), (n,)).copy()


def _eval(node: ast.AST, cols: Mapping[str, np.ndarray]):
    if isinstance(node, ast.BoolOp):
        values = np.broadcast_arrays(*(np.asarray(_eval(v, cols), dtype=bool) for v in node.values))
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
    return node.id if isinstance(node, ast.Name) else _source(node)


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
