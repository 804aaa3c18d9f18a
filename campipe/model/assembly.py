"""System matrices, modes, modal damping and the contact configurations (thesis Ch. II, III).

K = Σ βᵢᵀ Kₑᵢ βᵢ and M = Σ βᵢᵀ Mₑᵢ βᵢ (Eqs. 5, 6); the undamped eigenproblem (Eq. 14);
C = Φ⁻ᵀ diag(2ζω) Φ⁻¹ with mass-normalised Φ (Eqs. 21–23).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.model.elements import elements
from campipe.model.parameters import N_DOF, ValveTrain
from campipe.vocabulary import CONFIGURATIONS

#: Newmark linear acceleration (β = 1/6, γ = 1/2) is stable for ω·Δt < √12 (= (√3/π)·T),
#: whatever the damping (the γ = 1/2 family's limit does not depend on ζ).
NEWMARK_LINEAR_OMEGA_DT = math.sqrt(12.0)


@dataclass(frozen=True)
class Coordinate:
    """One system coordinate (thesis Figure 2, lost from the thesis's copy: this order and
    these signs are the ones that reproduce its Figures 11–14)."""

    symbol: str  # q1 … q7
    name: str  # readable name
    kind: str  # "translation" [m] or "rotation" [rad]
    positive: str  # positive direction


COORDINATES: tuple[Coordinate, ...] = (
    Coordinate("q1", "pushrod_foot", "translation", "down, away from the rocker"),
    Coordinate("q2", "pushrod_top", "translation", "up"),
    Coordinate("q3", "rocker_pushrod_end_rotation", "rotation", "rocker slope, pushrod to valve"),
    Coordinate("q4", "rocker_valve_end", "translation", "up"),
    Coordinate("q5", "rocker_valve_end_rotation", "rotation", "rocker slope, pushrod to valve"),
    Coordinate("q6", "rocker_pivot_rotation", "rotation", "rocker slope, pushrod to valve"),
    Coordinate("q7", "valve_foot", "translation", "down, valve opening"),
)
TRANSLATIONS = np.array([c.kind == "translation" for c in COORDINATES])


@dataclass(frozen=True)
class SystemMatrices:
    """The assembled model of one valve train, SI (translations in m, rotations in rad)."""

    mass: np.ndarray  # (7, 7) M [kg, kg·m, kg·m²]
    stiffness: np.ndarray  # (7, 7) K [N/m, N, N·m]
    damping: np.ndarray  # (7, 7) C [N·s/m, N·s, N·m·s]
    frequencies: np.ndarray  # (7,) undamped natural frequencies, ascending [rad/s]
    modes: np.ndarray  # (7, 7) mass-normalised mode shapes in columns (Φᵀ M Φ = I)
    preload: np.ndarray  # (7,) constant spring preload force vector [N]


def assemble(train: ValveTrain) -> tuple[np.ndarray, np.ndarray]:
    """Mass and stiffness matrices, thesis Eqs. 5 and 6."""
    M = np.zeros((N_DOF, N_DOF))
    K = np.zeros((N_DOF, N_DOF))
    for e in elements(train):
        K += e.beta.T @ e.stiffness @ e.beta
        M += e.beta.T @ e.mass @ e.beta
    return M, K


def normal_modes(mass: np.ndarray, stiffness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undamped eigenproblem (thesis Eq. 14): ascending ω [rad/s] and mass-normalised Φ.

    Each mode's sign is fixed so that its largest-magnitude translation is positive.
    """
    import scipy.linalg  # 0.1 s to import: not for --help, nor a finished study

    lam, phi = scipy.linalg.eigh(stiffness, mass)
    omega = np.sqrt(np.clip(lam, 0.0, None))
    n = mass.shape[0]
    trans = TRANSLATIONS if n == N_DOF else np.ones(n, bool)
    for j in range(phi.shape[1]):
        v = np.where(trans, phi[:, j], 0.0)
        if v[np.argmax(np.abs(v))] < 0:
            phi[:, j] = -phi[:, j]
    return omega, phi


def modal_damping(
    mass: np.ndarray, modes: np.ndarray, frequencies: np.ndarray, ratios
) -> np.ndarray:
    """C = Φ⁻ᵀ diag(2ζω) Φ⁻¹ (thesis Eq. 23); with Φᵀ M Φ = I, Φ⁻¹ = Φᵀ M."""
    zeta = np.asarray(ratios, dtype=float)
    left = mass @ modes
    C = left @ np.diag(2.0 * zeta * frequencies) @ left.T
    return 0.5 * (C + C.T)


def preload_vector(train: ValveTrain) -> np.ndarray:
    """The installed spring force as a constant load: it pushes the rocker valve end up (+q4)."""
    f = np.zeros(N_DOF)
    f[3] = train.spring_preload
    return f


def system_matrices(train: ValveTrain) -> SystemMatrices:
    """Assemble M, K, solve the modes and form the modal damping matrix for ``train``."""
    M, K = assemble(train)
    omega, phi = normal_modes(M, K)
    C = modal_damping(M, phi, omega, train.damping_ratios)
    return SystemMatrices(M, K, C, omega, phi, preload_vector(train))


def configuration_frequencies(
    mass: np.ndarray, stiffness: np.ndarray, configuration: int
) -> np.ndarray:
    """Natural frequencies [rad/s] of the train with the configuration's contacts held."""
    free = list(CONFIGURATIONS[configuration].free)
    omega, _ = normal_modes(mass[np.ix_(free, free)], stiffness[np.ix_(free, free)])
    return omega


def newmark_linear_stability_limit(
    mass: np.ndarray, stiffness: np.ndarray, configuration: int | None = None
) -> float:
    """Largest stable Δt [s] of the thesis integrator: √12 / ω_max.

    With ``configuration`` None, the smallest limit over the four configurations (the one a
    run that may visit any of them must respect).
    """
    configs = CONFIGURATIONS if configuration is None else (configuration,)
    return min(
        NEWMARK_LINEAR_OMEGA_DT / configuration_frequencies(mass, stiffness, c).max()
        for c in configs
    )


def unit_scale(display_length: float) -> np.ndarray:
    """Diagonal T with q_SI = T·q_display: translations scaled, rotations unchanged."""
    return np.where(TRANSLATIONS, display_length, 1.0)


def to_display_units(matrix: np.ndarray, length: float, energy: float) -> np.ndarray:
    """Convert an SI system matrix to another unit system of the same layout.

    Energy is invariant: qᵀ A q [J] = q_dᵀ A_d q_d · ``energy`` [J per display energy unit],
    with q = T q_d, T = diag(``length`` [m per display length] on translations, 1 on rotations).
    For the thesis's units, length = 0.0254 and energy = 0.1129848 (1 lbf·in in J).
    """
    t = unit_scale(length)
    return matrix * np.outer(t, t) / energy
