"""A lever layout's results at the cam: the roller's normal force, not the valve side's.

A lever layout runs as a chain in valve-side coordinates (:mod:`campipe.model.levers`), so the
engine's cam force is the force at the pallet along the valve that drives the chain's cam
mass. The roller presses on the cam with that force times the lever ratio r(θ) (by virtual
work, :func:`campipe.profiles.levers.lever_ratio`). :func:`at_the_cam` turns a result's cam
force into that normal force, for the histories and the per-turn ``max_cam_force``:

- the histories: F·r at each output sample, exactly;
- each turn's largest: the larger of the samples' largest F·r and the engine's largest
  valve-side force (taken on its steps' grid, which may be finer or coarser than the
  samples) times r at the sample of the largest sampled valve-side force. Between two output
  samples r changes by at most |dr/dθ|·Δθ (a fraction of a per cent at 1°), and both
  candidates are the normal force at some angle of the turn to that resolution, so the result
  is the turn's largest normal force to it (from below).
  A turn with no samples (the turns of a run of automatic length before its recorded
  window) takes r at the recorded window's peak.

Every other layout's result is returned as it is (the thesis's preset and the chains' runs
bit for bit). Pure numerics on the result's arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import Case
from campipe.engine.metrics import MAX_CAM_FORCE
from campipe.engine.result import BatchResult
from campipe.profiles.levers import is_valve_side, lever_ratio


def at_the_cam(result: BatchResult, cases: Sequence[Case]) -> BatchResult:
    """``result`` with each lever layout's cam force (histories and ``max_cam_force`` per
    turn) the roller's normal force on the cam (see the module); ``result`` itself if no
    case is a lever layout's."""
    levers = [i for i, c in enumerate(cases) if is_valve_side(c.profile)]
    if not levers:
        return result
    force, per_rev = result.cam_force.copy(), result.per_rev.copy()
    theta = np.asarray(result.cam_angle, float)
    ratios: dict[int, np.ndarray] = {}  # a study's cases share their derived profiles
    for i in levers:
        profile = cases[i].profile
        ratio = ratios.setdefault(id(profile), lever_ratio(profile, theta))
        force[i] = result.cam_force[i] * ratio
        first = int(result.recorded_from[i]) if result.recorded_from.size else 0
        per_rev[i, :, MAX_CAM_FORCE] = turn_maxima(
            result.cam_force[i], ratio, theta, result.per_rev[i, :, MAX_CAM_FORCE], first
        )
    return dataclasses.replace(result, cam_force=force, per_rev=per_rev, _derived={})


def turn_maxima(
    force: np.ndarray, ratio: np.ndarray, theta: np.ndarray, largest: np.ndarray, first: int = 0
) -> np.ndarray:
    """(n_turns,) each turn's largest normal force [N] (see the module) from the valve-side
    ``force`` [N] and the ``ratio`` [-] at the samples' cam angles ``theta`` [rad] (from the
    recorded window's start, turn ``first``), and the engine's per-turn valve-side
    ``largest`` [N]."""
    out = np.asarray(largest, float).copy()
    valid = np.isfinite(force)
    if not valid.any():
        return out
    n_hist = max(int(np.ceil(theta[-1] / TWO_PI - 1e-9)), 1)
    turn = first + np.minimum(np.floor(theta / TWO_PI + 1e-9).astype(np.int64), n_hist - 1)
    overall = ratio[np.nanargmax(np.where(valid, force, -np.inf))]
    for k in range(out.size):
        if not out[k] > 0.0:  # never on the cam, or a failed case's NaN
            continue
        here = (turn == k) & valid
        if not here.any():
            out[k] = largest[k] * overall
            continue
        j = np.argmax(np.where(here, force, -np.inf))
        out[k] = max(largest[k] * ratio[j], float(np.max((force * ratio)[here])))
    return out
