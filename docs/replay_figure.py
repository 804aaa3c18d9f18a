"""Draw a PNG of a replay from its recording: the picture of a bouncing case in the README and
docs/replay.md.

The viewer needs a GPU, so the docs show this instead: the same recorded data read back
with ``rerun.chunk.RrdReader`` (:func:`campipe.io.rerun_replay.read_recording`) and drawn with
matplotlib (``pip install 'campipe[plot]'``): the mechanism sketch at a few cam angles beside
the lift, force and contact-state plots, with the events marked.

    campipe study studies/quickstart.yaml -o /tmp/quickstart.nc --set run.record=[q] \
        --set run.revolutions=3
    campipe replay /tmp/quickstart.nc --where "speed_rpm == 11000 and seat > 0" -o /tmp/b.rrd
    python docs/replay_figure.py /tmp/b.rrd -o docs/replay-bouncing.png \
        --angle 770 --angle 793 --angle 825 --angle 862

(three fixed turns, all recorded: a run of automatic length records its last turn only)
"""

from __future__ import annotations

import argparse

import numpy as np

from campipe.io.rerun_replay import NANOS, read_recording

PARTS = ("cam", "pushrod", "rocker", "stem", "head", "spring", "retainer")


def _unit(rec, entity: str) -> str:
    """The units a recorded series is in, from its name (``cam lift [in]``)."""
    name = rec[entity].static["SeriesLines:names"][0]
    return name[name.rfind("[") + 1 : name.rfind("]")] if name.endswith("]") else ""


def _rgb(packed: int) -> tuple[float, float, float]:
    return tuple(((packed >> s) & 0xFF) / 255 for s in (24, 16, 8))


def draw(
    path: str, output: str, case: str | None = None, angles: list[float] | None = None
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rec = read_recording(path)
    cases = sorted({k.split("/")[1] for k in rec if k.startswith("cases/")})
    case = case or cases[0]
    root = f"cases/{case}"
    angle = rec[f"{root}/lift/cam"].times["cam_angle"] / NANOS
    lift = {n: rec[f"{root}/lift/{n}"].scalars() for n in ("cam", "follower", "valve")}
    events = rec.get(f"{root}/events")
    if angles is None:
        last = angle >= angle[-1] - 360.0
        gap = np.where(last, lift["follower"] - lift["cam"], -np.inf)
        top = angle[np.argmax(gap)]
        angles = [top - 90.0, top, top + 90.0]
    fig = plt.figure(figsize=(15, 8), layout="constrained")
    grid = fig.add_gridspec(3, 2 + len(angles), width_ratios=[1] * len(angles) + [2.2, 2.2])
    rows = [int(np.argmin(np.abs(angle - a))) for a in angles]
    strips = {part: rec[f"{root}/sketch/{part}"].columns["LineStrips2D:strips"] for part in PARTS}
    drawn = np.concatenate(
        [np.asarray(s).reshape(-1, 2) for part in PARTS for i in rows for s in strips[part][i]]
    )
    low, high = drawn.min(axis=0) - 10.0, drawn.max(axis=0) + 10.0
    for k, i in enumerate(rows):
        ax = fig.add_subplot(grid[:, k])
        for part in PARTS:
            e = rec[f"{root}/sketch/{part}"]
            colours = e.static.get("LineStrips2D:colors", [0])
            widths = e.static.get("LineStrips2D:radii", [0.5])
            for j, strip in enumerate(e.columns["LineStrips2D:strips"][i]):
                xy = np.asarray(strip)
                ax.plot(
                    xy[:, 0],
                    xy[:, 1],
                    color=_rgb(colours[min(j, len(colours) - 1)]),
                    lw=max(1.0, 1.2 * widths[min(j, len(widths) - 1)]),
                    solid_capstyle="butt",
                )
        for name in ("pivot", "ground", "spring_plate"):
            xy = np.asarray(rec[f"{root}/sketch/frame/{name}"].static["LineStrips2D:strips"][0])
            ax.plot(xy[:, 0], xy[:, 1], color="0.35", lw=1.2)
        seat = rec.get(f"{root}/sketch/frame/seat")
        if seat is not None:
            for c, h in zip(
                seat.static["Boxes2D:centers"], seat.static["Boxes2D:half_sizes"], strict=True
            ):
                ax.add_patch(
                    plt.Rectangle(
                        (c[0] - h[0], c[1] - h[1]),
                        2 * h[0],
                        2 * h[1],
                        color=_rgb(seat.static["Boxes2D:colors"][0]),
                    )
                )
        for marker in ("follower", "valve"):
            e = rec.get(f"{root}/sketch/{marker}")
            if e is not None:
                xy = e.columns["Points2D:positions"][i][0]
                ax.plot(*xy, "o", ms=7, color=_rgb(e.columns["Points2D:colors"][i][0]))
        ax.set_aspect("equal")
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_title(f"{angle[i]:.0f}°", fontsize=11)
        ax.tick_params(labelsize=8)
        if k == 0:
            ax.set_ylabel("mm")
    label = rec[f"{root}/sketch/frame/note"].static["Points2D:labels"][0]
    fig.text(0.01, 0.005, f"sketch: {label}; dots green in contact, red off it", fontsize=9)
    axes = [fig.add_subplot(grid[r, len(angles) :]) for r in range(3)]
    for n, colour in (("cam", "0.6"), ("follower", "C0"), ("valve", "C2")):
        axes[0].plot(
            angle,
            lift[n],
            color=colour,
            lw=1.2,
            label=rec[f"{root}/lift/{n}"].static["SeriesLines:names"][0],
        )
    for n in ("cam", "seat"):
        e = rec[f"{root}/force/{n}"]
        axes[1].plot(angle, e.scalars(), lw=1.0, label=e.static["SeriesLines:names"][0])
    e = rec[f"{root}/contact_state"]
    axes[2].step(angle, e.scalars(), where="post", color="0.2", lw=1.0)
    axes[2].set_yticks([1, 2, 3, 4], ["I cam", "II free", "III both", "IV seat"])
    if events is not None:
        at = events.times["cam_angle"] / NANOS
        text = [t[0] for t in events.columns["TextLog:text"]]
        for a, t in zip(at, text, strict=True):
            if "impact" in t:
                axes[0].axvline(a, color="C3" if "seat" in t else "C1", lw=0.6, alpha=0.6)
        axes[0].plot([], [], color="C1", lw=0.6, label="cam impact")
        axes[0].plot([], [], color="C3", lw=0.6, label="seat impact")
    for a in angles:
        for ax in axes:
            ax.axvline(a, color="k", ls=":", lw=0.8)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].legend(fontsize=8, loc="upper right")
    axes[0].set_ylabel(f"lift [{_unit(rec, f'{root}/lift/cam')}]")  # the recording's units
    axes[1].set_ylabel(f"force [{_unit(rec, f'{root}/force/cam')}]")
    axes[2].set_xlabel("cam angle [°] (the recording's cam_angle timeline)")
    doc = rec[f"{root}/parameters"].static["TextDocument:text"][0]
    fig.suptitle(f"campipe replay: {doc.splitlines()[0].lstrip('# ')}", fontsize=12)
    fig.savefig(output, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording")
    parser.add_argument("-o", "--output", default="replay.png")
    parser.add_argument("--case", help="case id (default: the recording's first)")
    parser.add_argument(
        "--angle", type=float, action="append", help="cam angle of a sketch [degree] (repeatable)"
    )
    args = parser.parse_args()
    draw(args.recording, args.output, args.case, args.angle)


if __name__ == "__main__":
    main()
