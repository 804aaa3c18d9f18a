"""Closed-form propagation data for the ``modal-exact`` integrator (pure numpy, per train).

Between events the train is linear in a fixed configuration, driven by constant loads (the
spring preload, the seat) and by the cam's prescribed motion, which on each piece of the
profile is a polynomial in the cam angle plus a harmonic term. Write the free coordinates'
state as z = [x; ẋ] (2·n_free entries):

    ż = A z + B_q q_p(t) + B_v q̇_p(t) + B_a q̈_p(t) + b_f

where p are the held coordinates (q1 on the cam, q7 on the seat). With A = V Λ V⁻¹, the
solution is z(t) = V e^{Λτ} y₀ + z_p(t), where z_p is the particular solution for the
piece's polynomial and harmonic forcing, found exactly (``Z_k = A⁻¹(ω(k+1) Z_{k+1} − b_k)``
and ``(iωI − A) Z_T = b_T``). Nothing here depends on a step size: the integrator is exact
between events up to rounding.

The contact forces are F_r = ρ_r·z + σ_r·(q_p, q̇_p, q̈_p) + σ0_r for r = q1, q7 (thesis
Eqs. 26, 27 with ẍ eliminated through the equation of motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from campipe.errors import CampipeError
from campipe.model.assembly import SystemMatrices
from campipe.vocabulary import CONFIGURATIONS, CONTACTS

NS = 14  # padded state size: 2 × 7 free coordinates (configuration II)
# Index hc of the held-coordinate axes below follows vocabulary.CONTACTS: 0 the cam, 1 the seat.


class DefectiveModesError(CampipeError, ValueError):
    """A configuration whose state matrix has no complete set of eigenvectors."""


@dataclass(frozen=True)
class ModalData:
    """Per-configuration closed-form data of one train, padded to NS states.

    Index 0–3 of the leading axis is configuration I–IV.
    """

    n_free: np.ndarray  # (4,) int: free coordinates; the state has 2·n_free entries
    free: np.ndarray  # (4, 7) int: the free coordinates in order, −1 padded
    lam: np.ndarray  # (4, NS) complex eigenvalues of A [1/s]
    vec: np.ndarray  # (4, NS, NS) complex right eigenvectors V (columns)
    vec_inv: np.ndarray  # (4, NS, NS) complex V⁻¹
    a_mat: np.ndarray  # (4, NS, NS) real state matrix A [1/s]
    a_inv: np.ndarray  # (4, NS, NS) real A⁻¹ [s]
    b_in: np.ndarray  # (4, NS, 3, 2) B for (q, q̇, q̈) of the held (cam, seat) coordinates
    b_load: np.ndarray  # (4, NS) constant forcing from the preload
    rho: np.ndarray  # (4, 2, NS) contact-force rows on the state, for (q1, q7)
    sigma: np.ndarray  # (4, 2, 3, 2) contact-force coefficients on the held inputs
    sigma0: np.ndarray  # (4, 2) constant part of the contact forces [N]
    impulse: np.ndarray  # (4, 2, 7) Δv of each coordinate per unit Δv of a held one
    rho_vec: np.ndarray  # (4, 2, NS) complex: the force rows in modal coordinates, ρ·V
    vnorm: np.ndarray  # (4, NS) largest |V_sj| of each mode j over the state
    lam_abs: np.ndarray  # (4, NS) |λ_j| [1/s]


def modal_data(sm: SystemMatrices, max_condition: float = 1e10) -> ModalData:
    """Closed-form data of every configuration for one train.

    Raises
    ------
    DefectiveModesError
        If a configuration's eigenvector matrix is ill-conditioned beyond ``max_condition``
        (critically damped modes), where the modal closed form would lose accuracy.
    """
    M, C, K, f = sm.mass, sm.damping, sm.stiffness, sm.preload
    out = {
        "n_free": np.zeros(4, np.int64),
        "free": np.full((4, 7), -1, np.int64),
        "lam": np.zeros((4, NS), complex),
        "vec": np.zeros((4, NS, NS), complex),
        "vec_inv": np.zeros((4, NS, NS), complex),
        "a_mat": np.zeros((4, NS, NS)),
        "a_inv": np.zeros((4, NS, NS)),
        "b_in": np.zeros((4, NS, 3, 2)),
        "b_load": np.zeros((4, NS)),
        "rho": np.zeros((4, 2, NS)),
        "sigma": np.zeros((4, 2, 3, 2)),
        "sigma0": np.zeros((4, 2)),
        "impulse": np.zeros((4, 2, 7)),
        "rho_vec": np.zeros((4, 2, NS), complex),
        "vnorm": np.zeros((4, NS)),
        "lam_abs": np.zeros((4, NS)),
    }
    for ci, cfg in enumerate((1, 2, 3, 4)):
        fr = np.array(CONFIGURATIONS[cfg].free)
        nf = fr.size
        ns = 2 * nf
        mff_inv = np.linalg.inv(M[np.ix_(fr, fr)])
        A = np.zeros((ns, ns))
        A[:nf, nf:] = np.eye(nf)
        A[nf:, :nf] = -mff_inv @ K[np.ix_(fr, fr)]
        A[nf:, nf:] = -mff_inv @ C[np.ix_(fr, fr)]
        lam, V = np.linalg.eig(A)
        # A real A's eigenvalues come in exact conjugate pairs (LAPACK's real eig), which
        # modal-exact relies on: it sums one mode of each pair, doubled.
        upper = np.sort_complex(lam[lam.imag > 0])
        assert np.array_equal(upper, np.sort_complex(lam[lam.imag < 0].conj())), lam
        if np.linalg.cond(V) > max_condition:
            raise DefectiveModesError(
                f"configuration {cfg}: the modes are nearly defective (critically damped?); "
                "use integrator newmark-linear or change damping_ratios"
            )
        out["n_free"][ci] = nf
        out["free"][ci, :nf] = fr
        out["lam"][ci, :ns] = lam
        out["vec"][ci, :ns, :ns] = V
        out["vec_inv"][ci, :ns, :ns] = np.linalg.inv(V)
        out["a_mat"][ci, :ns, :ns] = A
        out["a_inv"][ci, :ns, :ns] = np.linalg.inv(A)
        out["b_load"][ci, nf:ns] = mff_inv @ f[fr]
        for hc, p in enumerate(CONTACTS):
            for kind, mat in enumerate((K, C, M)):  # q, q̇, q̈ of the held coordinate
                out["b_in"][ci, nf:ns, kind, hc] = -mff_inv @ mat[fr, p]
        for r, row in enumerate(CONTACTS):
            mrf = M[row, fr]
            out["rho"][ci, r, :nf] = K[row, fr] + mrf @ A[nf:, :nf]
            out["rho"][ci, r, nf:ns] = C[row, fr] + mrf @ A[nf:, nf:]
            for hc, p in enumerate(CONTACTS):
                for kind, mat in enumerate((K, C, M)):
                    out["sigma"][ci, r, kind, hc] = mat[row, p] - mrf @ mff_inv @ mat[fr, p]
            out["sigma0"][ci, r] = mrf @ mff_inv @ f[fr] - f[row]
        out["rho_vec"][ci, :, :ns] = out["rho"][ci, :, :ns] @ V
        out["vnorm"][ci, :ns] = np.abs(V).max(axis=0)
        out["lam_abs"][ci, :ns] = np.abs(lam)
        # A plastic impact that sets held coordinate p's velocity: M Δv = P e_p with the other
        # held coordinates fixed, so Δv_free = −M_ff⁻¹ M_fp Δv_p.
        for hc, p in enumerate(CONTACTS):
            out["impulse"][ci, hc, fr] = -mff_inv @ M[fr, p]
            out["impulse"][ci, hc, p] = 1.0
    return ModalData(**out)


@njit(cache=True, nogil=True)
def harmonic_responses(train, n_free, a_mat, b_in, omega):
    """(n, 4, NS) complex ζ per case: the particular solution for a cam harmonic
    Re(β e^{iθ}) of the lift is Z_T = β·ζ, with θ = ωt (configurations I and III hold the cam).

    The cam coordinate is q1 = −lift, so (q1, q̇1, q̈1) = Re(β (−1, −iω, ω²) e^{iθ}) and
    (iωI − A) ζ = −b_q − iω b_v + ω² b_a.  Arrays as ``ModalData`` with a leading train axis;
    case c runs train ``train[c]`` at speed ``omega[c]``.
    """
    n = omega.shape[0]
    out = np.zeros((n, 4, NS), np.complex128)
    for c in range(n):
        w = omega[c]
        t = train[c]
        for ci in (0, 2):
            ns = 2 * n_free[t, ci]
            mat = np.zeros((ns, ns), np.complex128)
            rhs = np.zeros(ns, np.complex128)
            for s in range(ns):
                for j in range(ns):
                    mat[s, j] = -a_mat[t, ci, s, j]
                mat[s, s] += 1j * w
                rhs[s] = (
                    -b_in[t, ci, s, 0, 0]
                    - 1j * w * b_in[t, ci, s, 1, 0]
                    + w * w * b_in[t, ci, s, 2, 0]
                )
            sol = np.linalg.solve(mat, rhs)
            for s in range(ns):
                out[c, ci, s] = sol[s]
    return out
