"""Each plot kind as a matplotlib Figure, from an archive and a request.

The figures are built with matplotlib's object interface (no pyplot state: a figure lives as
long as its caller keeps it). Every figure is titled with the study's name, labels its axes
with units in the request's unit system (:mod:`campipe.study.query.display`) and draws each case
or group in a distinct line style and marker as well as a shade (:mod:`campipe.plot.style`).

- ``histories``: valve lift, valve velocity, valve acceleration, cam and follower lift, cam
  force and (when a case has a seat) seat force against cam angle, one panel each; the cases
  overlaid and labelled by what differs between them; cam events marked on the follower's
  lift, seat events on the valve's.
- ``metric``: a per-case value against a numeric column (a swept axis), one line per
  combination of the other varied columns.
- ``map``: a per-case value over two numeric columns as coloured cells (one per case), with
  its contour at ``level``; one panel per combination of the other varied columns.
- ``events``: every event of each case on a cam angle × case chart, a marker per kind.
- ``pareto``: a design file's (``campipe design``) two objectives, every design evaluated
  (those meeting the requirements filled), the Pareto front joined.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from campipe.engine.metrics import UNCERTAINTY
from campipe.errors import did_you_mean, excerpt
from campipe.plot.kinematics import kinematic_lift, rocker_ratios, turn_extensions
from campipe.plot.style import (
    COLORMAP,
    EVENT_MARKERS,
    SHORT_UNITS,
    axis_label,
    axis_words,
    colour_norm,
    line_styles,
)
from campipe.plot.values import shown_value
from campipe.study.archive.layout import CHAIN_NAMES, LEVER_NAMES
from campipe.study.query.display import display_units, format_value, to_display
from campipe.study.query.tables import OF_IMPACTS, CaseTable, case_table, displayed, select
from campipe.study.spec.drive import ENGINE_SPEED_NAME
from campipe.study.spec.plots import PlotError, PlotRequest, check_turn
from campipe.study.spec.variables import VARIABLES
from campipe.units import degree_speed, per_degree
from campipe.vocabulary import FAILURES

#: Most cases overlaid in one history figure (beyond, lines cannot be told apart).
MAX_OVERLAID = 10
#: Most rows of an events chart, panels of a map.
MAX_ROWS = 80
MAX_PANELS = 12
#: History panels: (title, variables drawn as the cases' lines).
PANELS = (
    ("valve lift", ("valve_lift",)),
    ("valve velocity", ("valve_velocity",)),
    ("valve acceleration", ("valve_acceleration",)),
    ("follower lift (cam lift dotted)", ("follower_lift",)),
    ("cam contact force", ("cam_force",)),
    ("seat contact force", ("seat_force",)),
)
#: Panel whose lines carry each event kind: cam events on the follower, seat events on the
#: valve.
EVENT_PANELS = {1: "follower_lift", 2: "follower_lift", 3: "valve_lift", 4: "valve_lift"}


@dataclass
class View:
    """The selected cases of an archive, their columns as stored and as shown."""

    ds: Any  # the xarray.Dataset the cases are selected from
    stored: CaseTable  # per-case columns, stored units
    shown: CaseTable  # the same in the shown units
    units: dict[str, str]  # every variable's shown units
    study: str  # the study's name
    rows: np.ndarray  # the selected rows of the archive


def figure(ds, request: PlotRequest) -> Figure:
    """The figure ``request`` asks for, drawn from the archive ``ds`` (an xarray.Dataset).

    Raises
    ------
    PlotError
        For a selection of no case, an unknown or unsuitable column, too many cases to tell
        apart, each naming the option (``--where``, ``--x``, ...) and what would do.
    """
    view = select_view(ds, request)
    draw = {"histories": histories, "metric": metric, "map": cell_map, "events": events}
    return draw[request.kind](view, request)


def select_view(ds, request: PlotRequest) -> View:
    """The cases ``request.where`` selects, with their shown units."""
    if "case" not in ds.variables or "event_count" not in ds.variables:
        layout = ds.attrs.get("campipe_layout")
        raise PlotError.at(
            "ARCHIVE",
            f"an archive of another layout ({layout}): rerun its study with --overwrite"
            if layout
            else "not a campipe archive (no case coordinate)",
        )
    table = case_table(ds)
    rows = np.sort(select(table, request.where))
    if rows.size == 0:
        raise PlotError.at(
            "--where",
            f"{request.where!r} selects none of the archive's {table.n} cases; nothing drawn",
        )
    stored_units = {
        name: str(v.attrs.get("units", ""))
        for name, v in ds.variables.items()
        if name not in table.units
    }
    stored_units.update(table.units)
    units = display_units(stored_units, ds.attrs, request.units)
    picked = CaseTable(
        {k: v[rows] for k, v in table.columns.items()},
        table.units,
        table.default,
        rows.size,
        table.study,
        table.flags,
    )
    shown = displayed(picked, units)
    return View(ds, picked, shown, units, table.study or "study", rows)


# -- labels ------------------------------------------------------------------------------------


def varied_columns(view: View, exclude: Sequence[str] = ()) -> list[str]:
    """Per-case parameters (not metrics, not the id) whose values differ among the selected
    cases, in the archive's order."""
    out = []
    for name, values in view.shown.columns.items():
        var = VARIABLES.get(name)
        if name == "case" or name in exclude or (var is not None and var.role != "parameter"):
            continue
        # the engine's speed is the cam's over the drive's ratio: one of the two is an axis
        if name in ("speed_rpm", ENGINE_SPEED_NAME) and {"speed_rpm", ENGINE_SPEED_NAME} & set(
            exclude
        ):
            continue
        if name == ENGINE_SPEED_NAME and "speed_rpm" in out:
            continue
        if name in view.ds.data_vars:
            continue  # a metric or count, not a parameter
        keys = {_key(v) for v in values}
        if len(keys) > 1:
            out.append(name)
    return out


def _key(value: object) -> object:
    if isinstance(value, np.ndarray):
        return tuple(value.tolist())
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    return value.item() if isinstance(value, np.generic) else value


def describe(name: str, value: object, units: str) -> str:
    """``9524 rpm``, ``seat none``, ``spring_preload 151 lbf``, ``closure form``."""
    if isinstance(value, np.ndarray):
        text = ", ".join(format_value(v, 4) for v in value)
    else:
        text = format_value(value, 6)
    if name == "speed_rpm":
        return f"{text} rpm"
    if name == ENGINE_SPEED_NAME:
        return f"engine {text} rpm"
    shown_units = f" {units}" if units and units != "1" and text != "none" else ""
    return f"{name} {text}{shown_units}"


def case_labels(view: View, names: Sequence[str]) -> list[str]:
    """Each selected case by its values of ``names`` (the case id when none differ)."""
    if not names:
        return [f"case {str(c)[:8]}" for c in view.shown.columns["case"]]
    if ENGINE_SPEED_NAME in view.shown.columns:  # a drive: the speed the spec gave
        names = [ENGINE_SPEED_NAME if n == "speed_rpm" else n for n in names]
    return [
        ", ".join(describe(n, view.shown.columns[n][i], view.shown.units.get(n, "")) for n in names)
        for i in range(view.shown.n)
    ]


#: Characters of an 11-point title a figure's inch of width holds (a title wider than its
#: figure is wrapped, not cut at both sides).
TITLE_CHARS_PER_INCH = 11


def set_title(fig: Figure, view: View, what: str, where: str | None) -> None:
    import textwrap

    selection = f" — where {where}" if where else ""
    width = max(int(fig.get_figwidth() * TITLE_CHARS_PER_INCH), 20)
    fig.suptitle(textwrap.fill(f"{view.study}: {what}{selection}", width), fontsize=11)


def column_values(view: View, name: str | None, option: str, numeric: bool = True) -> np.ndarray:
    """A per-case column as shown, or a PlotError naming the option and the columns."""
    columns = view.shown.columns
    usable = [k for k, v in columns.items() if v.ndim == 1 and v.dtype.kind in "iuf"]
    if name is None or name not in columns or (numeric and name not in usable):
        what = "unknown column" if name not in columns else "not a column of numbers"
        raise PlotError.at(
            option,
            f"{what} {excerpt(name)}{did_you_mean(str(name), usable)} (columns: "
            f"{', '.join(usable)})",
        )
    return np.asarray(columns[name], dtype=float)


def _cam_speed(view: View) -> np.ndarray | None:
    """(n,) the selected cases' cam speeds [rpm], for values shown per degree (the engine's,
    for values per degree of crank angle: ``--units mm-degca``)."""
    return view.stored.columns.get(degree_speed(view.units.values()))


def _usable(view: View) -> np.ndarray:
    """(n,) bool: the selected cases that did not fail (their results are NaN)."""
    status = view.stored.columns.get("status")
    return np.ones(view.stored.n, bool) if status is None else ~np.isin(status, FAILURES)


# -- histories -------------------------------------------------------------------------------


def _turn_mask(cam_angle: np.ndarray, turn: str | int | None) -> tuple[np.ndarray, str]:
    """The samples of the chosen turn, and a note for the title."""
    if turn is None or turn == "all":
        return np.ones(cam_angle.size, bool), ""
    turns = max(int(math.ceil(float(cam_angle[-1]) / 360.0 - 1e-9)), 1)
    number = turns if turn == "last" else int(turn)
    if number > turns:
        raise PlotError.at("--turn", f"found {turn}, but the run has {turns} turns")
    lo, hi = 360.0 * (number - 1), 360.0 * number
    return (cam_angle >= lo - 1e-9) & (cam_angle <= hi + 1e-9), f", turn {number}"


def histories(view: View, request: PlotRequest) -> Figure:
    """Valve lift, velocity, acceleration, follower and cam lift and the contact forces
    against cam angle, one panel each, the cases overlaid."""
    n = view.stored.n
    if n > MAX_OVERLAID:
        raise PlotError.at(
            "--where",
            f"selects {n} cases; overlay at most {MAX_OVERLAID} (e.g. --where "
            "'speed_rpm == 11000' or 'seat is none')",
        )
    ds = view.ds
    cam_angle = np.asarray(ds["cam_angle"].values, dtype=float)
    keep, turn_note = _turn_mask(cam_angle, check_turn(request.turn) if request.turn else None)
    if "recorded_revolution" in ds.variables:  # a run of automatic length
        turn_note = turn_note.replace(", turn", ", recorded turn") + (
            ", each case's last turns (settled: query's period_turns)"
        )
    # one turn chosen: its angles read 0–360°, as a designer reads a turn (the events too)
    axis = angle_axis(view, request, float(cam_angle[keep][0]) if turn_note else 0.0)
    keep &= axis.within(cam_angle, request.range)
    angle = cam_angle[keep]
    x = axis.shown(angle)
    seat = view.stored.columns.get("seat")
    panels = [
        p
        for p in PANELS
        if all(v in ds.variables for v in p[1])
        and (p[1] != ("seat_force",) or seat is None or np.isfinite(seat).any())
    ]
    cols = 2
    rows_n = -(-len(panels) // cols)
    fig = Figure(figsize=(11, 2.6 * rows_n + 1.2), layout="constrained")
    axes = fig.subplots(rows_n, cols, sharex=True, squeeze=False).ravel()
    styles = line_styles(n)
    labels = case_labels(view, varied_columns(view))
    samples = int(keep.sum())
    drawn: dict[str, np.ndarray] = {}
    for ax, (title, names) in zip(axes, panels, strict=False):
        name = names[0]
        units = view.units.get(name, "")
        values = to_display(
            np.asarray(ds[name].values[view.rows][:, keep], float),
            str(ds[name].attrs.get("units", "")),
            units,
            _cam_speed(view),
        )
        drawn[name] = values
        if name == "follower_lift":
            _cam_lines(ax, view, keep, x)
        for i in range(n):
            ax.plot(x, values[i], label=labels[i], **styles[i].kwargs(samples))
        if name == "valve_lift":
            _kinematic_lines(ax, view, keep, x)
            _seat_bands(ax, view, values)
        ax.set_title(_panel_title(ds, name, title), fontsize=10)
        per_cam_degree = per_degree(units)[1] and degree_speed([units]) == "speed_rpm"
        crank = axis.name == "crank_angle" and per_cam_degree  # say whose degree it is
        ax.set_ylabel(axis_label(name, units) + (" (per cam degree)" if crank else ""))
        ax.grid(alpha=0.3)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    kinds: dict[str, Any] = {}
    for ax, (_, names) in zip(axes, panels, strict=False):
        kinds.update(_mark_events(ax, view, names[0], drawn, angle, styles, axis))
    for ax in axes[max(len(panels) - cols, 0) : len(panels)]:
        ax.set_xlabel(axis_label(axis.name, "degree"))
        ax.tick_params(labelbottom=True)
    handles, texts = axes[0].get_legend_handles_labels()
    fig.legend(
        handles=[*handles, *kinds.values()],
        labels=[*texts, *kinds],
        loc="outside lower center",
        ncols=min(len(texts) + len(kinds), 4),
        fontsize=8,
    )
    set_title(fig, view, f"histories{turn_note}", request.where)
    return fig


def _panel_title(ds, name: str, title: str) -> str:
    """A history panel's title, the follower's in the layout's words: a lever layout's
    follower and cam lift are the valve side's (the archive's ``long_name`` says so), a
    chain's follower is its first mass."""
    long_name = str(ds[name].attrs.get("long_name", "")) if name == "follower_lift" else ""
    if long_name == LEVER_NAMES["follower_lift"]:
        return "lever at the pallet, valve side (kinematic valve lift dotted)"
    if long_name == CHAIN_NAMES["follower_lift"]:
        return "first mass lift (cam lift dotted)"
    return title


@dataclass(frozen=True)
class AngleAxis:
    """The angle a figure's x axis shows: the cam's or the crank's (``--angle``), from
    ``offset`` cam degrees (a chosen turn's start: it reads from 0°)."""

    name: str  # "cam_angle" or "crank_angle"
    offset: float  # [deg of cam angle] subtracted
    scale: float  # shown degrees per cam degree: 1, or 1 / drive.cam_per_crank

    def shown(self, cam_angle: np.ndarray) -> np.ndarray:
        """Cam angles [deg] as the axis shows them."""
        return (np.asarray(cam_angle, float) - self.offset) * self.scale

    def within(self, cam_angle: np.ndarray, span: tuple[float, float] | None) -> np.ndarray:
        """(samples,) bool: the cam angles whose shown angle is in ``span`` (``--range``;
        all for None); a PlotError for a span that holds no sample."""
        if span is None:
            return np.ones(np.shape(cam_angle), bool)
        shown = self.shown(cam_angle)
        inside = (shown >= span[0] - 1e-9) & (shown <= span[1] + 1e-9)
        if inside.sum() < 2:
            raise PlotError.at(
                "--range",
                f"{span[0]:g}:{span[1]:g} deg holds {int(inside.sum())} of the samples "
                f"({float(shown.min()):g} … {float(shown.max()):g} deg of "
                f"{axis_words(self.name).lower()}); choose a range inside it",
            )
        return inside


def angle_axis(view: View, request: PlotRequest, offset: float) -> AngleAxis:
    """The x axis ``request.angle`` asks for: the cam angle (the default) or, for an archive
    of a spec with a drive, the crank angle (``crank_angle``, the cam's over the ratio)."""
    if request.angle != "crank":
        return AngleAxis("cam_angle", offset, 1.0)
    crank = view.ds.variables.get("crank_angle")
    if crank is None:
        raise PlotError.at(
            "--angle",
            "the archive has no crank angle: its spec gives no drive (drive: {cam_per_crank: "
            "0.5}); draw --angle cam",
        )
    return AngleAxis("crank_angle", offset, 1.0 / float(crank.attrs["cam_per_crank"]))


def _kinematic_lines(ax, view: View, keep: np.ndarray, x: np.ndarray) -> None:
    """The kinematic valve lift (a rigid train's: :mod:`campipe.plot.kinematics`) under the
    cases' valve lifts, once per distinct curve (thin black dashes)."""
    ds = view.ds
    if "cam_lift" not in ds.variables:
        return
    ratios, lashes, in_link = rocker_ratios(ds.attrs, view.stored.columns)
    seats = view.stored.columns.get("seat", np.full(view.stored.n, -np.inf))
    stored = str(ds["cam_lift"].attrs.get("units", ""))
    lash = np.repeat(lashes[:, None], int(keep.sum()), axis=1)
    if in_link.any():  # a chain's lash adjuster takes its extension of lash up, turn by turn
        lash[in_link] -= turn_extensions(view.ds, view.rows, keep)[in_link]
    lifts = kinematic_lift(
        np.asarray(ds["cam_lift"].values[view.rows][:, keep], float), ratios, seats, lash
    )
    shown = to_display(lifts, stored, view.units.get("valve_lift", stored), _cam_speed(view))
    for k, lift in enumerate(_distinct(c for c in shown if np.isfinite(c).any())):
        ax.plot(
            x,
            lift,
            color="black",
            linestyle=(0, (4, 2)),
            linewidth=0.9,
            label="kinematic lift" if k == 0 else None,
            gid="kinematic",
            zorder=1,
        )


def _distinct(curves: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """Each curve not equal to an earlier one to rounding (1e-9 of its largest value): one
    cam, or one kinematic lift, for cases that differ only in speed (lift at angle = ω t)."""
    seen: list[np.ndarray] = []
    for curve in curves:
        scale = 1e-9 * float(np.nanmax(np.abs(curve), initial=1.0))
        if not any(np.allclose(curve, s, rtol=0.0, atol=scale, equal_nan=True) for s in seen):
            seen.append(curve)
            yield curve


def _seat_bands(ax, view: View, lifts: np.ndarray) -> None:
    """Each distinct seat of the cases drawn as a hatched band whose top is the seat's valve
    lift (the valve rests there, never below)."""
    seat = view.shown.columns.get("seat")
    if seat is None:
        return
    seats = np.unique(np.asarray(seat, float)[np.isfinite(np.asarray(seat, float))])
    finite = lifts[np.isfinite(lifts)]
    depth = 0.04 * (float(finite.max() - finite.min()) if finite.size else 1.0) or 1.0
    for k, at in enumerate(seats):
        ax.axhspan(
            at - depth,
            at,
            facecolor="0.85",
            edgecolor="0.3",
            hatch="///",
            linewidth=0.8,
            zorder=0,
            label="seat" if k == 0 else None,
        )


def _cam_lines(ax, view: View, keep: np.ndarray, angle: np.ndarray) -> None:
    """The cam's lift under the followers: once per distinct cam (a thin black dotted line)."""
    ds = view.ds
    units = view.units.get("cam_lift", "")
    lifts = to_display(
        np.asarray(ds["cam_lift"].values[view.rows][:, keep], float),
        str(ds["cam_lift"].attrs.get("units", "")),
        units,
        _cam_speed(view),
    )
    for k, lift in enumerate(_distinct(lifts)):
        ax.plot(
            angle,
            lift,
            color="black",
            linestyle=":",
            linewidth=0.9,
            label="cam lift" if k == 0 else None,
        )


def _events_of(view: View) -> list[dict[str, np.ndarray]]:
    """Each selected case's events: cam angle [degree] and kind."""
    ds = view.ds
    counts = np.asarray(ds["event_count"].values, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    angle = np.asarray(ds["event_cam_angle"].values, dtype=float)
    kind = np.asarray(ds["event_kind"].values, dtype=np.int64)
    out = []
    for r in view.rows:
        span = slice(int(starts[r]), int(starts[r + 1]))
        out.append({"angle": angle[span], "kind": kind[span]})
    return out


def _mark_events(ax, view, name, drawn, angle, styles, axis: AngleAxis) -> dict[str, Any]:
    """The events whose contact this panel shows, on each case's line, at their angle as
    ``axis`` shows it (a chosen turn from 0°); returns a legend handle for each kind marked
    (its text → handle)."""
    kinds = [k for k, panel in EVENT_PANELS.items() if panel == name]
    marked: dict[str, Any] = {}
    if not kinds or name not in drawn or angle.size < 2:
        return marked
    for i, ev in enumerate(_events_of(view)):
        for kind in kinds:
            at = ev["angle"][(ev["kind"] == kind) & (ev["angle"] >= angle[0])]
            at = at[at <= angle[-1]]
            if at.size == 0:
                continue
            marker, filled, text = EVENT_MARKERS[kind]
            color = styles[i].color
            ax.scatter(
                axis.shown(at),
                np.interp(at, angle, drawn[name][i]),
                marker=marker,
                s=30,
                facecolors=color if filled else "white",
                edgecolors=color,
                linewidths=1.0,
                zorder=3,
            )
            if text not in marked:
                marked[text] = _event_handle(kind)
    return marked


def _event_handle(kind: int):
    """A black legend entry for an event kind (the marks take each case's shade)."""
    from matplotlib.lines import Line2D

    marker, filled, text = EVENT_MARKERS[kind]
    return Line2D(
        [],
        [],
        linestyle="none",
        marker=marker,
        markersize=6,
        markerfacecolor="black" if filled else "white",
        markeredgecolor="black",
    )


# -- metric against an axis --------------------------------------------------------------------


def _default_x(view: View) -> str:
    """The speed (the engine's with a drive, as the cases' labels give it, else the cam's)
    where it varies or no column does; else the first numeric column that varies."""
    varied = [n for n in varied_columns(view) if view.shown.columns[n].dtype.kind in "iuf"]
    speed = ENGINE_SPEED_NAME if ENGINE_SPEED_NAME in view.shown.columns else "speed_rpm"
    if {"speed_rpm", ENGINE_SPEED_NAME} & set(varied):
        return speed
    if not varied:  # one case, or none varying: its point at its speed
        if speed in view.shown.columns:
            return speed
        raise PlotError.at("--x", "no numeric column varies among the selected cases")
    return varied[0]


def _finite_axis(view: View, name: str, option: str) -> np.ndarray:
    values = column_values(view, name, option)
    if not np.isfinite(values).all():
        raise PlotError.at(
            option,
            f"{name} holds none or nan for some cases, which have no place on an axis; "
            f"select the others (--where '{name} is not none') or draw a line per {name}",
        )
    return values


def groups(view: View, exclude: Sequence[str]) -> tuple[list[str], dict[tuple, list[int]]]:
    """The other varied columns and the selected cases grouped by their values (in order of
    first appearance)."""
    others = varied_columns(view, exclude)
    out: dict[tuple, list[int]] = {}
    for i in range(view.shown.n):
        out.setdefault(tuple(_key(view.shown.columns[n][i]) for n in others), []).append(i)
    return others, out


def metric(view: View, request: PlotRequest) -> Figure:
    """A per-case value against a numeric column, one line per group of the others."""
    xname = request.x or _default_x(view)
    yname = request.y or "separation_deg_per_rev"
    x = _finite_axis(view, xname, "--x")
    y = column_values(view, yname, "--y").copy()
    y[~_usable(view)] = np.nan
    others, grouped = groups(view, [xname])
    fig = Figure(figsize=(7.5, 4.8), layout="constrained")
    ax = fig.add_subplot()
    styles = line_styles(len(grouped))
    for style, members in zip(styles, grouped.values(), strict=True):
        idx = np.array(members)
        idx = idx[np.argsort(x[idx], kind="stable")]
        first = idx[0]
        text = ", ".join(
            describe(n, view.shown.columns[n][first], view.shown.units.get(n, "")) for n in others
        )
        ax.plot(x[idx], y[idx], label=text or "all cases", **style.kwargs())
    ringed = _mark_unsettled(ax, view, x, y, yname)
    ringed |= _mark_no_impact(ax, x, y, yname)
    units = view.shown.units.get(yname, "")
    for k, limit in enumerate(request.limit):
        at = shown_value(limit, view, yname, "--limit")
        ax.axhline(
            at,
            color="black",
            linestyle=(0, (6, 3)),
            linewidth=1.3,
            zorder=1,
            label=f"limit {at:g} {SHORT_UNITS.get(units, units)}".rstrip(),
            gid=f"limit-{k}",
        )
    ax.set_xlabel(axis_label(xname, view.shown.units.get(xname, "")))
    ax.set_ylabel(axis_label(yname, units))
    ax.grid(alpha=0.3)
    if others or ringed or request.limit:
        ax.legend(fontsize=8, loc="best")
    set_title(fig, view, f"{axis_words(yname)} against {axis_words(xname).lower()}", request.where)
    return fig


def _mark_unsettled(ax, view: View, x: np.ndarray, y: np.ndarray, yname: str) -> bool:
    """Ring the cases of a run of automatic length that did not repeat within its cap: their
    values are statistics over a window (mean per turn, largest), not a settled response's;
    a mean with its standard error (``<yname>_uncertainty``) as a bar of ± 1 of it."""
    period = view.stored.columns.get("period_turns")
    never = np.zeros(x.size, bool) if period is None else np.asarray(period) == 0
    error = view.shown.columns.get(yname + UNCERTAINTY)
    if never.any() and error is not None:
        ax.errorbar(x[never], y[never], yerr=error[never], fmt="none", ecolor="black",
                    elinewidth=1.0, capsize=3, zorder=4, gid="uncertainty")  # fmt: skip
    if never.any():
        ax.scatter(
            x[never],
            y[never],
            s=90,
            facecolors="none",
            edgecolors="black",
            linewidths=1.0,
            zorder=4,
            label="did not repeat: statistics over its window"
            + (" (bar: ± standard error)" if error is not None else ""),
        )
    return bool(never.any())


def _mark_no_impact(ax, x: np.ndarray, y: np.ndarray, yname: str) -> bool:
    """Mark at 0, apart from the line, the cases with no impact of the kind ``yname``
    measures (its value none: ``tables.OF_IMPACTS``), which the line leaves out: a valve that
    never seats has no seating velocity, and a line through 0 would read as a soft landing."""
    none = np.isneginf(y) if yname in OF_IMPACTS else np.zeros(x.size, bool)
    if none.any():
        what = "seat" if OF_IMPACTS[yname] == "seat_impacts" else "cam"
        ax.scatter(x[none], np.zeros(int(none.sum())), marker="x", s=60, color="black",
                   zorder=4, label=f"no {what} impact (none), drawn at 0",
                   gid="no-impact")  # fmt: skip
    return bool(none.any())


# -- map over two axes -------------------------------------------------------------------------


def _edges(centers: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres: midway between neighbours, half a step outside."""
    if centers.size == 1:
        return np.array([centers[0] - 0.5, centers[0] + 0.5])
    mid = (centers[1:] + centers[:-1]) / 2
    return np.concatenate([[2 * centers[0] - mid[0]], mid, [2 * centers[-1] - mid[-1]]])


def _level(request: PlotRequest, view: View, zname: str) -> float | None:
    """The contour's level in z's shown units: a number as it is, a quantity converted."""
    if request.level is None:
        return None
    return shown_value(request.level, view, zname, "--level")


def cell_map(view: View, request: PlotRequest) -> Figure:
    """A per-case value (z) over two numeric columns as coloured cells, its contour at the
    level; one panel per group of the other varied columns."""
    xname = request.x or _default_x(view)
    yname = request.y
    if yname is None:
        numeric = [
            n
            for n in varied_columns(view, [xname])
            if view.shown.columns[n].dtype.kind in "iuf"
            and np.isfinite(view.shown.columns[n].astype(float)).all()
        ]
        if not numeric:
            raise PlotError.at("--y", "no second numeric column varies; name one with --y")
        yname = numeric[0]
    zname = request.z or "separation_deg_per_rev"
    x = _finite_axis(view, xname, "--x")
    y = _finite_axis(view, yname, "--y")
    z = column_values(view, zname, "--z").copy()
    z[~_usable(view)] = np.nan
    level = _level(request, view, zname)
    others, grouped = groups(view, [xname, yname])
    if len(grouped) > MAX_PANELS:
        raise PlotError.at(
            "--where",
            f"{len(grouped)} panels (one per {', '.join(others)}); at most {MAX_PANELS}: "
            "select fewer cases",
        )
    xs, ys = np.unique(x), np.unique(y)
    ncols = min(len(grouped), 3)
    nrows = -(-len(grouped) // ncols)
    fig = Figure(figsize=(4.2 * ncols + 1.2, 3.6 * nrows + 0.8), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).ravel()
    norm = colour_norm(z)
    mesh = None
    for ax, (key, members) in zip(axes, grouped.items(), strict=False):
        grid = np.full((ys.size, xs.size), np.nan)
        filled = np.zeros(grid.shape, bool)
        for i in members:
            iy, ix = np.searchsorted(ys, y[i]), np.searchsorted(xs, x[i])
            if filled[iy, ix]:
                raise PlotError.at(
                    "--where",
                    f"two cases at {xname} {x[i]:g}, {yname} {y[i]:g}: select one per cell",
                )
            grid[iy, ix], filled[iy, ix] = z[i], True
        mesh = ax.pcolormesh(
            _edges(xs), _edges(ys), np.ma.masked_invalid(grid), cmap=COLORMAP, norm=norm
        )
        if level is not None and xs.size > 1 and ys.size > 1 and np.isfinite(grid).any():
            lo, hi = np.nanmin(grid), np.nanmax(grid)
            if lo < level < hi:
                contour = ax.contour(xs, ys, grid, levels=[level], colors="black", linewidths=1.6)
                ax.clabel(contour, fmt=lambda v: f"{v:g}", fontsize=8)
        ax.set_title(
            ", ".join(
                describe(n, v, view.shown.units.get(n, ""))
                for n, v in zip(others, key, strict=True)
            )
            or "all cases",
            fontsize=10,
        )
    for ax in axes[len(grouped) :]:
        ax.set_visible(False)
    for ax in axes[: len(grouped)]:
        ax.set_xlabel(axis_label(xname, view.shown.units.get(xname, "")))
        ax.set_ylabel(axis_label(yname, view.shown.units.get(yname, "")))
    assert mesh is not None
    bar = fig.colorbar(mesh, ax=list(axes[: len(grouped)]))
    bar.set_label(axis_label(zname, view.shown.units.get(zname, "")))
    what = f"{zname} over {xname} and {yname}"
    if level is not None:
        what += f", contour at {level:g} {view.shown.units.get(zname, '')}".rstrip()
        bar.ax.axhline(level, color="black", linewidth=1.6)
    set_title(fig, view, what, request.where)
    return fig


# -- events ------------------------------------------------------------------------------------


def events(view: View, request: PlotRequest) -> Figure:
    """Each selected case's events on a cam angle × case chart."""
    n = view.stored.n
    if n > MAX_ROWS:
        raise PlotError.at(
            "--where", f"selects {n} cases; an events chart shows at most {MAX_ROWS}"
        )
    labels = case_labels(view, varied_columns(view))
    cam_angle = np.asarray(view.ds["cam_angle"].values, dtype=float)
    keep, turn_note = _turn_mask(cam_angle, check_turn(request.turn) if request.turn else None)
    # one turn chosen: its angles read 0–360°
    axis = angle_axis(view, request, float(cam_angle[keep][0]) if turn_note else 0.0)
    keep &= axis.within(cam_angle, request.range)
    lo, hi = float(cam_angle[keep][0]), float(cam_angle[keep][-1])
    fig = Figure(figsize=(9, 1.2 + 0.32 * n + 0.8), layout="constrained")
    ax = fig.add_subplot()
    per_case = _events_of(view)
    for kind, (marker, filled, text) in EVENT_MARKERS.items():
        xs, ys = [], []
        for i, ev in enumerate(per_case):
            at = ev["angle"][(ev["kind"] == kind) & (ev["angle"] >= lo) & (ev["angle"] <= hi)]
            xs.append(axis.shown(at))
            ys.append(np.full(at.size, i))
        x = np.concatenate(xs) if xs else np.zeros(0)
        if x.size == 0:
            continue
        ax.scatter(
            x,
            np.concatenate(ys),
            marker=marker,
            s=36,
            facecolors="black" if filled else "white",
            edgecolors="black",
            linewidths=1.0,
            label=text,
            zorder=3,
        )
    for turn in np.arange(math.ceil(lo / 360.0), math.floor(hi / 360.0) + 1) * 360.0:
        ax.axvline(float(axis.shown(turn)), color="0.6", linewidth=0.8, zorder=1)
    ax.set_yticks(np.arange(n), labels, fontsize=8)
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_xlim(*axis.shown(np.array([lo, hi])))
    ax.set_xlabel(axis_label(axis.name, "degree"))
    ax.grid(axis="y", alpha=0.3)
    if ax.collections:
        fig.legend(loc="outside lower center", ncols=4, fontsize=8)
    set_title(fig, view, f"events{turn_note}", request.where)
    return fig
