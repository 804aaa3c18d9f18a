"""Lash: the clearance of a seated train on its cam's base circle, and the seat it places.

The model has two contacts, the cam and the seat, so a train with lash stands off its cam:
its valve seated, its follower ``gap`` above the base circle. A designer sets and measures
lash at the valve end of the rocker (the feeler gauge between the rocker's pad and the valve
stem): ``lash_side`` "valve", the default. Seated, the pushrod and the rocker carry no load
(the spring's force goes through the stem to the seat), so taking a gap up at the cam turns
the rocker as a rigid lever: the rocker's valve end travels ``lash_ratio`` times as far as
the follower, the rocker's geometric ratio (1.5 for the thesis's train) whatever the
members' give. A valve-side lash δ_v is the cam-side gap δ_v / ``lash_ratio``; "cam" takes
the lash as that gap itself.

The seat the lash places (``lash_seat``) is a valve lift from the valve's static position
with the follower on the base circle and no seat (the preload compressing the train, the
engine's valve reference). Seated, the train sheds that load: it grows by the preload's
give, all but the stem's share, so the seat is the lash's valve travel plus that give. The
engine reads valve lift from that seat in a train with lash (``Case.lift_zero``): 0 on the
seat.

``spring_preload`` is a designer's installed force: the spring's force with the valve closed
on its seat. The model's constant load is the spring's force at the train's unstressed
reference (``reference_preload``); the seat a lash places stands the lash's valve travel
further open than that reference, so that with lash the reference force is
``spring_preload`` less the spring's rate times that travel, and seated the spring pushes
with ``spring_preload`` (without lash the two are one).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from campipe.model.assembly import SystemMatrices, assemble, static_state, system_matrices
from campipe.model.coordinates import COORDINATES
from campipe.model.parameters import LASH_SIDES, ModelParameterError, ValveTrain
from campipe.vocabulary import CAM, SEAT

#: q4, the rocker's valve end (up positive): where a valve-side lash is measured.
VALVE_END = [c.name for c in COORDINATES].index("rocker_valve_end")


def _seated(sm: SystemMatrices) -> tuple[np.ndarray, np.ndarray]:
    """The static states of the seated train off its cam, its seat at valve lift 0 and 1 m
    (the states are linear in the seat)."""
    reference = static_state(sm.stiffness, sm.preload, {CAM: 0.0})[SEAT]
    low, high = (static_state(sm.stiffness, sm.preload, {SEAT: reference + s}) for s in (0, 1))
    return low, high


def _ratio(low: np.ndarray, high: np.ndarray) -> float:
    return float((high[VALVE_END] - low[VALVE_END]) / (high[CAM] - low[CAM]))


def _gap(low: np.ndarray, high: np.ndarray, lash: float, side: str) -> float:
    if side not in LASH_SIDES:
        raise ModelParameterError.at(
            "lash_side",
            f"found {side!r}, expected one of: " + ", ".join(LASH_SIDES),
            found=side,
            expected="one of: " + ", ".join(LASH_SIDES),
        )
    return lash / _ratio(low, high) if side == "valve" else lash


def lash_ratio(sm: SystemMatrices) -> float:
    """The rocker's valve-end travel per unit of the follower's as the seated train (no load
    in the pushrod or the rocker) takes a cam-side gap up [-]: the rocker's geometric ratio,
    from the model's static states."""
    return _ratio(*_seated(sm))


def cam_gap(sm: SystemMatrices, lash: float, side: str) -> float:
    """The cam-side gap [m] a lash of ``lash`` [m] measured on ``side`` ("valve": at the
    rocker's valve end, or "cam") is: a valve-side lash over ``lash_ratio``."""
    return _gap(*_seated(sm), lash, side)


def lash_seat(sm: SystemMatrices, lash: float, side: str) -> float:
    """The seat, as a valve lift [m], at which the train with its valve seated and its cam on
    the base circle stands off its cam by the lash ``lash`` [m] measured on ``side``
    ("valve" or "cam", see the module)."""
    low, high = _seated(sm)
    gap = _gap(low, high, lash, side)
    return float((gap + low[CAM]) / (low[CAM] - high[CAM]))


def train_lash_seat(train: ValveTrain) -> float:
    """The seat ``train``'s lash places (:func:`lash_seat` on its ``lash_side``). A chain of
    masses (:mod:`campipe.model.layouts`) takes a gap up as a rigid body, so its lash is the
    same measured at the valve or at the cam."""
    side = "cam" if train.chain else train.lash_side
    return lash_seat(system_matrices(train), train.lash, side)


def _seated_force(train: ValveTrain, stiffness: np.ndarray, load: np.ndarray) -> float:
    """The seat's reaction [N] (the spring's force: seated, nothing else loads the valve) with
    the train under ``load``, its valve on the seat its lash places."""
    reference = static_state(stiffness, load, {CAM: 0.0})[SEAT]
    low, high = (static_state(stiffness, load, {SEAT: reference + s}) for s in (0, 1))
    side = "cam" if train.chain else train.lash_side
    s = (_gap(low, high, train.lash, side) + low[CAM]) / (low[CAM] - high[CAM])
    q = static_state(stiffness, load, {SEAT: reference + s})
    return float(abs((stiffness @ q - load)[SEAT]))


@functools.lru_cache(maxsize=256)
def _preload_line(train: ValveTrain) -> tuple[float, float]:
    """(f0, slope): the seated spring force of ``train`` with lash is f0 + slope·P for a
    reference preload P (it is linear in P: f0 the lash's travel times the spring's rate)."""
    from campipe.model.assembly import preload_direction

    stiffness = assemble(train)[1]
    direction = preload_direction(train)
    f0 = _seated_force(train, stiffness, 0.0 * direction)
    return f0, _seated_force(train, stiffness, direction) - f0


def reference_preload(train: ValveTrain) -> float:
    """The spring's force [N] at the train's unstressed reference, the model's constant load:
    ``spring_preload`` without lash; with lash, the force for which the spring pushes with
    ``spring_preload`` on the seat the lash places (the module's text)."""
    if math.isnan(train.lash):
        return train.spring_preload
    f0, slope = _preload_line(train)
    return (train.spring_preload - f0) / slope


def installed_preload(train: ValveTrain, reference: float) -> float:
    """The ``spring_preload`` whose :func:`reference_preload` on ``train`` is ``reference``
    [N] (the inverse: without lash the same number)."""
    if math.isnan(train.lash):
        return reference
    f0, slope = _preload_line(train)
    return f0 + slope * reference
