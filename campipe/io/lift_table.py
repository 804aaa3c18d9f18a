"""Reading a measured cam lift table from CSV.

Format: comma-separated text; lines starting with ``#`` and blank lines are ignored. The first
other line is a header naming two columns, ``angle`` and ``lift``, each with its units in
square brackets (pint spelling); every following line holds one angle and one lift::

    # lift table of cam 17, measured 2024-03-02
    angle [deg],lift [in]
    0,0.0
    10,0.0021
    ...

Angles lie within one turn, [0, 360) deg, strictly increasing, at least four of them; the
profile passes through every point (a periodic cubic spline, see
:func:`campipe.profiles.table`).
"""

from __future__ import annotations

import csv
import hashlib
import math
import re
from pathlib import Path

import numpy as np

from campipe.errors import CampipeError, excerpt
from campipe.io import read_text
from campipe.units import QuantityError, parse_angular, parse_quantity

_HEADER = re.compile(r"^\s*(?P<name>[A-Za-z_]+)\s*\[(?P<units>[^\]]+)\]\s*$")
#: Column name → (SI units the numerics take, units suggested in errors).
COLUMNS = {"angle": ("rad", "deg"), "lift": ("m", "in")}


#: Largest lift table read [bytes]: a measured table of a few thousand lines is ~100 kB.
MAX_TABLE_BYTES = 16 * 2**20
#: Most rows of a lift table.
MAX_TABLE_ROWS = 100_000


class LiftTableError(CampipeError, ValueError):
    """A lift table file that cannot be read, with the file and line (``key``:
    ``<file>:<line>``, or the file alone)."""


def read_lift_table(path: str | Path) -> tuple[np.ndarray, np.ndarray, str]:
    """Read a lift table CSV (format above).

    Parameters
    ----------
    path : str or Path
        The CSV file.

    Returns
    -------
    angles : np.ndarray
        (m,) cam angles [rad].
    lifts : np.ndarray
        (m,) lifts [m].
    lift_units : str
        The lift column's units as its header writes them (``in``, ``mm``).

    Raises
    ------
    LiftTableError
        Naming the file and line: unreadable file, missing or bad header, unknown units,
        a non-numeric or non-finite value, a row without exactly two values.
    """
    path = Path(path)
    text = read_text(path, "the lift table", LiftTableError, MAX_TABLE_BYTES)
    rows = [
        (n, row)
        for n, row in enumerate(csv.reader(text.splitlines()), 1)
        if row and "".join(row).strip() and not row[0].lstrip().startswith("#")
    ]
    if not rows:
        raise LiftTableError.at(
            str(path),
            "empty; expected a header 'angle [deg],lift [in]' and rows",
            expected="a header 'angle [deg],lift [in]' and rows",
        )
    line, header = rows[0]
    if len(rows) - 1 > MAX_TABLE_ROWS:
        raise LiftTableError.at(
            str(path),
            f"{len(rows) - 1} rows, expected at most {MAX_TABLE_ROWS}",
            expected=f"at most {MAX_TABLE_ROWS} rows",
        )
    *scale, lift_units = _read_header(path, line, header)
    values = np.empty((len(rows) - 1, 2))
    for k, (n, row) in enumerate(rows[1:]):
        if len(row) != 2:
            raise LiftTableError.at(
                f"{path}:{n}",
                f"expected 2 values (angle, lift), found {len(row)}",
                found=row,
                expected="2 values (angle, lift)",
            )
        for j, cell in enumerate(row):
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise LiftTableError.at(
                    f"{path}:{n}",
                    f"found {_shown(cell)} in column {j + 1}, expected a finite number",
                    found=cell.strip() if _SHOWN.match(cell) else None,
                    expected="a finite number",
                )
            values[k, j] = v * scale[j]
    return values[:, 0].copy(), values[:, 1].copy(), lift_units


#: A cell quoted in a message: a short word, number or header cell. Anything else is not
#: echoed: a path given as a lift table may name a file that is no table (``/etc/shadow``),
#: whose content no message should show.
_SHOWN = re.compile(r"^\s*[\w.+\- ]{0,24}(\[[\w./*^ ]{0,16}\])?\s*$")


def _shown(cell: str) -> str:
    """``cell`` quoted if it is :data:`_SHOWN`, else its length only."""
    if _SHOWN.match(cell):
        return excerpt(cell.strip())
    return f"a value of {len(cell)} characters that is no number (not shown)"


def _read_header(path: Path, line: int, header: list[str]) -> tuple[float, float, str]:
    """The angle's and the lift's scale to SI, and the lift's units as written."""
    expected = "expected a header such as 'angle [deg],lift [in]'"
    if len(header) != 2:
        shown = ",".join(header)
        what = (
            excerpt(shown)
            if all(_SHOWN.match(c) for c in header)
            else f"a first line of {len(header)} field{'s' if len(header) != 1 else ''} "
            "that is no header (not shown)"
        )
        raise LiftTableError.at(f"{path}:{line}", f"found {what}, {expected}", found=len(header))
    scale = []
    written = ""
    for cell, (name, (units, example)) in zip(header, COLUMNS.items(), strict=True):
        m = _HEADER.match(cell)
        if not m or m["name"].lower() != name:
            raise LiftTableError.at(
                f"{path}:{line}",
                f"found column {_shown(cell)} where '{name} [units]' belongs; " + expected,
                found=cell.strip() if _SHOWN.match(cell) else None,
            )
        written = m["units"].strip()  # the last column's: the lift's
        try:
            parse = parse_angular if name == "angle" else parse_quantity
            scale.append(parse(f"1 {m['units']}", units, f"{path}:{line}: {name}", example))
        except QuantityError as exc:
            raise LiftTableError(
                str(exc), key=exc.key, found=exc.found, expected=exc.expected, reason=exc.reason
            ) from None
    return scale[0], scale[1], written


def table_digest(angles: np.ndarray, lifts: np.ndarray) -> str:
    """SHA-256 of a table's values in SI: what a case id records instead of the file's path."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(angles, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(lifts, dtype="<f8").tobytes())
    return h.hexdigest()
