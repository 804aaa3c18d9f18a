"""The plots a user asks for: ``campipe plot KIND ARCHIVE`` and a spec's ``plots:`` list.

One declaration of a plot's keys, checked the same way from the command line and from a
spec; :mod:`campipe.plot` draws them. A spec's entry::

    plots:
      - {kind: metric, x: speed_rpm, y: separation_deg_per_rev}        # one line per seat
      - {kind: histories, where: "speed_rpm == 11000", output: lift.svg}
      - {kind: map, x: speed_rpm, y: spring_preload, level: 1 deg}
      - {kind: events, where: "seat is none", turn: last}

Each is written beside the archive when ``campipe study`` finishes (``output``, relative to
the archive's folder; default ``<archive stem>-<kind>.png``, numbered when a kind repeats).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from campipe.errors import CampipeError, did_you_mean, excerpt
from campipe.study.where import QueryError, parse_where

#: The unit systems of ``--units`` (a plot's ``units``; :mod:`campipe.study.query.display`
#: converts to them).
SYSTEMS = ("spec", "si", "in-lbf", "mm-deg", "mm-degca")

#: Plot kinds and what each draws.
KINDS = {
    "histories": "valve lift, velocity and acceleration, cam and follower lift and the contact "
    "forces against cam angle, one panel each, the cases overlaid, events marked",
    "metric": "a per-case value (y) against a swept axis (x), one line per combination of "
    "the other varied keys",
    "map": "a per-case value (z) over two swept axes (x, y) as coloured cells, with its "
    "contour at level; one panel per combination of the other varied keys",
    "events": "each case's events on a cam angle × case chart",
    "pareto": "a campipe design file's two objectives (x, y), the designs evaluated and their "
    "Pareto front",
    "spectrum": "the order spectrum of a history (y; valve acceleration by default) over the "
    "last recorded turn, the cases overlaid",
}
#: File types by the output's suffix.
FORMATS = (".png", ".svg", ".pdf")
#: Keys each kind takes beyond kind, where, units and output.
KIND_KEYS = {
    "histories": ("turn", "angle", "range"),
    "metric": ("x", "y", "limit"),
    "map": ("x", "y", "z", "level"),
    "events": ("turn", "angle", "range"),
    "pareto": ("x", "y"),
    "spectrum": ("y",),
}
#: The angles a histories or events figure may draw along x.
ANGLES = ("cam", "crank")
COMMON_KEYS = ("kind", "where", "units", "output")


class PlotError(CampipeError, ValueError):
    """A plot that cannot be drawn as asked (``key`` the option or spec key)."""


@dataclass(frozen=True)
class PlotRequest:
    """One plot: its kind and options as given (column names checked against the archive
    when drawn)."""

    kind: str  # one of KINDS
    where: str | None = None  # --where selection of cases
    units: str = "spec"  # unit system (SYSTEMS)
    output: str | None = None  # file to write (.png, .svg, .pdf)
    x: str | None = None  # column along x (metric, map)
    y: str | None = (
        None  # metric: the value plotted; map: the column along y; spectrum: the history
    )
    z: str | None = None  # map: the value coloured
    level: str | float | None = None  # map: the contour's level, a number in z's shown
    #                                   units or a quantity ("1 deg")
    turn: str | int | None = None  # histories, events: a turn (1, 2, ... or "last")
    angle: str | None = None  # histories, events: along the cam angle or the crank angle
    range: tuple[float, float] | None = None  # histories, events: the angles shown [deg]
    limit: tuple[str | float, ...] = ()  # metric: y values drawn as limit lines

    def default_output(self, archive: str | Path, number: int = 0) -> Path:
        """``<archive stem>-<kind>.png`` beside the archive (``-<number>`` from the second
        plot of a kind)."""
        archive = Path(archive)
        tag = f"-{number + 1}" if number else ""
        return archive.with_name(f"{archive.stem}-{self.kind}{tag}.png")


def check_plot(raw: Mapping[str, object], path: str = "") -> PlotRequest:
    """A plot request from a spec entry or the command line's options.

    Raises
    ------
    PlotError
        Naming the key (``plots[0].kind``, ``--turn``), what was found and what is expected.
    """

    def at(key: str) -> str:
        return f"{path}.{key}" if path else key

    kind = raw.get("kind")
    if not isinstance(kind, str) or kind not in KINDS:
        raise PlotError.at(
            at("kind"),
            f"found {excerpt(kind)}, expected one of: {', '.join(KINDS)}"
            + (did_you_mean(kind, KINDS) if isinstance(kind, str) else ""),
        )
    allowed = (*COMMON_KEYS, *KIND_KEYS[kind])
    for key in raw:
        if key not in allowed:
            others = [k for k, v in KIND_KEYS.items() if key in v]
            hint = f" (a key of {', '.join(others)} plots)" if others else ""
            raise PlotError.at(
                at(str(key)),
                f"not a key of a {kind} plot{hint}; its keys: {', '.join(allowed)}"
                + did_you_mean(str(key), allowed),
            )
    values: dict[str, Any] = {k: v for k, v in raw.items() if v is not None}
    for key in ("where", "output", "x", "y", "z"):
        value = values.get(key)
        if key in values and (not isinstance(value, str) or not value.strip()):
            raise PlotError.at(at(key), f"found {excerpt(value)}, expected text")
    if "where" in values:
        try:
            parse_where(str(values["where"]))
        except QueryError as exc:
            raise PlotError.at(at("where"), exc.reason) from None
    units = values.get("units", "spec")
    if units not in SYSTEMS:
        raise PlotError.at(
            at("units"), f"found {excerpt(units)}, expected one of: {', '.join(SYSTEMS)}"
        )
    output = values.get("output")
    if output is not None and Path(str(output)).suffix.lower() not in FORMATS:
        raise PlotError.at(
            at("output"),
            f"found {excerpt(output)}, expected a file ending in {', '.join(FORMATS)} "
            "(the suffix chooses the format)",
        )
    if path and output is not None and _leaves_folder(str(output)):
        raise PlotError.at(
            at("output"),
            f"found {excerpt(output)}: a spec's plot is written inside the archive's folder; "
            f"write a relative path without '..', such as {Path(str(output)).name}",
            found=output,
            expected="a path relative to the archive's folder, inside it",
        )
    turn = values.get("turn")
    if turn is not None:
        values["turn"] = check_turn(turn, at("turn"))
    if "angle" in values and values["angle"] not in ANGLES:
        raise PlotError.at(
            at("angle"), f"found {excerpt(values['angle'])}, expected one of: {', '.join(ANGLES)}"
        )
    if "range" in values:
        values["range"] = check_range(values["range"], at("range"))
    if "limit" in values:
        values["limit"] = check_limits(values["limit"], at("limit"))
    level = values.get("level")
    if level is not None and (isinstance(level, bool) or not isinstance(level, int | float | str)):
        raise PlotError.at(
            at("level"), f"found {excerpt(level)}, expected a number or a quantity ('1 deg')"
        )
    known = {f.name for f in fields(PlotRequest)}
    return PlotRequest(**{k: v for k, v in values.items() if k in known})


def _leaves_folder(output: str) -> bool:
    """A spec's ``output`` that is absolute or climbs out of the archive's folder (links are
    followed when it is written: ``campipe.io.outputs``)."""
    path = Path(output)
    return path.is_absolute() or os.path.normpath(output).split(os.sep)[0] == ".."


def check_turn(turn: object, key: str = "--turn") -> str | int:
    """A turn: a whole number from 1, or ``last``, or ``all``."""
    if isinstance(turn, str) and turn.strip().lower() in ("last", "all"):
        return turn.strip().lower()
    try:
        number = int(str(turn))
    except ValueError:
        number = 0
    if isinstance(turn, bool) or number < 1 or str(number) != str(turn).strip():
        raise PlotError.at(key, f"found {excerpt(turn)}, expected a turn 1, 2, ..., last or all")
    return number


def check_range(value: object, key: str = "--range") -> tuple[float, float]:
    """An angle range ``LO:HI`` (or ``[LO, HI]``) [deg], LO below HI."""
    parts: list[object]
    if isinstance(value, str):
        parts = [p.strip().removesuffix("deg").strip() for p in value.split(":")]
    elif isinstance(value, list | tuple):
        parts = list(value)
    else:
        parts = []
    try:
        if len(parts) != 2 or any(isinstance(p, bool) for p in parts):
            raise ValueError
        lo, hi = (float(p) for p in parts)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise PlotError.at(
            key, f"found {excerpt(value)}, expected an angle range LO:HI in degrees, LO < HI"
        )
    return lo, hi


def check_limits(value: object, key: str = "--limit") -> tuple[str | float, ...]:
    """Limit lines: a number (in the y column's shown units) or a quantity (``0.5 m/s``),
    or a list of them."""
    values = value if isinstance(value, list | tuple) else [value]
    out: list[str | float] = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int | float | str) or not str(v).strip():
            raise PlotError.at(
                key, f"found {excerpt(v)}, expected a number or a quantity ('0.5 m/s')"
            )
        out.append(float(v) if isinstance(v, int | float) else v.strip())
    return tuple(out)
