"""Element matrices and compatibility matrices of the valve train (thesis Ch. II, Eqs. 2–10).

Pure functions on floats and arrays; any consistent unit system works (campipe uses SI).
The OCR copy of the thesis lost signs in Eqs. 7 and 9; the forms here are the standard ones,
k·[[1, −1], [−1, 1]] and the consistent bar mass (M/6)·[[2, 1], [1, 2]], and with them the
assembled matrices reproduce its Figures 11–14.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.constants import STANDARD_GRAVITY
from campipe.model.parameters import N_DOF, ValveTrain


def bar_stiffness(k: float) -> np.ndarray:
    """Axial bar stiffness, thesis Eq. 7 (with its lost sign restored): k·[[1, −1], [−1, 1]]."""
    return k * np.array([[1.0, -1.0], [-1.0, 1.0]])


def bar_mass(m: float) -> np.ndarray:
    """Consistent axial bar mass, thesis Eq. 9: (m/6)·[[2, 1], [1, 2]]."""
    return m / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])


def beam_stiffness(ei: float, length: float) -> np.ndarray:
    """Euler–Bernoulli beam stiffness, thesis Eq. 8, in the order (v1, v2, θ1, θ2)."""
    L = length
    return (
        ei
        / L**3
        * np.array(
            [
                [12.0, -12.0, 6 * L, 6 * L],
                [-12.0, 12.0, -6 * L, -6 * L],
                [6 * L, -6 * L, 4 * L**2, 2 * L**2],
                [6 * L, -6 * L, 2 * L**2, 4 * L**2],
            ]
        )
    )


def beam_mass(m: float, length: float) -> np.ndarray:
    """Consistent beam mass, thesis Eq. 10, in the order (v1, v2, θ1, θ2)."""
    L = length
    return (
        m
        / 420.0
        * np.array(
            [
                [156.0, 54.0, 22 * L, -13 * L],
                [54.0, 156.0, 13 * L, -22 * L],
                [22 * L, 13 * L, 4 * L**2, -3 * L**2],
                [-13 * L, -22 * L, -3 * L**2, 4 * L**2],
            ]
        )
    )


def _selector(rows: list[tuple[int, float]]) -> np.ndarray:
    """A compatibility matrix: row i picks sign·q[index], or nothing for index −1 (ground)."""
    beta = np.zeros((len(rows), N_DOF))
    for i, (j, sign) in enumerate(rows):
        if j >= 0:
            beta[i, j] = sign
    return beta


GROUND = (-1, 0.0)

#: Compatibility matrices [β]ᵢ (thesis Eqs. 2–4), element coordinates from system coordinates
#: (0-based q index, sign). Axial elements use (u_lower, u_upper) measured upward; q1 and q7
#: point down, so they enter with a minus sign. Beams use (v1, v2, θ1, θ2), v up and θ the slope
#: along the rocker from the pushrod end towards the valve end; the pivot cannot translate.
BETA: dict[str, np.ndarray] = {
    "pushrod": _selector([(0, -1.0), (1, 1.0)]),
    "rocker_pushrod_arm": _selector([(1, 1.0), GROUND, (2, 1.0), (5, 1.0)]),
    "rocker_valve_arm": _selector([GROUND, (3, 1.0), (5, 1.0), (4, 1.0)]),
    "spring": _selector([GROUND, (3, 1.0)]),
    "valve_stem": _selector([(6, -1.0), (3, 1.0)]),
}


@dataclass(frozen=True)
class Element:
    """One finite element of the train."""

    name: str  # element name (see campipe.model.parameters)
    beta: np.ndarray  # (n_e, 7) compatibility matrix
    stiffness: np.ndarray  # (n_e, n_e) element stiffness
    mass: np.ndarray  # (n_e, n_e) element consistent mass


def elements(train: ValveTrain) -> list[Element]:
    """The five elements of ``train`` with their matrices (thesis Eqs. 7–10)."""
    density = train.specific_weight / STANDARD_GRAVITY
    E = train.elastic_modulus
    out = []
    for name in BETA:
        L = getattr(train, f"{name}_length")
        D = getattr(train, f"{name}_diameter")
        area = math.pi * D**2 / 4.0
        m = density * area * L
        if name.startswith("rocker"):
            inertia = math.pi * D**4 / 64.0
            ke, me = beam_stiffness(E * inertia, L), beam_mass(m, L)
        else:
            k = train.spring_rate if name == "spring" else E * area / L
            ke, me = bar_stiffness(k), bar_mass(m)
        out.append(Element(name, BETA[name], ke, me))
    return out
