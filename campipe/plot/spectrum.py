"""``campipe plot spectrum``: the order spectrum of a history over a settled turn.

A turn's samples of a history (valve acceleration by default, or any history the archive
records, e.g. ``spring_force``), one turn of the cam long and evenly spaced, are a periodic
signal of the cam's order: its discrete Fourier transform gives the amplitude of each order
(harmonic of the cam's rotation), k·(cam speed) in frequency. The turn is the run's last
(with an automatic length, the settled window's last turn: its response repeats). Pure:
arrays in, a matplotlib Figure out.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from campipe.plot.figures import (
    MAX_OVERLAID,
    View,
    case_labels,
    select_view,
    set_title,
    varied_columns,
)
from campipe.plot.style import axis_label, line_styles
from campipe.study.query.display import to_display
from campipe.study.spec.plots import PlotError, PlotRequest
from campipe.units import degree_speed

#: The history drawn without --y, and the orders shown (at most half a turn's samples).
DEFAULT_HISTORY = "valve_acceleration"
MAX_ORDER = 40
#: A history's dimensions in the archive.
HISTORY_DIMS = ("case", "cam_angle")


def order_spectrum(turn: np.ndarray) -> np.ndarray:
    """(n, N//2 + 1) the amplitude of each order 0 … N//2 of ``turn`` (n, N), N evenly
    spaced samples of one turn (its end left out): the mean at order 0, the one-sided
    amplitude |X_k|·2/N above (a cosine of amplitude A at order k gives A)."""
    n_samples = turn.shape[-1]
    amplitude = np.abs(np.fft.rfft(turn, axis=-1)) * (2.0 / n_samples)
    amplitude[..., 0] /= 2.0
    if n_samples % 2 == 0:
        amplitude[..., -1] /= 2.0  # the Nyquist order, counted once
    return amplitude


def last_turn(cam_angle: np.ndarray) -> np.ndarray:
    """(N,) indices of the last whole turn's samples, its first angle included and the
    angle a turn later left out (the same point of the next turn)."""
    end = float(cam_angle[-1])
    keep = np.flatnonzero((cam_angle > end - 360.0 + 1e-9) & (cam_angle <= end + 1e-9))
    if keep.size < 4 or end < 360.0 - 1e-9:
        raise PlotError.at("kind", "a spectrum needs a whole turn of samples; the run has less")
    return keep


def spectrum_figure(ds, request: PlotRequest) -> Figure:
    """The order spectrum of ``request.y`` (a history; default valve acceleration) over the
    last recorded turn of each selected case, overlaid."""
    view = select_view(ds, request)
    name = request.y or DEFAULT_HISTORY
    var = view.ds.variables.get(name)
    if var is None or var.dims != HISTORY_DIMS:
        histories = sorted(k for k, v in view.ds.variables.items() if v.dims == HISTORY_DIMS)
        raise PlotError.at(
            "--y", f"found {name!r}, expected a history of the archive: {', '.join(histories)}"
        )
    return _draw(view, name, request.where)


def _draw(view: View, name: str, where: str | None) -> Figure:
    n = view.stored.n
    if n > MAX_OVERLAID:
        raise PlotError.at("--where", f"selects {n} cases; overlay at most {MAX_OVERLAID}")
    ds = view.ds
    keep = last_turn(np.asarray(ds["cam_angle"].values, float))
    units = view.units.get(name, "")
    values = to_display(
        np.asarray(ds[name].values[view.rows][:, keep], float),
        str(ds[name].attrs.get("units", "")),
        units,
        view.stored.columns.get(degree_speed([units])),
    )
    amplitude = order_spectrum(values)
    orders = np.arange(amplitude.shape[1])
    shown = orders <= MAX_ORDER
    fig = Figure(figsize=(9, 4.2), layout="constrained")
    ax = fig.subplots()
    styles = line_styles(n)
    labels = case_labels(view, varied_columns(view))
    width = 0.8 / n
    for i in range(n):
        x = orders[shown][1:] + (i - (n - 1) / 2) * width
        ax.bar(x, amplitude[i, shown][1:], width=width, label=labels[i],
               color=styles[i].kwargs().get("color"))  # fmt: skip
    ax.set_xlabel("Order of the cam's rotation [-]")
    ax.set_ylabel(axis_label(name, units) + " amplitude")
    set_title(fig, view, f"order spectrum of {name.replace('_', ' ')}, last turn", where)
    ax.grid(alpha=0.3, axis="y")
    if n > 1 or labels[0]:
        ax.legend(fontsize=8)
    return fig
