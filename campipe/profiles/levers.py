"""A lever layout's excitation: the kinematic valve lift its cam gives through its geometry
(:mod:`campipe.model.levers`), as a profile the engine drives the chain's cam mass with.

The kinematic lift is computed exactly (:func:`campipe.model.levers.kinematic_state`) every
:data:`STEP` of cam angle and passed through the measured table's periodic cubic spline
(:func:`campipe.profiles.table`): exact at those angles, its lift, velocity and acceleration
continuous, its error between them of order h·Δθ⁴ (1e-9 of the lift at 0.5° for the
harmonic cam). Pure Python and numpy.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.constants import TWO_PI
from campipe.model.declared import ModelParameterError
from campipe.model.levers import LEVERS, KinematicState, Lever, kinematic_state, lever_of
from campipe.profiles.pieces import Profile, evaluate
from campipe.profiles.shapes import table

#: The cam-angle spacing [rad] of the kinematic lift's samples.
STEP = math.radians(0.5)
#: A derived profile's label starts so.
VALVE_SIDE = "valve side of "
#: The farthest [rad] the lever may swing from the horizontal over the cam's turn.
MAX_SWING = math.radians(75.0)
#: The most derived profiles kept (a study's cases share a few cams and trains).
CACHED = 64

_CACHE: collections.OrderedDict[tuple, Profile] = collections.OrderedDict()


@dataclass(frozen=True, eq=False)
class ValveSideProfile(Profile):
    """A lever layout's kinematic valve lift (:func:`valve_side`), with the cam and the lever
    it came from (for the lever ratio over the turn, :func:`lever_ratio`)."""

    cam: Profile | None = None  # the cam's own lift
    lever: Lever | None = None  # the lever's geometry
    #: the lever ratio r(θ) and the pivot's gain g(θ) [-], sampled and splined on the
    #: profile's own grid from the same kinematics (:func:`lever_tables`)
    tables: tuple[Profile, Profile] | None = None


def is_valve_side(profile: Profile) -> bool:
    """A profile :func:`valve_side` derived (the engine's excitation of a lever layout)."""
    return isinstance(profile, ValveSideProfile)


def cam_of(profile: Profile) -> Profile:
    """The cam's own lift of a case whose excitation is ``profile``: a lever layout's cam
    (:class:`ValveSideProfile`), else ``profile`` itself."""
    cam = profile.cam if isinstance(profile, ValveSideProfile) else None
    return cam if cam is not None else profile


def _kinematics(profile: Profile, lever: Lever, theta: np.ndarray) -> KinematicState:
    return kinematic_state(lever, lambda s: evaluate(profile, s)[:2], theta)


def cam_kinematics(profile: Profile, train: Any, theta: np.ndarray) -> KinematicState:
    """The lever's kinematic motion under ``profile`` (the cam's own lift) at cam angles
    ``theta`` [rad]."""
    return _kinematics(profile, lever_of(train), theta)


def lever_ratio(profile: Profile, theta: np.ndarray) -> np.ndarray:
    """The lever ratio [-] at cam angles ``theta`` [rad] of the case whose excitation is
    ``profile``: the roller's normal force on the cam per valve-side cam force (by virtual
    work) for a lever layout's (:class:`ValveSideProfile`), 1 for any other."""
    theta = np.asarray(theta, float)
    if not isinstance(profile, ValveSideProfile) or profile.cam is None or profile.lever is None:
        return np.ones_like(theta)
    return _kinematics(profile.cam, profile.lever, theta).ratio.reshape(theta.shape)


def contact_angles(profile: Profile, theta: np.ndarray) -> np.ndarray:
    """The profile angles [rad] of the cam's contact at cam angles ``theta`` [rad] of the case
    whose excitation is ``profile``: for a lever layout's (:class:`ValveSideProfile`) where
    its roller's centre sits on the pitch curve (``KinematicState.contact``: the point a
    radial roller touches at that angle), ``theta`` itself for any other."""
    theta = np.asarray(theta, float)
    if not isinstance(profile, ValveSideProfile) or profile.cam is None or profile.lever is None:
        return theta
    return _kinematics(profile.cam, profile.lever, theta).contact.reshape(theta.shape)


def _check_swing(state: KinematicState, profile: Profile) -> None:
    """Refuse a cam that swings the lever past :data:`MAX_SWING` from the horizontal or past
    where its ratio turns (the valve would close as the cam lifts), naming
    ``pivot_to_roller``."""
    worst = float(np.abs(state.angle).max())
    if worst <= MAX_SWING and bool(np.all(state.ratio > 0.0)):
        return
    raise ModelParameterError.at(
        "pivot_to_roller",
        f"the cam ({profile.label}) swings the lever to {math.degrees(worst):.0f}° from the "
        f"horizontal (at most {math.degrees(MAX_SWING):.0f}°, its lever ratio positive): give "
        "a longer pivot_to_roller, or a cam of less lift",
        found=None,
        expected=f"a lever that stays within {math.degrees(MAX_SWING):.0f}° of the horizontal",
    )


def valve_side(profile: Profile, train: Any) -> Profile:
    """The excitation of ``train``'s chain: ``profile`` (the cam's lift) through the lever's
    kinematics for a lever layout, else ``profile`` itself. A profile derived already is the
    excitation of its own lever: kept for that lever, derived again from its cam for another
    (a case copied with another train), its cam for a train that is no lever."""
    if isinstance(profile, ValveSideProfile) and profile.cam is not None:
        own = profile.lever and dataclasses.replace(profile.lever, pivot_height=0.0)
        if train.layout in LEVERS and own == lever_of(train):
            return profile  # its own lever's, the pivot where a lash adjuster holds it
        profile = profile.cam
    if train.layout not in LEVERS:
        return profile
    lever = lever_of(train)
    key = (*profile.content_key, lever)
    found = _CACHE.get(key)
    if found is None:
        found = _derived(profile, lever)
        _CACHE[key] = found
        while len(_CACHE) > CACHED:
            _CACHE.popitem(last=False)
    _CACHE.move_to_end(key)
    return found


def _grid() -> np.ndarray:
    """The cam angles [rad] a derived profile is sampled at: every :data:`STEP` of a turn."""
    return np.arange(round(TWO_PI / STEP)) * (TWO_PI / round(TWO_PI / STEP))


def _derived(profile: Profile, lever: Lever) -> ValveSideProfile:
    """``profile`` (the cam's lift) through ``lever``'s kinematics, sampled and splined."""
    theta = _grid()
    state = _kinematics(profile, lever, theta)
    _check_swing(state, profile)
    derived = table(theta, state.valve_lift)
    label = f"{VALVE_SIDE}{profile.label} ({lever.kind})"
    tables = (table(theta, state.ratio), table(theta, state.gain))
    return ValveSideProfile(
        derived.breaks, derived.poly, derived.trig, label, profile, lever, tables
    )


def pivot_raised(profile: ValveSideProfile, height: float) -> ValveSideProfile:
    """A lever layout's excitation with its pivot raised ``height`` [m] from its rest (a lash
    adjuster's plunger extension under the pivot): the kinematic valve lift of the same cam
    and lever, the roller on the cam's pitch curve, derived exactly (not cached: the
    extension moves every turn)."""
    if profile.cam is None or profile.lever is None:
        raise TypeError("pivot_raised takes a lever layout's derived profile (valve_side)")
    return _derived(profile.cam, dataclasses.replace(profile.lever, pivot_height=height))


def pivot_gains(profile: ValveSideProfile, theta: np.ndarray) -> np.ndarray:
    """The valve lift's change per unit rise of the pivot [-] at cam angles ``theta`` [rad]
    of a lever layout's derived profile (its pivot where it stands):
    :attr:`~campipe.model.levers.KinematicState.gain` on the profile's grid, splined
    (:func:`lever_tables`); by virtual work the adjuster's load per unit of the pallet's
    force."""
    theta = np.asarray(theta, float)
    return evaluate(lever_tables(profile)[1], theta.ravel())[0].reshape(theta.shape)


def lever_tables(profile: Profile) -> tuple[Profile, Profile]:
    """(the lever ratio r(θ), the pivot's gain g(θ)) [-] of a lever layout's derived profile,
    each sampled on the profile's own grid and splined as it is (:func:`_derived` makes them
    with it), so their pieces are the profile's: the compliant integrator evaluates all three
    on the piece it is on (``campipe.engine.compliant``)."""
    if not isinstance(profile, ValveSideProfile) or profile.tables is None:
        raise TypeError("lever_tables takes a lever layout's derived profile (valve_side)")
    return profile.tables
