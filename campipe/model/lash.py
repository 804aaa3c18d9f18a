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

from campipe.model.assembly import (
    SystemMatrices,
    installed_preload,
    reference_preload,
    system_matrices,
)
from campipe.model.parameters import ValveTrain
from campipe.model.seated import (
    cam_side_gap,
    lash_seat_lift,
    measured_side,
    seated_states,
    valve_end_ratio,
)

__all__ = [
    "cam_gap",
    "installed_preload",
    "lash_ratio",
    "lash_seat",
    "reference_preload",
    "train_lash_seat",
]


def lash_ratio(sm: SystemMatrices) -> float:
    """The rocker's valve-end travel per unit of the follower's as the seated train (no load
    in the pushrod or the rocker) takes a cam-side gap up [-]: the rocker's geometric ratio,
    from the model's static states."""
    return valve_end_ratio(*seated_states(sm.stiffness, sm.preload))


def cam_gap(sm: SystemMatrices, lash: float, side: str) -> float:
    """The cam-side gap [m] a lash of ``lash`` [m] measured on ``side`` ("valve": at the
    rocker's valve end, or "cam") is: a valve-side lash over ``lash_ratio``."""
    return cam_side_gap(*seated_states(sm.stiffness, sm.preload), lash, side)


def lash_seat(sm: SystemMatrices, lash: float, side: str) -> float:
    """The seat, as a valve lift [m], at which the train with its valve seated and its cam on
    the base circle stands off its cam by the lash ``lash`` [m] measured on ``side``
    ("valve" or "cam", see the module)."""
    return lash_seat_lift(sm.stiffness, sm.preload, lash, side)


def train_lash_seat(train: ValveTrain) -> float:
    """The seat ``train``'s lash places (:func:`lash_seat` on its ``lash_side``). A chain of
    masses (:mod:`campipe.model.layouts`) takes a gap up as a rigid body, so its lash is the
    same measured at the valve or at the cam."""
    return lash_seat(system_matrices(train), train.lash, measured_side(train))
