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
from campipe.model.coordinates import GROUND, Dof, member_nodes
from campipe.model.hla import hla_series
from campipe.model.layouts import chain_placement
from campipe.model.parameters import ELEMENTS, NODE_COORDINATES, ValveTrain


def adjuster_stiffness(train: ValveTrain) -> float:
    """A chain's lash adjuster's stiffness [N/m] (NaN: none), in series with its link next to
    the cam; a finger follower's, under its pivot, seen at the pallet (``hla_series``)."""
    return hla_series(train)


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


def _selector(rows: list[Dof], n_coordinates: int) -> np.ndarray:
    """A compatibility matrix: row i picks sign·q[index], or nothing for index −1 (ground)."""
    beta = np.zeros((len(rows), n_coordinates))
    for i, (j, sign) in enumerate(rows):
        if j >= 0:
            beta[i, j] = sign
    return beta


@dataclass(frozen=True)
class Element:
    """One finite element of the train."""

    name: str  # the member it belongs to (see campipe.model.parameters.ELEMENTS)
    index: int  # 0 … n − 1 along the member, from its first end (see MEMBER_ENDS)
    beta: np.ndarray  # (n_e, n) compatibility matrix, n the train's coordinates
    stiffness: np.ndarray  # (n_e, n_e) element stiffness
    mass: np.ndarray  # (n_e, n_e) element consistent mass


def member_matrices(train: ValveTrain, member: str) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and consistent mass of each of the equal elements ``member`` is divided into
    (thesis Eqs. 7–10 on a length L/n of mass m/n).

    A bar's stiffness is E·A·n/L, the spring's n·``spring_rate`` (n springs in series make
    the rate); its mass is that of the equivalent wire, spread along the chain. A member's
    mass given directly (``<member>_mass``) replaces ρ·A·L, spread the same way.
    """
    n = train.elements_of(member)
    density = train.specific_weight / STANDARD_GRAVITY
    E = train.elastic_modulus
    L = getattr(train, f"{member}_length") / n
    D = getattr(train, f"{member}_diameter")
    area = math.pi * D**2 / 4.0
    given = getattr(train, f"{member}_mass")
    m = density * area * L if math.isnan(given) else given / n
    if NODE_COORDINATES[member] == 2:
        inertia = math.pi * D**4 / 64.0
        return beam_stiffness(E * inertia, L), beam_mass(m, L)
    k = train.spring_rate * n if member == "spring" else E * area / L
    return bar_stiffness(k), bar_mass(m)


def elements(train: ValveTrain) -> list[Element]:
    """Every finite element of ``train``, member by member (thesis Eqs. 2–10), each member's
    from its first end to its last; with one element a member, the thesis's five. A lumped
    chain's (:func:`chain_elements`) for a chain (layout lumped, direct-acting)."""
    if train.chain:
        return chain_elements(train)
    nodes = member_nodes(train)
    n_q = train.n_coordinates
    out = []
    for member in ELEMENTS:
        ke, me = member_matrices(train, member)
        chain = nodes[member]
        for i, (a, b) in enumerate(zip(chain[:-1], chain[1:], strict=True)):
            # A bar's local order is (u_a, u_b); a beam's (v_a, v_b, θ_a, θ_b) (Eqs. 8, 10).
            rows = [a[0], b[0]] if len(a) == 1 else [a[0], b[0], a[1], b[1]]
            out.append(Element(member, i, _selector(rows, n_q), ke, me))
    return out


def chain_elements(train: ValveTrain) -> list[Element]:
    """A lumped chain's elements (:mod:`campipe.model.layouts`): a point mass ``mass`` on
    each of its coordinates, a bar ``link`` (stiffness only) between neighbours, measured
    along the lift from the cam's side, and the valve ``spring`` from ground (its lower end)
    up to the valve: the valve's opening (+q7) compresses it, as the thesis's spring's
    (its extension is −q7); a one-mass chain's on its follower (its extension +q1). A
    hydraulic lash adjuster (``hla_stiffness``, :mod:`campipe.model.hla`) is in series with
    the link next to the cam."""
    index, sign = chain_placement(len(train.masses))
    n_q = train.n_coordinates
    node = [(int(i), float(s)) for i, s in zip(index, sign, strict=True)]
    none = np.zeros((1, 1))
    out = [
        Element("mass", j, _selector([node[j]], n_q), none, np.array([[m]]))
        for j, m in enumerate(train.masses)
    ]
    zero = np.zeros((2, 2))
    hla = adjuster_stiffness(train)
    for j, k in enumerate(train.stiffnesses):
        k = 1.0 / (1.0 / k + 1.0 / hla) if j == 0 and hla == hla else k  # in series
        out.append(Element("link", j, _selector(node[j : j + 2], n_q), bar_stiffness(k), zero))
    # the spring's upper end moves against the lift: −q7, or a one-mass chain's +q1
    spring = _selector([GROUND, (node[-1][0], -node[-1][1])], n_q)
    out.append(Element("spring", 0, spring, bar_stiffness(train.spring_rate), zero))
    return out
