"""The cost of automatic run length (``run.revolutions: auto``) on the bench: a sweep through
the onset run until each case repeats, against the same sweep run a fixed 4 turns, and what
the fixed run's no-follow misses.

Pure numerics: it times runs but writes nothing.
"""

from __future__ import annotations

import math
import time

import numpy as np

from campipe.constants import INCH, RPM
from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic

#: The sweep: the thesis train, harmonic cam 1 in, speeds through its no-follow onset (about
#: 9524 rpm without a seat), without a seat and with one at 0.1 in; run in batches of BATCH.
SPEEDS_RPM = (7000.0, 15000.0)
SEATS = (math.nan, 0.1 * INCH)
FULL_SPEEDS, QUICK_SPEEDS = 500, 50
BATCH = 100
FIXED_TURNS = 4
#: A fixed run's no-follow counts as off where it differs from the settled one by more than
#: this (relative): the agreement the settled runs are held to (tests/integration).
OFF = 0.02


def sweep(quick: bool) -> list[Case]:
    """The sweep's cases, seat innermost."""
    speeds = np.linspace(*SPEEDS_RPM, QUICK_SPEEDS if quick else FULL_SPEEDS)
    train, profile = thesis_train(), harmonic(1.0 * INCH)
    return [Case(train, profile, s * RPM, seat) for s in speeds for seat in SEATS]


def _timed(cases: list[Case], settings: RunSettings, repeats: int):
    # the kernels loaded (or compiled) before the clock starts
    run_batch(cases[:2], settings, full_state=False, on_failure="record")
    best, results = math.inf, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        results = [
            run_batch(cases[i : i + BATCH], settings, full_state=False, on_failure="record")
            for i in range(0, len(cases), BATCH)
        ]
        best = min(best, time.perf_counter() - t0)
    return best, results


def settling_cost(quick: bool = False, repeats: int = 2) -> dict:
    """Seconds of the sweep at a fixed 4 turns and until settled, how the cases settled, and
    how far the fixed run's no-follow per turn is from the settled one."""
    cases = sweep(quick)
    fixed_s, fixed = _timed(cases, RunSettings(revolutions=FIXED_TURNS), repeats)
    auto_s, auto = _timed(cases, RunSettings(revolutions=None), repeats)
    period = np.concatenate([r.period_turns for r in auto])
    turns = np.concatenate([r.turns_run for r in auto])
    sep_fixed = np.concatenate([r.separation for r in fixed])
    sep_auto = np.concatenate([r.separation for r in auto])
    off_cam = sep_auto > 0
    rel = np.abs(sep_fixed[off_cam] / sep_auto[off_cam] - 1.0)
    return {
        "cases": len(cases),
        "speeds_rpm": list(SPEEDS_RPM),
        "seats_in": ["none" if math.isnan(s) else s / INCH for s in SEATS],
        "fixed_turns": FIXED_TURNS,
        "fixed_seconds": fixed_s,
        "auto_seconds": auto_s,
        "ratio": auto_s / fixed_s,
        "periods": {str(p): int(np.count_nonzero(period == p)) for p in np.unique(period)},
        "mean_turns": float(turns.mean()),
        "one_turn": int(np.count_nonzero(turns == 1)),
        "separating": int(off_cam.sum()),
        "fixed_off": int(np.count_nonzero(rel > OFF)),
        "fixed_worst": float(rel.max()) if rel.size else 0.0,
        "fixed_median": float(np.median(rel)) if rel.size else 0.0,
    }


def markdown(result: dict) -> str:
    """The measurement in words, or why there is none."""
    if not result:
        return "Not measured in this run (`campipe bench` without `--scenes`, a later run)."
    r = result
    periods = ", ".join(
        f"{n} {'did not repeat' if p == '0' else f'period {p}'}" for p, n in r["periods"].items()
    )
    return "\n".join(
        [
            f"- **{r['cases']} cases** through the onset (thesis train, harmonic cam 1 in, "
            f"{r['speeds_rpm'][0]:g}–{r['speeds_rpm'][1]:g} rpm, seat none and 0.1 in): "
            f"**{r['auto_seconds']:.2f} s** until each repeats against "
            f"**{r['fixed_seconds']:.2f} s** at a fixed {r['fixed_turns']} turns "
            f"(**{r['ratio']:.2f}×**), one process.",
            f"- How they settled: {periods}; {r['mean_turns']:.1f} turns a case on average, "
            f"{r['one_turn']} in one turn (they follow the cam: no slower than a fixed run).",
            f"- What the fixed {r['fixed_turns']} turns miss: of {r['separating']} cases that "
            f"leave the cam, {r['fixed_off']} are more than {OFF:.0%} off the settled no-follow "
            f"(median {r['fixed_median']:.1%}, worst {r['fixed_worst']:.0%}).",
        ]
    )
