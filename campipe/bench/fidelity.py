"""Which fidelity level a scene needs: a short probe at full fidelity and at candidate cut-offs.

The reduced fidelity (``RunSettings(fidelity="reduced", mode_cutoff=…)``, modal-exact only)
keeps each configuration's modes up to the cut-off and the rest only through their
quasi-static response. Whether that is good enough depends on the scene: a slow, smooth scene
hardly excites the upper modes; an impact rings them all. The probe runs the cases for a few
turns at full fidelity and at each candidate cut-off, measures the valve-lift error of each
level against the full model, and times each level; the cheapest level within the tolerance
wins, and the full model unless a reduced level saves at least ``MIN_SAVING`` of its time.

Pure numerics: it times runs but writes nothing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from campipe.constants import INCH
from campipe.engine import Case, RunSettings, run_batch

#: Reduced-fidelity cut-offs tried [rad/s]: between the configurations' natural frequencies
#: (I: 1.29e4, 4.87e4, 1.46e5, 2.45e5, 5.14e5, 1.06e6 rad/s).
CANDIDATE_CUTOFFS = (3e4, 1e5, 2e5, 3e5, 6e5)
#: Cam turns a probe integrates (at most the run's own).
PROBE_REVOLUTIONS = 2.0
#: A reduced level must save this share of the full model's time to be chosen.
MIN_SAVING = 0.05
#: The reduced model's stated error on a slow scene: at 3000 rpm (the cam always in contact),
#: from the quasi-static start whose transient excites every mode, the default cut-off
#: (``campipe.engine.batch.DEFAULT_MODE_CUTOFF``) keeps the valve lift within this of the
#: full model's [m] (tests/test_bench.py).
SLOW_SCENE_ERROR = 1e-7 * INCH
#: Cases a probe batch holds at least (cases are repeated to fill it) so its time is stable.
MIN_BATCH = 16


@dataclass(frozen=True)
class Level:
    """One fidelity level as the probe found it."""

    fidelity: str  # "full" or "reduced"
    mode_cutoff: float | None  # highest mode kept [rad/s]; None for full
    seconds: float  # wall time per case of the probe batch [s]
    errors: np.ndarray  # (n_cases,) max |Δ valve lift| against full fidelity [m]


@dataclass(frozen=True)
class Probe:
    """Every level for a batch of cases, and the choice for a tolerance."""

    tolerance: float  # valve-lift tolerance [m]
    levels: tuple[Level, ...]  # full first, then the cut-offs ascending
    choice: tuple[int, ...]  # per case: index into levels of the cheapest level within it
    common: int  # index of the cheapest level within the tolerance for every case

    def setting(self, i: int | None = None) -> tuple[str, float | None]:
        """(fidelity, mode_cutoff) chosen for case ``i``, or for all cases together."""
        level = self.levels[self.common if i is None else self.choice[i]]
        return level.fidelity, level.mode_cutoff


def _timed(cases: list[Case], settings: RunSettings, repeats: int):
    batch = cases * max(1, math.ceil(MIN_BATCH / len(cases)))
    result = run_batch(cases, settings)  # untimed: fills the engine's caches
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_batch(batch, settings)
        best = min(best, (time.perf_counter() - t0) / len(batch))
    return result, best


def probe(
    cases: Sequence[Case],
    tolerance: float,
    settings: RunSettings | None = None,
    *,
    cutoffs: Sequence[float] = CANDIDATE_CUTOFFS,
    revolutions: float = PROBE_REVOLUTIONS,
    repeats: int = 3,
) -> Probe:
    """Probe the fidelity levels on a batch of cases.

    Parameters
    ----------
    cases : sequence of Case
        The cases (any mix).
    tolerance : float
        Largest acceptable valve-lift error against the full model [m].
    settings : RunSettings, optional
        The run's settings (default: the default integrator); its fidelity is ignored.
    cutoffs : sequence of float
        Candidate cut-offs [rad/s].
    revolutions : float
        Cam turns probed (at most the settings' own).
    repeats : int
        Timed repeats per level; the best is kept.
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance: found {tolerance!r} m, expected > 0")
    cases = list(cases)
    base = settings or RunSettings()
    base = replace(
        base, revolutions=min(base.revolutions, revolutions), fidelity="full", mode_cutoff=None
    )
    if base.method != "modal-exact":
        base = replace(base, integrator="modal-exact", dt=None)
    full, full_seconds = _timed(cases, base, repeats)
    levels = [Level("full", None, full_seconds, np.zeros(len(cases)))]
    for cutoff in sorted(cutoffs):
        res, seconds = _timed(cases, replace(base, fidelity="reduced", mode_cutoff=cutoff), repeats)
        err = np.abs(res.valve_lift - full.valve_lift).max(axis=1)
        levels.append(Level("reduced", float(cutoff), seconds, err))

    def cheapest(ok: np.ndarray) -> int:
        best = 0
        for k in range(1, len(levels)):
            if ok[k] and levels[k].seconds < min(
                levels[best].seconds, (1 - MIN_SAVING) * full_seconds
            ):
                best = k
        return best

    within = np.array([lv.errors <= tolerance for lv in levels])  # (n_levels, n_cases)
    choice = tuple(cheapest(within[:, i]) for i in range(len(cases)))
    return Probe(tolerance, tuple(levels), choice, cheapest(np.asarray(within.all(axis=1))))


def recommend(
    case: Case, tolerance: float, settings: RunSettings | None = None, **kw
) -> tuple[str, float | None]:
    """The cheapest fidelity level whose valve lift stays within ``tolerance`` [m] of the full
    model's on ``case``: ``("full", None)`` or ``("reduced", mode_cutoff [rad/s])``.

    Keywords as :func:`probe`.
    """
    return probe([case], tolerance, settings, **kw).setting(0)


#: Most cases ``campipe validate --tolerance`` probes; a larger study is probed on an evenly
#: spaced subset.
MAX_PROBE_CASES = 256


def study_needs(
    cases: Sequence[Case],
    settings: Sequence[RunSettings],
    tolerance: float,
    unit: tuple[str, float] = ("in", INCH),
) -> str:
    """What ``campipe validate --tolerance`` prints: the fidelity level a study's cases need.

    Parameters
    ----------
    cases, settings : sequences
        Each case and its run settings (cases are probed in groups of equal settings).
    tolerance : float
        Valve-lift tolerance [m].
    unit : (name, metres)
        The length unit of the text.
    """
    name, metres = unit
    index = np.arange(len(cases))
    if len(cases) > MAX_PROBE_CASES:
        index = np.unique(np.linspace(0, len(cases) - 1, MAX_PROBE_CASES).round().astype(int))
    groups: dict[RunSettings, list[int]] = {}
    for i in index.tolist():
        groups.setdefault(settings[i], []).append(i)
    lines = [
        f"fidelity for a valve-lift tolerance of {tolerance / metres:g} {name} "
        f"(probe: {index.size} of {len(cases)} cases, up to {PROBE_REVOLUTIONS:g} turns, "
        "modal-exact, valve lift against the full model):"
    ]
    for group_settings, members in groups.items():
        p = probe([cases[i] for i in members], tolerance, group_settings)
        counts: dict[int, int] = {}
        for k in p.choice:
            counts[k] = counts.get(k, 0) + 1
        chosen = np.array(p.choice)
        for k in sorted(counts):
            lv = p.levels[k]
            what = (
                "full"
                if lv.mode_cutoff is None
                else f"reduced, mode_cutoff {lv.mode_cutoff:g} rad/s"
            )
            worst = float(lv.errors[chosen == k].max()) / metres
            lines.append(
                f"  {what}: {counts[k]} case{'s' if counts[k] != 1 else ''}"
                + (f" (largest error {worst:.2g} {name})" if k else "")
            )
        lv = p.levels[p.common]
        if lv.mode_cutoff is None:
            lines.append(
                "  the whole study: run.fidelity: full (no reduced level is both within "
                "the tolerance for every case and cheaper)"
            )
        else:
            saving = 1 - lv.seconds / p.levels[0].seconds
            lines.append(
                f"  the whole study: run.fidelity: reduced, run.mode_cutoff: "
                f"{lv.mode_cutoff:g} rad/s (about {saving:.0%} less time than full)"
            )
        if group_settings.method != "modal-exact":
            lines.append(
                f"  (these cases run {group_settings.method}; the reduced fidelity "
                "needs integrator modal-exact)"
            )
    return "\n".join(lines)
