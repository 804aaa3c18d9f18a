"""System matrices, modes, damping and the contact configurations (thesis Ch. II, III).

K = Σ βᵢᵀ Kₑᵢ βᵢ and M = Σ βᵢᵀ Mₑᵢ βᵢ (Eqs. 5, 6) over every finite element; the undamped
eigenproblem (Eq. 14); the damping matrix of the train's ``damping_kind``: modal,
C = Φ⁻ᵀ diag(2ζω) Φ⁻¹ with mass-normalised Φ (Eqs. 21–23), Rayleigh's C = α·M + β·K, or each
member's loss factor η as structural damping: ζ = η/2 weighted by each mode's strain energy.

A train of n coordinates (seven for the thesis's model, more with refined members, see
:mod:`campipe.model.coordinates`) gives n×n matrices with q1 … q7 at indices 0–6.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe import disk_cache
from campipe.model.coordinates import TRANSLATIONS, translations
from campipe.model.elements import elements
from campipe.model.layouts import (
    chain_matrices,
    mirror,
    mirror_dynamics,
    placeholder_dynamics,
    placeholders,
    used_coordinates,
)
from campipe.model.parameters import N_DOF, ValveTrain, mode_damping_ratios
from campipe.model.seated import seated_force
from campipe.vocabulary import CAM, CONFIGURATIONS, SEAT, free_coordinates

#: Newmark linear acceleration (β = 1/6, γ = 1/2) is stable for ω·Δt < √12 (= (√3/π)·T),
#: whatever the damping (the γ = 1/2 family's limit does not depend on ζ).
NEWMARK_LINEAR_OMEGA_DT = math.sqrt(12.0)


@dataclass(frozen=True)
class SystemMatrices:
    """The assembled model of one valve train, SI (translations in m, rotations in rad); n is
    the train's number of coordinates (7 for the thesis's model), q1 … q7 at indices 0–6."""

    mass: np.ndarray  # (n, n) M [kg, kg·m, kg·m²]
    stiffness: np.ndarray  # (n, n) K [N/m, N, N·m]
    damping: np.ndarray  # (n, n) C [N·s/m, N·s, N·m·s]
    frequencies: np.ndarray  # (n,) undamped natural frequencies, ascending [rad/s]
    modes: np.ndarray  # (n, n) mass-normalised mode shapes in columns (Φᵀ M Φ = I)
    preload: np.ndarray  # (n,) constant spring preload force vector [N]


def assemble(train: ValveTrain) -> tuple[np.ndarray, np.ndarray]:
    """Mass and stiffness matrices, thesis Eqs. 5 and 6, (n, n) each."""
    n = train.n_coordinates
    M = np.zeros((n, n))
    K = np.zeros((n, n))
    for e in elements(train):
        K += e.beta.T @ e.stiffness @ e.beta
        M += e.beta.T @ e.mass @ e.beta
    spare = placeholders(train)
    if spare.size:  # a short lumped chain's placeholders: decoupled, at rest
        m, k, _ = placeholder_dynamics(train)
        M[spare, spare] = m
        K[spare, spare] = k
    if mirror(train):  # a one-mass chain's valve, q7 = −q1 (campipe.model.layouts)
        mu, kappa, _ = mirror_dynamics(train)
        M[np.ix_(_PAIR, _PAIR)] += mu
        K[np.ix_(_PAIR, _PAIR)] += kappa
    return M, K


#: A one-mass chain's follower and its mirror, the valve.
_PAIR = [CAM, SEAT]


def normal_modes(
    mass: np.ndarray, stiffness: np.ndarray, translation: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Undamped eigenproblem (thesis Eq. 14): ascending ω [rad/s] and mass-normalised Φ.

    Each mode's sign is fixed so that its largest-magnitude translation is positive;
    ``translation`` (n,) bool says which coordinates are translations (by default the
    thesis's for a 7×7 problem, else all). Kept on disk for the next process
    (``campipe.disk_cache.arrays``): a study of trains solved before never imports
    ``scipy.linalg``.
    """
    n = mass.shape[0]
    if translation is None:
        translation = TRANSLATIONS if n == N_DOF else np.ones(n, bool)
    translation = np.asarray(translation, bool)
    omega, phi = disk_cache.arrays(
        "modes",
        [mass, stiffness, translation],
        lapack_version(),
        lambda: _normal_modes(mass, stiffness, translation),
    )
    return omega, phi


def _normal_modes(
    mass: np.ndarray, stiffness: np.ndarray, translation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    import scipy.linalg  # 0.1 s to import: not for --help, a finished study or a known train

    lam, phi = scipy.linalg.eigh(stiffness, mass)
    omega = np.sqrt(np.clip(lam, 0.0, None))
    for j in range(phi.shape[1]):
        v = np.where(translation, phi[:, j], 0.0)
        if v[np.argmax(np.abs(v))] < 0:
            phi[:, j] = -phi[:, j]
    return omega, phi


@functools.cache
def lapack_version() -> str:
    """What the LAPACK results kept on disk (``campipe.disk_cache.arrays``) depend on beyond
    their inputs: the numpy and SciPy that computed them (SciPy's LAPACK) and the processor
    they ran on (``disk_cache.processor_kind``)."""
    import scipy  # numba imports it too: its top level only, a few ms

    return f"numpy {np.__version__}; scipy {scipy.__version__}; {disk_cache.processor_kind()}"


def struck_mass(mass: np.ndarray, struck: int, free: Sequence[int]) -> float:
    """The mass [kg] an impulse at coordinate ``struck`` meets, the coordinates ``free`` free
    and the rest held: M_pp − M_pf·M_ff⁻¹·M_fp (a Schur complement). A perfectly plastic
    impact that changes the struck coordinate's velocity by Δv delivers the impulse m·Δv."""
    free = list(free)
    mpf = mass[struck, free]
    return float(mass[struck, struck] - mpf @ np.linalg.solve(mass[np.ix_(free, free)], mpf))


def modal_damping(
    mass: np.ndarray, modes: np.ndarray, frequencies: np.ndarray, ratios
) -> np.ndarray:
    """C = Φ⁻ᵀ diag(2ζω) Φ⁻¹ (thesis Eq. 23); with Φᵀ M Φ = I, Φ⁻¹ = Φᵀ M. One ratio a mode."""
    zeta = np.asarray(ratios, dtype=float)
    left = mass @ modes
    C = left @ np.diag(2.0 * zeta * frequencies) @ left.T
    return 0.5 * (C + C.T)


def rayleigh_damping(
    mass: np.ndarray, stiffness: np.ndarray, alpha: float, beta: float
) -> np.ndarray:
    """C = α·M + β·K: mode j's damping ratio is α/(2ωⱼ) + β·ωⱼ/2.

    Parameters
    ----------
    alpha : float
        Mass coefficient [1/s].
    beta : float
        Stiffness coefficient [s].
    """
    return alpha * mass + beta * stiffness


def loss_factor_damping(
    train: ValveTrain, mass: np.ndarray, modes: np.ndarray, frequencies: np.ndarray
) -> np.ndarray:
    """Each member's loss factor η as structural damping: mode j is damped by

        ζⱼ = ½ Σₑ ηₑ Uₑⱼ / Uⱼ,

    the loss factors weighted by the share of the mode's strain energy each element stores
    (Uₑⱼ = ½ φⱼᵀ βᵀKₑβ φⱼ of Uⱼ = ½ φⱼᵀ K φⱼ: the modal strain energy method), and
    C = Φ⁻ᵀ diag(2ζω) Φ⁻¹ (thesis Eq. 23's form). A hysteretic member dissipates 2π·η times
    its strain energy a cycle at every frequency; ζ = η/2 is its usual time-domain
    equivalent, on every mode (not only at one reference frequency, as a viscous C = (η/ω)·K
    would be), so one η on every member gives ζ = η/2 on every mode."""
    share = np.zeros(len(frequencies))
    for e in elements(train):
        eta = getattr(train, f"{e.name}_loss_factor")
        if eta:
            global_k = e.beta.T @ e.stiffness @ e.beta
            share += eta * np.einsum("ij,ik,kj->j", modes, global_k, modes)
    zeta = 0.5 * share / frequencies**2  # φⱼᵀ K φⱼ = ωⱼ² for mass-normalised modes
    return modal_damping(mass, modes, frequencies, zeta)


def damping_matrix(
    train: ValveTrain,
    mass: np.ndarray,
    stiffness: np.ndarray,
    frequencies: np.ndarray,
    modes: np.ndarray,
) -> np.ndarray:
    """The damping matrix of ``train``'s ``damping_kind`` (see the module); a lumped chain's
    from its own modes (:func:`chain_damping`)."""
    if train.chain:
        return chain_damping(train, mass, stiffness)
    if train.damping_kind == "rayleigh":
        return rayleigh_damping(mass, stiffness, train.rayleigh_alpha, train.rayleigh_beta)
    if train.damping_kind == "loss-factor":
        return loss_factor_damping(train, mass, modes, frequencies)
    ratios = mode_damping_ratios(train.damping_ratios, len(frequencies))
    return modal_damping(mass, modes, frequencies, ratios)


def chain_damping(train: ValveTrain, mass: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """A lumped chain's damping matrix: its ``damping_kind`` on the chain's own coordinates
    (modal: ``damping_ratios`` on the chain's modes with every mass free, Rayleigh's), each
    placeholder's own (:func:`campipe.model.layouts.placeholder_dynamics`) on its diagonal."""
    used = used_coordinates(train)
    chain = np.ix_(used, used)
    m, k = mass[chain], stiffness[chain]
    if mirror(train):  # the follower's own, its mirror's share left out
        m, k = chain_matrices(train)
    if train.damping_kind == "rayleigh":
        c = rayleigh_damping(m, k, train.rayleigh_alpha, train.rayleigh_beta)
    else:
        omega, phi = normal_modes(m, k, np.ones(used.size, bool))
        c = modal_damping(m, phi, omega, mode_damping_ratios(train.damping_ratios, used.size))
    out = np.zeros_like(mass)
    out[chain] = c
    spare = placeholders(train)
    out[spare, spare] = placeholder_dynamics(train)[2]
    if mirror(train):
        out[np.ix_(_PAIR, _PAIR)] += mirror_dynamics(train)[2]
    return out


def modal_damping_ratios(
    damping: np.ndarray, modes: np.ndarray, frequencies: np.ndarray
) -> np.ndarray:
    """Each mode's damping ratio, (Φᵀ C Φ)ⱼⱼ / (2ωⱼ): exact where C is diagonal in the modes
    (every damping kind campipe forms)."""
    return np.einsum("ij,ik,kj->j", modes, damping, modes) / (2.0 * frequencies)


def preload_direction(train: ValveTrain) -> np.ndarray:
    """The spring's constant load per newton of its force, (n,): it pushes the rocker valve
    end up (+q4). A refined spring carries the same force in every element, so its internal
    nodes take none. A lumped chain's spring pushes its valve closed (−q7), a one-mass chain's
    its follower onto the cam (+q1: the follower is the valve)."""
    f = np.zeros(train.n_coordinates)
    if mirror(train):
        f[CAM] = 1.0
    elif train.chain:
        f[SEAT] = -1.0
    else:
        f[3] = 1.0
    return f


def preload_vector(train: ValveTrain) -> np.ndarray:
    """The spring's force at the train's unstressed reference as a constant load, (n,)
    (:func:`preload_direction`): ``spring_preload``, or with lash the force that leaves the
    seated spring pushing with it (:func:`reference_preload`)."""
    return reference_preload(train) * preload_direction(train)


@functools.lru_cache(maxsize=256)
def _preload_line(train: ValveTrain) -> tuple[float, float]:
    """(f0, slope): the seated spring force of ``train`` with lash is f0 + slope·P for a
    reference preload P (it is linear in P: f0 the lash's travel times the spring's rate)."""
    stiffness = assemble(train)[1]
    direction = preload_direction(train)
    f0 = seated_force(train, stiffness, 0.0 * direction)
    return f0, seated_force(train, stiffness, direction) - f0


def reference_preload(train: ValveTrain) -> float:
    """The spring's force [N] at the train's unstressed reference, the model's constant load:
    ``spring_preload`` without lash; with lash, the force for which the spring pushes with
    ``spring_preload`` on the seat the lash places (``campipe.model.lash``'s text)."""
    if math.isnan(train.lash):
        return train.spring_preload
    f0, slope = _preload_line(train)
    return (train.spring_preload - f0) / slope


def installed_preload(train: ValveTrain, reference: float) -> float:
    """The ``spring_preload`` whose :func:`reference_preload` on ``train`` is ``reference``
    [N] (the inverse: without lash the same number)."""
    if math.isnan(train.lash):
        return reference
    f0, slope = _preload_line(train)
    return f0 + slope * reference


def system_matrices(train: ValveTrain) -> SystemMatrices:
    """Assemble M, K, solve the modes and form the damping matrix for ``train``."""
    M, K = assemble(train)
    omega, phi = normal_modes(M, K, translations(train))
    C = damping_matrix(train, M, K, omega, phi)
    return SystemMatrices(M, K, C, omega, phi, preload_vector(train))


def configuration_frequencies(
    mass: np.ndarray, stiffness: np.ndarray, configuration: int
) -> np.ndarray:
    """Natural frequencies [rad/s] of the train with the configuration's contacts held."""
    free = list(free_coordinates(configuration, mass.shape[0]))
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


def unit_scale(display_length: float, translation: np.ndarray = TRANSLATIONS) -> np.ndarray:
    """Diagonal T with q_SI = T·q_display: translations scaled, rotations unchanged."""
    return np.where(translation, display_length, 1.0)


def to_display_units(
    matrix: np.ndarray, length: float, energy: float, translation: np.ndarray | None = None
) -> np.ndarray:
    """Convert an SI system matrix to another unit system of the same layout.

    Energy is invariant: qᵀ A q [J] = q_dᵀ A_d q_d · ``energy`` [J per display energy unit],
    with q = T q_d, T = diag(``length`` [m per display length] on translations, 1 on rotations).
    For the thesis's units, length = 0.0254 and energy = 0.1129848 (1 lbf·in in J).
    ``translation`` (n,) bool marks the translations (default: the thesis's seven).
    """
    t = unit_scale(length, TRANSLATIONS if translation is None else translation)
    return matrix * np.outer(t, t) / energy


#: Element counts ``campipe model --convergence`` compares: each twice the one before, so an
#: observed order follows from the last three.
CONVERGENCE_ELEMENTS = (1, 2, 4, 8, 16)


def frequency_convergence(
    train: ValveTrain,
    member: str,
    counts: tuple[int, ...] = CONVERGENCE_ELEMENTS,
    n_modes: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """The lowest natural frequencies of ``train`` with ``member`` divided into each number of
    elements in ``counts`` (the other members as ``train`` has them).

    New members' internal modes (a spring's surge) enter as n grows, so a column is one mode
    only once it settles. The eigensolver's round-off in ωⱼ is about ε/2·(ω_max/ωⱼ)²·ωⱼ: a
    refined stiff member (the rocker arms) raises ω_max and with it the noise in the low modes.

    Returns
    -------
    frequencies : (len(counts), n_modes) array
        Ascending [rad/s], NaN beyond a model's number of modes.
    roundoff : (len(counts), n_modes) array
        The round-off bound above [rad/s].
    """
    freqs = np.full((len(counts), n_modes), np.nan)
    roundoff = np.full((len(counts), n_modes), np.nan)
    for i, n in enumerate(counts):
        omega = _eigenfrequencies(train.replace(**{f"{member}_elements": n}))
        k = min(n_modes, omega.size)
        freqs[i, :k] = omega[:k]
        roundoff[i, :k] = 0.5 * np.finfo(float).eps * omega[-1] ** 2 / omega[:k]
    return freqs, roundoff


def _eigenfrequencies(train: ValveTrain) -> np.ndarray:
    M, K = assemble(train)
    return normal_modes(M, K)[0]


def _orders(frequencies: np.ndarray, roundoff: np.ndarray, ratio: float) -> np.ndarray:
    """Observed orders from three successive rows; NaN where the changes differ in sign or
    the last is within 10× round-off."""
    d1 = frequencies[0] - frequencies[1]
    d2 = frequencies[1] - frequencies[2]
    ok = (d1 * d2 > 0) & (np.abs(d2) > 10.0 * roundoff.max(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, np.log(d1 / d2) / math.log(ratio), np.nan)


def observed_orders(
    frequencies: np.ndarray, roundoff: np.ndarray, counts: tuple[int, ...] = CONVERGENCE_ELEMENTS
) -> np.ndarray:
    """Each column's observed order of convergence in 1/n from the last three counts,
    p = log(d₁/d₂)/log(r), d the changes between successive counts and r their ratio.

    NaN where it means nothing: the changes differ in sign, the last is within 10× round-off
    (converged to the solver's precision), or, given four counts or more, the order from the
    three before differs by more than 0.5 (the column has not yet settled into one mode).
    """
    tail = counts[-4:]
    ratios = {b / a for a, b in zip(tail[:-1], tail[1:], strict=True)}
    if len(counts) < 3 or len(ratios) != 1:
        raise ValueError(f"element counts must be geometric, three or more, not {counts}")
    ratio = ratios.pop()
    last = _orders(frequencies[-3:], roundoff[-3:], ratio)
    if len(counts) == 3:
        return last
    before = _orders(frequencies[-4:-1], roundoff[-4:-1], ratio)
    return np.where(np.abs(last - before) <= 0.5, last, np.nan)
