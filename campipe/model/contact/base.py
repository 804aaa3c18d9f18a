"""The interface every contact law implements, and what the laws share: the pair's modulus
and the peak Hertz pressure of a line contact."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from campipe.model.contact_keys import _contact_geometry
from campipe.model.parameters import ValveTrain


def pair_modulus(modulus: float, poisson: float) -> float:
    """E* [Pa] of two bodies of one material: 1/E* = 2(1 − ν²)/E."""
    return modulus / (2.0 * (1.0 - poisson**2))


@dataclass(frozen=True)
class ContactLaw(ABC):
    """One contact's force law, SI: the force F of the approach δ [m] (the penetration of the
    undeformed surfaces, positive in contact) and its rate δ̇ [m/s], compressive positive.

    A law is a subclass in a file of its own, registered by name
    (:func:`campipe.model.contact.register_law`)."""

    #: The law's name in a spec's ``cam_contact`` / ``seat_contact``.
    name: ClassVar[str]
    #: Parameter name suffixes of the law's constants, the stiffness first
    #: (``parameters.CONTACT_CONSTANTS``).
    constants: ClassVar[tuple[str, ...]]
    #: A force element of δ (integrated by ``engine.compliant``), not a held coordinate.
    compliant: ClassVar[bool] = True
    #: F = stiffness·δ + damping·δ̇ while closed: propagated exactly (``engine.compliant``).
    linear: ClassVar[bool] = False

    stiffness: float  # the law's stiffness constant [N/m, N/m^1.5, …]; inf: rigid
    damping: float  # its damping constant [N·s/m, s/m, …]
    modulus: float  # E* of the pair [Pa]
    width: float  # line contact length [m]; 0: not a line contact
    radius: float  # relative radius of curvature R' [m]; 0: not given

    @classmethod
    def from_train(cls, train: ValveTrain, contact: str) -> ContactLaw:
        """The law of ``contact`` ("cam" or "seat") from a train's constants; a stiffness of
        0 (not given) from the contact's geometry."""
        pair = pair_modulus(train.contact_modulus, train.contact_poisson)
        width, radius = _contact_geometry(train, contact)
        stiffness_name, damping_name = cls.constants
        stiffness = getattr(train, f"{contact}_{stiffness_name}")
        if stiffness == 0.0:
            stiffness = cls.geometric_stiffness(pair, width, radius)
        return cls(stiffness, getattr(train, f"{contact}_{damping_name}"), pair, width, radius)

    @staticmethod
    def geometric_stiffness(pair: float, width: float, radius: float) -> float:
        """The stiffness constant from the pair's modulus E* [Pa], the line contact's length
        [m] and the relative radius R' [m]; NaN where the law has none."""
        return math.nan

    @abstractmethod
    def force(self, delta: float, rate: float) -> float:
        """The force [N] at approach δ [m] and rate δ̇ [m/s], before the no-tension cut."""

    @abstractmethod
    def slopes(self, delta: float, rate: float) -> tuple[float, float]:
        """(∂F/∂δ [N/m], ∂F/∂δ̇ [N·s/m]) at δ, δ̇."""

    @abstractmethod
    def monitor(self, delta: float, rate: float) -> float:
        """Positive exactly where the contact is closed (approach and force both positive):
        its zero is the closing (crossed upward) and the release (downward) [m]."""

    @abstractmethod
    def approach(self, force: float) -> float:
        """The static approach δ [m] under a compressive force [N]."""

    def pressure(self, force: np.ndarray) -> np.ndarray:
        """Peak Hertz pressure [Pa] under a compressive force [N]: a line contact
        p = √(F'·E*/(π·R')), F' = F/w; a point contact where the law is Hertz's
        (:meth:`point_pressure`); NaN where the geometry does not give it."""
        f = np.maximum(np.asarray(force, dtype=float), 0.0)
        if self.radius > 0.0 and self.width > 0.0:
            return np.sqrt(f / self.width * self.modulus / (math.pi * self.radius))
        return self.point_pressure(f)

    def line_pressure(self, load: np.ndarray) -> np.ndarray:
        """Peak Hertz pressure [Pa] of the line contact (its width) under a compressive force
        F over the relative radius of curvature R', ``load`` = F/R' [N/m]: √(F'·E*/(π·R')),
        F' = F/w (:meth:`pressure` at a radius of its own)."""
        load = np.maximum(np.asarray(load, dtype=float), 0.0)
        return np.sqrt(load / self.width * self.modulus / math.pi)

    def point_pressure(self, force: np.ndarray) -> np.ndarray:
        """The peak pressure [Pa] of a contact that is not a line contact, under a
        compressive force [N]: NaN unless the law says."""
        return np.full(force.shape, np.nan)
