"""Cam lift profiles: kinds, defects, and one piecewise form for the integrators.

Every profile — harmonic, polydyne, measured table, with any defects — is a
:class:`Profile`: pieces of a degree-7 polynomial in the local angle plus sin θ and cos θ
terms, over one turn, SI units (rad, m). :func:`pack` turns a batch of them into padded
arrays for :func:`evaluate_packed`, the compiled evaluator the integrator calls every step.
"""

from campipe.profiles.defects import bump, flat
from campipe.profiles.packed import PackedProfiles, evaluate_packed, pack
from campipe.profiles.pieces import (
    Profile,
    evaluate,
    max_lift,
    min_lift,
    shift_polynomial,
    split,
)
from campipe.profiles.shapes import (
    POLYDYNE_POLYNOMIALS,
    RAMP_SHAPES,
    Ramp,
    harmonic,
    polydyne,
    table,
)

__all__ = [
    "POLYDYNE_POLYNOMIALS",
    "RAMP_SHAPES",
    "PackedProfiles",
    "Profile",
    "Ramp",
    "bump",
    "evaluate",
    "evaluate_packed",
    "flat",
    "harmonic",
    "max_lift",
    "min_lift",
    "pack",
    "polydyne",
    "shift_polynomial",
    "split",
    "table",
]
