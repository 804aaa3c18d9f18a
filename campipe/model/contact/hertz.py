"""Hertz's point contact with Hunt and Crossley's damping (1975): F = K·δ^(3/2)·(1 + α·δ̇).

The damping force vanishes with the approach, so the force is continuous at first touch; for a
mass striking at v₀ the coefficient of restitution is e ≈ 1 − (2/3)·α·v₀ while α·v₀ is
small, so α = 3(1 − e)/(2v₀) sets e at one impact speed. K from a point contact of relative
radius R' (a crowned follower, a ball): K = (4/3)·E*·√R' (Hertz 1882); its peak pressure
p = (6·F·E*²/(π³·R'²))^(1/3)."""

from __future__ import annotations

import math

import numpy as np

from campipe.model.contact.base import ContactLaw
from campipe.model.contact_keys import CONTACT_CONSTANTS

#: Hertz's point-contact exponent.
HERTZ_EXPONENT = 1.5
#: The scale [m] of the force's sign in the monitor: min(δ, scale·(1 + α·δ̇)).
MONITOR_SCALE = 1e-3


def hertz_constant(pair: float, radius: float) -> float:
    """K [N/m^1.5] of Hertz's point contact of relative radius ``radius`` [m]: (4/3)·E*·√R'."""
    return 4.0 / 3.0 * pair * math.sqrt(radius)


class Hertz(ContactLaw):
    name = "hertz"
    constants = CONTACT_CONSTANTS["hertz"]  # K [N/m^1.5], α [s/m]

    @staticmethod
    def geometric_stiffness(pair: float, width: float, radius: float) -> float:
        return hertz_constant(pair, radius)

    def force(self, delta: float, rate: float) -> float:
        return self.stiffness * max(delta, 0.0) ** 1.5 * (1.0 + self.damping * rate)

    def slopes(self, delta: float, rate: float) -> tuple[float, float]:
        root = math.sqrt(max(delta, 0.0))
        k, alpha = self.stiffness, self.damping
        return 1.5 * k * root * (1.0 + alpha * rate), k * root**3 * alpha

    def monitor(self, delta: float, rate: float) -> float:
        """min(δ, the sign of 1 + α·δ̇); δ undamped."""
        if self.damping == 0.0:
            return delta
        return min(delta, MONITOR_SCALE * (1.0 + self.damping * rate))

    def approach(self, force: float) -> float:
        return (max(force, 0.0) / self.stiffness) ** (1.0 / HERTZ_EXPONENT)

    def point_pressure(self, force: np.ndarray) -> np.ndarray:
        if self.radius > 0.0:
            return np.cbrt(6.0 * force * self.modulus**2 / (math.pi**3 * self.radius**2))
        return super().point_pressure(force)
