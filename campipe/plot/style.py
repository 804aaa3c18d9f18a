"""Lines, markers and labels of campipe's figures: every case distinct in grey, not only in
colour (a figure is often printed or copied in black and white)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.colors import Normalize, SymLogNorm

from campipe.vocabulary import CAM_IMPACT, CAM_SEPARATION, SEAT_IMPACT, SEAT_SEPARATION

#: Line styles and markers cycled together: 4 × 7 = 28 distinct pairs before one repeats.
LINESTYLES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "D", "v", "P", "X")
#: A sequential colour map whose lightness rises monotonically (it reads as a grey ramp).
COLORMAP = "cividis"
#: A map's positive values spanning more decades than this get a logarithmic colour scale.
SPAN_DECADES = 2
#: Each event kind's marker and whether it is filled: shape and fill tell them apart in grey.
EVENT_MARKERS = {
    CAM_SEPARATION: ("^", False, "cam separation"),
    CAM_IMPACT: ("v", True, "cam impact"),
    SEAT_SEPARATION: ("s", False, "seat separation"),
    SEAT_IMPACT: ("o", True, "seat impact"),
}


@dataclass(frozen=True)
class LineStyle:
    """How one case or group is drawn."""

    color: tuple[float, float, float, float]  # RGBA
    linestyle: str
    marker: str

    def kwargs(self, samples: int = 0) -> dict[str, Any]:
        """Keyword arguments of ``Axes.plot``; on a long history, markers about every
        twelfth of its length (so the marker, not only the colour, names the line)."""
        out: dict[str, Any] = {
            "color": self.color,
            "linestyle": self.linestyle,
            "marker": self.marker,
            "markersize": 4,
            "markerfacecolor": "white",
        }
        if samples > 24:
            out["markevery"] = max(samples // 12, 1)
        return out


def line_styles(n: int) -> list[LineStyle]:
    """``n`` styles, each a distinct (line style, marker) pair and a step darker to lighter
    along the colour map (kept off its palest end, which vanishes on white)."""
    from matplotlib import colormaps

    cmap = colormaps[COLORMAP]
    shades = np.linspace(0.0, 0.8, n) if n > 1 else np.array([0.0])
    return [
        LineStyle(
            tuple(float(c) for c in cmap(float(shade))),  # type: ignore[arg-type]
            LINESTYLES[i % len(LINESTYLES)],
            MARKERS[(i + i // len(LINESTYLES)) % len(MARKERS)],
        )
        for i, shade in enumerate(shades)
    ]


#: A figure's words for the per-case columns that are not metrics (a metric's are its
#: ``label`` in :data:`campipe.engine.metrics.METRICS`).
WORDS = {
    "speed_rpm": "Cam speed",
    "engine_speed_rpm": "Engine speed",
    "seat": "Seat (valve lift)",
    "cam_angle": "Cam angle",
    "crank_angle": "Crank angle",
    "spring_preload": "Spring preload",
    "spring_rate": "Spring rate",
}
#: Units as a figure writes them.
SHORT_UNITS = {"degree": "deg", "1": "", "": ""}


def axis_words(name: str) -> str:
    """A figure's words for a column, without its units (``No-follow``, ``Cam speed``)."""
    return axis_label(name, "").split(" [")[0]


def axis_label(name: str, units: str) -> str:
    """A figure's label for a column: words with units, a metric's mean over turns per turn
    (``No-follow [deg/turn]``, ``Cam impacts [per turn]``, ``Cam speed [rpm]``)."""
    from campipe.engine.metrics import METRICS

    metric = next((m for m in METRICS if name in (m.summary, m.per_rev)), None)
    shown = SHORT_UNITS.get(units, units)
    if metric is None:
        words = WORDS.get(name, name.replace("_", " ").capitalize())
        return f"{words} [{shown}]" if shown else words
    words = metric.label or metric.description.split(":")[0].capitalize()
    if metric.summary_of_turns == "mean" and name == metric.summary:
        shown = f"{shown}/turn" if shown else "per turn"
    return f"{words} [{shown}]" if shown else words


def colour_norm(values: np.ndarray) -> Normalize:
    """The map's colour scale: linear, or where the values are not negative and the positive
    ones span more than SPAN_DECADES decades (no-follow from thousandths of a degree a turn to
    tens) logarithmic above the least positive value and linear below it, so small values
    read apart from zero and from each other."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return Normalize(0.0, 1.0)
    lo, hi = float(finite.min()), float(finite.max())
    positive = finite[finite > 0.0]
    if lo >= 0.0 and positive.size and hi > 10.0**SPAN_DECADES * float(positive.min()):
        return SymLogNorm(float(positive.min()), vmin=lo, vmax=hi, base=10)
    return Normalize(lo, hi)
