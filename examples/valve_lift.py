"""Valve lift against cam angle, the chosen cases overlaid.

    python examples/valve_lift.py studies/quickstart.nc --where "speed_rpm == 11000" -o lift.png

Chooses cases with campipe's query language (``campipe query --where``: comparisons of the
archive's per-case columns joined by ``and``, ``or``, ``not``; never run as Python) and draws
each one's valve lift [mm] against the cam angle [deg] over every turn the archive holds.
"""

from __future__ import annotations

import argparse

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from campipe.study.query.tables import case_table, select


def chosen(ds: xr.Dataset, where: str | None) -> np.ndarray:
    """Indices of the cases ``where`` selects (all without it), in the archive's order."""
    return np.sort(select(case_table(ds), where))


def plot(ds: xr.Dataset, cases: np.ndarray):
    """The figure: one line per chosen case."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    angle = ds.cam_angle.values
    for i in cases:
        seat = ds.seat.values[i]
        where = "no seat" if np.isneginf(seat) else f"seat {seat * 1e3:g} mm"
        ax.plot(
            angle,
            ds.valve_lift.values[i] * 1e3,
            lw=1,
            label=f"{ds.speed_rpm.values[i]:g} rpm, {where}",
        )
    ax.set_xlabel("cam angle [deg]")
    ax.set_ylabel("valve lift [mm]")
    ax.set_title(f"{ds.attrs.get('study_name', '')}: {len(cases)} cases")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("archive", help="a campipe archive (.nc)")
    parser.add_argument("--where", help='e.g. "speed_rpm >= 9524 and seat is none"')
    parser.add_argument("-o", "--output", default="lift.png", help="the PNG to write")
    args = parser.parse_args(argv)
    with xr.open_dataset(args.archive) as ds:
        ds = ds.load()
    cases = chosen(ds, args.where)
    if cases.size == 0:
        parser.error(f"--where {args.where!r} selects no case")
    fig = plot(ds, cases)
    fig.savefig(args.output, dpi=110)
    print(args.output)
    return fig


if __name__ == "__main__":
    main()
