"""How hard a mass lands on a contact: the coefficient of restitution of a linear contact that
lets go where its force reaches zero, its inverse, and the mass an impulse at a contact meets
(the rest of the train free). ``campipe model`` shows them (:mod:`campipe.model.contact_modes`);
a kelvin-voigt contact given its restitution takes its damping from them
(:func:`landing_damping`, ``contact.KelvinVoigt.from_train``). No contact law is imported
here: the laws import this module.

Pure numerics: a train and numbers in, numbers out.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from campipe.model.assembly import struck_mass, system_matrices
from campipe.model.layouts import mirror, own_matrices, used_coordinates
from campipe.model.levers import LEVERS, rest_ratio
from campipe.vocabulary import CAM, SEAT


def released_restitution(zeta: float) -> float:
    """The coefficient of restitution of a mass landing on a spring k and dashpot c in
    parallel (ζ = c/(2√(k·m))) that let go where their force k·δ + c·δ̇ reaches zero: with
    δ = (v₀/ω_d)·e^(−ζωt)·sin(ω_d·t), the force vanishes at ω_d·t* = π − 2·asin ζ, where
    δ̇ = −v₀·e^(−ζωt*), so e = exp(−ζ·(π − 2·asin ζ)/√(1 − ζ²)) (ζ < 1; e⁻² at ζ = 1, and
    exp(−ζ·atanh(2ζ√(ζ² − 1)/(2ζ² − 1))/√(ζ² − 1)) beyond). Not the classic
    exp(−πζ/√(1 − ζ²)), which holds the dashpot in tension until δ = 0."""
    if not zeta >= 0.0:
        raise ValueError(f"zeta: found {zeta!r}, expected ≥ 0")
    if zeta < 1.0:
        return math.exp(-zeta * (math.pi - 2.0 * math.asin(zeta)) / math.sqrt(1.0 - zeta * zeta))
    if zeta == 1.0:
        return math.exp(-2.0)
    beta = math.sqrt(zeta * zeta - 1.0)
    return math.exp(-zeta * math.atanh(2.0 * zeta * beta / (2.0 * zeta * zeta - 1.0)) / beta)


def restitution_damping_ratio(restitution: float) -> float:
    """The ζ whose :func:`released_restitution` is ``restitution`` e (0 < e ≤ 1): e falls
    from 1 at ζ = 0 towards 0 (as 1/(4ζ²) for large ζ); found by bisection (Brent's) on a
    bracket doubled until it holds e, to ζ's rounding."""
    if not 0.0 < restitution <= 1.0:
        raise ValueError(f"restitution: found {restitution!r}, expected 0 < e ≤ 1")
    if restitution == 1.0:
        return 0.0
    from scipy.optimize import brentq  # (not at import: the command line's start)

    high = 1.0
    while released_restitution(high) > restitution:
        high *= 2.0
    return float(
        brentq(lambda z: released_restitution(z) - restitution, 0.0, high, xtol=1e-15, rtol=1e-15)
    )


def contact_point(train, contact: str) -> tuple[int, float]:
    """A contact's coordinate (q1 for the cam, q7 for the seat, q1 for a one-mass chain's
    seat: its valve is its follower) and the lever ratio r there (a lever's rest ratio at its
    cam, else 1)."""
    if contact == "cam":
        return CAM, rest_ratio(train) if train.layout in LEVERS else 1.0
    return (CAM if mirror(train) else SEAT), 1.0


def struck_at(train, mass: np.ndarray, contact: str) -> tuple[float, int, float]:
    """(the mass an impulse at the contact's coordinate meets, the rest of the train free
    [kg]; that coordinate's row in the train's own ``mass`` (``layouts.own_matrices``); the
    lever ratio r there)."""
    coordinate, ratio = contact_point(train, contact)
    used = used_coordinates(train)
    at = int(np.flatnonzero(used == coordinate)[0])
    return struck_mass(mass, at, [j for j in range(used.size) if j != at]), at, ratio


@functools.lru_cache(maxsize=256)
def struck(train, contact: str) -> tuple[float, float]:
    """(the struck mass [kg], the lever ratio r) of :func:`struck_at` for the train's own
    matrices, once per train."""
    sm = system_matrices(train)
    mass, _, ratio = struck_at(
        train, own_matrices(train, sm.mass, sm.stiffness, sm.damping)[0], contact
    )
    return mass, ratio


def landing_damping(train, contact: str, stiffness: float, restitution: float) -> float:
    """The damping c [N·s/m] at a kelvin-voigt contact of stiffness k [N/m] on which the
    struck mass m lands with coefficient of restitution e (``*_restitution``): on the valve
    side k/r² and c/r², so c = 2·ζ(e)·r·√(k·m) (:func:`restitution_damping_ratio`)."""
    mass, ratio = struck(train, contact)
    return 2.0 * restitution_damping_ratio(restitution) * ratio * math.sqrt(stiffness * mass)
