"""The steady-state path on the bench: the closed form against the engine on the scenes that
follow the cam, and an onset map over many designs against the time-domain grid it replaces.

Pure numerics: it times runs but writes nothing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from campipe.bench.measure import OUTPUT_EVERY, reference
from campipe.bench.suite import Scene
from campipe.constants import INCH, LBF, RPM
from campipe.engine import Case, RunSettings, batch, onset, periodic, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.study.onset import search_designs

#: The onset map: preloads × spring rates of the thesis's train with the harmonic cam over
#: this speed range, to the default tolerance.
MAP_PRELOADS = np.linspace(120.0, 180.0, 25) * LBF
MAP_RATES = np.linspace(200.0, 300.0, 40) * LBF / INCH
MAP_RANGE = (6000.0 * RPM, 14000.0 * RPM)
QUICK_MAP = (4, 4)
#: The onset goal: the map of 1000 designs within this many seconds on this many workers.
GOAL_MAP_SECONDS = 1.0
GOAL_MAP_WORKERS = 2
#: The time-domain grid the map replaces: this many speeds a design, each run this many turns.
GRID_SPEEDS = 33
GRID_TURNS = 4
#: Onsets of the map checked by the time-domain engine either side (evenly spaced designs).
MAP_CHECKED = 32


def _best(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def steady_scenes(scenes: Sequence[Scene], copies: int, repeats: int) -> list[dict]:
    """Per scene: whether the closed form is its steady state (the follower on the cam, the
    valve off its seat all turn) and its margin; where it is, the per-case time of the margin
    alone and of one turn's histories, and the valve lift's largest difference from the
    reference's last turn."""
    rows = []
    n_turn = int(round(2 * math.pi / OUTPUT_EVERY)) + 1
    for scene in scenes:
        case = scene.case
        ext = periodic.steady_extremes([case])
        row: dict = {
            "scene": scene.name,
            "applies": bool(ext.holds[0]),
            "margin": float(ext.min_cam_force[0]),
            "seat_height": float(ext.min_seat_height[0]),
        }
        if ext.holds[0]:
            ss = periodic.steady_state([case], OUTPUT_EVERY)
            ref = reference(scene).valve_lift[-n_turn:]
            row["valve_lift"] = float(np.abs(ss.valve_lift[0] - ref).max())
            row["margin_seconds"], row["seconds"] = steady_times(case, copies, repeats)
        rows.append(row)
    return rows


def steady_times(case: Case, copies: int, repeats: int) -> tuple[float, float]:
    """The per-case time [s] of the steady state's margin alone and of one turn's histories,
    on a batch of ``copies`` of ``case``, each the least of ``repeats``."""
    many = [case] * copies
    periodic.steady_state(many[:1], OUTPUT_EVERY)
    margin = _best(lambda: periodic.steady_extremes(many), repeats)
    turn = _best(lambda: periodic.steady_state(many, OUTPUT_EVERY), repeats)
    return margin / copies, turn / copies


def map_designs(n_preloads: int | None = None, n_rates: int | None = None) -> list[Case]:
    """The map's designs: the thesis's train and harmonic cam, preloads × spring rates."""
    preloads = MAP_PRELOADS if n_preloads is None else np.linspace(120, 180, n_preloads) * LBF
    rates = MAP_RATES if n_rates is None else np.linspace(200, 300, n_rates) * LBF / INCH
    train = thesis_train()
    cam = harmonic(INCH)
    return [
        Case(train.replace(spring_preload=float(p), spring_rate=float(k)), cam, 1.0)
        for p in preloads
        for k in rates
    ]


def run_designs(quick: bool) -> list[Case]:
    """The designs a bench run maps: QUICK_MAP's for ``--quick``, else the whole map."""
    return map_designs(*QUICK_MAP) if quick else map_designs()


def _clear_caches() -> None:
    """The engine's per-train caches, so a timing includes each design's modes."""
    batch.train_modal.cache_clear()
    batch.train_matrices.cache_clear()


def map_seconds(designs: Sequence[Case], repeats: int) -> float:
    """The onset map of ``designs`` timed cold (the engine's per-train caches cleared, so
    each design's modes are computed), best of ``repeats``, on GOAL_MAP_WORKERS threads."""
    low, high = MAP_RANGE
    tol = onset.DEFAULT_ONSET_TOLERANCE_RPM * RPM
    search_designs(designs[:2], low, high, tol, GOAL_MAP_WORKERS)  # compiled kernels loaded

    def run():
        _clear_caches()
        return search_designs(designs, low, high, tol, GOAL_MAP_WORKERS)

    return _best(run, repeats)


def grid_per_case(designs: Sequence[Case], repeats: int) -> float:
    """The time-domain grid's cost per case [s]: ``run_batch`` at GRID_TURNS turns, contacts
    only, on a sample of 64 of ``designs`` × the grid's speeds, best of ``repeats``."""
    low, high = MAP_RANGE
    grid = np.linspace(low, high, GRID_SPEEDS)
    sample = [
        Case(designs[i].train, designs[i].profile, float(grid[k % GRID_SPEEDS]))
        for k, i in enumerate(np.linspace(0, len(designs) - 1, 64).round().astype(int))
    ]
    settings = RunSettings(revolutions=GRID_TURNS, output_every=OUTPUT_EVERY)
    # A design that flies off beyond the physical bounds at the top speeds ends early, as
    # the grid's own run of it would.
    run_batch(sample[:2], settings, full_state=False, on_failure="record")
    seconds = _best(
        lambda: run_batch(sample, settings, full_state=False, on_failure="record"), repeats
    )
    return seconds / len(sample)


def grid_seconds(n_designs: int, per_case: float) -> float:
    """The time-domain grid's time [s] for ``n_designs`` at ``per_case`` seconds a case, on
    GOAL_MAP_WORKERS workers."""
    return n_designs * GRID_SPEEDS * per_case / GOAL_MAP_WORKERS


def onset_map(quick: bool = False, repeats: int = 3) -> dict:
    """The onset map's cost (:func:`map_seconds`) and what the time-domain grid would cost
    for it (:func:`grid_per_case`): the grid that fits in the map's time has ``map seconds /
    (designs × per-case)`` speeds."""
    designs = run_designs(quick)
    low, high = MAP_RANGE
    tol = onset.DEFAULT_ONSET_TOLERANCE_RPM * RPM
    seconds = map_seconds(designs, repeats)
    found = search_designs(designs, low, high, tol, GOAL_MAP_WORKERS)
    pick = np.unique(np.linspace(0, len(designs) - 1, MAP_CHECKED).round().astype(int))
    below, above, _, _ = onset.confirm_onsets([designs[i] for i in pick], found.speed[pick])
    checked = np.isfinite(below)
    agree = int(((below == 0) & (above > 0))[checked].sum())
    per_case = grid_per_case(designs, repeats)
    n = len(designs)
    points = seconds / (n * per_case)
    return {
        "designs": n,
        "preloads_lbf": [float(MAP_PRELOADS[0] / LBF), float(MAP_PRELOADS[-1] / LBF)],
        "rates_lbf_per_in": [float(MAP_RATES[0] * INCH / LBF), float(MAP_RATES[-1] * INCH / LBF)],
        "range_rpm": [low / RPM, high / RPM],
        "tolerance_rpm": tol / RPM,
        "workers": GOAL_MAP_WORKERS,
        "seconds": seconds,
        "steady_states": int(found.evaluations.sum()),
        "found": int((found.status == "found").sum()),
        "checked": int(checked.sum()),
        "agree": agree,
        "grid_turns": GRID_TURNS,
        "grid_per_case": per_case,
        "grid_speeds": GRID_SPEEDS,
        "grid_seconds": grid_seconds(n, per_case),
        "grid_resolution_rpm": (high - low) / (GRID_SPEEDS - 1) / RPM,
        # Speeds a design the grid affords in the map's time on as many workers.
        "equal_time_speeds": points * GOAL_MAP_WORKERS,
        "equal_time_resolution_rpm": (
            (high - low) / (points * GOAL_MAP_WORKERS - 1) / RPM
            if points * GOAL_MAP_WORKERS > 1
            else math.inf
        ),
    }
