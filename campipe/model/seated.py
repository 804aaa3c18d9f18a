"""The statics of a seated train: its static states with coordinates held, and where a lash
places its seat (``campipe.model.lash``) and what the spring pushes with there (the model's
preload with lash, ``campipe.model.assembly.reference_preload``). Pure functions of a
stiffness matrix and a load, below the assembly that needs them for its preload."""

from __future__ import annotations

import numpy as np

from campipe.model.coordinates import COORDINATES
from campipe.model.parameters import LASH_SIDES, ModelParameterError, ValveTrain
from campipe.vocabulary import CAM, SEAT

#: q4, the rocker's valve end (up positive): where a valve-side lash is measured.
VALVE_END = [c.name for c in COORDINATES].index("rocker_valve_end")


def static_state(stiffness: np.ndarray, load: np.ndarray, held: dict[int, float]) -> np.ndarray:
    """The static displacement under ``load`` with the coordinates ``held`` (index → value)
    prescribed: K_ff·q_f = f_f − K_fh·q_h."""
    n = stiffness.shape[0]
    h = np.array(sorted(held), dtype=int)
    f = np.setdiff1d(np.arange(n), h)
    q = np.zeros(n)
    q[h] = [held[i] for i in h]
    q[f] = np.linalg.solve(stiffness[np.ix_(f, f)], load[f] - stiffness[np.ix_(f, h)] @ q[h])
    return q


def seated_states(stiffness: np.ndarray, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The static states of the seated train off its cam under ``load``, its seat at valve
    lift 0 and 1 m from the valve's static position on the base circle (the states are
    linear in the seat)."""
    reference = static_state(stiffness, load, {CAM: 0.0})[SEAT]
    low, high = (static_state(stiffness, load, {SEAT: reference + s}) for s in (0, 1))
    return low, high


def valve_end_ratio(low: np.ndarray, high: np.ndarray) -> float:
    """The rocker's valve-end travel per unit of the follower's between two seated states."""
    return float((high[VALVE_END] - low[VALVE_END]) / (high[CAM] - low[CAM]))


def cam_side_gap(low: np.ndarray, high: np.ndarray, lash: float, side: str) -> float:
    """The cam-side gap [m] of a lash measured on ``side``: a valve-side lash over
    :func:`valve_end_ratio`; refuses an unknown side at ``lash_side``."""
    if side not in LASH_SIDES:
        raise ModelParameterError.at(
            "lash_side",
            f"found {side!r}, expected one of: " + ", ".join(LASH_SIDES),
            found=side,
            expected="one of: " + ", ".join(LASH_SIDES),
        )
    return lash / valve_end_ratio(low, high) if side == "valve" else lash


def lash_seat_lift(stiffness: np.ndarray, load: np.ndarray, lash: float, side: str) -> float:
    """The seat [m of valve lift, from the valve's static position on the base circle] at
    which the train under ``load``, its valve seated, stands off its cam by ``lash`` [m]
    measured on ``side``."""
    low, high = seated_states(stiffness, load)
    gap = cam_side_gap(low, high, lash, side)
    return float((gap + low[CAM]) / (low[CAM] - high[CAM]))


def measured_side(train: ValveTrain) -> str:
    """Where ``train``'s lash is measured: its ``lash_side``; "cam" for a chain of masses,
    which takes a gap up as a rigid body (the same on either side)."""
    return "cam" if train.chain else train.lash_side


def seated_force(train: ValveTrain, stiffness: np.ndarray, load: np.ndarray) -> float:
    """The seat's reaction [N] (the spring's force: seated, nothing else loads the valve) with
    the train under ``load``, its valve on the seat its lash places."""
    s = lash_seat_lift(stiffness, load, train.lash, measured_side(train))
    reference = static_state(stiffness, load, {CAM: 0.0})[SEAT]
    q = static_state(stiffness, load, {SEAT: reference + s})
    return float(abs((stiffness @ q - load)[SEAT]))
