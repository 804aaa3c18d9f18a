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
bit for bit), but for the cam contact's radius: where a case's cam's shape is known (a line
contact, ``cam_contact_width``, on a cam of given ``cam_base_radius``), :func:`contact_radii`
gives the relative radius of curvature R' of cam and follower at each sample
(:func:`campipe.profiles.curvature.contact_radius`; a lever's on its cam's own lift, where its
swinging roller touches: ``profiles.levers.contact_angles``), which the
Hertz pressure (``max_cam_pressure``) then takes in place of one ``cam_curvature_radius``:
each turn's largest F/R' by the sampled rule above (the ratio 1/R').

Pure numerics on the result's arrays.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from functools import partial

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import Case
from campipe.engine.loads import sample_turns, turn_maxima
from campipe.engine.metrics import MAX_CAM_FORCE, MAX_CAM_IMPACT_VELOCITY, MAX_ROLLER_FORCE
from campipe.engine.plunger import EXTENSION
from campipe.engine.result import BatchResult
from campipe.engine.settings import DEFAULT_CAPTURE_VELOCITY
from campipe.model.hla import on_pivot
from campipe.profiles import Profile
from campipe.profiles.curvature import contact_radius
from campipe.profiles.levers import (
    ValveSideProfile,
    cam_of,
    contact_angles,
    is_valve_side,
    lever_ratio,
    pivot_raised,
)
from campipe.vocabulary import CAM_IMPACT, EV_IMPULSE, EV_KIND, EV_TIME, EV_VELOCITY

#: The cam angles [rad] a turn's largest lever ratio is taken over (every 0.5°).
_TURN = np.linspace(0.0, TWO_PI, 721)


def at_the_cam(
    result: BatchResult,
    cases: Sequence[Case],
    capture: float = DEFAULT_CAPTURE_VELOCITY,
    pressure: bool = True,
) -> BatchResult:
    """``result`` with each lever layout's cam force (histories and ``max_cam_force`` per
    turn) the roller's normal force on the cam, and its cam impacts (events and
    ``max_cam_impact_velocity`` per turn) the roller's, for a run of capture velocity
    ``capture`` [m/s] (see the module), and with ``pressure`` (the Hertz pressure wanted) the
    cam contact's radius at the samples where the cam's shape gives it (:func:`contact_radii`:
    a lever's takes its kinematics at every sample, 23 ms for a finger's three turns at 1°);
    ``result`` itself if neither. A finger whose pivot has an adjuster ran each turn on its
    pivot raised by the turn's starting extension (``engine.lash_adjuster.extended``): its
    ratio is that turn's (:class:`TurnRatio`)."""
    radius = contact_radii(np.asarray(result.cam_angle, float), cases) if pressure else None
    if radius is not None:
        result = dataclasses.replace(result, cam_contact_radius=radius, _derived={})
    levers = [i for i, c in enumerate(cases) if is_valve_side(c.profile)]
    if not levers:
        return result
    force, per_rev = result.cam_force.copy(), result.per_rev.copy()
    events = list(result.events)
    theta = np.asarray(result.cam_angle, float)
    ratios: dict[int, np.ndarray] = {}  # a study's cases share their derived profiles
    for i in levers:
        profile = cases[i].profile
        first = int(result.recorded_from[i]) if result.recorded_from.size else 0
        turns = TurnRatio(profile, _pivot_extensions(result, cases[i], i))
        if turns.extensions is None:
            ratio = ratios.setdefault(id(profile), lever_ratio(profile, theta))
        else:
            turn = sample_turns(theta, first)
            ratio = turns(theta, turn)
            if radius is not None and np.isfinite(radius[i]).any():  # (result's own array)
                radius[i] = turns.over(partial(_radius, cases[i].train), theta, turn)
        force[i] = result.cam_force[i] * ratio
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
                cases[i].speed, capture, turns.extensions,
            )  # fmt: skip
    return dataclasses.replace(result, cam_force=force, per_rev=per_rev, events=events, _derived={})


class TurnRatio:
    """A lever layout's ratio r(θ) at cam angles of given turns: on its derived ``profile``,
    or where a pivot's adjuster ran turn by turn (``extensions``, each turn's at its start
    [m]; None: none), turn k's on the pivot raised by ``extensions[k]``, the profile that
    turn ran on (``engine.lash_adjuster.extended``, each extension's derived once)."""

    def __init__(self, profile: Profile, extensions: np.ndarray | None) -> None:
        self.profile, self.extensions = profile, extensions
        self._raised: dict[float, Profile] = {}

    def __call__(self, theta: np.ndarray, turn: np.ndarray) -> np.ndarray:
        return self.over(lever_ratio, theta, turn)

    def over(self, f, theta: np.ndarray, turn: np.ndarray) -> np.ndarray:
        """f(profile, θ) at cam angles ``theta`` [rad] of turns ``turn``, each turn's on the
        profile it ran on."""
        if self.extensions is None:
            return f(self.profile, theta)
        out = np.empty(np.shape(theta))
        last = self.extensions.size - 1
        for k in np.unique(turn):
            e = float(self.extensions[min(max(int(k), 0), last)])
            e = e if math.isfinite(e) else 0.0  # (a failed case's turns: the nominal)
            if e not in self._raised:
                profile = self.profile
                if e and isinstance(profile, ValveSideProfile):
                    profile = pivot_raised(profile, e)
                self._raised[e] = profile
            here = turn == k
            out[here] = f(self._raised[e], theta[here])
        return out


def _pivot_extensions(result: BatchResult, case: Case, i: int) -> np.ndarray | None:
    """Each turn's extension at its start [m] of case ``i``'s pivot adjuster, else None. A
    finger's run is turn by turn whenever its pivot has an adjuster, each turn on the pivot
    raised by the extension it starts with: moved once a turn with rigid contacts, or carried
    (a compliant run, ``engine.lash_adjuster.Carried``) with the plunger's motion within the
    turn on the pivot's gain linearised there."""
    if not (result.lash_adjuster.size and on_pivot(case.train)):
        return None
    return np.asarray(result.lash_adjuster[i, :, EXTENSION], float)


def _radius(train, profile: Profile, theta: np.ndarray) -> np.ndarray:
    """The cam contact's relative radius of curvature R' [m] at cam angles ``theta`` [rad] of
    a case of known cam shape on ``train`` whose excitation is ``profile``."""
    return contact_radius(
        cam_of(profile),
        float(train.cam_base_radius),
        float(train.cam_roller_radius),
        contact_angles(profile, theta),
    )


def contact_radii(theta: np.ndarray, cases: Sequence[Case]) -> np.ndarray | None:
    """(n_cases, n_out) the cam contact's relative radius of curvature R' [m] at cam angles
    ``theta`` [rad] of each case whose cam's shape is known: a line contact
    (``cam_contact_width``) on a cam of given ``cam_base_radius``, under a flat face or a
    roller (``cam_roller_radius``), a lever's on its cam's own lift; NaN for the others, and
    where the cam is undercut. None where no case's is known."""
    out = None
    known: dict[tuple, np.ndarray] = {}  # a study's cases share their cams
    for i, case in enumerate(cases):
        train = case.train
        if not (train.cam_base_radius > 0.0 and train.cam_contact_width > 0.0):  # NaN: none
            continue
        key = (id(case.profile), train.cam_base_radius, train.cam_roller_radius)
        if key not in known:  # a lever's roller touches where a radial one would at s(θ)
            known[key] = _radius(train, case.profile, theta)
        if out is None:
            out = np.full((len(cases), theta.size), np.nan)
        out[i] = known[key]
    return out


def impacts_at_the_cam(
    events: np.ndarray,
    fastest: np.ndarray,
    profile: Profile,
    speed: float,
    capture: float,
    extensions: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A lever layout's case's events (n_ev, 6) with each cam impact's closing velocity and
    impulse the roller's, and (n_turns,) each turn's largest closing velocity [m/s] from the
    valve side's ``fastest`` (see the module), at cam speed ``speed`` [rad/s] on the derived
    ``profile`` (each turn's pivot raised by ``extensions``: :class:`TurnRatio`), impacts
    slower than ``capture`` [m/s] not counted."""
    events = np.array(events, float, copy=True)
    out = np.asarray(fastest, float).copy()
    cam = np.flatnonzero(events[:, EV_KIND] == CAM_IMPACT) if events.size else np.zeros(0, int)
    angle = speed * events[cam, EV_TIME]
    valve_side = events[cam, EV_VELOCITY].copy()
    turn = np.floor(angle / TWO_PI + 1e-12).astype(np.int64)
    r = TurnRatio(profile, extensions)(np.mod(angle, TWO_PI), turn)
    events[cam, EV_VELOCITY] = valve_side / r
    events[cam, EV_IMPULSE] *= r
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
