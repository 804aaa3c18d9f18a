"""campipe validate's estimate: a sample of the study run through run_study and scaled (how it
compares with a run on the bundled studies is campipe bench's to show, not a timed test)."""

from collections import Counter

import numpy as np
import pytest
from click.testing import CliRunner
from study_helpers import write_spec

import campipe.engine
import campipe.study.run.estimate as est
from campipe.cli import main
from campipe.study import load_study

SPEC = """
name: e
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 1, output_every: 4 deg}
sweep:
  speed: {from: 6000 rpm, to: 12000 rpm, num: 25}
  seat: [none, 0.1 in]
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return load_study(write_spec(tmp_path_factory.mktemp("e"), SPEC))


def test_the_sample_is_one_batch_per_worker_spread_through_the_study(study):
    assert len(study.cases) == 50
    size = est.batch_size(study, 50, 2)
    assert est.sample_size(study, 2) == size * 2 == 14  # batches of 7: four per worker
    sample = est.sample_cases(study, 14)
    index = [c.index for c in sample]
    assert index[0] == 0 and index[-1] == 49 and np.all(np.diff(index) >= 3)
    speeds = {c.case.speed for c in sample}
    seats = {np.isnan(c.case.seat) for c in sample}
    assert len(speeds) >= 7 and seats == {True, False}


def test_the_estimate_scales_the_sample_beyond_the_fixed_cost(study, monkeypatch):
    """first: a one-case run in a fresh process; again: the same warm; the sample's run
    beyond it scales with the cases (50 / 14), and so does its engine calls' time."""
    runs = {1: [(0.30, 0.05), (0.10, 0.01)], 14: [(0.80, 0.14)]}
    calls = []

    def time_run(s, cases, workers, size=None):
        calls.append((len(cases), size))
        return runs[len(cases)].pop(0)

    monkeypatch.setattr(est, "time_run", time_run)
    monkeypatch.setattr(est, "warm_up", lambda s: 0.25)
    e = est.estimate(study, 2)
    assert calls == [(1, None), (1, None), (14, 7)]  # the sample in the study's batches
    assert e.seconds == pytest.approx(0.25 + 0.30 + (0.80 - 0.10) * 50 / 14)
    assert e.engine == pytest.approx(0.14 / 2 * 50 / 14)  # two batches, two workers
    assert e.engine + e.layer + e.startup == pytest.approx(e.seconds)
    assert e.sample == 14 and e.workers == 2


def test_a_long_study_is_timed_on_two_short_runs_and_extrapolated(tmp_path, monkeypatch):
    """A study of 40 turns a case is timed on runs of 1 and of 3 turns (its warm-up 0), the 37
    turns beyond extrapolated at the difference per turn: a run costing F + P·turns (here
    made so) is estimated at F + 40·P, its engine likewise, each short run in the batches of
    the study's 40 turns; run whole when its 3 turns scaled to 40 are cheap.
    Broken copies: the run timed for its 40 turns (the calls' turns), the extrapolation from
    the longer run alone (3 → 40 turns scales F too)."""
    spec = SPEC.replace("num: 25", "num: 3").replace("revolutions: 1,", "revolutions: 40,")
    long = load_study(write_spec(tmp_path, spec))
    turns, sizes = [], []

    def time_run(s, cases, workers, size=None):
        n = {c.settings.revolutions for c in cases} | {s.revolutions}
        assert len(n) == 1 and len(cases) == len(s.cases)  # the study's and its cases' turns
        turns.append(n.pop())
        sizes.append(size)
        return 0.3 + 0.1 * turns[-1], 0.02 * turns[-1]

    monkeypatch.setattr(est, "time_run", time_run)
    monkeypatch.setattr(est, "warm_up", lambda s: 0.0)
    e = est.estimate(long, 2)
    assert turns == [3.0, 1.0] and e.turns == (1, 3)
    assert sizes == [est.batch_size(long, 6, 2)] * 2  # the 40 turns' batches, not 1 or 3's
    assert e.seconds == pytest.approx(0.3 + 0.1 * 40)
    assert e.engine == pytest.approx(0.02 * 40 / est.busy_workers(long, long.cases, 2))
    turns.clear()  # cheap turns: 0.3 + 0.1·3 s scaled to 40 turns is 8 s
    monkeypatch.setattr(est, "WHOLE_SECONDS", 8.5)
    assert est.estimate(long, 2).turns is None and turns == [3.0, 40.0]  # then run whole
    for short in (1, 5):  # shorter than twice the longer run's 3 turns: timed as it is
        text = spec.replace("revolutions: 40,", f"revolutions: {short},")
        study_ = load_study(write_spec(tmp_path, text))
        assert est.timed_turns(study_, study_.cases) is None


def test_validate_says_a_long_study_s_turns_were_extrapolated(tmp_path, monkeypatch):
    monkeypatch.setattr(est, "WHOLE_SECONDS", 0.0)  # (its cases are cheap: run whole)
    spec = SPEC.replace("num: 25", "num: 2").replace("revolutions: 1,", "revolutions: 12,")
    out = CliRunner().invoke(main, ["validate", str(write_spec(tmp_path, spec)), "--workers", "1"])
    assert out.exit_code == 0, out.output
    line = next(x for x in out.output.splitlines() if x.startswith("run time:"))
    assert "(timed on runs of the whole study for 1 and for 3 of its 12 turns, the turns " in line


def case_key(case) -> tuple[float, bool]:
    """A case of SPEC's studies by its axes: its speed and whether it has a seat."""
    return case.speed, bool(np.isnan(case.seat))


def counted_engine(monkeypatch) -> Counter:
    """Case (:func:`case_key`) → times it ran through the engine at the run's fidelity
    (``campipe.engine.run_at_fidelity``: what a study's batch calls)."""
    ran: Counter = Counter()
    engine = campipe.engine.run_at_fidelity

    def run_at_fidelity(cases, settings, **options):
        ran.update(case_key(c) for c in cases)
        return engine(cases, settings, **options)

    monkeypatch.setattr(campipe.engine, "run_at_fidelity", run_at_fidelity)
    return ran


def test_a_small_study_is_timed_whole_each_case_run_once(tmp_path, monkeypatch):
    """The engine's share comes from the run itself: each case goes through the engine once.
    Fails if the estimate ran the study again (or the engine alone) to split its time."""
    small = load_study(write_spec(tmp_path, SPEC.replace("num: 25", "num: 3")))
    monkeypatch.setattr(est, "warm_up", lambda s: 0.0)
    ran = counted_engine(monkeypatch)
    e = est.estimate(small, 2)
    assert ran == Counter(case_key(c.case) for c in small.cases)  # each case, once
    assert e.sample == len(small.cases) == 6
    assert 0 < e.engine <= e.seconds
    assert e.engine + e.layer == pytest.approx(e.seconds)
    assert not list(tmp_path.glob("*.nc"))  # the timed run wrote only in a temporary folder


def test_a_large_study_runs_its_sample_once(study, monkeypatch):
    """50 cases on 2 workers: the sample's 14 cases run once, its first case twice more (the
    one-case runs, first and again), no other case. Fails if the sample ran again to time
    the engine."""
    monkeypatch.setattr(est, "warm_up", lambda s: 0.0)
    ran = counted_engine(monkeypatch)
    e = est.estimate(study, 2)
    sample = est.sample_cases(study, 14)
    assert ran == Counter(case_key(c.case) for c in sample + sample[:1] * 2)
    assert e.sample == 14
    assert 0 < e.engine <= e.seconds
    assert e.engine + e.layer == pytest.approx(e.seconds)


def test_validate_prints_the_estimate_with_its_parts(tmp_path):
    spec = write_spec(tmp_path, SPEC.replace("num: 25", "num: 2"))
    out = CliRunner().invoke(main, ["validate", str(spec), "--workers", "1"])
    assert out.exit_code == 0, out.output
    line = next(x for x in out.output.splitlines() if x.startswith("run time:"))
    assert "on 1 worker: the engine " in line and "storing and writing the archive" in line
    assert "(timed on a run of the whole study;" in line


def test_the_replay_selection_is_counted_and_one_case_timed(tmp_path):
    from campipe.replay.live import time_replay

    spec = write_spec(tmp_path, SPEC + 'replay: {where: "speed_rpm >= 11500 rpm"}\n')
    count, each = time_replay(load_study(spec), tmp_path)
    assert count == 6 and each > 0  # 11500, 11750, 12000 rpm, with and without a seat
    assert (tmp_path / "estimate.rrd").stat().st_size > 0
    spec.write_text(SPEC + 'replay: {where: "separation_deg_per_rev > 0"}\n')
    count, each = time_replay(load_study(spec), tmp_path)
    assert count is None and each > 0  # known only once the cases have run


def test_validate_states_the_memory_bound_of_the_batches_in_flight(tmp_path):
    """100 cases of 2 turns at 1° (721 samples) on 2 workers: batches of 13 cases (about four
    a worker: ⌈100 / 8⌉), at most 2 a worker in flight, so validate states 4 × 13 × 721 × 320
    bytes = 12.0 MB whatever the study's size; 10 cases (batches of 4, 3 of them) only 3
    batches. Fails if the bound counted every batch of the study, or more in flight than
    there are batches."""
    spec = """
name: mem
model: {preset: thesis-1971}
profile: {kind: harmonic, lift: 1 in}
seat: none
run: {revolutions: 2, output_every: 1 deg}
sweep:
  speed: {from: 3000 rpm, to: 9000 rpm, num: %d}
"""
    lines = {}
    for n in (100, 10):
        path = write_spec(tmp_path, spec % n, f"mem{n}.yaml")
        out = CliRunner().invoke(main, ["validate", str(path), "--no-estimate", "--workers", "2"])
        assert out.exit_code == 0, out.output
        lines[n] = next(t for t in out.output.splitlines() if t.startswith("memory:"))
    assert f"at most about {4 * 13 * 721 * 320 / 1e6:.3g} MB" in lines[100]
    assert "(4 batches of up to 13 cases: at most 2 a worker in flight" in lines[100]
    assert f"at most about {3 * 4 * 721 * 320 / 1e6:.3g} MB" in lines[10]
    assert "each case 721 samples × 320 bytes" in lines[10]


SLOW_IMPORT = """
import importlib.abc, sys, time
from pathlib import Path

class Slow(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):  # the engine's import made 2 s longer
        if name == "campipe.engine.batch":
            time.sleep(2.0)
        return None

from campipe.study import load_study
from campipe.study.run.estimate import warm_up
study = load_study(Path(sys.argv[1]))
assert "campipe.engine.batch" not in sys.modules and "numba" not in sys.modules
sys.meta_path.insert(0, Slow())
if sys.argv[2] == "warm_up":
    print(warm_up(study))
else:
    from campipe.cli import main
    main(["validate", sys.argv[1]], standalone_mode=False)
"""


@pytest.mark.parametrize("how", ["warm_up", "validate"])
def test_the_start_up_counts_the_engine_s_import(tmp_path, how):
    """A study's process imports the engine's batch module (and numba) before it loads a
    kernel, and validate's start-up counts it where its process has not imported it yet
    (0.18 s here): with the import made 2 s longer, the start-up is 2 s or more, from
    ``warm_up`` and in ``campipe validate``'s line (which compiles the kernels first).
    Broken copies: the import outside the timing (the start-up then the tiny runs' alone,
    under 1 s a group); validate importing the engine before the estimate times it."""
    import re
    import subprocess
    import sys

    spec = write_spec(tmp_path, SPEC.replace("num: 25", "num: 2"))
    run = subprocess.run(
        [sys.executable, "-c", SLOW_IMPORT, str(spec), how], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr[-2000:]
    if how == "warm_up":
        assert float(run.stdout) >= 2.0
    else:
        found = re.search(r"loading the engine ([0-9.]+) s", run.stdout)
        assert found, run.stdout
        assert float(found.group(1)) >= 2.0
