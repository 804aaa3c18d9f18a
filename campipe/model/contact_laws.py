"""Compliant contact laws at the cam–follower and valve–seat contacts, from the parameters.

The thesis's contacts are rigid (``rigid``: a contact holds its coordinate, an impact is
perfectly plastic). A compliant contact is a force element of the approach δ [m] (the
penetration of the undeformed surfaces, positive in contact) that never pulls:

- ``kelvin-voigt``: F = k·δ + c·δ̇ while positive (linear: a spring and a damper in
  parallel, released when the force reaches zero);
- ``hertz``: F = K·δ^(3/2)·(1 + α·δ̇), Hertz's point contact with Hunt and Crossley's damping
  (1975): the damping force vanishes with the approach, so the force is continuous at first
  touch; for a mass striking at v₀ the coefficient of restitution is e ≈ 1 − (2/3)·α·v₀ while
  α·v₀ is small, so α = 3(1 − e)/(2v₀) sets e at one impact speed.

Stiffness from the geometry (``contact_modulus`` E and ``contact_poisson`` ν of both bodies,
E* = E / (2(1 − ν²)), the plane-strain modulus of the pair):

- a line contact of length w (a flat-faced follower's or a roller's width, a seat's
  circumference): its approach is linear in the force up to a logarithm of the bodies' size,
  so it is linear: k = (π/4)·E·w/(1 − ν²) = (π/2)·E*·w (the line contact stiffness of gear
  teeth, Yang and Lin 1987);
- a point contact of relative radius R' (a crowned follower, a ball): K = (4/3)·E*·√R'
  (Hertz 1882).

The peak contact pressure (Hertz): a line contact p = √(F'·E*/(π·R')), F' = F/w the force
per length; a point contact p = (6·F·E*²/(π³·R'²))^(1/3). R' = ρ·r/(ρ + r) for a roller of
radius r on a cam of radius of curvature ρ, ρ for a flat-faced follower.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.model.parameters import CONTACT_CONSTANTS, ValveTrain, _contact_geometry

#: Law codes the integrator branches on.
RIGID, KELVIN_VOIGT, HERTZ = 0, 1, 2
LAW_CODES = {"rigid": RIGID, "kelvin-voigt": KELVIN_VOIGT, "hertz": HERTZ}
#: Hertz's point-contact exponent.
HERTZ_EXPONENT = 1.5


@dataclass(frozen=True)
class ContactLaw:
    """One contact's force law, SI."""

    law: int  # RIGID, KELVIN_VOIGT or HERTZ
    stiffness: float  # k [N/m] (kelvin-voigt) or K [N/m^1.5] (hertz)
    damping: float  # c [N·s/m] (kelvin-voigt) or α [s/m] (hertz)
    modulus: float  # E* of the pair [Pa]
    width: float  # line contact length [m]; 0: not a line contact
    radius: float  # relative radius of curvature R' [m]; 0: not given

    @property
    def compliant(self) -> bool:
        return self.law != RIGID

    @property
    def exponent(self) -> float:
        """p of F = stiffness·δ^p."""
        return HERTZ_EXPONENT if self.law == HERTZ else 1.0

    def force(self, delta: float, rate: float) -> float:
        """The law's force [N] at approach δ [m] and approach rate δ̇ [m/s], before the
        no-tension cut (negative where it would pull)."""
        if self.law == KELVIN_VOIGT:
            return self.stiffness * delta + self.damping * rate
        return self.stiffness * max(delta, 0.0) ** 1.5 * (1.0 + self.damping * rate)

    def approach(self, force: float) -> float:
        """The static approach [m] under a compressive force [N]."""
        f = max(force, 0.0)
        if self.law == KELVIN_VOIGT:
            return f / self.stiffness
        return (f / self.stiffness) ** (1.0 / HERTZ_EXPONENT)

    def pressure(self, force: np.ndarray) -> np.ndarray:
        """Peak Hertz pressure [Pa] under a compressive force [N] (module docstring); NaN where
        the geometry does not give it."""
        f = np.maximum(np.asarray(force, dtype=float), 0.0)
        if self.radius > 0.0 and self.width > 0.0:
            return np.sqrt(f / self.width * self.modulus / (math.pi * self.radius))
        if self.radius > 0.0 and self.law == HERTZ:
            return np.cbrt(6.0 * f * self.modulus**2 / (math.pi**3 * self.radius**2))
        return np.full(f.shape, np.nan)


def pair_modulus(modulus: float, poisson: float) -> float:
    """E* [Pa] of two bodies of one material: 1/E* = 2(1 − ν²)/E."""
    return modulus / (2.0 * (1.0 - poisson**2))


def line_contact_stiffness(pair: float, width: float) -> float:
    """k [N/m] of a line contact of length ``width`` [m]: (π/2)·E*·w."""
    return 0.5 * math.pi * pair * width


def hertz_constant(pair: float, radius: float) -> float:
    """K [N/m^1.5] of Hertz's point contact of relative radius ``radius`` [m]: (4/3)·E*·√R'."""
    return 4.0 / 3.0 * pair * math.sqrt(radius)


def contact_law(train: ValveTrain, contact: str) -> ContactLaw:
    """The law of ``contact`` ("cam" or "seat") of a train (checked by ``valve_train``)."""
    name = getattr(train, f"{contact}_contact")
    code = LAW_CODES[name]
    pair = pair_modulus(train.contact_modulus, train.contact_poisson)
    width, radius = _contact_geometry(train, contact)
    if code == RIGID:
        return ContactLaw(RIGID, math.inf, 0.0, pair, width, radius)
    stiffness_name, damping_name = CONTACT_CONSTANTS[name]
    stiffness = getattr(train, f"{contact}_{stiffness_name}")
    if stiffness == 0.0:
        stiffness = (
            line_contact_stiffness(pair, width)
            if code == KELVIN_VOIGT
            else hertz_constant(pair, radius)
        )
    return ContactLaw(
        code, stiffness, getattr(train, f"{contact}_{damping_name}"), pair, width, radius
    )


def is_compliant(train: ValveTrain) -> bool:
    """A train with a compliant law at either contact."""
    return train.cam_contact != "rigid" or train.seat_contact != "rigid"
