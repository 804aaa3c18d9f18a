"""The developer's benchmark (``benchmarks/`` at the repository's root, not installed): campipe's
own latencies and study layer against the engine. Its figures are measured, never asserted;
what is checked is that each is measured, consistent with the others and judged."""

import json
import os
import subprocess
import sys

import pytest
from study_helpers import ROOT

if str(ROOT) not in sys.path:  # benchmarks/ is not installed: imported from the repository
    sys.path.insert(0, str(ROOT))

from benchmarks import goals, scaling, study  # noqa: E402
from campipe.study.spec.fields import COMPRESSIONS  # noqa: E402


def _benchmarks(*args: str) -> subprocess.CompletedProcess:
    """``python -m benchmarks.… ARGS`` from the repository's root, as CONTRIBUTING.md runs it,
    importing this checkout's campipe."""
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run(
        [sys.executable, "-m", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
    )


def test_the_study_layer_scales_the_engines_cases(tmp_path):
    """``campipe bench``'s scaling cases through the study layer, archive written."""
    points = scaling.study_scaling([4], tmp_path, workers=(1,))
    assert [(p.layer, p.n_cases, p.workers) for p in points] == [("study", 4, 1)]
    # 4 cases × 721 samples × several float64 histories: tens of kB per case.
    assert 5e3 < points[0].archive_bytes / 4 < 2e5
    assert (tmp_path / "bench-scaling-4-w1.nc").exists()
    assert points[0].per_case == pytest.approx(points[0].seconds / 4)


def test_the_quick_benchmark_measures_the_study_section(tmp_path):
    """``python -m benchmarks.study --quick``: each size end to end against the engine with
    its archive's bytes, the start-up latencies (a finished study answered "up to date",
    asserted where it is timed), the client's ceiling against each compression, 1/2/4 worker
    processes; then its goals, the bundled studies' estimates, the first run and validate at
    scale not shown (--quick: the estimates run each bundled study whole, and validate's
    estimate of a small study runs it once more, minutes for the compliant ones; the full run
    shows them, and tests/integration/test_estimate.py tests the estimate)."""
    done = _benchmarks("benchmarks.study", "--quick", "--no-scaling", "-o", str(tmp_path))
    assert done.returncode == 0, done.stderr[-2000:]
    data = json.loads((tmp_path / "study.json").read_text())
    assert data["meta"]["quick"] and data["scaling"] == []
    s = data["study"]
    assert [r["n_cases"] for r in s["sizes"]] == list(study.QUICK_COUNTS)
    # --quick times each figure once (the full run: best of LATENCY_REPEATS, SIZE_REPEATS)
    assert s["latencies"]["repeats"] == study.QUICK_REPEATS == 1
    assert [r["repeats"] for r in s["sizes"]] == [study.QUICK_REPEATS] * len(study.QUICK_COUNTS)
    for r in s["sizes"]:
        assert r["wall"] > r["study"] > 0 and r["engine"] > 0 and r["archive_bytes"] > 0
        assert r["ratio"] == pytest.approx(r["wall"] / r["engine"])
        assert r["bytes_per_case"] == pytest.approx(r["archive_bytes"] / r["n_cases"])
        assert r["goal"] == pytest.approx(study.GOAL_FACTOR * r["engine"] + study.GOAL_OFFSET)
    lat = s["latencies"]
    assert lat["finished_cases"] == study.GOAL_CASES
    assert min(lat["help"], lat["one_case"], lat["finished"]) > 0
    c = s["ceiling"]
    assert c["n_cases"] == study.QUICK_COUNTS[-1]
    assert c["cases_per_second"] == pytest.approx(c["n_cases"] / c["seconds"])
    assert c["compression"] == "zstd" and set(c["compressions"]) == set(COMPRESSIONS)
    assert c["compressions"]["none"]["bytes"] >= c["raw_bytes"] > c["compressed_bytes"] > 0
    assert c["compressions"]["zstd"]["bytes"] == c["compressed_bytes"]
    assert [r["workers"] for r in s["cluster"]] == [1, 2, 4]
    assert "estimates" not in s and "first_run" not in s and "validate" not in s
    # stdout: the json's path, then the goals as benchmarks.goals judges them from it
    lines = done.stdout.splitlines()
    assert lines[0] == str(tmp_path / "study.json") and lines[1] == "goals:"
    judged = goals.goals(s)
    assert [line.split("  ")[1] for line in lines[2:]] == [g.status for g in judged]
    # the 1000-case goal needs the full sizes; the first run, both installs' and validate's
    # need the full run
    assert [(g.status, g.note) for g in judged if g.status == "not shown"] == [
        ("not shown", "not measured: --quick")
    ] * 3
    assert [g.figure for g in judged[1:4]] == [
        f"{goals.format_short(lat[k], 2)} s" for k in ("help", "one_case", "finished")
    ]


def test_the_goals_judge_the_stored_run_and_a_worse_one():
    """Each goal from the committed study.json, reached where its figure is within the goal,
    and not reached once the figure is pushed past it."""
    data = json.loads((ROOT / "docs" / "bench" / "study.json").read_text())
    s = data["study"]
    judged = goals.goals(s)
    assert [g.area for g in judged] == ["study"] * 7
    at = next(r for r in s["sizes"] if r["n_cases"] == s["goals"]["cases"])
    first = judged[0]
    assert first.status == ("reached" if at["wall"] <= at["goal"] else "not reached")
    at["wall"] = at["goal"] * 1.01
    s["latencies"]["help"] = s["goals"]["help"] * 2
    s["validate"] = {"n_cases": 10**6, "failed": "campipe validate failed: no memory"}
    worse = goals.goals(s)
    assert worse[0].status == "not reached" and worse[1].status == "not reached"
    assert worse[1].figure == f"{goals.format_short(s['goals']['help'] * 2, 2)} s"
    assert (worse[-1].status, worse[-1].note) == (
        "not shown",
        "campipe validate failed: no memory",
    )
    del s["first_run"]
    assert [g.what for g in goals.goals(s)][-2] == (
        f"the quickstart from a fresh install under {goals.format_short(s['goals']['first_run'])} s"
    )
    assert len(goals.goals(s)) == 6  # no second install without a first run


def test_validate_s_estimate_and_the_run_each_in_a_fresh_process(tmp_path):
    """``benchmarks.fresh``: a bundled study's estimate and its run, each timed in a process
    of its own that loads the engine (the full run's table of estimates; --quick leaves it
    out): both positive, the run's archive written, neither process this one."""
    import campipe.engine.batch as batch
    from benchmarks import fresh

    spec = ROOT / "studies" / "thesis-member-loads.yaml"
    before = batch.train_modal.cache_info().misses
    row = fresh.estimate_and_run(spec, tmp_path / "a.nc", 2)
    assert (row["study"], row["cases"]) == ("thesis-member-loads.yaml", 1)
    assert row["estimate"] > 0 and row["measured"] > 0 and (tmp_path / "a.nc").exists()
    assert batch.train_modal.cache_info().misses == before  # nothing ran here
