"""A linear spring and damper in parallel: F = k·δ + c·δ̇ while positive, released when the
force reaches zero (no tension).

Its stiffness from a line contact of length w (a flat-faced follower's or a roller's width, a
seat's circumference): the approach is linear in the force up to a logarithm of the bodies'
size, so k = (π/4)·E·w/(1 − ν²) = (π/2)·E*·w (the line contact stiffness of gear teeth, Yang
and Lin 1987)."""

from __future__ import annotations

import dataclasses
import math

from campipe.model.contact.base import ContactLaw
from campipe.model.contact_keys import CONTACT_CONSTANTS
from campipe.model.landing import landing_damping
from campipe.model.parameters import ValveTrain


def line_contact_stiffness(pair: float, width: float) -> float:
    """k [N/m] of a line contact of length ``width`` [m]: (π/2)·E*·w."""
    return 0.5 * math.pi * pair * width


class KelvinVoigt(ContactLaw):
    name = "kelvin-voigt"
    constants = CONTACT_CONSTANTS["kelvin-voigt"]  # k [N/m], c [N·s/m]
    linear = True

    @classmethod
    def from_train(cls, train: ValveTrain, contact: str) -> ContactLaw:
        """The base's law; with the contact's ``*_restitution`` e given (its damping not),
        the damping that lands the struck mass on it with e
        (``landing.landing_damping``: the contact's own restitution, the train's other
        forces during the contact left out)."""
        law = super().from_train(train, contact)
        restitution = getattr(train, f"{contact}_restitution")
        if restitution == 0.0:
            return law
        damping = landing_damping(train, contact, law.stiffness, restitution)
        return dataclasses.replace(law, damping=damping)

    @staticmethod
    def geometric_stiffness(pair: float, width: float, radius: float) -> float:
        return line_contact_stiffness(pair, width)

    def force(self, delta: float, rate: float) -> float:
        return self.stiffness * delta + self.damping * rate

    def slopes(self, delta: float, rate: float) -> tuple[float, float]:
        return self.stiffness, self.damping

    def monitor(self, delta: float, rate: float) -> float:
        """min(δ, F/k)."""
        return min(delta, delta + self.damping / self.stiffness * rate)

    def approach(self, force: float) -> float:
        return max(force, 0.0) / self.stiffness
