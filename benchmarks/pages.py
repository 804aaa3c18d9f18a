"""docs/bench.md's part of the developer benchmark, generated from ``docs/bench/study.json``.

The page's ``study-…`` blocks are written here, as ``campipe.bench.pages`` writes its
``bench-…`` blocks from ``docs/bench/bench.json`` (the same markers, see
:func:`campipe.bench.pages.render`); the prose around them carries no figure. From the
repository's root::

    python -m benchmarks.pages            # docs/bench.md's study blocks
    python -m benchmarks.pages --check    # exit 1 if the committed page differs (a test runs it)
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from benchmarks import goals
from benchmarks.goals import bytecode_note
from campipe.bench.pages import duration, ms, render, scaling_table, table, update
from campipe.bench.verdict import format_short

#: The committed run, and the page whose study blocks it fills (relative to the root).
STUDY_JSON = Path("docs/bench/study.json")
PAGES = (Path("docs/bench.md"),)
#: The prefix of this generator's block names.
PREFIX = "study-"


def run_block(data: dict) -> str:
    """Which run the figures come from."""
    m = data["meta"]
    text = (
        f"The {'`--quick`' if m['quick'] else 'full'} run of {m['date']} on {m['machine']} "
        f"(Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, numba {m['numba']})"
    )
    if m.get("from"):
        text += f", {m['from']}"
    return text + "."


def verdict_block(data: dict) -> str:
    """The study goals, each reached or not, after the line naming the run."""
    return run_block(data) + "\n\n" + goals.markdown(data["study"])


def scaling_block(data: dict) -> str:
    """The study layer's time against cases and workers, and the archive's size."""
    if not data["scaling"]:
        return "Not measured in this run (`--no-scaling`)."
    return scaling_table(data["scaling"])


def _workers(n: float) -> str:
    """``n`` workers to two figures: "1 worker", "1.4 workers"."""
    shown = format_short(n, 2)
    return f"{shown} worker{'' if shown == '1' else 's'}"


def _rate(bytes_per_second: float) -> str:
    return f"{format_short(bytes_per_second / 1e6, 3)} MB/s"


def section_block(data: dict) -> str:
    """campipe study end to end against the engine: sizes, start-up, the client's
    ceiling on a cluster, local worker processes, validate's estimates."""
    s = data["study"]
    w = s["workers"]
    lines = [
        f"Measured {s['date']} on {w} worker thread{'s' if w != 1 else ''}, load average "
        f"{format_short(s['load_average_at_start'], 2)} at the start and "
        f"{format_short(s['load_average_at_end'], 2)} at the end ({duration(s['seconds'])}). "
        "End to end: `python -m campipe study SPEC` in a fresh process, best of "
        f"{s['sizes'][0].get('repeats', 3)} (one run above 1000 cases); in process: "
        "`run_study` with the kernels loaded; engine: "
        "`run_batch` on the same cases in the study's own batches, on as many threads.",
        "",
    ]
    rows = [
        [
            str(r["n_cases"]),
            duration(r["wall"]),
            duration(r["study"]),
            duration(r["engine"]),
            f"{format_short(r['ratio'], 3)}×",
            duration(r["goal"]),
            f"{format_short(r['bytes_per_case'] / 1e3)} kB",
        ]
        for r in s["sizes"]
    ]
    lines += table(
        [
            "cases",
            "end to end",
            "in process",
            "engine",
            "end to end / engine",
            "1.5 × engine + 0.5 s",
            "archive per case",
        ],
        rows,
    )
    lat = s["latencies"]
    lines += [
        "",
        f"Start-up, best of {lat['repeats']} fresh processes{bytecode_note(lat)}: `campipe --help` "
        f"{duration(lat['help'])}; a one-case study {duration(lat['one_case'])}; "
        f"a finished {lat['finished_cases']}-case study run again {duration(lat['finished'])}.",
    ]
    first = s.get("first_run")
    if first:
        lines += [
            "",
            f"First run (the quickstart with numba's, pint's and campipe's caches empty): "
            f"{duration(first['seconds'])}; its first line on the terminal came after "
            f"{duration(first['first_line_seconds'])}, saying "
            f"“{first['first_line'].split(': ')[1] if first['notice'] else first['first_line']}”.",
        ]
        if "reinstall_seconds" in first:
            lines[-1] += (
                f" A second copy of campipe at another path (a new clone or venv) then ran it "
                f"in {duration(first['reinstall_seconds'])}: numba keys its cache by the "
                "source files' paths and time stamps, so a new copy compiles again."
            )
        if "measured" in first:
            lines[-1] += f" ({first['measured']})"
    c = s["ceiling"]
    packed = c["compressed_bytes"] / c["raw_bytes"]
    disk = c["disk_rate"] / packed  # raw bytes a second, the disk taking them compressed
    limit = min(c["compress_rate"], disk)
    engine_rate = next((r["engine_rate"] for r in s["cluster"] if r["workers"] == 1), None)
    lines += [
        "",
        f"The client's ceiling: assembling {c['n_cases']} cases from stored batch files took "
        f"{duration(c['seconds'])}, **{format_short(c['cases_per_second'], 3)} cases/s**, "
        f"writing {_rate(c['write_rate'])} of raw histories; netCDF-C writes the same "
        f"histories with the archive's compression ({c.get('compression', 'zlib')}) at "
        f"{_rate(c['compress_rate'])} on one core, given them all at once (to "
        f"{format_short(100 * packed, 2)} %), and the disk takes {_rate(c['disk_rate'])} "
        f"flushed, {_rate(disk)} of raw histories so compressed: the assembly runs at "
        f"{format_short(100 * c['write_rate'] / limit, 2)} % of the lower limit, "
        f"{'the compression' if limit == c['compress_rate'] else 'the disk'}'s.",
    ]
    others = [
        f"{name} at {_rate(o['rate'])} (to {format_short(100 * o['bytes'] / c['raw_bytes'], 2)} %)"
        for name, o in c.get("compressions", {}).items()
        if name != c.get("compression")
    ]
    if others:
        lines[-1] += f" The other values of `run.compression` write them {' and '.join(others)}."
    if engine_rate:
        compress = c["raw_bytes_per_case"] / c["compress_rate"]
        lines[-1] += (
            f" One worker's engine computes {format_short(engine_rate, 3)} cases/s, so the "
            f"client binds at about {_workers(c['cases_per_second'] / engine_rate)}. With one "
            "compressed file per batch, written by its worker and read as "
            f"one dataset, each worker would compress at {ms(compress, 2)} ms per case "
            f"beside its engine's {ms(1 / engine_rate, 2)} ms "
            f"(+{format_short(100 * compress * engine_rate, 2)} %), and the client would only "
            "track batches."
        )
    lines += [""]
    lines += table(
        ["worker processes", "study, cases/s", "engine, cases/s", "study / engine"],
        [
            [
                str(r["workers"]),
                format_short(r["study_rate"], 3),
                format_short(r["engine_rate"], 3),
                format_short(r["study_rate"] / r["engine_rate"], 2),
            ]
            for r in s["cluster"]
        ],
    )
    n = s["cluster"][0]["n_cases"] if s["cluster"] else 0
    lines += [
        "",
        f"({n} cases on a local dask cluster of single-threaded worker processes, which write "
        "their own batch files; the study's default batches for the engine and the study "
        "alike; cluster start-up left out.)",
    ]
    if s.get("estimates"):
        lines += [
            "",
            "`campipe validate`'s run-time estimate of each bundled study beside its run "
            + (
                "(each in a fresh process of its own, from after the spec's reading: both "
                "load the engine, as a user's `campipe validate` and `campipe study` do):"
                if s.get("estimates_fresh")
                else "(in process, kernels loaded):"
            ),
            "",
        ]
        lines += table(
            ["study", "cases", "validate's estimate", "measured", "measured / estimate"],
            [
                [
                    f"`{e['study']}`",
                    str(e["cases"]),
                    duration(e["estimate"]),
                    duration(e["measured"]),
                    f"{format_short(e['measured'] / e['estimate'], 2)}×",
                ]
                for e in s["estimates"]
            ],
        )
    v = s.get("validate")
    if v:
        lines += [
            "",
            f"`campipe validate --no-estimate` of {format_short(v['n_cases'])} cases: "
            + (
                f"{duration(v['seconds'])}, {format_short(v['peak_bytes'] / 1e6, 3)} MB at "
                "its peak."
                if "seconds" in v
                else f"failed ({v['failed']})."
            ),
        ]
    return "\n".join(lines)


#: Every block of this generator, by name.
BLOCKS: dict[str, Callable[[dict], str]] = {
    "study-verdict": verdict_block,
    "study-section": section_block,
    "study-scaling": scaling_block,
}


def read_json(path: str | Path) -> dict:
    """What a ``study.json`` holds (NaN and inf written as null read back as None)."""
    return json.loads(Path(path).read_text())


def blocks(data: dict) -> dict[str, str]:
    """The text of every block, from ``data`` (a ``study.json``)."""
    return {name: make(data) for name, make in BLOCKS.items()}


def rendered(data: dict, pages: Sequence[Path]) -> dict[Path, str]:
    """What each page should hold: its ``study-…`` blocks filled from ``data``."""
    generated = blocks(data)
    return {page: render(page.read_text(encoding="utf-8"), generated, PREFIX) for page in pages}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.pages",
        description="Regenerate the developer benchmark's figures in the docs from a study.json.",
    )
    parser.add_argument("--json", type=Path, default=STUDY_JSON, help=f"default: {STUDY_JSON}")
    parser.add_argument(
        "pages", nargs="*", type=Path, default=list(PAGES), help="default: docs/bench.md"
    )
    parser.add_argument(
        "--check", action="store_true", help="change nothing; exit 1 if a page differs"
    )
    args = parser.parse_args(argv)
    stale = update(rendered(read_json(args.json), args.pages), args.check)
    verb = "differs from" if args.check else "rewritten from"
    for path in stale:
        print(f"{path}: {verb} {args.json}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
