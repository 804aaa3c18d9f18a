"""Layouts: which valve train a model describes, and how its masses sit in the engine's
coordinates.

``model.layout`` names the train:

==================  ===========================================================================
``pushrod-rocker``  the thesis's train (the default): pushrod, rocker arm, valve spring and
                    stem, every mass from the members' geometry (:mod:`campipe.model.elements`)
``lumped``          a chain of point masses from the cam to the valve given directly
                    (``masses``, the first on the cam, the last the valve), the stiffnesses
                    between neighbours (``stiffnesses``, one fewer) and the valve spring to
                    ground on the valve (``spring_rate``, ``spring_preload``)
``direct-acting``   a bucket tappet on its valve, from named masses and stiffnesses
                    (``tappet_mass``, ``valve_mass``, ``stem_stiffness``,
                    ``tappet_contact_stiffness``), built as a two-mass chain
                    (:func:`campipe.model.checks.direct_acting_chain`)
==================  ===========================================================================

The engine holds the cam contact at coordinate 0 (q1) and the seat at coordinate 6 (q7) for
every train (:mod:`campipe.vocabulary`), so a lumped chain of N masses is laid out to match:
its first mass is q1, its last (the valve) q7, masses 2 … 6 are q2 … q6 and masses 7 … N − 1
follow q7 (q8 …), as a refined member's internal nodes do. A chain of fewer than seven masses
leaves some of q2 … q6 unused: *placeholders*, each a decoupled oscillator of its own
(:func:`placeholder_dynamics`: a mass, a spring to ground, a damper, nothing else) that no load
and no contact reaches, so it stays at rest at zero in every configuration, and the kernels
need not know of layouts at all. The archive's ``q`` holds NaN there, ``campipe model`` leaves
them out, and they are not the chain's modes (``damping_ratios`` are the chain's).

A chain of one mass is a rigid direct-acting follower: the follower is the valve, so while it
rides the cam nothing of the train is free and its cam force is algebraic,
F = m·ẍ + c·ẋ + k·x + P. Its mass is q1; q7, the valve, is its *mirror*
(:func:`mirror_dynamics`): a coordinate of its own mass μ, stiffness κ and damping γ on the
relative motion y = q1 + q7 only (kinetic energy ½·m·q̇1² + ½·μ·ẏ², potential ½·k·q1² +
½·κ·y²), so y is an oscillator decoupled from the follower, at rest at zero from any start at
rest, and q7 = −q1 (the valve's lift is the follower's) in both configurations the train can
visit, I and II, to round-off: with q1 held by the cam, the free coordinates (the mirror and the
placeholders) leave the cam force exactly m·ẍ + c·ẋ + k·x + P (their Schur complement
cancels), and the impact mass at the cam is m. The engine needs no configuration without a
free coordinate. Both contacts on one body are beyond the model's two contacts, so such a
chain runs without a seat and without lash (refused, naming the key).

Signs, as the thesis's: q1 is positive *away from the lift* (towards the cam's centre: a cam
lift h holds q1 = −h), every other mass positive *along the lift*, so q7 is the valve's
opening (valve lift positive); the spring preload pushes the valve closed (a load −P on q7).
Pure Python and numpy.
"""

from __future__ import annotations

import numpy as np

from campipe.model.checks import DIRECT_ACTING, LAYOUTS, LUMPED, PUSHROD_ROCKER
from campipe.model.parameters import ValveTrain
from campipe.vocabulary import CAM, N_COORDINATES, SEAT

__all__ = [
    "DIRECT_ACTING",
    "LAYOUTS",
    "LUMPED",
    "PUSHROD_ROCKER",
    "chain_matrices",
    "chain_placement",
    "lumped_coordinates",
    "mirror",
    "mirror_dynamics",
    "own_matrices",
    "placeholder_dynamics",
    "placeholders",
    "used_coordinates",
]

#: The placeholders' damping ratio: damped, so that a steady state's periodic solution never
#: meets an undamped resonance, yet underdamped (distinct complex poles, a plain block form).
PLACEHOLDER_DAMPING = 0.5
#: The placeholders' natural frequencies as fractions of the chain's lowest (over the four
#: configurations): below every chain mode (they never set a stability limit or a step) and
#: distinct from each other and from the chain's.
PLACEHOLDER_FRACTIONS = (0.25, 0.3, 0.35, 0.4, 0.45)
#: The one-mass chain's mirror (:func:`mirror_dynamics`): its frequency as a fraction of the
#: follower's on its spring, distinct from the placeholders', damped as they are.
MIRROR_FRACTION = 0.2


def chain_index(mass: int, n_masses: int) -> int:
    """The coordinate (0-based) of a lumped chain's mass ``mass`` (0 the cam's, n − 1 the
    valve; a single mass the cam's, q1, its valve the mirror q7: :func:`mirror_dynamics`)."""
    if mass == n_masses - 1 and n_masses > 1:
        return SEAT
    return mass if mass < SEAT else mass + 1


def chain_placement(n_masses: int) -> tuple[np.ndarray, np.ndarray]:
    """Each mass's coordinate (0-based) and sign (q = sign·x with x positive along the lift),
    the cam's mass first."""
    index = np.array([chain_index(j, n_masses) for j in range(n_masses)], np.int64)
    sign = np.ones(n_masses)
    sign[0] = -1.0
    assert index[0] == CAM
    return index, sign


def n_coordinates(n_masses: int) -> int:
    """A lumped chain's coordinates: seven at least (the thesis's q1 … q7), one a mass
    beyond."""
    return max(N_COORDINATES, n_masses)


def used_coordinates(train: ValveTrain) -> np.ndarray:
    """The coordinates (0-based, ascending) that carry ``train``'s masses: all of them but a
    lumped chain's placeholders."""
    if not train.chain:
        return np.arange(train.n_coordinates)
    return np.sort(chain_placement(len(train.masses))[0])


def mirror(train: ValveTrain) -> bool:
    """A one-mass chain, whose valve q7 mirrors its follower q1 (:func:`mirror_dynamics`)."""
    return train.chain and len(train.masses) == 1


def placeholders(train: ValveTrain) -> np.ndarray:
    """The placeholder coordinates (0-based) of ``train``: none but a lumped chain's of fewer
    than seven masses (a one-mass chain's q7 is its mirror, not a placeholder)."""
    spare = np.setdiff1d(np.arange(train.n_coordinates), used_coordinates(train))
    return spare[spare != SEAT] if mirror(train) else spare


def mirror_dynamics(train: ValveTrain) -> tuple[float, float, float]:
    """A one-mass chain's mirror: (μ [kg], κ [N/m], γ [N·s/m]) on y = q1 + q7, each entering
    M, K and C as that value times [[1, 1], [1, 1]] on (q1, q7) (see the module): the
    follower's mass, at :data:`MIRROR_FRACTION` of its frequency on the spring, damped by
    :data:`PLACEHOLDER_DAMPING`."""
    mass = float(train.masses[0])
    omega = MIRROR_FRACTION * _lowest_frequency(*chain_matrices(train))
    return mass, mass * omega**2, 2.0 * PLACEHOLDER_DAMPING * mass * omega


def own_matrices(
    train: ValveTrain, mass: np.ndarray, stiffness: np.ndarray, damping: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The train's own mass, stiffness and damping matrices, over its used coordinates
    (:func:`used_coordinates`: a lumped chain's placeholders left out), a one-mass chain's
    mirror taken out of q1: the follower alone on its spring, m·ẍ + c·ẋ + k·x."""
    used = used_coordinates(train)
    sub = np.ix_(used, used)
    m, k, c = mass[sub].copy(), stiffness[sub].copy(), damping[sub].copy()
    if mirror(train):
        mu, kappa, gamma = mirror_dynamics(train)
        m[0, 0] -= mu
        k[0, 0] -= kappa
        c[0, 0] -= gamma
    return m, k, c


def chain_matrices(train: ValveTrain) -> tuple[np.ndarray, np.ndarray]:
    """A lumped chain's (N, N) mass and stiffness matrices in its own coordinates x (each
    mass's displacement along the lift, the cam's first): diagonal masses, the links between
    neighbours, the valve spring from the last mass to ground."""
    m = np.asarray(train.masses, float)
    k = np.asarray(train.stiffnesses, float)
    n = m.size
    K = np.zeros((n, n))
    for j, kj in enumerate(k):
        K[j : j + 2, j : j + 2] += kj * np.array([[1.0, -1.0], [-1.0, 1.0]])
    K[-1, -1] += train.spring_rate
    return np.diag(m), K


def _lowest_frequency(mass: np.ndarray, stiffness: np.ndarray) -> float:
    """The chain's lowest natural frequency [rad/s] over the four contact configurations
    (cam, seat, both or neither held)."""
    n = mass.shape[0]
    lowest = np.inf
    for held in ({0}, set(), {0, n - 1}, {n - 1}):
        free = [i for i in range(n) if i not in held]
        if not free:
            continue
        scale = 1.0 / np.sqrt(np.diag(mass)[free])
        a = stiffness[np.ix_(free, free)] * np.outer(scale, scale)
        lowest = min(lowest, float(np.sqrt(max(np.linalg.eigvalsh(a)[0], 0.0))))
    return lowest


def placeholder_dynamics(train: ValveTrain) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each placeholder's (mass [kg], stiffness [N/m], damping [N·s/m]): the chain's mean
    mass, at :data:`PLACEHOLDER_FRACTIONS` of the chain's lowest natural frequency, damped
    by :data:`PLACEHOLDER_DAMPING`."""
    index = placeholders(train)
    M, K = chain_matrices(train)
    mass = float(np.mean(np.diag(M)))
    omega = _lowest_frequency(M, K) * np.array(PLACEHOLDER_FRACTIONS[: index.size])
    return (
        np.full(index.size, mass),
        mass * omega**2,
        2.0 * PLACEHOLDER_DAMPING * mass * omega,
    )


def lumped_coordinates(n_masses: int) -> list[tuple[int, str, str]]:
    """(index, name, positive direction) of each coordinate of a chain of ``n_masses``, in
    coordinate order, placeholders named ``unused``."""
    index, _ = chain_placement(n_masses)
    n = n_coordinates(n_masses)
    out = [(i, "unused", "none: a placeholder, at rest") for i in range(n)]
    if n_masses == 1:
        out[CAM] = (CAM, "follower", "away from the lift, towards the cam")
        out[SEAT] = (SEAT, "valve", "along the lift, valve opening: the follower, q7 = -q1")
        return out
    for j, i in enumerate(index):
        if j == 0:
            out[i] = (i, "cam_mass", "away from the lift, towards the cam")
        elif j == n_masses - 1:
            out[i] = (i, "valve", "along the lift, valve opening")
        else:
            out[i] = (i, f"mass_{j + 1}", "along the lift, valve opening")
    return out
