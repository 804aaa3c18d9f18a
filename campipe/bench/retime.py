"""The regression gate's second look (``campipe.bench.gate.confirm``): a figure the gate is
about to name slower, timed once more now, the way the run timed it.

Timed again: a scene's engine runs (``measure.time_engine`` at the row's setting), its
steady-state path (``onset.steady_times``), the throughput batches (``scaling.throughput``),
the engine's scaling points (``scaling.engine_scaling``) and the onset map and its
time-domain grid (``onset.map_seconds``, ``onset.grid_per_case``). Not timed again (None: the
gate names them on the run's timing alone): the speed sweep and the first run, each timed as
a part of a whole that takes tens of seconds to a minute.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from campipe.bench import gate, measure, onset, scaling
from campipe.bench.onset import steady_times
from campipe.bench.run import QUICK_REVOLUTIONS, Bench, settings_rows, throughput_repeats
from campipe.bench.suite import FULL, QUICK, Scene, suite


def retimer(bench: Bench) -> Callable[[dict], float | None]:
    """A function of one of ``bench``'s regressions (``gate.compare``) to its figure's
    seconds timed again now, or None where the figure is not timed again (the module)."""
    ladder = QUICK if bench.quick else FULL
    scenes = {s.name: s for s in suite()}
    settings = {
        f"{family}, {label}": (s, full_state)
        for family, label, s, full_state in settings_rows(ladder)
    }
    repeats = throughput_repeats(bench.quick)
    timers: dict[tuple[str, str], Callable[[], float]] = {}
    for t in bench.throughput:
        timers["throughput", gate.throughput_name(t)] = functools.partial(_throughput, t, repeats)
    for p in bench.scaling:
        if p["layer"] == "engine":
            timers["scaling", gate.scaling_name(p)] = functools.partial(_scaling, p)
    if bench.onset:  # as run_bench's onset.onset_map
        o = bench.onset
        timers["onset map", gate.map_name(o)] = functools.partial(_map, bench.quick, ladder.repeats)
        timers["onset map", gate.grid_name(o)] = functools.partial(
            _grid, bench.quick, ladder.repeats
        )

    def retime(regression: dict) -> float | None:
        scene, figure = regression["scene"], regression["figure"]
        if (scene, figure) in timers:
            return timers[scene, figure]()
        steady = figure in (gate.STEADY_MARGIN, gate.STEADY_TURN)
        if scene not in scenes or not (steady or figure in settings):
            return None
        s = scenes[scene]
        turns = QUICK_REVOLUTIONS if bench.quick else s.revolutions
        if regression.get("turns") not in (None, turns):
            return None  # another kind of scene than this suite's
        if steady:
            margin, turn = steady_times(s.case, ladder.copies, ladder.repeats)
            return margin if figure == gate.STEADY_MARGIN else turn
        run, full_state = settings[figure]
        one = Scene(s.name, s.description, s.case, turns)
        seconds, _, _ = measure.time_engine(
            one, run, ladder.copies, ladder.repeats, full_state=full_state
        )
        return seconds

    return retime


def _throughput(t: dict, repeats: int) -> float:
    return scaling.throughput(
        t["n_cases"], t["workers"], t["integrator"], t["revolutions"], repeats
    ).seconds


def _map(quick: bool, repeats: int) -> float:
    return onset.map_seconds(onset.run_designs(quick), repeats)


def _grid(quick: bool, repeats: int) -> float:
    designs = onset.run_designs(quick)
    return onset.grid_seconds(len(designs), onset.grid_per_case(designs, repeats))


def _scaling(p: dict) -> float:
    return scaling.engine_scaling([p["n_cases"]], [p["workers"]])[0].seconds
