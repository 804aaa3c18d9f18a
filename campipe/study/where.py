"""The ``--where`` language: parsing a condition on per-case columns, and evaluating it.

``--where`` takes comparisons of per-case columns joined by ``and``, ``or``, ``not`` and
parentheses::

    speed_rpm > 9000 and seat > 0
    closure == "form" or not (cam_impacts >= 2)
    9000 <= speed_rpm < 12000
    spring_preload > 150 lbf     # a quantity: converted to the column's units
    seat == 0.1 in
    seat is none                 # no seat (also: seat == none; is not none)
    profile in ["harmonic 1 in", "polydyne-4567 1 in 90/90/90/90 deg"]
    defects == "flat 268-272 deg"   # a label's en dash (268–272) reads as a typed hyphen

The text is parsed with Python's ``ast`` module and every node is checked against a short
whitelist (comparisons, boolean operators, names of columns, numbers, strings, lists of
them); nothing is ever evaluated as Python. Attribute access, calls, subscripts, arithmetic,
lambdas and names that are not columns are refused.

A number followed by units (``150 lbf``, ``0.1 in``, ``245 lbf/in``) is a quantity, read by
:func:`campipe.units.read_quantity` (after a number, ``in`` is the inch unless a list
follows) and converted to the units of the column it is compared with; its dimension must
match. A length per degree (``0.2 mm/deg``, ``5e-4 mm/deg^2``; ``mm/degCA`` per degree of
crank angle), as ``--units mm-deg`` and ``mm-degca`` show a velocity or an acceleration, is
converted at each case's cam speed (the engine's for ``degCA``), so the one threshold is a
different m/s in each case. A bare number compares in the column's stored units, and is
accepted only where those are what a reader types: rpm, degrees, counts and ratios (or zero,
in any units); a bare ``0.00254`` against ``seat`` [m] is refused with the quantity to write
instead.

Numbers compare equal within a relative :data:`EQUAL_RTOL` (1e-9), after conversion: so
``speed_rpm == 11000`` finds 11000 rpm however it was converted and ``seat == 0.1 in`` the
seat written as ``0.1 in``; zero equals only zero.

``none`` is the value of no seat (stored as ``-inf``: see
:data:`campipe.study.spec.variables.NO_SEAT`). ``x is none`` holds where ``x`` has no value: no
seat, or NaN (a failed case's metric, ``dt`` chosen by the integrator); ``x == none`` and
``x in [none, ...]`` mean the same, ``is not none`` and ``!= none`` the opposite. ``is nan``
is the older spelling of ``is none`` and means the same. A seat of none orders below every
seat: ``seat < 0.05 in`` holds for it. Any other column's none (an impact velocity where the
case had no such impact, ``query.tables.OF_IMPACTS``) is no value, for which no ``<``, ``<=``,
``>`` or ``>=`` holds: a valve that never seats has no seating velocity, not a slow one.
"""

from __future__ import annotations

import ast
import io
import keyword
import math
import tokenize
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from campipe.errors import CampipeError, did_you_mean, excerpt
from campipe.units import (
    QuantityError,
    UnitSystemError,
    convert,
    convert_values,
    degree_speed,
    is_unit,
    names_an_angle,
    no_speed,
    per_degree,
    read_quantity,
    registry,
    written_per_degree,
)

MAX_WHERE_LENGTH = 2000
#: Relative tolerance of ``==`` between numbers (after converting a quantity).
EQUAL_RTOL = 1e-9


class _NoValue:
    """The word ``none``: no seat (``-inf`` in the archive), or no value (NaN)."""

    def __repr__(self) -> str:
        return "none"


NONE = _NoValue()
#: Words that are values, not columns.
WORDS: dict[str, object] = {
    "nan": NONE,
    "none": NONE,
    "inf": math.inf,
    "true": True,
    "false": False,
}
#: Stored units in which a bare number is read as written (what a reader types anyway).
BARE_UNITS = ("", "1", "rpm", "degree")
#: Prefix of the names standing for quantities in the parsed text (a user's name may not
#: start with an underscore, so none collides).
_QUANTITY_NAME = "_quantity_"


@dataclass(frozen=True)
class Quantity:
    """A quantity written in a ``--where``: its number and units as written."""

    value: float | np.ndarray  # the number (per case: a length per degree, in SI)
    units: str  # pint spelling of its units (a length per degree: as ``units.per_degree`` reads)
    text: str  # as written, for messages

    def __neg__(self) -> Quantity:
        return Quantity(-self.value, self.units, f"-{self.text}")


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
    quantities: dict[str, Quantity] = field(default_factory=dict)  # placeholder name → quantity


def _has_comment(source: str) -> bool:
    """Whether Python's tokenizer reads a comment in ``source`` (its syntax errors are the
    parser's to report)."""
    try:
        tokens = tokenize.generate_tokens(io.StringIO(source).readline)
        return any(t.type == tokenize.COMMENT for t in tokens)
    except (tokenize.TokenError, SyntaxError):
        return False


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
    text = " ".join(text.splitlines())  # a condition split over lines reads as one
    source, quantities = _read_quantities(text.strip())
    if _has_comment(source):
        raise QueryError.at(
            "--where",
            f"found '#' in {excerpt(text)}: it would start a comment and drop the rest of the "
            "condition unread; remove it (a '#' inside a quoted string is text)",
        )
    try:
        with warnings.catch_warnings():  # e.g. "invalid decimal literal": refused below anyway
            warnings.simplefilter("ignore", SyntaxWarning)
            tree = ast.parse(source, mode="eval")
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
            if not all(_is_value(e, quantities) for e in node.elts):
                raise QueryError.at(
                    "--where",
                    "the list after 'in' holds numbers, quantities, strings or none only",
                )
        if not isinstance(node, _ALLOWED):
            raise QueryError.at(
                "--where",
                f"{_describe(node)} is not allowed; expected comparisons "
                "of columns with numbers or strings, joined by and, or, not",
            )
        if isinstance(node, ast.Name):
            if node.id in quantities:
                continue
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
            and not (
                isinstance(node.operand, ast.Constant)
                or isinstance(node.operand, ast.Name)
                and (node.operand.id in quantities or node.operand.id.lower() == "inf")
            )
        ):
            raise QueryError.at("--where", "a sign applies to a number only")
        if isinstance(node, ast.Compare):
            for op, right in zip(node.ops, node.comparators, strict=True):
                if isinstance(op, ast.Is | ast.IsNot) and not (
                    isinstance(right, ast.Name) and right.id.lower() in ("nan", "none")
                ):
                    raise QueryError.at(
                        "--where",
                        "'is' and 'is not' compare with none only, e.g. 'seat is none'",
                    )
                if isinstance(op, ast.In | ast.NotIn) and not isinstance(
                    right, ast.List | ast.Tuple
                ):
                    raise QueryError.at(
                        "--where", "'in' takes a list, e.g. 'speed_rpm in [9000, 9524]'"
                    )
    _check_condition(tree.body)
    return Where(text, tree, frozenset(names), quantities)


def _read_quantities(text: str) -> tuple[str, dict[str, Quantity]]:
    """``text`` with each quantity (a number followed by units) replaced by a placeholder
    name, and the quantities by name. Text that does not tokenize is returned as it is (the
    parser then says why)."""
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError, IndentationError):
        return text, {}
    for tok in tokens:
        if tok.type == tokenize.NAME and tok.string.startswith("_"):
            raise QueryError.at("--where", f"the name {excerpt(tok.string)} is not allowed")
    starts = [0]
    for line in io.StringIO(text).readlines():  # the lines tokenize numbers its rows by
        starts.append(starts[-1] + len(line))

    def offset(pos: tuple[int, int]) -> int:
        return starts[pos[0] - 1] + pos[1]

    spans: list[tuple[int, int]] = []
    i = 0
    while i < len(tokens) - 1:
        end = _units_end(tokens, i) if tokens[i].type == tokenize.NUMBER else i
        if end > i:
            spans.append((offset(tokens[i].start), offset(tokens[end].end)))
        i = end + 1
    quantities: dict[str, Quantity] = {}
    out = []
    last = 0
    for k, (a, b) in enumerate(spans):
        written = text[a:b]
        name = f"{_QUANTITY_NAME}{k}"
        quantities[name] = _quantity(written)
        out += [text[last:a], name]
        last = b
    out.append(text[last:])
    return "".join(out), quantities


def _quantity(written: str) -> Quantity:
    """A quantity as written: a length per degree (``units.per_degree``) kept as written,
    any other read by ``units.read_quantity``."""
    per = written_per_degree(written)
    if per is not None:
        try:
            return Quantity(float(per[0]), per[1], written)
        except ValueError:
            pass
    try:
        q = read_quantity(written, "--where")
    except QuantityError as exc:
        raise QueryError.at("--where", exc.reason) from None
    return Quantity(float(q.magnitude), str(q.units), written)


#: Unit names pint does not know that a per-degree quantity may use (``mm/degCA``).
_DEGREE_WORDS = ("degCA",)


def _is_unit_name(tokens: list[tokenize.TokenInfo], j: int, after_number: bool) -> bool:
    """Token ``j`` is a unit's name: ``in`` right after a number is the inch unless a list
    or a parenthesis follows (``speed_rpm in [..]`` never has a number before ``in``)."""
    tok = tokens[j]
    if tok.type != tokenize.NAME:
        return False
    if tok.string == "in":
        nxt = tokens[j + 1].string if j + 1 < len(tokens) else ""
        return not (after_number and nxt in ("[", "("))
    if keyword.iskeyword(tok.string) or tok.string.lower() in WORDS:
        return False
    return tok.string in _DEGREE_WORDS or is_unit(tok.string)


def _units_end(tokens: list[tokenize.TokenInfo], i: int) -> int:
    """The last token of the units after the number at ``i`` (``lbf``, ``lbf/in``,
    ``m/s**2``), or ``i`` when no unit follows."""
    if i + 1 >= len(tokens) or not _is_unit_name(tokens, i + 1, True):
        return i
    end = i + 1
    while end + 2 < len(tokens):
        op, nxt = tokens[end + 1], tokens[end + 2]
        if op.string in ("*", "/") and _is_unit_name(tokens, end + 2, False):
            end += 2
        elif op.string in ("**", "^") and nxt.type == tokenize.NUMBER:
            end += 2
        else:
            break
    return end


def _is_value(node: ast.AST, quantities: Mapping[str, Quantity]) -> bool:
    """A plain value: a number or string, a quantity, a word (none, inf), or one signed."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        node = node.operand
    if isinstance(node, ast.Name):
        return node.id in quantities or node.id.lower() in ("none", "nan", "inf")
    return isinstance(node, ast.Constant)


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


def evaluate(
    where: Where,
    columns: Mapping[str, np.ndarray],
    n: int,
    units: Mapping[str, str] | None = None,
    flags: Mapping[str, Mapping[str, int]] | None = None,
) -> np.ndarray:
    """(n,) bool: the rows where the expression holds.

    Parameters
    ----------
    columns : mapping
        Column name → (n,) values, as stored (no seat as ``-inf``).
    units : mapping, optional
        Column name → its stored units (pint spelling, "" for none): quantities convert to
        them and bare numbers are checked against them (see the module). Without it every
        column is taken as unitless and a quantity is refused.
    flags : mapping, optional
        Column name → its CF flags (meaning → value, ``status``'s ``ok`` → 0): the column
        compares with a flag's meaning as a quoted string as with its value.
    """
    check_names(where, list(columns))
    evaluation = _Evaluation(columns, dict(units or {}), where.quantities, dict(flags or {}))
    out = evaluation.eval(where.tree.body)
    return np.broadcast_to(np.asarray(out, dtype=bool), (n,)).copy()


@dataclass
class _Column:
    """A column's values with its name, stored units and CF flags (meaning → value)."""

    name: str
    values: np.ndarray
    units: str
    flags: Mapping[str, int] | None = None


def _flag_values(a, b):
    """(a, b) with a quoted flag meaning compared with a flagged column (``status == "ok"``,
    ``status in ["ok", "step_limit"]``) read as its value; an unknown meaning is refused,
    naming the flags."""
    for column, other, first in ((a, b, True), (b, a, False)):
        if not (isinstance(column, _Column) and column.flags):
            continue
        texts = other if isinstance(other, list) else [other]
        if not any(isinstance(t, str) for t in texts):
            continue
        meanings = ", ".join(f"{k} ({v})" for k, v in column.flags.items())
        values = []
        for t in texts:
            if isinstance(t, str) and t not in column.flags:
                raise QueryError.at(
                    "--where", f"{column.name} is one of {meanings}: found {excerpt(t)}"
                )
            values.append(column.flags[t] if isinstance(t, str) else t)
        mapped = values if isinstance(other, list) else values[0]
        return (column, mapped) if first else (mapped, column)
    return a, b


class _Evaluation:
    """One expression evaluated over columns."""

    def __init__(self, cols, units, quantities, flags) -> None:
        self.cols = cols
        self.units = units
        self.quantities = quantities
        self.flags = flags

    def eval(self, node: ast.AST):
        if isinstance(node, ast.BoolOp):
            values = np.broadcast_arrays(
                *(np.asarray(self.eval(v), dtype=bool) for v in node.values)
            )
            reduce = np.logical_and.reduce if isinstance(node.op, ast.And) else np.logical_or.reduce
            return reduce(values)
        if isinstance(node, ast.UnaryOp):
            value = self.eval(node.operand)
            if isinstance(node.op, ast.Not):
                return ~np.asarray(value, dtype=bool)
            if not (_is_number(value) or isinstance(value, Quantity)):
                raise QueryError.at("--where", "a sign applies to a number only")
            return -value if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.Compare):
            result = None
            left = self.eval(node.left)
            for op, right_node in zip(node.ops, node.comparators, strict=True):
                right = self.eval(right_node)
                a, b = _flag_values(left, right)
                one = _compare(_COMPARE[type(op)], a, b, node.left, right_node)
                result = one if result is None else result & one
                left = right
            return result
        if isinstance(node, ast.Name):
            if node.id in self.quantities:
                return self._per_case(self.quantities[node.id])
            if node.id.lower() in WORDS:
                return WORDS[node.id.lower()]
            col = self.cols[node.id]
            if col.ndim != 1:
                raise QueryError.at(
                    "--where",
                    f"{node.id} holds {col.shape[1]} values per case and cannot be compared",
                )
            return _Column(node.id, col, self.units.get(node.id, ""), self.flags.get(node.id))
        if isinstance(node, ast.Constant):
            if isinstance(node.value, float) and not math.isfinite(node.value):
                raise QueryError.at(
                    "--where", "found a number beyond a double's range (about 1.8e308)"
                )
            return node.value
        if isinstance(node, ast.List | ast.Tuple):
            return [self.eval(e) for e in node.elts]
        raise QueryError.at("--where", f"{_describe(node)} is not allowed")

    def _per_case(self, q: Quantity) -> Quantity:
        """``q``, but a length per degree as each case's SI value [m/s or m/s²], at the
        speed its degrees turn at (``units.degree_speed``: the cam's, or the engine's)."""
        power = per_degree(q.units)[1]
        if not power:
            return q
        speed = degree_speed([q.units])
        if speed not in self.cols:
            raise QueryError.at("--where", f"{q.text}: {no_speed(q.units).reason}")
        units = "m/s" if power == 1 else "m/s^2"
        try:  # q's units in one of SI's, at each case's speed
            per_si = convert_values(
                np.ones(len(self.cols[speed])), units, q.units, self.cols[speed]
            )
        except UnitSystemError:  # not a length per degree
            raise QueryError.at("--where", f"{q.text}: not a length per degree") from None
        return Quantity(q.value / per_si, units, q.text)


#: Characters a label writes that a keyboard types otherwise: a range's en dash (``flat
#: 268–272 deg``) reads as the hyphen typed for it.
_TYPED = str.maketrans({"\u2013": "-", "\u2212": "-"})


def _plain(text) -> np.ndarray:
    """Text (one or an array of them) as typed (:data:`_TYPED`), for ``==`` and ``!=``."""
    values = np.asarray(text, dtype=object)
    return np.frompyfunc(lambda t: t.translate(_TYPED) if isinstance(t, str) else t, 1, 1)(values)


def _is_text(v) -> bool:
    if isinstance(v, _Column):
        v = v.values
    return isinstance(v, str) or (isinstance(v, np.ndarray) and v.dtype.kind in "OUS")


def _is_number(v) -> bool:
    if isinstance(v, _Column):
        v = v.values
    return (isinstance(v, int | float) and not isinstance(v, bool)) or (
        isinstance(v, np.ndarray) and v.dtype.kind in "iuf"
    )


def _name(node: ast.AST, value: object = None) -> str:
    if isinstance(value, Quantity):
        return value.text
    return node.id if isinstance(node, ast.Name) else _source(node)


def _no_value(v) -> np.ndarray:
    """Where ``v`` has no value: none itself, no seat (-inf), NaN, a text column's "none"
    (``defects``' none, as the table shows it); a quantity and other text always have one."""
    if v is NONE:
        return np.ones((), dtype=bool)
    if isinstance(v, Quantity):
        return np.zeros((), dtype=bool)
    if _is_text(v):
        if isinstance(v, _Column):
            return np.asarray(_plain(v.values) == "none", dtype=bool)
        return np.zeros(np.shape(v), dtype=bool)
    a = np.asarray(v.values if isinstance(v, _Column) else v, dtype=float)
    return np.isnan(a) | np.isneginf(a)


#: Columns whose none (-inf) orders below every value: no seat (see the module).
ORDERED_NONE = frozenset({"seat"})


def unordered_none(name: str, values: np.ndarray) -> np.ndarray:
    """A column's values with none (-inf) as NaN where none is no value (every column but
    :data:`ORDERED_NONE`): it then orders nowhere, and sorts last."""
    if name in ORDERED_NONE or values.dtype.kind != "f":
        return values
    return np.where(np.isneginf(values), np.nan, values)


def _unordered_none(v, x: np.ndarray) -> np.ndarray:
    return unordered_none(v.name, x) if isinstance(v, _Column) else x


def _numbers(a, b) -> tuple[np.ndarray, np.ndarray]:
    """Both sides as floats in the units of the column among them (see the module)."""
    column = a if isinstance(a, _Column) else b if isinstance(b, _Column) else None
    units = column.units if column is not None else ""
    return _in_units(a, units, column), _in_units(b, units, column)


def _in_units(v, units: str, column: _Column | None) -> np.ndarray:
    if isinstance(v, _Column):
        return np.asarray(v.values, dtype=float)
    if isinstance(v, Quantity):
        return np.asarray(_convert(v, units, column), dtype=float)
    value = np.asarray(v, dtype=float)
    if (
        column is not None
        and units not in BARE_UNITS
        and np.any(value != 0)
        and np.all(np.isfinite(value))
    ):
        raise QueryError.at(
            "--where",
            f"{column.name} is stored in {units}: write the number with its units, e.g. "
            f"'{column.name} > {float(value):.6g} {units}' (or in any units of the same kind)",
        )
    return value


def _convert(q: Quantity, units: str, column: _Column | None) -> float | np.ndarray:
    """``q`` in the column's stored ``units``; its dimension must match (an angle for an
    angle or a speed, never a bare frequency)."""
    name = column.name if column is not None else "a number"
    if column is None:
        raise QueryError.at("--where", f"compare {q.text} with a column, e.g. 'seat == 0.1 in'")
    if units == "":
        raise QueryError.at(
            "--where", f"{q.text} has units, but {name} has none; compare it with a bare number"
        )
    ureg = registry()
    try:  # an archive's own attribute: edited by hand, it may not be units at all
        stored = ureg.Quantity(1.0, units)
        angle = names_an_angle(stored)
    except Exception:  # pint's errors, and its AssertionError and OverflowError on odd text
        raise QueryError.at(
            "--where",
            f"{name}'s units attribute in the archive, {excerpt(units)}, is not units campipe "
            "writes (edited by hand?): run the study again to write the archive anew",
        ) from None
    given = ureg.Quantity(1.0, q.units)
    if angle and not names_an_angle(given):
        raise QueryError.at(
            "--where",
            f"{q.text} names no angle, and {name} is stored in {units}: write it in "
            f"{units} or other units of an angle{' per time' if stored.dimensionality else ''}",
        )
    try:
        if isinstance(q.value, np.ndarray):  # per case (a length per degree, in SI)
            return q.value * convert(1.0, q.units, units)
        return convert(q.value, q.units, units)
    except Exception:  # pint's DimensionalityError and its kin
        raise QueryError.at(
            "--where",
            f"{q.text} {given.dimensionality} cannot be compared with {name}, stored in "
            f"{units} {stored.dimensionality}",
        ) from None


def _compare(op: str, a, b, a_node, b_node) -> np.ndarray:
    if b is NONE or a is NONE:
        other = a if b is NONE else b
        if op in ("is", "==", "is not", "!="):
            none = _no_value(other)
            return none if op in ("is", "==") else ~none
        raise QueryError.at(
            "--where", f"none compares with ==, !=, is, is not and in only (found {op})"
        )
    if op in ("is", "is not"):
        none = _no_value(a)
        return none if op == "is" else ~none
    if op in ("in", "not in"):
        hit = np.zeros(np.shape(a.values if isinstance(a, _Column) else a), dtype=bool)
        for item in b:
            hit |= _compare("==", a, item, a_node, b_node)
        return hit if op == "in" else ~hit
    if isinstance(a, bool) or isinstance(b, bool):
        raise QueryError.at(
            "--where",
            "true and false stand alone as conditions; compare a column with a number, a "
            "quantity or a quoted string",
        )
    if _is_text(a) != _is_text(b):
        text, other = ((a_node, a), (b_node, b)) if _is_text(a) else ((b_node, b), (a_node, a))
        raise QueryError.at(
            "--where",
            f"{_name(*text)} is text and {_name(*other)} is not; "
            'compare text with a quoted string, e.g. closure == "form"',
        )
    if _is_text(a):
        if op not in ("==", "!="):
            raise QueryError.at(
                "--where",
                f"text compares with == and != only (found {op} "
                f"between {_name(a_node, a)} and {_name(b_node, b)})",
            )
        left = a.values if isinstance(a, _Column) else a
        right = b.values if isinstance(b, _Column) else b
        eq = _plain(left) == _plain(right)
        return eq if op == "==" else ~eq
    x, y = _numbers(a, b)
    if op in ("==", "!="):
        eq = np.isclose(x, y, rtol=EQUAL_RTOL, atol=0.0) | ((x == y) & np.isinf(x))
        return eq if op == "==" else ~eq
    x, y = _unordered_none(a, x), _unordered_none(b, y)  # no value (but no seat) orders nowhere
    with np.errstate(invalid="ignore"):
        return {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal}[op](
            x, y
        )
