"""``campipe plot pareto``: a ``campipe design`` file's two objectives and its Pareto front.
Pure: an archive's dataset in, a matplotlib Figure out."""

from __future__ import annotations

import json

import numpy as np
from matplotlib.figure import Figure

from campipe.plot.figures import View, column_values, select_view, set_title
from campipe.plot.style import axis_label
from campipe.study.spec.plots import PlotError, PlotRequest


def pareto_figure(ds, request: PlotRequest) -> Figure:
    """The figure of ``request`` (kind ``pareto``) from the design file ``ds``."""
    return pareto(select_view(ds, request), request)


def pareto(view: View, request: PlotRequest) -> Figure:
    """A design file's two objectives (``--x``, ``--y``; default its
    ``design_objective_columns``): the designs evaluated, hollow where they fail a
    requirement, filled where they meet them, the front (``chosen == "front"``) joined."""
    names = json.loads(str(view.ds.attrs.get("design_objective_columns", "[]")))
    if "chosen" not in view.shown.columns or len(names) != 2 and not (request.x and request.y):
        raise PlotError.at(
            "ARCHIVE",
            "not the file of a campipe design with two objectives (minimize and maximize, or "
            "a list of two); give --x and --y to draw two columns of a design file",
        )
    xname = request.x or names[0]
    yname = request.y or names[1]
    x, y = column_values(view, xname, "--x"), column_values(view, yname, "--y")
    chosen = view.shown.columns["chosen"]
    feasible = view.shown.columns.get("feasible", np.full(view.shown.n, "yes")) == "yes"
    front = np.flatnonzero(chosen == "front")
    front = front[np.argsort(x[front], kind="stable")]
    fig = Figure(figsize=(7.5, 4.8), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(x[~feasible], y[~feasible], "o", mfc="none", color="0.6", label="fails a requirement")
    ax.plot(x[feasible], y[feasible], "o", color="0.35", ms=4, label="meets the requirements")
    if front.size:
        ax.plot(x[front], y[front], "s-", color="black", ms=5, label="Pareto front")
    ax.set_xlabel(axis_label(xname, view.shown.units.get(xname, "")))
    ax.set_ylabel(axis_label(yname, view.shown.units.get(yname, "")))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    set_title(fig, view, f"{front.size} designs on the Pareto front", request.where)
    return fig
