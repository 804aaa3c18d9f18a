"""A lever layout's results at the cam: the roller's normal force and closing velocity, not
the valve side's.

A lever layout runs as a chain in valve-side coordinates (:mod:`campipe.model.levers`), so the
engine's cam force is the force at the pallet along the valve that drives the chain's cam
mass. The roller presses on the cam with that force times the lever ratio r(θ) (by virtual
work, :func:`campipe.profiles.levers.lever_ratio`). :func:`at_the_cam` turns a result's cam
force into that normal force, for the histories and the per-turn ``max_cam_force``:

- the histories: F·r at each output sample, exactly;
- each turn's largest: the engine's own (``max_roller_force``, the integrators follow F·r:
  modal-exact to its peaks, located between the grid's points, newmark-linear at its steps,
  the compliant integrator at its located maxima of F·r and of F); where an engine gave none
  (the steady state's closed form, ``run.fidelity: steady``), the larger of the samples'
  largest F·r and the engine's largest valve-side force times r at the sample of the largest
  sampled valve-side force (to the samples' resolution: r changes by |dr/dθ|·Δθ between
  them, and the largest F·r may sit on another hump of F than F's largest). A turn with no
  samples (the turns of a run of automatic length before its recorded window) takes r at
  the recorded window's peak.

Its cam impacts likewise (:func:`impacts_at_the_cam`): the roller closes on the cam along the
contact normal at the valve side's closing velocity over r at the impact's cam angle (the
ratio is the valve's travel per unit of the roller's along the normal), and its impulse is r
times the valve side's (virtual work, as the force). Each event's velocity and impulse, and
each turn's ``max_cam_impact_velocity``: the largest of the turn's converted impacts (those
the turn counts: at least the capture velocity, or its only ones), exactly; a turn whose
impacts were not recorded (before a recorded window, past a full event buffer) takes its
valve-side largest over the turn's largest r (from below).

Every other layout's result is returned as it is (the thesis's preset and the chains' runs
bit for bit). Pure numerics on the result's arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import Case
from campipe.engine.metrics import MAX_CAM_FORCE, MAX_CAM_IMPACT_VELOCITY, MAX_ROLLER_FORCE
from campipe.engine.result import BatchResult
from campipe.engine.settings import DEFAULT_CAPTURE_VELOCITY
from campipe.profiles import Profile
from campipe.profiles.levers import is_valve_side, lever_ratio
from campipe.vocabulary import CAM_IMPACT, EV_IMPULSE, EV_KIND, EV_TIME, EV_VELOCITY

#: The cam angles [rad] a turn's largest lever ratio is taken over (every 0.5°).
_TURN = np.linspace(0.0, TWO_PI, 721)


def at_the_cam(
    result: BatchResult, cases: Sequence[Case], capture: float = DEFAULT_CAPTURE_VELOCITY
) -> BatchResult:
    """``result`` with each lever layout's cam force (histories and ``max_cam_force`` per
    turn) the roller's normal force on the cam, and its cam impacts (events and
    ``max_cam_impact_velocity`` per turn) the roller's, for a run of capture velocity
    ``capture`` [m/s] (see the module); ``result`` itself if no case is a lever layout's."""
    levers = [i for i, c in enumerate(cases) if is_valve_side(c.profile)]
    if not levers:
        return result
    force, per_rev = result.cam_force.copy(), result.per_rev.copy()
    events = list(result.events)
    theta = np.asarray(result.cam_angle, float)
    ratios: dict[int, np.ndarray] = {}  # a study's cases share their derived profiles
    for i in levers:
        profile = cases[i].profile
        ratio = ratios.setdefault(id(profile), lever_ratio(profile, theta))
        force[i] = result.cam_force[i] * ratio
        first = int(result.recorded_from[i]) if result.recorded_from.size else 0
        followed = result.per_rev[i, :, MAX_ROLLER_FORCE]
        if np.all(followed > 0.0):  # the engine's own in every turn
            per_rev[i, :, MAX_CAM_FORCE] = followed
        else:  # the sampled rule where it gave none (the steady closed form; never on the cam)
            sampled = turn_maxima(
                result.cam_force[i], ratio, theta, result.per_rev[i, :, MAX_CAM_FORCE], first
            )
            per_rev[i, :, MAX_CAM_FORCE] = np.where(followed > 0.0, followed, sampled)
        if i < len(events):
            events[i], per_rev[i, :, MAX_CAM_IMPACT_VELOCITY] = impacts_at_the_cam(
                events[i], result.per_rev[i, :, MAX_CAM_IMPACT_VELOCITY], profile,
                cases[i].speed, capture,
            )  # fmt: skip
    return dataclasses.replace(result, cam_force=force, per_rev=per_rev, events=events, _derived={})


def impacts_at_the_cam(
    events: np.ndarray, fastest: np.ndarray, profile: Profile, speed: float, capture: float
) -> tuple[np.ndarray, np.ndarray]:
    """A lever layout's case's events (n_ev, 6) with each cam impact's closing velocity and
    impulse the roller's, and (n_turns,) each turn's largest closing velocity [m/s] from the
    valve side's ``fastest`` (see the module), at cam speed ``speed`` [rad/s] on the derived
    ``profile``, impacts slower than ``capture`` [m/s] not counted."""
    events = np.array(events, float, copy=True)
    out = np.asarray(fastest, float).copy()
    cam = np.flatnonzero(events[:, EV_KIND] == CAM_IMPACT) if events.size else np.zeros(0, int)
    angle = speed * events[cam, EV_TIME]
    valve_side = events[cam, EV_VELOCITY].copy()
    r = lever_ratio(profile, np.mod(angle, TWO_PI))
    events[cam, EV_VELOCITY] = valve_side / r
    events[cam, EV_IMPULSE] *= r
    turn = np.floor(angle / TWO_PI + 1e-12).astype(np.int64)
    widest = None  # the turn's largest ratio, found only for a turn with none recorded
    for k in np.flatnonzero(out > 0.0):  # (NaN: a failed case's, kept)
        counted = (turn == k) & (angle >= 0.0) & (valve_side >= min(capture, out[k]) * (1 - 1e-12))
        if counted.any():
            out[k] = (valve_side / r)[counted].max()
            continue
        if widest is None:
            widest = float(lever_ratio(profile, _TURN).max())
        out[k] /= widest
    return events, out


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
