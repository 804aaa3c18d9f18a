"""Closed-form propagation data for the ``modal-exact`` integrator (pure numpy, per train).

Between events the train is linear in a fixed configuration, driven by constant loads (the
spring preload, the seat) and by the cam's prescribed motion, which on each piece of the
profile is a polynomial in the cam angle plus a harmonic term. Write the free coordinates'
state as z = [x; ẋ] (2·n_free entries):

    ż = A z + B_q q_p(t) + B_v q̇_p(t) + B_a q̈_p(t) + b_f

where p are the held coordinates (q1 on the cam, q7 on the seat). The solution is
z(t) = e^{Aτ} (z(t_s) − z_p(t_s)) + z_p(t), where z_p is the particular solution for the
piece's polynomial and harmonic forcing, found exactly (``Z_k = A⁻¹(ω(k+1) Z_{k+1} − b_k)``
and ``(iωI − A) Z_T = b_T``). Nothing here depends on a step size: the integrator is exact
between events up to rounding.

The homogeneous part is propagated in a real block-diagonal form A = X B X⁻¹: each block
B_b is 1×1 (a real eigenvalue) or 2×2 (a conjugate pair, or two real eigenvalues closer
than ``NEAR``: a critically damped mode), with an orthonormal basis of its invariant
subspace from the balanced real Schur form (LAPACK ``dtrsen``). With λ̄ = tr B_b / 2,
δ² = (tr B_b / 2)² − det B_b and N_b = B_b − λ̄ I,

    e^{B_b τ} = f1(τ)·I + f2(τ)·N_b,   f1 = e^{λ̄τ}·C(τ),   f2 = e^{λ̄τ}·S(τ),

C = cos ντ, S = sin(ντ)/ν for a pair with δ² = −ν² < 0, C = cosh δτ, S = sinh(δτ)/δ for
δ² > 0, and C = 1, S = τ at δ = 0 (the Jordan form of a critically damped mode): one formula,
uniformly accurate as a mode passes through critical damping, where an eigenvector basis
becomes singular.

The contact forces are F_r = ρ_r·z + σ_r·(q_p, q̇_p, q̈_p) + σ0_r for r = q1, q7 (thesis
Eqs. 26, 27 with ẍ eliminated through the equation of motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from campipe import disk_cache
from campipe.errors import CampipeError
from campipe.model.assembly import SystemMatrices, lapack_version
from campipe.vocabulary import (
    CAM,
    CAM_CONTACT,
    CONFIGURATIONS,
    CONTACTS,
    SEAT,
    SEATED,
    free_coordinates,
)

NS = 14  # the thesis train's state size: 2 × 7 free coordinates (configuration II)
# Index hc of the held-coordinate axes below follows vocabulary.CONTACTS: 0 the cam, 1 the seat.
#: Two real eigenvalues closer than this (relative) share a 2×2 block: their eigenvectors
#: are nearly parallel (a mode near critical damping), the block's basis is not.
NEAR = 1e-3
#: A configuration whose scaled block basis is conditioned worse than this (three or more
#: coinciding eigenvalues) is refused.
MAX_CONDITION = 1e12
#: A block whose eigenvalues are all slower than this [1/s] is slow: its particular solutions
#: are not A⁻¹'s recursion, whose coefficients grow as (ω/|λ|)^k at cam speed ω, but a series
#: that converges as (|λ|·x/ω)^k/k! (``closed_form.particular``). The train's own modes are
#: far faster; a lash adjuster's plunger relaxing through its dashpot (``plunger_modes``),
#: or drifting (an eigenvalue 0), is slow.
SLOW_RATE = 20.0


class DefectiveModesError(CampipeError, ValueError):
    """A configuration whose state matrix has no well-conditioned block-diagonal form."""


@dataclass(frozen=True)
class ModalData:
    """Per-configuration closed-form data of one train of n coordinates, padded to its
    configuration II's ns = 2n states (NS = 14 for the thesis's seven coordinates; a batch
    pads every train's to its largest, ``pad_stack``).

    Index 0–3 of the leading axis is configuration I–IV; blocks are ordered fastest first.
    """

    n_free: np.ndarray  # (4,) int: free coordinates; the state has 2·n_free entries
    free: np.ndarray  # (4, n) int: the free coordinates in order, −1 padded
    eigenvalues: np.ndarray  # (4, NS) complex eigenvalues of A [1/s] (for reports)
    a_mat: np.ndarray  # (4, NS, NS) real state matrix A [1/s]
    #: (4, NS, NS) real A⁻¹ [s]; with slow blocks (SLOW_RATE), the inverse on the others
    #: only (X·blockdiag(B_b⁻¹, 0 for a slow one)·X⁻¹)
    a_inv: np.ndarray
    slow: np.ndarray  # (4, NS) bool: block b is slow (SLOW_RATE)
    any_slow: np.ndarray  # (4,) bool: the configuration has a slow block
    b_in: np.ndarray  # (4, NS, 3, 2) B for (q, q̇, q̈) of the held (cam, seat) coordinates
    b_load: np.ndarray  # (4, NS) constant forcing from the preload
    rho: np.ndarray  # (4, 2, NS) contact-force rows on the state, for (q1, q7)
    sigma: np.ndarray  # (4, 2, 3, 2) contact-force coefficients on the held inputs
    sigma0: np.ndarray  # (4, 2) constant part of the contact forces [N]
    impulse: np.ndarray  # (4, 2, n) Δv of each coordinate per unit Δv of a held one
    n_blocks: np.ndarray  # (4,) int: blocks of the real block-diagonal form
    bstart: np.ndarray  # (4, NS) int: first basis column of block b
    bdim: np.ndarray  # (4, NS) int: 1 or 2
    lam_bar: np.ndarray  # (4, NS) λ̄ of block b [1/s]
    delta2: np.ndarray  # (4, NS) δ² of block b [1/s²]
    rate: np.ndarray  # (4, NS) slowest decay rate of block b, its envelope e^{rate·τ} [1/s]
    speed: np.ndarray  # (4, NS) largest |λ| of block b [1/s]
    basis: np.ndarray  # (4, NS, NS) X, the blocks' bases in columns
    basis_inv: np.ndarray  # (4, NS, NS) X⁻¹
    basis_n: np.ndarray  # (4, NS, NS) X·N (N block-diagonal, the N_b)
    block_n: np.ndarray  # (4, NS, NS) N, block-diagonal: the N_b
    rho_x: np.ndarray  # (4, 2, NS) ρ·X
    rho_xn: np.ndarray  # (4, 2, NS) ρ·X·N
    #: (2,) an impact at one contact (cam, seat) with the other held: the velocity at which the
    #: other would separate, per unit velocity change of the struck one, if it were released
    #: (the impact taken in the single-contact configuration, I or IV) [-]; positive where it
    #: separates, which is where its reaction impulse in configuration III would pull
    separation: np.ndarray


def state_matrix(M: np.ndarray, C: np.ndarray, K: np.ndarray, free) -> np.ndarray:
    """A of ż = A z + … for the free coordinates ``free`` (z = [x; ẋ])."""
    fr = np.asarray(free)
    nf = fr.size
    mff_inv = np.linalg.inv(M[np.ix_(fr, fr)])
    A = np.zeros((2 * nf, 2 * nf))
    A[:nf, nf:] = np.eye(nf)
    A[nf:, :nf] = -mff_inv @ K[np.ix_(fr, fr)]
    A[nf:, nf:] = -mff_inv @ C[np.ix_(fr, fr)]
    return A


def _schur_groups(T: np.ndarray) -> list[list[int]]:
    """The diagonal positions of a real Schur form grouped into blocks: its 2×2 blocks (a
    conjugate pair), and its real eigenvalues singly or in pairs closer than NEAR."""
    ns = T.shape[0]
    groups, singles, i = [], [], 0
    while i < ns:
        if i + 1 < ns and T[i + 1, i] != 0.0:
            groups.append([i, i + 1])
            i += 2
        else:
            singles.append(i)
            i += 1
    singles.sort(key=lambda k: T[k, k])
    j = 0
    while j < len(singles):
        a = singles[j]
        if j + 1 < len(singles):
            b = singles[j + 1]
            if abs(T[b, b] - T[a, a]) <= NEAR * max(abs(T[a, a]), abs(T[b, b])):
                groups.append([a, b])
                j += 2
                continue
        groups.append([a])
        j += 1
    return groups


def block_form(A: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """A = X·blockdiag(B_b)·X⁻¹: the blocks' bases X (ns × ns, block b in its columns) and the
    blocks B_b, fastest first. Each basis is orthonormal in the balanced coordinates, from the
    real Schur form reordered to put the block first (LAPACK dtrsen). Kept on disk for the
    next process (``campipe.disk_cache.arrays``), as the train's modes are."""
    X, *blocks = disk_cache.arrays("block-forms", [A], lapack_version(), lambda: _block_form(A))
    return X, blocks


def _block_form(A: np.ndarray) -> list[np.ndarray]:
    """X and the blocks, in one list (:func:`block_form`)."""
    import scipy.linalg  # 0.1 s to import: not for a train solved before
    from scipy.linalg import lapack

    ns = A.shape[0]
    balanced, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
    T, Q = scipy.linalg.schur(balanced, output="real")
    cols, blocks = [], []
    for group in _schur_groups(T):
        select = np.zeros(ns, np.int32)
        select[group] = 1
        ts, qs, *_, m, _s, _sep, info = lapack.dtrsen(select, T, Q, job="N")
        if info != 0 or m != len(group):
            raise DefectiveModesError(f"the block-diagonal form failed (dtrsen info {info})")
        cols.append(scale[:, None] * qs[:, :m])
        blocks.append(ts[:m, :m])
    speed = [_block_speed(b) for b in blocks]
    order = np.argsort(speed, kind="stable")[::-1]
    return [np.hstack([cols[k] for k in order]), *[blocks[k] for k in order]]


def _fast_inverse(X: np.ndarray, Xinv: np.ndarray, blocks: list[np.ndarray], slow: list[bool]
                  ) -> np.ndarray:  # fmt: skip
    """X·blockdiag(B_b⁻¹, or 0 for a slow block)·X⁻¹: A's inverse on its fast blocks (a slow
    block may be singular: an eigenvalue 0, a drift)."""
    inverse = [
        np.zeros(B.shape) if s else np.linalg.inv(B) for B, s in zip(blocks, slow, strict=True)
    ]
    return X @ _block_diag(inverse) @ Xinv


def _block_diag(blocks: list[np.ndarray]) -> np.ndarray:
    import scipy.linalg

    return scipy.linalg.block_diag(*blocks)


def _block_numbers(B: np.ndarray) -> tuple[float, float]:
    """λ̄ and δ² of a block."""
    if B.shape[0] == 1:
        return float(B[0, 0]), 0.0
    half = 0.5 * (B[0, 0] - B[1, 1])
    return 0.5 * float(B[0, 0] + B[1, 1]), float(half * half + B[0, 1] * B[1, 0])


def _block_speed(B: np.ndarray) -> float:
    lbar, d2 = _block_numbers(B)
    return float(np.sqrt(lbar * lbar - d2)) if d2 < 0.0 else abs(lbar) + float(np.sqrt(d2))


def modal_data(sm: SystemMatrices) -> ModalData:
    """Closed-form data of every configuration for one train.

    Raises
    ------
    DefectiveModesError
        If a configuration's block basis, scaled (positions by 1, velocities by 1/|λ|max), is
        conditioned worse than MAX_CONDITION.
    """
    M, C, K, f = sm.mass, sm.damping, sm.stiffness, sm.preload
    n = M.shape[0]
    size = 2 * n  # the state size of configuration II, which pads the others'
    out = {
        "n_free": np.zeros(4, np.int64),
        "free": np.full((4, n), -1, np.int64),
        "eigenvalues": np.zeros((4, size), complex),
        "a_mat": np.zeros((4, size, size)),
        "a_inv": np.zeros((4, size, size)),
        "slow": np.zeros((4, size), np.bool_),
        "any_slow": np.zeros(4, np.bool_),
        "b_in": np.zeros((4, size, 3, 2)),
        "b_load": np.zeros((4, size)),
        "rho": np.zeros((4, 2, size)),
        "sigma": np.zeros((4, 2, 3, 2)),
        "sigma0": np.zeros((4, 2)),
        "impulse": np.zeros((4, 2, n)),
        "n_blocks": np.zeros(4, np.int64),
        "bstart": np.zeros((4, size), np.int64),
        "bdim": np.zeros((4, size), np.int64),
        "lam_bar": np.zeros((4, size)),
        "delta2": np.zeros((4, size)),
        "rate": np.zeros((4, size)),
        "speed": np.zeros((4, size)),
        "basis": np.zeros((4, size, size)),
        "basis_inv": np.zeros((4, size, size)),
        "basis_n": np.zeros((4, size, size)),
        "block_n": np.zeros((4, size, size)),
        "rho_x": np.zeros((4, 2, size)),
        "rho_xn": np.zeros((4, 2, size)),
        "separation": np.zeros(2),
    }
    for ci, cfg in enumerate(CONFIGURATIONS):
        fr = np.array(free_coordinates(cfg, n))
        nf = fr.size
        ns = 2 * nf
        mff_inv = np.linalg.inv(M[np.ix_(fr, fr)])
        A = state_matrix(M, C, K, fr)
        X, blocks = block_form(A)
        Xinv = np.linalg.inv(X)
        eig = np.linalg.eigvals(A)
        scaled = X / np.r_[np.ones(nf), np.full(nf, np.abs(eig).max())][:, None]
        condition = np.linalg.cond(scaled / np.linalg.norm(scaled, axis=0))
        if condition > MAX_CONDITION:
            raise DefectiveModesError(
                f"configuration {CONFIGURATIONS[cfg].roman}: its modes have no well-conditioned "
                f"block form (condition {condition:.2g}); change damping_ratios"
            )
        out["n_free"][ci] = nf
        out["free"][ci, :nf] = fr
        out["eigenvalues"][ci, :ns] = eig
        out["a_mat"][ci, :ns, :ns] = A
        slow = [_block_speed(B) < SLOW_RATE for B in blocks]
        out["slow"][ci, : len(blocks)] = slow
        out["any_slow"][ci] = any(slow)
        out["a_inv"][ci, :ns, :ns] = (
            _fast_inverse(X, Xinv, blocks, slow) if any(slow) else (np.linalg.inv(A))
        )
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
        # The blocks.
        XN = np.zeros((ns, ns))
        col = 0
        out["n_blocks"][ci] = len(blocks)
        for b, B in enumerate(blocks):
            k = B.shape[0]
            lbar, d2 = _block_numbers(B)
            N = B - lbar * np.eye(k)
            XN[:, col : col + k] = X[:, col : col + k] @ N
            out["block_n"][ci, col : col + k, col : col + k] = N
            out["bstart"][ci, b] = col
            out["bdim"][ci, b] = k
            out["lam_bar"][ci, b] = lbar
            out["delta2"][ci, b] = d2
            out["rate"][ci, b] = lbar + np.sqrt(d2) if d2 > 0.0 else lbar
            out["speed"][ci, b] = _block_speed(B)
            col += k
        out["basis"][ci, :ns, :ns] = X
        out["basis_inv"][ci, :ns, :ns] = Xinv
        out["basis_n"][ci, :ns, :ns] = XN
        out["rho_x"][ci, :, :ns] = out["rho"][ci, :, :ns] @ X
        out["rho_xn"][ci, :, :ns] = out["rho"][ci, :, :ns] @ XN
        # A plastic impact that sets held coordinate p's velocity: M Δv = P e_p with the other
        # held coordinates fixed, so Δv_free = −M_ff⁻¹ M_fp Δv_p.
        for hc, p in enumerate(CONTACTS):
            out["impulse"][ci, hc, fr] = -mff_inv @ M[fr, p]
            out["impulse"][ci, hc, p] = 1.0
    # The other contact's separation velocity if released: q7 opening (+) leaves the seat, q1
    # moving up (−) leaves the cam.
    out["separation"][0] = out["impulse"][CAM_CONTACT - 1, 0, SEAT]
    out["separation"][1] = -out["impulse"][SEATED - 1, 1, CAM]
    return ModalData(**out)


def harmonic_responses(train, n_free, a_mat, b_in, omega):
    """(n, 4, ns) complex ζ per case (ns the padded state size of ``a_mat``): the particular
    solution for a cam harmonic Re(β e^{iθ}) of the lift is Z_T = β·ζ, with θ = ωt
    (configurations I and III hold the cam).

    The cam coordinate is q1 = −lift, so (q1, q̇1, q̈1) = Re(β (−1, −iω, ω²) e^{iθ}) and
    (iωI − A) ζ = −b_q − iω b_v + ω² b_a.  Arrays as ``ModalData`` with a leading train axis;
    case c runs train ``train[c]`` at speed ``omega[c]``. One LAPACK solve (zgesv) per case
    and configuration, stacked by train: the reference the kernels' own solve
    (``closed_form.harmonic_response``, a case at its start) is tested against.
    """
    out = np.zeros((omega.shape[0], 4, a_mat.shape[2]), np.complex128)
    for t in range(a_mat.shape[0]):
        cases = np.flatnonzero(train == t)
        if cases.size == 0:
            continue
        w = omega[cases][:, None]
        iw = 1j * w
        w2 = w * w
        for ci in (0, 2):
            ns = int(2 * n_free[t, ci])
            mat = np.empty((cases.size, ns, ns), np.complex128)
            mat[:] = -a_mat[t, ci, :ns, :ns]
            mat.reshape(cases.size, ns * ns)[:, :: ns + 1] += iw  # the diagonal
            b = b_in[t, ci, :ns, :, 0]
            rhs = -b[:, 0] - iw * b[:, 1] + w2 * b[:, 2]
            out[cases, ci, :ns] = np.linalg.solve(mat, rhs[..., None])[..., 0]
    return out


def pad_stack(arrays: list[np.ndarray], fill=0) -> np.ndarray:
    """Stack arrays of one field of several trains' ``ModalData`` along a new leading axis,
    each padded at the end of every axis to the largest size there (trains of more
    coordinates have longer coordinate and state axes) with ``fill``. A train's numbers are
    unchanged by the padding: the kernels loop over its own sizes (``n_free``)."""
    shape = tuple(max(a.shape[k] for a in arrays) for k in range(arrays[0].ndim))
    out = np.full((len(arrays), *shape), fill, dtype=arrays[0].dtype)
    for i, a in enumerate(arrays):
        region: tuple[int | slice, ...] = (i, *(slice(0, m) for m in a.shape))
        out[region] = a
    return out
