"""The system coordinates: the thesis's seven, then the internal nodes of refined members.

The thesis's q1 … q7 keep their indices 0–6 whatever the refinement, so the cam contact is
always coordinate 0 and the seat coordinate 6. A member divided into n equal elements has
n − 1 internal nodes, counted from the member's first end (see :data:`MEMBER_ENDS`); their
coordinates follow q7, member by member in the order of
:data:`campipe.model.parameters.ELEMENTS`: one per node of a bar (its axial displacement, up),
two per node of a beam (v up, then θ). A chain of masses (``layout`` lumped or
direct-acting) keeps the same two places, its cam's mass q1 and its valve q7
(:mod:`campipe.model.layouts`). Pure Python and numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from campipe.model.layouts import lumped_coordinates
from campipe.model.parameters import ELEMENTS, N_DOF, NODE_COORDINATES, ValveTrain

#: A node's coordinate as (0-based q index, sign), or GROUND (−1, 0): fixed.
Dof = tuple[int, float]
GROUND: Dof = (-1, 0.0)


@dataclass(frozen=True)
class Coordinate:
    """One system coordinate (thesis Figure 2, lost from the thesis's copy: this order and
    these signs are the ones that reproduce its Figures 11–14)."""

    symbol: str  # q1 … q7, then q8 … for internal nodes
    name: str  # readable name
    kind: str  # "translation" [m] or "rotation" [rad]
    positive: str  # positive direction


SLOPE = "rocker slope, pushrod to valve"

COORDINATES: tuple[Coordinate, ...] = (
    Coordinate("q1", "pushrod_foot", "translation", "down, away from the rocker"),
    Coordinate("q2", "pushrod_top", "translation", "up"),
    Coordinate("q3", "rocker_pushrod_end_rotation", "rotation", SLOPE),
    Coordinate("q4", "rocker_valve_end", "translation", "up"),
    Coordinate("q5", "rocker_valve_end_rotation", "rotation", SLOPE),
    Coordinate("q6", "rocker_pivot_rotation", "rotation", SLOPE),
    Coordinate("q7", "valve_foot", "translation", "down, valve opening"),
)
TRANSLATIONS = np.array([c.kind == "translation" for c in COORDINATES])

#: Each member's two end nodes in the thesis's coordinates (thesis Eqs. 2–4): a bar's node is
#: its axial displacement measured up (q1 and q7 point down, so they enter with a minus sign),
#: a beam's node is (v up, θ slope along the rocker from the pushrod end towards the valve end);
#: the pivot cannot translate. Bars run from their lower end up, beams from the pushrod end
#: towards the valve end.
MEMBER_ENDS: dict[str, tuple[tuple[Dof, ...], tuple[Dof, ...]]] = {
    "pushrod": (((0, -1.0),), ((1, 1.0),)),
    "rocker_pushrod_arm": (((1, 1.0), (2, 1.0)), (GROUND, (5, 1.0))),
    "rocker_valve_arm": ((GROUND, (5, 1.0)), ((3, 1.0), (4, 1.0))),
    "spring": ((GROUND,), ((3, 1.0),)),
    "valve_stem": (((6, -1.0),), ((3, 1.0),)),
}


def member_nodes(train: ValveTrain) -> dict[str, list[tuple[Dof, ...]]]:
    """Each member's n + 1 nodes, first end to last, as the coordinates (index, sign) of each
    node: the ends' from :data:`MEMBER_ENDS`, the internal nodes' numbered from 7 on."""
    out = {}
    next_index = N_DOF
    for member in ELEMENTS:
        first, last = MEMBER_ENDS[member]
        nodes = [first]
        for _ in range(train.elements_of(member) - 1):
            width = NODE_COORDINATES[member]
            nodes.append(tuple((next_index + k, 1.0) for k in range(width)))
            next_index += width
        nodes.append(last)
        out[member] = nodes
    return out


def n_coordinates(train: ValveTrain) -> int:
    """The number of system coordinates of ``train`` (7 for the thesis's model)."""
    return train.n_coordinates


def coordinates(train: ValveTrain) -> tuple[Coordinate, ...]:
    """``train``'s coordinates in order: :data:`COORDINATES`, then each refined member's
    internal nodes (``spring_1`` … for a bar, ``rocker_valve_arm_1`` and
    ``rocker_valve_arm_1_rotation`` … for a beam), node 1 next to the member's first end.
    A lumped chain's (:func:`campipe.model.layouts.lumped_coordinates`): ``cam_mass``,
    ``mass_2`` …, ``valve``, and its placeholders ``unused``."""
    if train.chain:
        return tuple(
            Coordinate(f"q{i + 1}", name, "translation", positive)
            for i, name, positive in lumped_coordinates(len(train.masses))
        )
    out = list(COORDINATES)
    for member in ELEMENTS:
        for node in range(1, train.elements_of(member)):
            out.append(Coordinate(f"q{len(out) + 1}", f"{member}_{node}", "translation", "up"))
            if NODE_COORDINATES[member] == 2:
                name = f"{member}_{node}_rotation"
                out.append(Coordinate(f"q{len(out) + 1}", name, "rotation", SLOPE))
    return tuple(out)


def translations(train: ValveTrain) -> np.ndarray:
    """(n,) bool: which of ``train``'s coordinates are translations [m] (else rotations [rad])."""
    return np.array([c.kind == "translation" for c in coordinates(train)])
