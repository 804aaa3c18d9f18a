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
import math
from typing import Any

import numpy as np

from campipe.constants import TWO_PI
from campipe.model.levers import LEVERS, KinematicState, kinematic_state, lever_of
from campipe.profiles.pieces import Profile, evaluate
from campipe.profiles.shapes import table

#: The cam-angle spacing [rad] of the kinematic lift's samples.
STEP = math.radians(0.5)
#: A derived profile's label starts so (it is never derived again).
VALVE_SIDE = "valve side of "
#: The most derived profiles kept (a study's cases share a few cams and trains).
CACHED = 64

_CACHE: collections.OrderedDict[tuple, Profile] = collections.OrderedDict()


def is_valve_side(profile: Profile) -> bool:
    """A profile :func:`valve_side` derived (the engine's excitation of a lever layout)."""
    return profile.label.startswith(VALVE_SIDE)


def cam_kinematics(profile: Profile, train: Any, theta: np.ndarray) -> KinematicState:
    """The lever's kinematic motion under ``profile`` (the cam's own lift) at cam angles
    ``theta`` [rad]."""
    return kinematic_state(lever_of(train), lambda s: evaluate(profile, s)[:2], theta)


def valve_side(profile: Profile, train: Any) -> Profile:
    """The excitation of ``train``'s chain: ``profile`` (the cam's lift) through the lever's
    kinematics for a lever layout, else ``profile`` itself (as it is for one derived
    already)."""
    if train.layout not in LEVERS or is_valve_side(profile):
        return profile
    lever = lever_of(train)
    key = (profile.breaks.tobytes(), profile.poly.tobytes(), profile.trig.tobytes(), lever)
    found = _CACHE.get(key)
    if found is None:
        theta = np.arange(round(TWO_PI / STEP)) * (TWO_PI / round(TWO_PI / STEP))
        lift = cam_kinematics(profile, train, theta).valve_lift
        derived = table(theta, lift)
        found = Profile(
            derived.breaks,
            derived.poly,
            derived.trig,
            f"{VALVE_SIDE}{profile.label} ({train.layout})",
        )
        _CACHE[key] = found
        while len(_CACHE) > CACHED:
            _CACHE.popitem(last=False)
    _CACHE.move_to_end(key)
    return found
