"""The separation onset: the first swept speed at which the follower leaves the cam, per group.

    python examples/onset_speed.py studies/quickstart.nc -o onset.png

For each combination of the study's varied keys other than the speed (for the quickstart, the
seat; grouped as in ``separation_vs_speed.py``), the lowest speed with
``separation_deg_per_rev > 0``: what ``campipe query --summary`` prints, here with xarray and
numpy. Printed as a table and drawn one marker per group: a circle at the onset, a downward
triangle at the lowest speed where the follower is already off the cam there ("at or below"),
a cross at the highest where it never leaves ("none up to").

This reads the onset off the sweep's grid, so it is only as fine as the grid: ``campipe onset
SPEC`` finds it to 0.1 rpm on the steady state, without the sweep.
"""

from __future__ import annotations

import argparse

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from separation_vs_speed import groups  # the grouping by the other varied keys, beside this file

#: How an onset was found: its marker in the plot and its words in the table.
FOUND, BELOW, NONE = "o", "v", "x"
WORDS = {FOUND: "", BELOW: "at or below ", NONE: "none up to "}


def onsets(ds: xr.Dataset) -> dict[str, tuple[float, str]]:
    """Per group of the other varied keys: (speed [rpm], how it was found)."""
    speed = ds.speed_rpm.values
    off = ds.separation_deg_per_rev.values > 0
    out = {}
    for key, cases in groups(ds).items():  # each group's cases in order of speed
        hit = np.flatnonzero(off[cases])
        if hit.size == 0:
            out[key] = (float(speed[cases[-1]]), NONE)
        else:
            out[key] = (float(speed[cases[hit[0]]]), BELOW if hit[0] == 0 else FOUND)
    return out


def plot(ds: xr.Dataset):
    """The figure: one marker (a line of one point) per group."""
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    found = onsets(ds)
    for x, (speed, how) in enumerate(found.values()):
        ax.plot([x], [speed], how, ms=9, label=f"{WORDS[how]}{speed:g} rpm")
    ax.set_xticks(range(len(found)), list(found), fontsize=8)
    ax.set_xlim(-0.5, len(found) - 0.5)
    ax.set_ylabel("separation onset [rpm]")
    ax.set_title(ds.attrs.get("study_name", ""))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("archive", help="a campipe archive (.nc) whose study sweeps the speed")
    parser.add_argument("-o", "--output", default="onset.png", help="the PNG to write")
    args = parser.parse_args(argv)
    with xr.open_dataset(args.archive) as ds:
        ds = ds.load()
    for key, (speed, how) in onsets(ds).items():
        print(f"{key}: {WORDS[how]}{speed:g} rpm")
    fig = plot(ds)
    fig.savefig(args.output, dpi=110)
    print(args.output)
    return fig


if __name__ == "__main__":
    main()
