"""The thesis's rigid contact: a closed contact holds its coordinate and an impact is
perfectly plastic (or has the coefficient of restitution ``{contact}_restitution``).

It is a constraint, not a force element: the rigid integrators hold the coordinate and
compute the reaction, so the law has no force of the approach, and ``engine.compliant``
refuses it (``engine.settings``)."""

from __future__ import annotations

import math

from campipe.model.contact.base import ContactLaw, pair_modulus
from campipe.model.contact_keys import CONTACT_CONSTANTS, _contact_geometry
from campipe.model.parameters import ValveTrain


class Rigid(ContactLaw):
    name = "rigid"
    constants = CONTACT_CONSTANTS["rigid"]
    compliant = False

    @classmethod
    def from_train(cls, train: ValveTrain, contact: str) -> ContactLaw:
        """Infinitely stiff, undamped; the geometry kept for the peak pressure."""
        pair = pair_modulus(train.contact_modulus, train.contact_poisson)
        width, radius = _contact_geometry(train, contact)
        return cls(math.inf, 0.0, pair, width, radius)

    def _constraint(self) -> ValueError:
        return ValueError("a rigid contact holds its coordinate: it has no force law of δ")

    def force(self, delta: float, rate: float) -> float:
        raise self._constraint()

    def slopes(self, delta: float, rate: float) -> tuple[float, float]:
        raise self._constraint()

    def monitor(self, delta: float, rate: float) -> float:
        raise self._constraint()

    def approach(self, force: float) -> float:
        return 0.0
