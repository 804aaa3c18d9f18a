"""Member loads from the coordinates: forces in the bars, the spring, and rocker bending.

Element end forces are Kₑ·β·q (thesis Eqs. 2, 7, 8); these are the histories a scene asks for
(thesis Figures 37–39). Pure functions over arrays of any leading shape.
"""

from __future__ import annotations

import numpy as np

from campipe.model import ValveTrain
from campipe.model.elements import elements

#: name → (long name, units)
MEMBER_LOADS = {
    "pushrod_force": ("pushrod axial force, compressive positive", "N"),
    "stem_force": ("valve stem axial force, compressive positive", "N"),
    "spring_force": ("valve spring force on the rocker, compressive positive", "N"),
    "rocker_moment": ("rocker arm bending moment at the pivot, valve side", "N m"),
}


def member_loads(train: ValveTrain, q: np.ndarray) -> dict[str, np.ndarray]:
    """Member loads for coordinates ``q`` (..., 7) [m, rad] of ``train``.

    Returns
    -------
    dict
        ``pushrod_force``, ``stem_force``, ``spring_force`` [N] and ``rocker_moment`` [N·m],
        each of q's leading shape.
    """
    q = np.asarray(q, dtype=float)
    by_name = {e.name: e for e in elements(train)}

    def end_forces(name: str) -> np.ndarray:
        e = by_name[name]
        return q @ (e.stiffness @ e.beta).T  # (..., n_e): forces on the element's ends

    # Axial elements use (lower, upper) measured upward: the upper end force is the tension.
    return {
        "pushrod_force": -end_forces("pushrod")[..., 1],
        "stem_force": -end_forces("valve_stem")[..., 1],
        "spring_force": train.spring_preload - end_forces("spring")[..., 1],
        # The rocker's valve arm starts at the pivot: its θ1 end moment.
        "rocker_moment": end_forces("rocker_valve_arm")[..., 2],
    }
