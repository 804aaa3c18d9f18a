"""The developer benchmark's goals: campipe's own latencies and study layer, each with the
figure a run measured and whether it reaches it.

Pure functions of the study section (:func:`benchmarks.study.measure`, or its part of a
``study.json`` read back), in the words and statuses of ``campipe bench``'s verdict
(:class:`campipe.bench.verdict.Goal`). ``python -m benchmarks.study`` prints :func:`text`
last; ``benchmarks.pages`` writes :func:`markdown` into the documentation.
"""

from __future__ import annotations

from campipe.bench.verdict import NOT_REACHED, NOT_SHOWN, REACHED, Goal, format_short


def _seconds(x: float) -> str:
    return f"{format_short(x, 2)} s"


def bytecode_note(latencies: dict) -> str:
    """How the start-up latencies were timed, where the run says: with Python's bytecode
    cache, as an installed campipe has it (``benchmarks.study._campipe``)."""
    return ", Python's bytecode cached" if latencies.get("bytecode") else ""


def _under(words: str, seconds: float | None, limit: float, note: str, missing: str) -> Goal:
    """The study goal "``words`` under ``limit`` s": reached below it, not shown (saying
    ``missing``) where nothing was measured."""
    what = f"{words} under {format_short(limit)} s"
    if seconds is None:
        return Goal("study", what, "–", NOT_SHOWN, missing)
    return Goal("study", what, _seconds(seconds), REACHED if seconds < limit else NOT_REACHED, note)


def goals(s: dict) -> list[Goal]:
    """Every goal of the study section ``s`` (:func:`benchmarks.study.measure`), in a fixed
    order: the study layer, start-up, the first run, validate at scale."""
    g = s["goals"]
    out = []
    at = next((r for r in s.get("sizes", []) if r["n_cases"] == g["cases"]), None)
    what = (
        f"a {g['cases']}-case study end to end at most {format_short(g['factor'])} × the "
        f"engine's time + {format_short(g['offset'])} s"
    )
    if at is None:
        out.append(Goal("study", what, "–", NOT_SHOWN, "not measured: --quick"))
    else:
        out.append(
            Goal(
                "study",
                what,
                f"{_seconds(at['wall'])} against {_seconds(at['goal'])}",
                REACHED if at["wall"] <= at["goal"] else NOT_REACHED,
                f"engine {_seconds(at['engine'])} on {at['workers']} workers, "
                f"{format_short(at['ratio'], 2)}× end to end; the study section of "
                f"{s['date']}, load average {format_short(s['load_average_at_start'], 2)}",
            )
        )
    lat = s["latencies"]
    for key, words in (
        ("help", "campipe --help"),
        ("one_case", "a one-case study, warm"),
        ("finished", f"a finished {lat['finished_cases']}-case study run again"),
    ):
        how = f"best of {lat['repeats']} fresh processes{bytecode_note(lat)}"
        out.append(_under(words, lat[key], g[key], how, ""))
    first = s.get("first_run")
    said = (
        f"it says what it compiles after {_seconds(first['first_line_seconds'])}"
        if first and first["notice"]
        else "silent while numba compiles"
    )
    out.append(
        _under(
            "the quickstart from a fresh install",
            None if first is None else first["seconds"],
            g["first_run"],
            f"numba's, pint's and campipe's caches empty; {said}",
            "not measured: --quick",
        )
    )
    if first is not None:
        out.append(
            _under(
                "the quickstart from a fresh install of a campipe this machine has run,",
                first.get("reinstall_seconds"),
                g["first_run"],
                "a second copy of campipe at another path, no __pycache__: numba keys its "
                "cache by the source files' paths, so the copy compiles again",
                "not measured in this run",
            )
        )
    v = s.get("validate")
    what = (
        f"campipe validate of {format_short(g['validate_cases'])} cases under "
        f"{format_short(g['validate_seconds'])} s and {format_short(g['validate_bytes'] / 1e6)} MB"
    )
    if v is None or "seconds" not in v:
        why = v["failed"] if v else "not measured: --quick"
        out.append(Goal("study", what, "–", NOT_SHOWN, why))
    else:
        ok = v["seconds"] < g["validate_seconds"] and v["peak_bytes"] < g["validate_bytes"]
        out.append(
            Goal(
                "study",
                what,
                f"{_seconds(v['seconds'])}, {format_short(v['peak_bytes'] / 1e6)} MB",
                REACHED if ok else NOT_REACHED,
                "--no-estimate, peak memory of the process",
            )
        )
    return out


def text(s: dict) -> str:
    """The goals block ``python -m benchmarks.study`` ends with."""
    lines = ["goals:"]
    width = max(len(x) for x in (REACHED, NOT_REACHED, NOT_SHOWN))
    for g in goals(s):
        lines.append(f"  {g.status:<{width}}  {g.area}: {g.what}: {g.figure} ({g.note})")
    return "\n".join(lines)


def markdown(s: dict) -> str:
    """The goals as markdown bullets, as ``campipe bench``'s verdict writes its own."""
    return "\n".join(
        f"- **{g.status}** ({g.area}): {g.what}: **{g.figure}** ({g.note})." for g in goals(s)
    )
