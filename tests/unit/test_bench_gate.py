"""The bench's regression gate (issue 34): a run's timed figures against the previous run's on
the same machine, on synthetic bench.json dicts (no timing is measured or asserted)."""

import json
from pathlib import Path

import pytest

from campipe.bench import gate, measure, onset, pages, report, verdict
from campipe.bench.run import Bench
from campipe.bench.suite import QUICK

MACHINE = {
    "machine": "x86_64, 2 cores, Linux",
    "processor": "AMD EPYC",
    "numpy": "2.4.6",
    "numba": "0.68.1",
}
COMMITTED = Path(__file__).parents[2] / "docs" / "bench" / "bench.json"


def _row(scene: str, family: str, setting: str, seconds: float) -> dict:
    return {"scene": scene, "family": family, "setting": setting, "seconds": seconds}


def _run(times: dict[str, float], quick: bool = False, date: str = "then", **meta) -> dict:
    """A bench.json as a dict: on scenes a, b, c, d the default's time from ``times``, a
    solve_ivp row on a, a throughput batch and a scaling point."""
    return {
        "quick": quick,
        "meta": {
            **MACHINE,
            "date": date,
            "scenes": {s: {"description": s, "revolutions": 2} for s in times},
            **meta,
        },
        "rows": [_row(s, "modal-exact", "tol 1e-12 s", t) for s, t in times.items()]
        + [_row("a", "solve_ivp", "Radau rtol 1e-10", 9.0)],
        "throughput": [
            {
                "integrator": "newmark-linear",
                "n_cases": 256,
                "workers": 2,
                "revolutions": 4.0,
                "seconds": 0.5,
            }
        ],
        "scaling": [{"layer": "engine", "n_cases": 10, "workers": 1, "seconds": 0.02}],
    }


PREVIOUS = _run({"a": 1e-3, "b": 1e-3, "c": 1e-3, "d": 2e-3})


def _new(times: dict[str, float], **kw) -> Bench:
    return Bench(**_run(times, date="now", **kw))


def test_a_figure_more_than_ten_per_cent_slower_is_named_with_both_times():
    # a 11 % slower, b 9 % slower, c faster, d unchanged
    new = _new({"a": 1.11e-3, "b": 1.09e-3, "c": 0.5e-3, "d": 2e-3})
    block, regressions = gate.compare(new, PREVIOUS, "old/bench.json")
    assert gate.SLOWER == 0.10
    assert [(r["scene"], r["figure"]) for r in regressions] == [("a", "modal-exact, tol 1e-12 s")]
    (a,) = regressions
    assert (a["previous"], a["new"], a["turns"]) == (1e-3, 1.11e-3, 2)
    assert a["ratio"] == pytest.approx(1.11)
    # 4 scenes' defaults, the throughput batch and the scaling point; not solve_ivp's time
    assert (block["status"], block["compared"], block["faster"]) == ("compared", 6, 1)
    assert (block["date"], block["machine"], block["quick"]) == ("then", MACHINE["machine"], False)
    assert {f["scene"]: f["seconds"] for f in block["figures"]} == {
        "a": 1e-3,
        "b": 1e-3,
        "c": 1e-3,
        "d": 2e-3,
        "throughput": 0.5,
        "scaling": 0.02,
    }


def test_the_throughput_and_scaling_figures_are_gated_too():
    new = Bench(**_run({"a": 1e-3, "b": 1e-3, "c": 1e-3, "d": 2e-3}))
    new.throughput[0]["seconds"] = 0.6  # 20 % slower
    new.scaling[0]["seconds"] = 0.021  # 5 % slower
    _, regressions = gate.compare(new, PREVIOUS, "old/bench.json")
    assert [(r["scene"], r["figure"], r["ratio"]) for r in regressions] == [
        ("throughput", "newmark-linear, 256 cases × 4 turns, 2 workers", pytest.approx(1.2))
    ]


def test_regressions_are_listed_slowest_first_and_their_scenes_named():
    new = _new({"a": 1.2e-3, "b": 1.5e-3, "c": 1e-3, "d": 2.3e-3})
    block, regressions = gate.compare(new, PREVIOUS, "old/bench.json")
    assert [r["scene"] for r in regressions] == ["b", "a", "d"]
    assert [r["ratio"] for r in regressions] == pytest.approx([1.5, 1.2, 1.15])
    bench = new
    bench.previous, bench.regressions = block, regressions
    assert gate.slower_scenes(bench) == ["b", "a", "d"]
    assert gate.summary(bench) == (
        "Against the previous run (old/bench.json, then), on the same machine and versions "
        "(machine, processor, numpy, numba): 3 of 6 timed figures more than 10 % slower, on b, "
        "a, d (0 more than 10 % faster)."
    )
    lines = gate.text(bench)
    assert lines[1] == "  slower  b: modal-exact, tol 1e-12 s: 1 ms → 1.5 ms (1.5×)"
    assert len(lines) == 4


def test_another_machine_names_none_and_says_why():
    new = _new({"a": 2e-3, "b": 2e-3, "c": 2e-3, "d": 4e-3}, numba="0.69.0")
    block, regressions = gate.compare(new, PREVIOUS, "old/bench.json")
    assert regressions == [] and block["status"] == gate.OTHER_MACHINE
    assert block["reason"] == (
        "the previous run was on another machine or versions (numba 0.68.1 then, 0.69.0 now)"
    )
    assert len(block["figures"]) == 6  # kept all the same
    new.previous, new.regressions = block, regressions
    assert gate.summary(new).startswith("Not compared with the previous run (old/bench.json, then)")
    assert gate.summary(new).endswith("; no figure is named slower.")
    other = _new({"a": 2e-3}, machine="arm64, 8 cores, Darwin")
    assert (
        "machine x86_64, 2 cores, Linux then, arm64, 8 cores, Darwin now"
        in (gate.compare(other, PREVIOUS, "p")[0]["reason"])
    )
    # one architecture and core count, another processor: not the same machine either
    intel = _new({"a": 2e-3}, processor="Intel Xeon")
    assert (
        "processor AMD EPYC then, Intel Xeon now" in gate.compare(intel, PREVIOUS, "p")[0]["reason"]
    )


def test_a_quick_run_is_compared_only_with_a_quick_run():
    slow = {"a": 2e-3, "b": 2e-3, "c": 2e-3, "d": 4e-3}
    block, regressions = gate.compare(_new(slow, quick=True), PREVIOUS, "p")
    assert regressions == [] and block["status"] == gate.OTHER_KIND
    assert block["reason"].startswith("the previous run was a full run, this one a --quick run")
    quick = _run({"a": 1e-3, "b": 1e-3, "c": 1e-3, "d": 2e-3}, quick=True)
    block, regressions = gate.compare(_new(slow, quick=True), quick, "p")
    assert block["status"] == gate.COMPARED and len(regressions) == 4


def test_figures_of_other_turns_or_scenes_are_not_matched():
    previous = _run({"a": 1e-3})
    previous["meta"]["scenes"]["a"]["revolutions"] = 1.5
    block, regressions = gate.compare(_new({"a": 5e-3}), previous, "p")
    # the throughput and scaling figures still match; the scene's turns differ
    assert (block["status"], block["compared"], regressions) == ("compared", 2, [])
    block, _ = gate.compare(_new({"e": 5e-3}), {**_run({"f": 1e-3}), "throughput": []}, "p")
    assert block["status"] == gate.COMPARED and block["compared"] == 1  # the scaling point
    bare = {"quick": False, "meta": dict(MACHINE), "rows": []}
    block, _ = gate.compare(_new({"e": 5e-3}), bare, "p")
    assert block["status"] == gate.NOTHING_IN_COMMON and block["compared"] == 0


def test_a_missing_or_unreadable_previous_file_is_said(tmp_path):
    bench = _new({"a": 1e-3})
    missing = report.with_previous(bench, tmp_path / "none.json")
    assert missing.previous["status"] == gate.NO_PREVIOUS and missing.regressions == []
    assert gate.summary(missing) == f"No previous run to compare with: no {tmp_path}/none.json."
    assert bench.previous == {}  # the run itself is left as it was
    broken = tmp_path / "bench.json"
    broken.write_text("{")
    unread = report.with_previous(bench, broken)
    assert unread.previous["status"] == gate.UNREADABLE
    assert unread.previous["reason"].startswith(f"{broken} could not be read: ")
    # A run never compared (the committed run predates the gate) says so.
    assert gate.summary(bench) == (
        "No previous run to compare with: this run's bench.json keeps none."
    )


def test_the_report_keeps_the_previous_figures_beside_the_new_ones(tmp_path):
    """write_report reads the folder's bench.json (here the committed full run) before
    overwriting it: the new json holds the new rows, the previous run's figures and the figures
    named slower; bench.md, the pages' block and the verdict name the scene."""
    (tmp_path / "bench.json").write_bytes(COMMITTED.read_bytes())
    previous = json.loads(COMMITTED.read_text())
    new = report.read_json(COMMITTED)
    new.meta["date"] = "now"
    # A run just measured: not compared yet (the committed run keeps its own comparison).
    new.previous, new.regressions = {}, []
    row = next(r for r in new.rows if r["scene"] == "seat-13205" and r.get("default"))
    was = row["seconds"]
    row["seconds"] = was * 1.25
    report.write_report(new, tmp_path, with_plot=False)
    written = json.loads((tmp_path / "bench.json").read_text())
    assert written["meta"]["date"] == "now"
    assert written["previous"]["date"] == previous["meta"]["date"]
    assert written["previous"]["source"] == str(tmp_path / "bench.json")
    new_row = next(r for r in written["rows"] if r["scene"] == "seat-13205" and r["default"])
    assert new_row["seconds"] == was * 1.25
    kept = {(f["scene"], f["figure"]): f["seconds"] for f in written["previous"]["figures"]}
    figure = f"modal-exact, {row['setting']}"
    assert kept["seat-13205", figure] == was
    assert len(kept) == written["previous"]["compared"] == len(gate.figures(previous))
    assert [(r["scene"], r["figure"], r["previous"], r["new"]) for r in written["regressions"]] == [
        ("seat-13205", figure, was, was * 1.25)
    ]
    back = report.read_json(tmp_path / "bench.json")
    block = pages.regressions_block(back)
    assert f"1 of {len(kept)} timed figures more than 10 % slower, on seat-13205 " in block
    assert f"| seat-13205 | {figure} | " in block and " | 1.25× |" in block
    new.meta["load_average_at_start"] = 1.5
    load = pages.format_short(previous["meta"]["load_average_at_start"], 2)
    assert f"faster); load average {load} then, 1.5 now.\n" in pages.regressions_block(
        report.with_previous(new, COMMITTED)
    )
    md = (tmp_path / "bench.md").read_text()
    assert "## Against the previous run\n\n" + block in md
    assert f"  slower  seat-13205: {figure}: " in verdict.text(back)
    # --previous: another file than the folder's, read as given; nothing slower there
    other = tmp_path / "elsewhere.json"
    previous["meta"]["date"] = "long ago"
    previous["rows"] = [{**r, "seconds": 2 * r["seconds"]} for r in previous["rows"]]
    other.write_text(json.dumps(previous))
    fresh = report.read_json(COMMITTED)
    fresh.previous, fresh.regressions = {}, []
    report.write_report(fresh, tmp_path / "out", False, previous=other)
    again = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert again["previous"]["date"] == "long ago" and again["regressions"] == []
    engine = [r for r in previous["rows"] if r["family"] != "solve_ivp"]
    assert again["previous"]["faster"] == len(engine)


def test_the_committed_run_s_figures():
    """Each kind of timed figure of the committed full run, and not the peer's."""
    run = json.loads(COMMITTED.read_text())
    found = {(f["scene"], f["figure"]): f for f in gate.figures(run)}
    default = next(r for r in run["rows"] if r["scene"] == "separation-11000" and r["default"])
    f = found["separation-11000", f"modal-exact, {default['setting']}"]
    assert (f["seconds"], f["turns"]) == (default["seconds"], 2)
    t = next(t for t in run["throughput"] if t["workers"] == 2 and t["integrator"] == "modal-exact")
    assert (
        found["throughput", "modal-exact, 256 cases × 4 turns, 2 workers"]["seconds"]
        == (t["seconds"])
    )
    p = next(p for p in run["scaling"] if p["n_cases"] == 1000 and p["workers"] == 2)
    assert found["scaling", "engine, 1000 cases, 2 workers"]["seconds"] == p["seconds"]
    assert found["onset map", "1000 designs, 2 workers"]["seconds"] == run["onset"]["seconds"]
    applies = [s for s in run["steady"] if s["applies"]]
    assert applies and all((s["scene"], "steady state, one turn") in found for s in applies)
    assert not [k for k in found if "solve_ivp" in k[1] or "Radau" in k[1]]
    engine = [r for r in run["rows"] if r["family"] != "solve_ivp"]
    assert len([k for k in found if k[0] in run["meta"]["scenes"]]) == len(engine) + 2 * len(
        applies
    )


def test_a_cheap_setting_is_timed_more_often_than_an_expensive_one(monkeypatch):
    """``measure.time_engine`` times a batch ``repeats`` times, and more (up to MAX_REPEATS)
    while the repeats take less than ``batch_seconds``: a cheap setting's best is not a best of
    three. Counted on a stand-in engine that returns the same result at once (no time is
    asserted). Broken copy: ``for _ in range(repeats)`` (three runs for any setting) fails
    the first count; a loop without MAX_REPEATS never ends."""
    from campipe.bench import measure
    from campipe.bench.suite import suite
    from campipe.engine import RunSettings

    scene = suite()[0]
    result = measure.run_batch([scene.case], RunSettings(revolutions=scene.revolutions))
    calls = []

    def stand_in(cases, settings, full_state=True):
        calls.append(len(cases))
        return result

    monkeypatch.setattr(measure, "run_batch", stand_in)
    measure.time_engine(scene, RunSettings(), max_copies=4, repeats=3)
    assert len(calls) == 1 + measure.MAX_REPEATS  # the untimed run, then the repeats
    calls.clear()
    measure.time_engine(scene, RunSettings(), max_copies=4, repeats=3, batch_seconds=0.0)
    assert len(calls) == 1 + 3


def test_a_figure_named_slower_is_timed_again_and_named_only_if_slower_again():
    """``gate.confirm``: b (1.5×) timed again at 1.45 ms stays named, with that time; a
    (1.2×) timed again at 1.05 ms, within 10 % of the previous 1 ms, is no longer named and is
    listed as such; d (1.15×), which cannot be timed again (None), stays named on the run's
    time. The run's own figures are unchanged. Broken copies: the second time compared with
    the run's own (b's 1.45 ms within 10 % of its 1.5: no longer named); the least of the two
    times written into the run's figures."""
    new = _new({"a": 1.2e-3, "b": 1.5e-3, "c": 1e-3, "d": 2.3e-3})
    block, regressions = gate.compare(new, PREVIOUS, "old/bench.json")
    new.previous, new.regressions = block, regressions
    again = {"a": 1.05e-3, "b": 1.45e-3, "d": None}
    asked = []

    def retime(r):
        asked.append(r["scene"])
        return again[r["scene"]]

    confirmed = gate.confirm(new, retime)
    assert asked == ["b", "a", "d"]
    assert [(r["scene"], r["again"]) for r in confirmed.regressions] == [
        ("b", 1.45e-3),
        ("d", None),
    ]
    assert confirmed.previous["not_again"] == [
        {"scene": "a", "figure": "modal-exact, tol 1e-12 s", "turns": 2, "new": 1.2e-3,
         "again": 1.05e-3}
    ]  # fmt: skip
    assert [r["seconds"] for r in confirmed.rows][:4] == [1.2e-3, 1.5e-3, 1e-3, 2.3e-3]
    lines = gate.text(confirmed)
    assert (
        lines[1]
        == "  slower  b: modal-exact, tol 1e-12 s: 1 ms → 1.5 ms (1.5×), timed again 1.45 ms"
    )
    assert lines[2] == "  slower  d: modal-exact, tol 1e-12 s: 2 ms → 2.3 ms (1.15×)"
    assert lines[0].endswith(
        "; 1 more, more than 10 % slower in the run, were timed again and then were not "
        "(a: modal-exact, tol 1e-12 s 1.2 ms, again 1.05 ms)."
    )
    assert "| b | modal-exact, tol 1e-12 s | 1 ms | 1.5 ms | 1.5× | 1.45 ms |" in gate.markdown(
        confirmed
    )
    plain = _new({"a": 1e-3})
    assert gate.confirm(plain, retime) is plain and len(asked) == 3  # none named: none asked


def test_the_retimer_times_the_engine_s_figures_again_and_not_the_others(monkeypatch):
    """``campipe.bench.retime``: a scene's ladder row and steady path, a throughput batch, a
    scaling point and the onset map and its grid are timed again (a positive time); the speed
    sweep's, a scene of other turns and an unknown figure are not (None). The onset map is
    timed again on the run's designs, as many times as the run's ladder times it, and its
    grid's figure is the designs × the grid's speeds × the time a case over the workers
    (broken copies: the full map's 1000 designs for a quick run; the grid's time a case
    given as its figure). A ladder row is timed as the run timed it:
    "contacts only" with the contact coordinates alone (broken copy: ``full_state`` handed in
    as ``time_engine``'s fifth argument, its batch's seconds: the full state timed on one
    copy, 1.7 times the run's time on flat-15000)."""
    from campipe.bench.retime import retimer

    bench = _new({"smooth-9000": 1e-3})
    bench.quick = True
    bench.throughput[0].update(n_cases=4, revolutions=0.5)
    bench.scaling[0].update(n_cases=2)
    retime = retimer(bench)
    row = {"scene": "smooth-9000", "figure": "modal-exact, tol 1e-12 s", "turns": 1.5}
    assert retime(row) > 0
    assert retime({**row, "turns": 7}) is None
    for figure in (gate.STEADY_MARGIN, gate.STEADY_TURN):  # the cam followed: a steady state
        assert retime({**row, "figure": figure}) > 0
    figure = gate.throughput_name(bench.throughput[0])
    assert retime({"scene": "throughput", "figure": figure}) > 0
    figure = gate.scaling_name(bench.scaling[0])
    assert retime({"scene": "scaling", "figure": figure}) > 0
    assert retime({"scene": "speed sweep", "figure": "32 one-case calls"}) is None
    bench.onset = {"designs": 16, "workers": 2, "grid_speeds": onset.GRID_SPEEDS}
    retime = retimer(bench)
    map_figure = {"scene": "onset map", "figure": gate.map_name(bench.onset)}
    grid_figure = {"scene": "onset map", "figure": gate.grid_name(bench.onset)}
    assert retime(map_figure) > 0 and retime(grid_figure) > 0
    asked = []

    def map_seconds(designs, repeats):
        asked.append((len(designs), repeats))
        return 0.5

    monkeypatch.setattr(onset, "map_seconds", map_seconds)
    monkeypatch.setattr(onset, "grid_per_case", lambda designs, repeats: 1e-3)
    assert retime(map_figure) == 0.5 and asked == [(16, QUICK.repeats)]
    assert retime(grid_figure) == pytest.approx(16 * onset.GRID_SPEEDS * 1e-3 / 2)
    timed = []

    def time_engine(scene, settings, copies, repeats, batch_seconds=0.2, full_state=True):
        timed.append((scene.revolutions, settings.method, batch_seconds, full_state))
        return 1e-3, None, 0

    monkeypatch.setattr(measure, "time_engine", time_engine)
    assert retime({**row, "figure": "contacts only, full"}) == 1e-3
    assert retime({**row, "figure": "newmark-linear, dt 1 µs"}) == 1e-3
    assert timed == [(1.5, "modal-exact", 0.2, False), (1.5, "newmark-linear", 0.2, True)]
    assert retime({"scene": "smooth-9000", "figure": "modal-exact, tol 7 s"}) is None
