"""Separation against cam speed: one line per combination of the study's other varied keys.

    python examples/separation_vs_speed.py studies/quickstart.nc -o separation.png

Plots ``separation_deg_per_rev`` (the cam angle the follower spends off the cam in the last
turn, in degrees) against ``speed_rpm`` for an archive whose study sweeps the speed. The cases
are grouped by the other keys the study varies (``study_axes``: for the quickstart, the seat),
one line per group, in the order the study lists them.
"""

from __future__ import annotations

import argparse
import json

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr


def label(ds: xr.Dataset, name: str, i: int) -> str:
    """``name = value unit`` of case ``i`` (-inf: none, the archive's missing seat)."""
    value = ds[name].values[i]
    if isinstance(value, float | np.floating) and np.isneginf(value):
        return f"{name} none"
    unit = ds[name].attrs.get("units", "")
    text = f"{value:g}" if isinstance(value, float | np.floating) else str(value)
    return f"{name} {text} {unit}".rstrip()


def groups(ds: xr.Dataset) -> dict[str, np.ndarray]:
    """Case indices by the varied keys other than the speed, each group sorted by speed."""
    others = [a["name"] for a in json.loads(ds.attrs["study_axes"]) if a["name"] != "speed_rpm"]
    out: dict[str, list[int]] = {}
    for i in range(ds.sizes["case"]):
        key = ", ".join(label(ds, name, i) for name in others) or "all cases"
        out.setdefault(key, []).append(i)
    speed = ds.speed_rpm.values
    return {k: np.array(sorted(v, key=lambda i: speed[i])) for k, v in out.items()}


def plot(ds: xr.Dataset):
    """The figure: one line per group."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for key, cases in groups(ds).items():
        ax.plot(
            ds.speed_rpm.values[cases],
            ds.separation_deg_per_rev.values[cases],
            "o-",
            label=key,
        )
    ax.set_xlabel("cam speed [rpm]")
    ax.set_ylabel("off the cam [deg per turn, last turn]")
    ax.set_title(ds.attrs.get("study_name", ""))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("archive", help="a campipe archive (.nc) whose study sweeps the speed")
    parser.add_argument("-o", "--output", default="separation.png", help="the PNG to write")
    args = parser.parse_args(argv)
    with xr.open_dataset(args.archive) as ds:
        fig = plot(ds.load())
    fig.savefig(args.output, dpi=110)
    print(args.output)
    return fig


if __name__ == "__main__":
    main()
