"""The bench's files: a markdown report, the rows as CSV, everything as JSON, and PNG plots of
wall time against the valve-lift error and against the event errors (separation angle, seating
velocity); :func:`read_json` reads a run back, :func:`with_previous` compares a run with the
previous one (``campipe.bench.gate``) before its json is overwritten. With
``campipe.bench.pages`` the only module of ``campipe.bench`` that writes files; matplotlib
(the ``plot`` extra) is imported only inside :func:`plot`.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from campipe.bench import cluster, gate, memory, settling, sweep, verdict
from campipe.bench.figures import finite
from campipe.bench.run import FAMILIES, Bench
from campipe.constants import INCH

#: File names written into the output folder.
FILES = {
    "markdown": "bench.md",
    "csv": "bench.csv",
    "json": "bench.json",
    "plot": "bench.png",
    "events_plot": "bench-events.png",
}
#: The errors each plot draws: (row key, axis label, factor from SI, floor in the axis's unit:
#: smaller errors are drawn at it, as a log axis has no zero).
VALVE_LIFT = ("valve_lift", "valve-lift max error [in]", 1 / INCH, 1e-14)
EVENT_ERRORS = (
    ("separation_angle", "separation-angle error [deg]", math.degrees(1.0), 1e-16),
    ("seating_velocity", "seating-velocity error [in/s]", 1 / INCH, 1e-14),
)
#: How a time-to-error was found, in words.
HOW = {
    "cheapest": "its cheapest point is already below",
    "interpolated": "interpolated",
    "extrapolated": "not reached in its ladder; extrapolated",
    "not reached": "not reached in its ladder",
}
#: Columns of the CSV and the markdown tables, with their units and conversion from SI.
COLUMNS = (
    ("scene", "", None),
    ("family", "", None),
    ("setting", "", None),
    ("seconds", "ms/case", 1e3),
    ("cost", "steps or f-evals", None),
    ("valve_lift", "valve err [in]", 1 / INCH),
    ("separation_angle", "sep. angle err [deg]", math.degrees(1.0)),
    ("separation", "sep./turn err [deg]", math.degrees(1.0)),
    ("seating_velocity", "seating vel. err [in/s]", 1 / INCH),
    ("event_angle", "event angle err [deg]", math.degrees(1.0)),
    ("impact_velocity", "cam impact vel. err [in/s]", 1 / INCH),
    ("events_match", "events match", None),
)


def _num(x, scale: float | None = None, fmt: str = ".3g") -> str:
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, float)):
        if isinstance(x, float) and math.isnan(x):
            return "–"
        if isinstance(x, float) and math.isinf(x):
            return "∞"
        return format(x * scale if scale else x, fmt)
    return str(x)


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return lines


def _section(title: str, block, data) -> list[str]:
    """A measurement's section: its title, its module's ``notes`` of ``data``, its table."""
    return [
        "",
        f"## {title}",
        "",
        *block.notes(data),
        "",
        *_table(block.HEADER, block.table_rows(data)),
    ]


def _clean(obj):
    """JSON-safe: NaN and inf become null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def _bounded(row: dict, name: str, scale: float) -> str:
    """A row's error, "≤" where the reference's resolution bounds it (``measure.resolved``)."""
    text = _num(row[name], scale, ".2e")
    return f"≤{text}" if name in row.get("at_resolution", ()) else text


def summary_rows(bench: Bench) -> list[list[str]]:
    """Per scene: the default, the steady fidelity, the default with only the contact
    coordinates sampled, the thesis algorithm at 1 µs and the solve_ivp peer's most accurate
    point, with time and errors."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in bench.rows):
        mine = [r for r in bench.rows if r["scene"] == scene]
        picks = [next((r for r in mine if r.get("default")), None)]
        steady = [r for r in mine if r["family"] == "steady"]
        picks.append(min(steady, key=lambda r: r["seconds"]) if steady else None)
        picks.append(
            next(
                (r for r in mine if r["family"] == "contacts only" and r["setting"] == "full"), None
            )
        )
        picks.append(next((r for r in mine if r.get("thesis")), None))
        ivp = [r for r in mine if r["family"] == "solve_ivp"]
        picks.append(min(ivp, key=lambda r: r["valve_lift"]) if ivp else None)
        for r in picks:
            if r is None:
                continue
            name = "default (modal-exact)" if r.get("default") else r["family"]
            out.append(
                [
                    scene,
                    name,
                    r["setting"],
                    _num(r["seconds"], 1e3),
                    _bounded(r, "valve_lift", 1 / INCH),
                    _bounded(r, "separation_angle", math.degrees(1.0)),
                    _bounded(r, "seating_velocity", 1 / INCH),
                ]
            )
    return out


def markdown(bench: Bench, with_plots: bool = True) -> str:
    """The report as markdown."""
    m = bench.meta
    lines = [f"# campipe bench{' --quick' if bench.quick else ''}", ""]
    lines.append(
        f"{m['date']}; {m['machine']}, {m.get('processor', 'processor not recorded')}; "
        f"Python {m['python']}, numpy {m['numpy']}, "
        f"scipy {m['scipy']}, numba {m['numba']}; bench wall time "
        f"{bench.seconds:.0f} s; load average {m['load_average_at_start']:.2f} at "
        f"the start, {m.get('load_average_at_end', math.nan):.2f} at the end (other "
        "work on the machine slows the timings and the 2-worker runs)."
    )
    lines.append("")
    lines.append(
        f"Errors are against a converged reference computed in the same run: "
        f"{m['reference']}; output every {m['output_every_deg']:g} deg. Timing: "
        f"{m['timing']}."
    )
    lines.append("")
    if with_plots:
        lines += [
            f"![wall time against valve-lift error]({FILES['plot']})",
            "",
            f"![wall time against separation-angle and seating-velocity error]"
            f"({FILES['events_plot']})",
            "",
        ]
    lines += ["## Verdict", "", verdict.markdown(bench), ""]
    lines += ["## Against the previous run", "", gate.markdown(bench), ""]
    lines += ["## The reference, checked", ""]
    lines.append(
        f"Second reference: {m['reference_check']}. Stated agreement: valve lift "
        f"{m['agreement']['valve_lift'] / INCH:g} in, event angles "
        f"{math.degrees(m['agreement']['event_angle']):g} deg, separation per turn "
        f"{math.degrees(m['agreement']['separation']):g} deg, seating and impact "
        f"velocities {m['agreement']['seating_velocity'] / INCH:g} in/s."
    )
    lines.append("")
    lines += _table(
        [
            "scene",
            "agrees",
            "valve lift [in]",
            "event angles [deg]",
            "sep./turn [deg]",
            "seating vel. [in/s]",
            "impact vel. [in/s]",
            "check time [s]",
        ],
        [
            [
                c["scene"],
                _num(c["agrees"]) if c["events_match"] else "no (events differ)",
                _num(c["valve_lift"], 1 / INCH, ".2e"),
                _num(c["event_angle"], math.degrees(1.0), ".2e"),
                _num(c["separation"], math.degrees(1.0), ".2e"),
                _num(c["seating_velocity"], 1 / INCH, ".2e"),
                _num(c["impact_velocity"], 1 / INCH, ".2e"),
                _num(c["seconds"], fmt=".1f"),
            ]
            for c in bench.checks
        ],
    )
    lines += [
        "",
        "## Summary: default, steady fidelity, contacts only, thesis algorithm, solve_ivp",
        "",
    ]
    lines += _table(
        [
            "scene",
            "method",
            "setting",
            "ms/case",
            "valve err [in]",
            "sep. angle err [deg]",
            "seating vel. err [in/s]",
        ],
        summary_rows(bench),
    )
    lines += ["", "## Peers at equal valve-lift error", ""]
    lines.append(
        "Time ratio = peer time / campipe time for the same valve-lift error, "
        "interpolated on each method's time/error curve (log–log). *At the default's "
        "error* (the issue's ratio): the time the peer needs to reach the default's "
        "error. Where no point of its ladder reaches it, the measured figure is a "
        "lower bound, the time of its most accurate point (a finer setting is "
        "needed), and the estimate extrapolated along the slope of its last three "
        "points is given beside it. "
        "*At the peer's point*: the thesis algorithm at 1 µs, or solve_ivp's most "
        "accurate point, against the time campipe's default integrator (full "
        "fidelity, any tolerance or step cap of its ladder) needs for that error (its "
        "cheapest setting is an upper bound when it is already more accurate)."
    )
    lines.append("")

    def at_default(r: dict) -> list[str]:
        """Peer time, measured ratio and extrapolated ratio at the default's error."""
        bound = "" if r["peer_reaches_default_error"] else "> "
        how = "measured" if not bound else "not reached; its most accurate point"
        return [
            f"{bound}{_num(r['peer_seconds_at_default_error_measured'], 1e3)} ms ({how})",
            bound + _num(r["measured_ratio_at_default_error"], fmt=".3g"),
            "–" if not bound else _num(r["ratio_at_default_error"], fmt=".3g"),
        ]

    lines += _table(
        [
            "scene",
            "peer",
            "default ms/case",
            "default err [in]",
            "peer time at default err",
            "ratio",
            "ratio extrapolated",
            "peer point",
            "peer ms",
            "peer err [in]",
            "ratio at peer's error",
        ],
        [
            [
                r["scene"],
                r["peer"],
                _num(r["default_seconds"], 1e3),
                _num(r["default_error"], 1 / INCH, ".2e"),
                *at_default(r),
                r["peer_point"],
                _num(r["peer_point_seconds"], 1e3),
                _num(r["peer_point_error"], 1 / INCH, ".2e"),
                _num(r["ratio_at_peer_error"], fmt=".3g") + f" ({HOW[r['how_campipe']]})",
            ]
            for r in bench.ratios
        ],
    )
    ladders = [r for r in bench.ratios if r["peer"] == "newmark-linear" and r.get("ladder")]
    if ladders:
        lines += ["", "### The thesis algorithm at each step of its ladder", ""]
        lines.append(
            "newmark-linear's time at each step against the time campipe's default "
            "integrator needs for the same valve-lift error (as above)."
        )
        lines.append("")
        lines += _table(
            ["scene", "newmark step", "err [in]", "newmark ms", "campipe ms", "ratio"],
            [
                [
                    r["scene"],
                    p["setting"],
                    _num(p["error"], 1 / INCH, ".2e"),
                    _num(p["seconds"], 1e3),
                    _num(p["campipe_seconds"], 1e3) + f" ({HOW[p['how_campipe']]})",
                    _num(p["ratio"], fmt=".3g"),
                ]
                for r in ladders
                for p in r["ladder"]
            ],
        )
    for peer, g in bench.goals.items():
        below = g.get("goal_reached_below_error", {})
        if below:
            lines.append("")
            lines.append(
                f"≥ {g['goal']:g}× faster than {peer} at every point of its ladder with a "
                "valve-lift error up to: "
                + "; ".join(
                    f"{scene} {_num(e, 1 / INCH, '.1e')} in" if finite(e) else f"{scene} none"
                    for scene, e in below.items()
                )
                + "."
            )
    a = bench.accuracy_for_cost
    if a:
        lines += ["", "## Accuracy for cost on 11000 rpm", ""]
        cheapest = a["newmark_cheapest_meeting"]
        lines.append(
            f"- default: valve-lift error {a['default_error'] / INCH:.2e} in "
            f"({'below' if a['default_below_target'] else 'not below'} 1e-6 in) in "
            f"{a['default_seconds'] * 1e3:.3g} ms/case ({a['default_steps']} grid steps)."
        )
        lines.append(
            f"- newmark-linear for {a['newmark_target'] / INCH:g} in: "
            f"{_num(a['newmark_seconds_at_target'], 1e3)} ms/case ({HOW[a['how']]})"
            + (
                f"; cheapest ladder point meeting it: {cheapest['setting']}, "
                f"{cheapest['seconds'] * 1e3:.3g} ms/case, error {cheapest['error'] / INCH:.2e}"
                f" in, {cheapest['steps']} steps"
                if cheapest
                else "; no ladder point meets it"
            )
            + f". Ratio newmark/default: {_num(a['ratio'])}."
        )
        if a.get("contacts_only_seconds"):
            lines.append(
                f"- default sampling only the contact coordinates (what a study that records "
                f"no q or member loads runs): error {a['contacts_only_error'] / INCH:.2e} in "
                f"in {a['contacts_only_seconds'] * 1e3:.3g} ms/case. Ratio newmark/that: "
                f"{_num(a['ratio_contacts_only'])}."
            )
    if bench.sweep:
        lines += _section("The speed sweep: the default against the thesis's algorithm", sweep,
                          bench.sweep)  # fmt: skip
    if bench.throughput:
        lines += ["", "## Throughput: a 256-case batch", ""]
        lines += _table(
            [
                "integrator",
                "cases",
                "workers",
                "turns/case",
                "case-steps",
                "seconds",
                "case-steps/s",
            ],
            [
                [
                    t["integrator"],
                    str(t["n_cases"]),
                    str(t["workers"]),
                    _num(t["revolutions"]),
                    str(t["case_steps"]),
                    _num(t["seconds"], fmt=".3f"),
                    _num(t["rate"], fmt=".3g"),
                ]
                for t in bench.throughput
            ],
        )
        lines.append("")
        lines.append(
            "modal-exact counts its grid steps (output samples and event refinement), "
            "so its case-steps are not newmark-linear's; the goal (> 2e7 case-steps/s "
            "on 2 cores) is newmark-linear's."
        )
    lines += ["", "## Automatic run length", "", settling.markdown(bench.settling)]
    if bench.scaling:
        lines += ["", "## Scaling", ""]
        lines.append(
            "Default integrator, 2 turns per case, harmonic cam 6000–14000 rpm, "
            "alternately without and with a seat; the engine alone, batches of 32 as dask "
            "tasks on the threaded scheduler, nothing stored."
        )
        lines.append("")
        lines += _table(
            [
                "layer",
                "cases",
                "workers",
                "seconds",
                "ms/case",
                "archive [MB]",
                "archive/case [kB]",
            ],
            [
                [
                    p["layer"],
                    str(p["n_cases"]),
                    str(p["workers"]),
                    _num(p["seconds"], fmt=".3g"),
                    _num(p["per_case"], 1e3),
                    _num(p["archive_bytes"] / 1e6) if p["archive_bytes"] else "–",
                    _num(p["archive_bytes"] / p["n_cases"] / 1e3) if p["archive_bytes"] else "–",
                ]
                for p in bench.scaling
            ],
        )
    if bench.cluster:
        lines += _section("A study on a dask cluster", cluster, bench.cluster)
    if bench.memory:
        lines += _section("A study's peak memory", memory, bench.memory)
    lines += ["", "## Every run", ""]
    lines += _table(
        [c[1] or c[0] for c in COLUMNS],
        [
            [
                (_num(r.get(k), s, ".3g") if k == "seconds" else _bounded(r, k, s))
                if s
                else _num(r.get(k))
                for k, _, s in COLUMNS
            ]
            for r in bench.rows
        ],
    )
    lines += [
        "",
        "≤: an error below the reference's resolution, its difference from the second "
        "reference (the check above), is reported as that bound.",
    ]
    return "\n".join(lines) + "\n"


def csv_text(bench: Bench) -> str:
    """The rows, one per scene × setting, in the report's units, as CSV (the last column: the
    errors at the reference's resolution, bounds: ``measure.resolved``)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([*(c[1] or c[0] for c in COLUMNS), "errors at the reference's resolution"])
    for r in bench.rows:
        w.writerow(
            [
                (
                    ""
                    if r.get(k) is None or (isinstance(r.get(k), float) and math.isnan(r[k]))
                    else r[k] * s
                    if s
                    else r[k]
                )
                for k, _, s in COLUMNS
            ]
            + [" ".join(r.get("at_resolution", ()))]
        )
    return buf.getvalue()


def write_csv(bench: Bench, path: Path) -> Path:
    """:func:`csv_text` into ``path``."""
    with open(path, "w", newline="") as fh:
        fh.write(csv_text(bench))
    return path


def plot(bench: Bench, path: Path, errors: tuple[tuple, ...] = (VALVE_LIFT,)) -> Path:
    """Wall time per case against each error of ``errors``: a panel per scene and error, for
    the scenes that have that error (a separation, a seat)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [
        (scene, err)
        for err in errors
        for scene in dict.fromkeys(r["scene"] for r in bench.rows)
        if any(r["scene"] == scene and finite(r.get(err[0])) for r in bench.rows)
    ]
    ncol = max(1, min(3, len(panels)))
    nrow = max(1, math.ceil(len(panels) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.8 * nrow), squeeze=False)
    styles = {
        "modal-exact": ("C0", "o-"),
        "modal-exact capped": ("C9", "s:"),
        "steady": ("C2", "^"),
        "contacts only": ("C4", "P"),
        "newmark-linear": ("C3", "D-"),
        "solve_ivp": ("C1", "v-"),
    }
    for ax, (scene, (key, label, scale, floor)) in zip(axes.flat, panels, strict=False):
        mine = [r for r in bench.rows if r["scene"] == scene and finite(r.get(key))]

        def x_of(r: dict, key=key, scale=scale, floor=floor) -> float:
            return max(r[key] * scale, floor)

        for fam in FAMILIES:
            pts = [r for r in mine if r["family"] == fam]
            if not pts:
                continue
            color, style = styles[fam]
            ax.plot(
                [x_of(r) for r in pts],
                [r["seconds"] * 1e3 for r in pts],
                style,
                color=color,
                ms=4,
                lw=1,
                label=fam,
            )
        for r in mine:
            if r.get("default"):
                ax.plot(x_of(r), r["seconds"] * 1e3, "*", color="k", ms=12, label="default")
            if r.get("thesis"):
                ax.plot(
                    x_of(r),
                    r["seconds"] * 1e3,
                    "s",
                    mfc="none",
                    color="k",
                    ms=9,
                    label="thesis (1 µs)",
                )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(
            scene if len(errors) == 1 else f"{scene}: {label.split(' error')[0]}", fontsize=10
        )
        ax.set_xlabel(label)
        ax.set_ylabel("wall time per case [ms]")
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    # One legend entry per label, from every panel (a panel may lack a family).
    entries: dict[str, Any] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(lab, h)
    if not panels:  # no chosen scene has this error (a form-closed scene has no events)
        axes.flat[0].text(0.5, 0.5, "no scene with this error", ha="center", va="center")
    if entries:
        fig.legend(
            list(entries.values()),
            list(entries),
            loc="lower center",
            ncol=len(entries),
            fontsize=8,
            frameon=False,
        )
    what = " and ".join(label.split(" error")[0] for _, label, _, _ in errors)
    fig.suptitle(
        f"campipe bench: wall time against {what} error" + (" (--quick)" if bench.quick else ""),
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def read_json(path: str | Path) -> Bench:
    """The :class:`Bench` a ``bench.json`` holds (as :func:`write_report` wrote it: NaN and inf
    are null, so a missing figure reads as None)."""
    return Bench(**json.loads(Path(path).read_text()))


def with_previous(bench: Bench, path: str | Path) -> Bench:
    """``bench`` with the previous run at ``path`` (a ``bench.json``) compared and kept: its
    ``previous`` block and ``regressions`` (:func:`campipe.bench.gate.compare`). A missing or
    unreadable file is said, not raised."""
    path = Path(path)
    previous, problem = None, None
    if path.is_file():
        try:
            previous = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            problem = str(exc)
        else:
            if not isinstance(previous, dict):
                previous, problem = None, "not a bench.json (no object at its top)"
    block, regressions = gate.compare(bench, previous, str(path), problem)
    return replace(bench, previous=block, regressions=regressions)


def write_report(
    bench: Bench,
    directory: str | Path,
    with_plot: bool = True,
    previous: str | Path | None = None,
) -> dict[str, Path]:
    """Write the report's files into ``directory`` (created if missing); returns their paths.

    Unless ``bench`` was compared already (:func:`with_previous`), the previous run is read
    first, before its files are overwritten: ``previous``, by default the ``bench.json``
    already in ``directory``; the written json keeps its figures beside the new ones."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = {k: directory / v for k, v in FILES.items()}
    if not bench.previous:
        bench = with_previous(bench, paths["json"] if previous is None else previous)
    if with_plot:
        plot(bench, paths["plot"])
        plot(bench, paths["events_plot"], EVENT_ERRORS)
    else:
        del paths["plot"], paths["events_plot"]
    paths["markdown"].write_text(markdown(bench, with_plot))
    write_csv(bench, paths["csv"])
    paths["json"].write_text(json.dumps(_clean(asdict(bench)), indent=1))
    return paths
