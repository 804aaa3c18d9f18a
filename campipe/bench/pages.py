"""The documentation's bench figures, generated from a ``bench.json``: one source of truth.

A page holds generated blocks between two markers::

    <!-- generated: bench-verdict -->
    ... written by this module, never by hand ...
    <!-- end generated -->

:func:`blocks` turns a :class:`~campipe.bench.run.Bench` into the text of every block,
:func:`render` puts them into a page; the prose around them is written by hand and carries no
figure. The bench's own report files (``bench.md``, ``bench.csv`` beside the json) are
rendered from the same json by ``campipe.bench.report``. Its blocks are named ``bench-…``; a
page's ``study-…`` blocks belong to the developer's benchmark of campipe's own latencies
(``benchmarks/pages.py`` in the repository, from ``docs/bench/study.json``) and are left as
they are.

From the repository's root::

    python -m campipe.bench.pages           # README.md, docs/bench.md, docs/bench/bench.{md,csv}
    python -m campipe.bench.pages --check   # exit 1 if a committed file differs (a test runs it)
    python -m campipe.bench.pages --plots   # also re-draw docs/bench/*.png (needs matplotlib)
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from campipe.bench import cluster, gate, memory, report, settling, sweep, verdict
from campipe.bench.figures import finite, format_short
from campipe.bench.run import (
    ACCURACY_DEFAULT_ERROR,
    ACCURACY_SCENE,
    THESIS_STEP,
    Bench,
)
from campipe.constants import INCH, LBF

#: The committed latest full run, and the pages generated from it (relative to the root).
BENCH_JSON = Path("docs/bench/bench.json")
PAGES = (Path("README.md"), Path("docs/bench.md"))
#: A generated block: its opening marker (with the block's name), its body, its end marker.
BLOCK = re.compile(
    r"(?P<open><!-- generated: (?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)"
    r"(?P<close><!-- end generated -->)",
    re.DOTALL,
)


def ms(seconds: float | None, digits: int = 3) -> str:
    return format_short(seconds * 1e3, digits) if finite(seconds) else "–"


def _inch(metres: float | None, digits: int = 1) -> str:
    return format_short(metres / INCH, digits) if finite(metres) else "–"


def duration(seconds: float) -> str:
    return (
        f"{format_short(seconds * 1e3, 2)} ms" if seconds < 0.1 else f"{format_short(seconds, 2)} s"
    )


def span(values: Sequence[float], digits: int = 2, unit: str = "") -> str:
    """The range of the finite values, "a–b unit" ("a unit" when they round alike)."""
    kept = [v for v in values if finite(v)]
    if not kept:
        return "–"
    low, high = format_short(min(kept), digits), format_short(max(kept), digits)
    return (low if low == high else f"{low}–{high}") + (f" {unit}" if unit else "")


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return lines + ["| " + " | ".join(r) + " |" for r in rows]


def _scenes(bench: Bench) -> list[str]:
    return list(dict.fromkeys(r["scene"] for r in bench.rows))


def _rows(bench: Bench, scene: str, family: str | None = None) -> list[dict]:
    return [
        r for r in bench.rows if r["scene"] == scene and (family is None or r["family"] == family)
    ]


def _pick(rows: list[dict], test: Callable[[dict], object]) -> dict | None:
    return next((r for r in rows if test(r)), None)


def _ratio(bench: Bench, scene: str, peer: str) -> dict | None:
    return _pick(bench.ratios, lambda r: r["scene"] == scene and r["peer"] == peer)


# -- the blocks ---------------------------------------------------------------------------------


def _machine(meta: dict) -> str:
    """The machine a run measured on, its processor where recorded."""
    processor = meta.get("processor")
    return f"{meta['machine']}, {processor}" if processor else meta["machine"]


def run_block(bench: Bench) -> str:
    """Which run the figures come from."""
    m = bench.meta
    return (
        f"The {'`--quick`' if bench.quick else 'full'} run of {m['date']} on {_machine(m)} "
        f"(campipe {m.get('campipe', 'of an unrecorded commit')}, Python {m['python']}, numpy "
        f"{m['numpy']}, scipy {m['scipy']}, numba {m['numba']}): "
        f"{bench.seconds:.0f} s of wall time, load average "
        f"{format_short(m['load_average_at_start'], 2)} at the start and "
        f"{format_short(m.get('load_average_at_end', math.nan), 2)} at the end."
    )


def verdict_block(bench: Bench) -> str:
    """The verdict, as ``campipe bench`` ends with it, after the line naming the run."""
    return run_block(bench) + "\n\n" + verdict.markdown(bench)


def setup_block(bench: Bench) -> str:
    """What the bench runs: the scenes, the ladders, the timing, the references."""
    m = bench.meta
    lad = m["ladder"]
    scenes = m["scenes"]
    turns = {format_short(s["revolutions"]) for s in scenes.values()}
    lines = [
        f"- **{len(scenes)} scenes**, each {' or '.join(sorted(turns))} cam turns sampled every "
        f"{format_short(m['output_every_deg'])} deg: "
        + "; ".join(f"`{name}`, {s['description']}" for name, s in scenes.items())
        + ".",
        "- **Ladders**: modal-exact at event tolerances "
        + ", ".join(format_short(t) for t in lad["modal_tolerances"])
        + " s"
        + (
            " and step caps " + ", ".join(f"{c * 1e6:g}" for c in lad["modal_caps"]) + " µs"
            if lad["modal_caps"]
            else ""
        )
        + ("; the default sampling only the contact coordinates" if lad["contacts_only"] else "")
        + "; newmark-linear at steps "
        + ", ".join(f"{dt * 1e6:g}" for dt in lad["newmark_steps"])
        + f" µs; solve_ivp {lad['ivp_method']} at rtol "
        + ", ".join(format_short(r) for r in lad["ivp_rtols"])
        + ".",
        f"- **Timing**: {m['timing']}.",
        f"- **Reference**: {m['reference']}. **Its check**: {m['reference_check']}, stated "
        f"agreement {format_short(m['agreement']['valve_lift'] / INCH)} in of valve lift, "
        f"{format_short(math.degrees(m['agreement']['event_angle']))} deg in every event angle "
        f"and {format_short(math.degrees(m['agreement']['separation']))} deg in the separation "
        f"per turn, {format_short(m['agreement']['seating_velocity'] / INCH)} in/s in the "
        "seating and cam-impact velocities.",
        "- " + run_block(bench),
    ]
    return "\n".join(lines)


def _point(r: dict | None) -> str:
    """A run's time and valve-lift error ("≤": the reference's resolution bounds it)."""
    if not r:
        return "–"
    bound = "≤" if "valve_lift" in r.get("at_resolution", ()) else ""
    return f"{ms(r['seconds'])} ({bound}{_inch(r['valve_lift'])})"


def _at_default(r: dict | None) -> str:
    """A peer's measured time ratio at the default's error; "> " marks a lower bound."""
    if r is None:
        return "–"
    bound = "" if r["peer_reaches_default_error"] else "> "
    return f"{bound}{format_short(r['measured_ratio_at_default_error'], 2)}×"


def scenes_block(bench: Bench) -> str:
    """Per scene: the default, contacts only, the thesis algorithm at its step, solve_ivp at its
    most accurate point, and the time ratios."""
    out = []
    for scene in _scenes(bench):
        mine = _rows(bench, scene)
        default = _pick(mine, lambda r: r.get("default"))
        lean = _pick(mine, lambda r: r["family"] == "contacts only" and r["setting"] == "full")
        thesis = _pick(mine, lambda r: r.get("thesis"))
        ivp = [r for r in mine if r["family"] == "solve_ivp" and finite(r["valve_lift"])]
        best = min(ivp, key=lambda r: r["valve_lift"]) if ivp else None
        nm = _ratio(bench, scene, "newmark-linear")
        out.append(
            [
                scene,
                _point(default),
                ms(lean["seconds"]) if lean else "–",
                _point(thesis),
                f"{_point(best)}, {best['setting'].split(' ', 1)[1]}" if best else "–",
                _at_default(nm),
                _at_default(_ratio(bench, scene, "solve_ivp")),
                f"{format_short(nm['ratio_at_peer_error'], 2)}×" if nm else "–",
            ]
        )
    header = [
        "scene",
        "default: ms/case (valve err, in)",
        "contacts only: ms",
        f"newmark-linear {THESIS_STEP * 1e6:g} µs: ms (err, in)",
        "solve_ivp, most accurate: ms (err, in), setting",
        "vs newmark-linear at the default's error",
        "vs solve_ivp at the default's error",
        f"vs newmark-linear {THESIS_STEP * 1e6:g} µs at its error",
    ]
    return "\n".join(table(header, out))


def ratios_block(bench: Bench) -> str:
    """How far the peers' ladders fall short of the default's error, and the ratio along
    newmark-linear's ladder."""
    lines = []
    steps = bench.meta["ladder"]["newmark_steps"]
    for peer in ("newmark-linear", "solve_ivp"):
        short = [
            r for r in bench.ratios if r["peer"] == peer and not r["peer_reaches_default_error"]
        ]
        if not short:
            continue
        factors = []
        for r in short:
            pts = [p for p in _rows(bench, r["scene"], peer) if finite(p["valve_lift"])]
            factors.append(min(p["valve_lift"] for p in pts) / r["default_error"])
        finest = (
            f"at {min(steps) * 1e6:g} µs, {format_short(THESIS_STEP / min(steps))} times the "
            "thesis's steps"
            if peer == "newmark-linear"
            else f"at rtol {min(bench.meta['ladder']['ivp_rtols']):g}"
        )
        extrapolated = [r["ratio_at_default_error"] for r in short if r["how"] == "extrapolated"]
        lines.append(
            f"- {peer}'s most accurate point ({finest}) is still {span(factors, 1)} times less "
            f"accurate than the default on {len(short)} of {len(_scenes(bench))} scenes "
            f"({', '.join(r['scene'] for r in short)}); extrapolating along its time/error "
            f"curve puts the ratio at the default's error at {span(extrapolated, 2)}×."
        )
    nm = [r for r in bench.ratios if r["peer"] == "newmark-linear"]
    if nm:
        accuracy = [r["peer_point_error"] / r["default_error"] for r in nm]
        lines.append(
            f"- At newmark-linear's {THESIS_STEP * 1e6:g} µs step the default is "
            f"{span([r['ratio_at_peer_error'] for r in nm], 2)}× faster for the step's error, "
            f"while it is {span(accuracy, 1)} times more accurate itself."
        )
    goal = bench.goals.get("newmark-linear")
    if goal and goal.get("goal_reached_below_error"):
        lines.append(
            f"- The ratio is at least {goal['goal']:g}× at every point of newmark-linear's ladder "
            "with a valve-lift error up to "
            + "; ".join(
                f"{_inch(e)} in ({scene})" if finite(e) else f"no point ({scene})"
                for scene, e in goal["goal_reached_below_error"].items()
            )
            + "."
        )
    if nm:
        lines += [
            "",
            "The ratio at each step of newmark-linear's ladder (its time over the "
            "time the default integrator needs for that step's error):",
            "",
        ]
        scenes = [r["scene"] for r in nm]
        settings = list(dict.fromkeys(p["setting"] for r in nm for p in r["ladder"]))
        by = {(r["scene"], p["setting"]): p for r in nm for p in r["ladder"]}
        lines += table(
            ["newmark-linear step", *scenes],
            [
                [
                    s,
                    *(
                        f"{format_short(by[sc, s]['ratio'], 2)}× ({_inch(by[sc, s]['error'])} in)"
                        if (sc, s) in by
                        else "–"
                        for sc in scenes
                    ),
                ]
                for s in settings
            ],
        )
    return "\n".join(lines)


def accuracy_block(bench: Bench) -> str:
    """Accuracy for cost on the separation scene."""
    a = bench.accuracy_for_cost
    if not a:
        return f"{ACCURACY_SCENE} was not run."
    turns = bench.meta["scenes"][ACCURACY_SCENE]["revolutions"]
    text = (
        f"On {ACCURACY_SCENE} the default reaches a valve-lift error of "
        f"{_inch(a['default_error'], 2)} in (goal: below {_inch(ACCURACY_DEFAULT_ERROR)} in) in "
        f"{ms(a['default_seconds'])} ms per case ({a['default_steps']} grid steps, "
        f"{format_short(turns)} turns)."
    )
    cheapest = a["newmark_cheapest_meeting"]
    if cheapest:
        text += (
            f" newmark-linear's cheapest ladder point meeting {_inch(a['newmark_target'])} in "
            f"is {cheapest['setting']} ({_inch(cheapest['error'], 2)} in, {cheapest['steps']} "
            f"steps) at {ms(cheapest['seconds'])} ms"
        )
        text += ", the ladder's coarsest step" if a["how"] == "cheapest" else ""
        text += "."
    text += (
        f" newmark-linear's time for {_inch(a['newmark_target'])} in over the default's: "
        f"**{format_short(a['ratio'])}×**"
    )
    if finite(a.get("ratio_contacts_only")):
        text += (
            f"; sampling only the contact coordinates the default takes "
            f"{ms(a['contacts_only_seconds'])} ms, **{format_short(a['ratio_contacts_only'])}×**"
        )
    return text + "."


def throughput_block(bench: Bench) -> str:
    """The 256-case batch: case-steps per second on one and two workers."""
    if not bench.throughput:
        return "Not measured in this run (`--no-scaling`)."
    lines = table(
        [
            "integrator",
            "cases",
            "workers",
            "turns per case",
            "case-steps",
            "seconds",
            "case-steps/s",
        ],
        [
            [
                t["integrator"],
                str(t["n_cases"]),
                str(t["workers"]),
                format_short(t["revolutions"]),
                format_short(t["case_steps"]),
                format_short(t["seconds"]),
                format_short(t["rate"]),
            ]
            for t in bench.throughput
        ],
    )
    one = _pick(
        bench.throughput, lambda t: t["integrator"] == "newmark-linear" and t["workers"] == 1
    )
    if one:
        lines += [
            "",
            f"One worker: {format_short(1e9 / one['rate'], 2)} ns per newmark-linear case-step.",
        ]
    return "\n".join(lines)


def _change(r: dict | None, default: dict) -> str:
    """A run's time against the default's, in per cent."""
    if r is None:
        return "–"
    return f"{round((r['seconds'] / default['seconds'] - 1) * 100):+d} %"


def fidelity_block(bench: Bench) -> str:
    """Per scene: the default, contacts only, and the steady-state path where the scene follows
    the cam (its margin, the margin's cost, one turn's cost and its error)."""
    steady = {r["scene"]: r for r in bench.steady}
    rows = []
    for scene in _scenes(bench):
        mine = _rows(bench, scene)
        default = _pick(mine, lambda r: r.get("default"))
        if default is None:
            continue
        lean = _pick(mine, lambda r: r["family"] == "contacts only")
        row = [scene, ms(default["seconds"]), _change(lean, default)]
        st = steady.get(scene)
        if st is None:
            row += ["–"] * 3
        elif not st["applies"]:
            why = "the valve seats" if finite(st["seat_height"]) and st["seat_height"] < 0 else ""
            margin = f"{format_short(st['margin'] / LBF)} lbf" if finite(st["margin"]) else "–"
            row += [f"no ({margin}{', ' + why if why else ''})", "–", "–"]
        else:
            margin = f"{format_short(st['margin'] / LBF)} lbf" if finite(st["margin"]) else "form"
            row += [
                f"yes ({margin})",
                f"{format_short(st['margin_seconds'] * 1e6)} µs",
                f"{ms(st['seconds'])} ms ({_inch(st['valve_lift'])} in)",
            ]
        rows.append(row)
    return "\n".join(
        table(
            [
                "scene",
                "default ms/case",
                "contacts only: time",
                "steady state (least cam force)",
                "its margin: µs/case",
                "one turn of it: ms/case (err)",
            ],
            rows,
        )
    )


def onset_block(bench: Bench) -> str:
    """The onset map of many designs against the time-domain grid it replaces."""
    o = bench.onset
    if not o:
        return "Not measured in this run."
    equal = (
        f"a resolution of {format_short(o['equal_time_resolution_rpm'], 2)} rpm"
        if o["equal_time_speeds"] >= 2
        else "fewer than the two a bracket needs"
    )
    speeds = format_short(o["equal_time_speeds"])
    if float(speeds) >= 2 > o["equal_time_speeds"]:  # not rounded up to the two it lacks
        speeds = f"{math.floor(o['equal_time_speeds'] * 100) / 100:g}"
    return "\n".join(
        [
            f"- **The map**: {o['designs']} designs (preload {format_short(o['preloads_lbf'][0])}"
            f"–{format_short(o['preloads_lbf'][1])} lbf × spring rate "
            f"{format_short(o['rates_lbf_per_in'][0])}–{format_short(o['rates_lbf_per_in'][1])}"
            f" lbf/in, harmonic cam), each onset in {format_short(o['range_rpm'][0])}–"
            f"{format_short(o['range_rpm'][1])} rpm to {format_short(o['tolerance_rpm'])} rpm: "
            f"**{format_short(o['seconds'], 2)} s** on {o['workers']} workers, the designs' "
            f"modes included ({o['steady_states']} steady states, "
            f"{format_short(o['seconds'] / o['designs'] * 1e3, 2)} ms a design); "
            f"{o['found']} onsets inside the range.",
            f"- **Its check**: {o['agree']} of {o['checked']} onsets checked by the time-domain "
            "engine either side (0.5 % below: follows; 0.5 % above: leaves the cam) agree.",
            f"- **The time-domain grid it replaces**: {o['grid_speeds']} speeds a design, "
            f"{o['grid_turns']} turns each ({format_short(o['grid_per_case'] * 1e3)} ms a run, "
            f"timed on 64 of them in one process): an estimated "
            f"**{format_short(o['grid_seconds'], 2)} s** on {o['workers']} workers (its runs "
            f"spread evenly) for a "
            f"resolution of {format_short(o['grid_resolution_rpm'])} rpm; in the map's time it "
            f"affords {speeds} speeds a design ({equal}).",
        ]
    )


def scaling_table(points: Sequence[dict]) -> str:
    """Time against cases and workers of each layer of ``points`` (``ScalingPoint`` rows: the
    engine's here, the study layer's in the developer's benchmark), with the archive's size
    where a layer writes one."""
    at = {(p["layer"], p["n_cases"], p["workers"]): p for p in points}
    counts = sorted({p["n_cases"] for p in points})
    workers = sorted({p["workers"] for p in points})
    layers = list(dict.fromkeys(p["layer"] for p in points))
    archives = any(p["archive_bytes"] for p in points)
    rows = []
    for n in counts:
        row = [str(n)]
        for layer in layers:
            for w in workers:
                p = at.get((layer, n, w))
                row.append(duration(p["seconds"]) if p else "–")
        stored = next((at[k] for k in at if k[1] == n and at[k]["archive_bytes"]), None)
        if archives:
            row.append(f"{format_short(stored['archive_bytes'] / n / 1e3)} kB" if stored else "–")
        rows.append(row)
    header = ["cases"]
    header += [f"{layer}, {w} worker{'s' if w > 1 else ''}" for layer in layers for w in workers]
    lines = table(header + (["archive per case"] if archives else []), rows)
    large = counts[-2:]
    if len(counts) > 2:
        parts = []
        for layer in layers:
            for w in workers:
                per = [at[layer, n, w]["per_case"] for n in large if (layer, n, w) in at]
                if per:
                    shown = span([p * 1e3 for p in per], 2, "ms")
                    parts.append(f"{layer} on {w} worker{'s' if w > 1 else ''} {shown}")
        top, one, most = max(counts), workers[0], workers[-1]
        gains = [
            f"{layer} {format_short(at[k1]['seconds'] / at[k2]['seconds'], 2)}×"
            for layer in layers
            if (k1 := (layer, top, one)) in at and (k2 := (layer, top, most)) in at
        ]
        lines += [
            "",
            f"Per case at {' and '.join(map(str, large))} cases: "
            + "; ".join(parts)
            + "."
            + (
                f" At {top} cases the second worker gives " + ", ".join(gains) + "."
                if len(workers) > 1 and gains
                else ""
            ),
        ]
    return "\n".join(lines)


def scaling_block(bench: Bench) -> str:
    """The engine's time against cases and workers."""
    if not bench.scaling:
        return "Not measured in this run (`--no-scaling`)."
    return scaling_table(bench.scaling)


def cluster_block(bench: Bench) -> str:
    """A study with --parts on 1, 2, 4 worker processes: cases per second against the
    client's CPU per case."""
    if not bench.cluster:
        return (
            "Not measured in this run (`--no-scaling` or `--no-cluster`, or a run from before "
            "the block): `python -m campipe.bench.cluster` runs it alone.\n"
        )
    return _notes_and_table(cluster, bench.cluster)


def memory_block(bench: Bench) -> str:
    """A study's peak memory against the bound campipe validate states."""
    if not bench.memory:
        return (
            "Not measured in this run (`--no-scaling`, or a run from before the block): "
            "`python -m campipe.bench.memory` runs it alone.\n"
        )
    return _notes_and_table(memory, bench.memory)


def _notes_and_table(block, data) -> str:
    """A measurement's block: its module's ``notes`` of ``data``, then its table
    (``HEADER``, ``table_rows``)."""
    lines = block.notes(data) + [""]
    lines += table(block.HEADER, block.table_rows(data))
    return "\n".join(lines) + "\n"


def settling_block(bench: Bench) -> str:
    """Automatic run length against a fixed 4 turns on a sweep through the onset."""
    return settling.markdown(bench.settling)


def sweep_block(bench: Bench) -> str:
    """The speed sweep: the default against the thesis's loop and newmark-linear, the
    overhead a call, each against the earlier figures."""
    if not bench.sweep:
        return "Not measured in this run (`--no-scaling`, or a run from before the sweep).\n"
    lines = sweep.notes(bench.sweep) + [""]
    lines += table(sweep.HEADER, sweep.table_rows(bench.sweep))
    return "\n".join(lines) + "\n"


def regressions_block(bench: Bench) -> str:
    """The figures more than 10 % slower than the previous run's, none, or why none could be
    compared (``campipe.bench.gate``)."""
    return gate.markdown(bench)


#: Every block a page may hold, by name.
BLOCKS: dict[str, Callable[[Bench], str]] = {
    "bench-verdict": verdict_block,
    "bench-setup": setup_block,
    "bench-scenes": scenes_block,
    "bench-ratios": ratios_block,
    "bench-accuracy": accuracy_block,
    "bench-throughput": throughput_block,
    "bench-fidelity": fidelity_block,
    "bench-onset": onset_block,
    "bench-settling": settling_block,
    "bench-scaling": scaling_block,
    "bench-cluster": cluster_block,
    "bench-memory": memory_block,
    "bench-sweep": sweep_block,
    "bench-regressions": regressions_block,
}


def blocks(bench: Bench) -> dict[str, str]:
    """The text of every block, from ``bench``."""
    return {name: make(bench) for name, make in BLOCKS.items()}


def block_names(text: str) -> list[str]:
    """The names of the generated blocks in ``text``, in order."""
    return [m["name"] for m in BLOCK.finditer(text)]


def render(text: str, generated: dict[str, str], prefix: str = "bench-") -> str:
    """``text`` with each generated block named ``prefix``… replaced by ``generated[name]``;
    the blocks of another generator (another prefix: the developer's benchmark writes
    ``study-`` blocks) are left as they are."""

    def fill(m: re.Match) -> str:
        name = m["name"]
        if not name.startswith(prefix):
            return m[0]
        if name not in generated:
            raise KeyError(f"unknown generated block {name!r}; known: {', '.join(generated)}")
        return f"{m['open']}{generated[name].rstrip()}\n{m['close']}"

    return BLOCK.sub(fill, text)


def rendered(bench: Bench, bench_json: Path, pages: Sequence[Path]) -> dict[Path, str]:
    """What every generated file should hold: each page with its blocks filled, and the
    bench's report files beside ``bench_json``."""
    generated = blocks(bench)
    out = {page: render(page.read_text(encoding="utf-8"), generated) for page in pages}
    folder = bench_json.parent
    with_plots = (folder / report.FILES["plot"]).exists()
    out[folder / report.FILES["markdown"]] = report.markdown(bench, with_plots)
    out[folder / report.FILES["csv"]] = report.csv_text(bench)
    return out


def update(files: dict[Path, str], check: bool) -> list[Path]:
    """The files of ``files`` whose bytes differ from their text (a CSV's ``\\r\\n``, which
    reading as text would hide, included); each rewritten unless ``check``."""
    stale = []
    for path, text in files.items():
        if not path.exists() or path.read_bytes() != text.encode():
            stale.append(path)
            if not check:
                path.write_bytes(text.encode())
    return stale


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m campipe.bench.pages",
        description="Regenerate the documentation's bench figures from a bench.json.",
    )
    parser.add_argument("--json", type=Path, default=BENCH_JSON, help=f"default: {BENCH_JSON}")
    parser.add_argument(
        "pages", nargs="*", type=Path, default=list(PAGES), help="default: README.md docs/bench.md"
    )
    parser.add_argument(
        "--check", action="store_true", help="change nothing; exit 1 if a file differs"
    )
    parser.add_argument("--plots", action="store_true", help="also re-draw the bench's PNG plots")
    args = parser.parse_args(argv)
    bench = report.read_json(args.json)
    stale = update(rendered(bench, args.json, args.pages), args.check)
    if args.plots and not args.check:
        folder = args.json.parent
        report.plot(bench, folder / report.FILES["plot"])
        report.plot(bench, folder / report.FILES["events_plot"], report.EVENT_ERRORS)
    verb = "differs from" if args.check else "rewritten from"
    for path in stale:
        print(f"{path}: {verb} {args.json}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
