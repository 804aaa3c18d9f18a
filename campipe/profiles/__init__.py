"""Cam lift profiles: kinds, defects, and one piecewise form for the integrators.

Every profile — harmonic, polydyne, measured table, with any defects — is a
:class:`Profile`: pieces of a degree-7 polynomial in the local angle plus sin θ and cos θ
terms, over one turn, SI units (rad, m). :func:`pack` turns a batch of them into padded
arrays for :func:`evaluate_packed`, the compiled evaluator the integrator calls every step.

The compiled part (:mod:`~campipe.profiles.packed`, numba) loads when its names are first
used: a spec is checked without it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from campipe import kernel_cache
from campipe.profiles.defects import bump, flat
from campipe.profiles.pieces import (
    INCHES,
    LengthUnit,
    Lift,
    Profile,
    evaluate,
    format_length,
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

# numba's cache folder, set before this package's compiled part imports numba
kernel_cache.configure()

if TYPE_CHECKING:
    from campipe.profiles.packed import PackedProfiles, evaluate_packed, pack

_PACKED = ("PackedProfiles", "evaluate_packed", "pack")

__all__ = [
    "INCHES",
    "POLYDYNE_POLYNOMIALS",
    "RAMP_SHAPES",
    "LengthUnit",
    "Lift",
    "PackedProfiles",
    "Profile",
    "Ramp",
    "bump",
    "evaluate",
    "evaluate_packed",
    "flat",
    "format_length",
    "harmonic",
    "max_lift",
    "min_lift",
    "pack",
    "polydyne",
    "shift_polynomial",
    "split",
    "table",
]


def __getattr__(name: str) -> object:
    if name not in _PACKED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module("campipe.profiles.packed"), name)
    globals()[name] = value
    return value
