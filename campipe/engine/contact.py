"""The four contact configurations and the quantities the integrators need from them.

Thesis Ch. III and Table I: I cam contact (q1 prescribed by the cam), II free, III cam and seat
(q1 and q7 prescribed), IV seat only (q7 prescribed). Pure numpy on one case's matrices.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.newmark import N_X, N_Z, X_A, X_Q, X_V
from campipe.model.assembly import struck_mass
from campipe.vocabulary import CAM, CONFIGURATIONS, N_COORDINATES, SEAT, free_coordinates

#: HELD[c - 1, i]: coordinate i is prescribed in configuration c (the thesis's seven; a
#: refined member's internal coordinates are never held, ``held_mask``).
HELD = np.array(
    [[i in CONFIGURATIONS[c].held for i in range(7)] for c in CONFIGURATIONS], dtype=np.bool_
)


def held_mask(configuration: int, n_coordinates: int = N_COORDINATES) -> np.ndarray:
    """(n_coordinates,) bool: the coordinates configuration ``configuration`` prescribes in a
    train of ``n_coordinates`` (only q1 and q7 ever are)."""
    out = np.zeros(n_coordinates, np.bool_)
    out[:N_COORDINATES] = HELD[configuration - 1]
    return out


def effective_mass_inverses(mass, damping, stiffness, dt: float) -> np.ndarray:
    """(4, 7, 7): inverse of M + Δt/2·C + Δt²/6·K over each configuration's free coordinates,
    zero in the held rows and columns (thesis Eq. 67, partitioned as in Appendix A)."""
    meff = mass + 0.5 * dt * damping + dt * dt / 6.0 * stiffness
    out = np.zeros((4, 7, 7))
    for c in CONFIGURATIONS:
        free = list(CONFIGURATIONS[c].free)
        out[c - 1][np.ix_(free, free)] = np.linalg.inv(meff[np.ix_(free, free)])
    return out


def newmark_step_maps(mass, damping, stiffness, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """newmark-linear's step (β = 1/6, γ = 1/2) in each configuration as two matrix products
    (thesis Appendix B, steps 2–6; applied by ``newmark._newmark_step``):

        r = load − A·x,    z = G·r.

    x is the state (q, v, a) in the layout ``newmark.X_Q``, ``X_V``, ``X_A``: at the step start
    for the free coordinates; for the held ones, their values at the step end (the cam's lift,
    lift rate and acceleration; the seat's position, 0 and 0; over an impact's first step the
    acceleration is the velocity change over Δt, Eq. 28). A·x is M·a + C·v + K·q on the
    predictors q + Δt·v + Δt²/3·a, v + Δt/2·a, 0 of the free coordinates and the held ones'
    values, so r is the force left to accelerate the train. In a free coordinate's row, z is
    its acceleration at the step end, M_eff⁻¹·r (Eq. 67); in a held coordinate's row, its
    contact force at the step end, that row of M·a + C·v + K·q − load (Eqs. 26, 27).

    The products are split where the thesis splits them: r carries the large, nearly
    cancelling spring and preload forces and is formed afresh from K and the load each step.
    Folded into one product, M_eff⁻¹·K rounded once would bias every step the same way (about
    1e-11 relative on impact velocities after a few turns, against 1e-13).

    Returns
    -------
    A : (4, N_X, N_Z)
        Per configuration I–IV, by columns: ``A[k, j]`` multiplies x[j]. Row 7 and the
        padding columns are zero.
    G : (4, N_Z, N_Z)
        Per configuration, by columns: ``G[k, j]`` multiplies r[j]. Row and column 7 are zero.
    """
    h = dt
    meff = mass + 0.5 * h * damping + h * h / 6.0 * stiffness
    minv = effective_mass_inverses(mass, damping, stiffness, dt)
    eye = np.eye(7)
    zero = np.zeros((7, 7))
    columns = np.r_[X_Q : X_Q + 7, X_V : X_V + 7, X_A : X_A + 7]
    A = np.zeros((4, N_X, N_Z))
    G = np.zeros((4, N_Z, N_Z))
    for c in CONFIGURATIONS:
        held = HELD[c - 1]
        free = np.diag(~held).astype(float)
        # The predictors as maps of x = (q, v, a).
        qt = np.hstack([eye, h * free, h * h / 3.0 * free])
        vt = np.hstack([zero, eye, 0.5 * h * free])
        at = np.hstack([zero, zero, np.diag(held).astype(float)])
        A[c - 1][np.ix_(columns, range(7))] = (mass @ at + damping @ vt + stiffness @ qt).T
        # The step end adds M_eff⁻¹·r to a, Δt/2 of it to v and Δt²/6 of it to q, which adds
        # M_eff·M_eff⁻¹·r to the held rows' M·a + C·v + K·q; less the load, that is −r + ….
        force = meff @ minv[c - 1] - eye
        G[c - 1][:7, :7] = np.where(held[:, None], force, minv[c - 1]).T
    return A, G


def impact_mass(mass: np.ndarray, struck: int, configuration_after: int) -> float:
    """Effective mass [kg] at coordinate ``struck`` for an impulse there, the other held
    coordinates of ``configuration_after`` fixed (``model.assembly.struck_mass``)."""
    return struck_mass(mass, struck, free_coordinates(configuration_after, mass.shape[0]))


def impact_masses(mass: np.ndarray) -> np.ndarray:
    """(4,) effective masses for: cam impact into I, cam impact into III, seat impact into IV,
    seat impact into III."""
    return np.array(
        [
            impact_mass(mass, CAM, 1),
            impact_mass(mass, CAM, 3),
            impact_mass(mass, SEAT, 4),
            impact_mass(mass, SEAT, 3),
        ]
    )


def static_position(mass, stiffness, load, held, held_q) -> np.ndarray:
    """(n,) The held coordinates at ``held_q`` and the free ones in static equilibrium with
    the load: the positions of :func:`quasi_static_batch` for one case (thesis Appendix B,
    step 1), without its compiled kernel. The same products and sums in the same order, each
    sum over j one NumPy step (IEEE arithmetic, element by element), so the result equals
    the kernel's bit for bit. ``batch.prepare`` needs it for every train; a run from the
    periodic start then loads no quasi-static kernel."""
    kinv, _ = held_inverses(mass, stiffness, held)
    held = np.asarray(held, dtype=bool)
    q = np.where(held, held_q, 0.0)
    rq = np.array(load, dtype=float)
    for j in range(q.size):
        rq -= stiffness[:, j] * q[j]
    free = np.zeros(q.size)
    for j in range(q.size):
        free += kinv[:, j] * rq[j]
    return np.where(held, q, free)


def held_inverses(mass, stiffness, held) -> tuple[np.ndarray, np.ndarray]:
    """K_ff⁻¹ and M_ff⁻¹ over the free coordinates, zero-padded to n×n."""
    free = np.flatnonzero(~held)
    n = mass.shape[0]
    kinv = np.zeros((n, n))
    minv = np.zeros((n, n))
    kinv[np.ix_(free, free)] = np.linalg.inv(stiffness[np.ix_(free, free)])
    minv[np.ix_(free, free)] = np.linalg.inv(mass[np.ix_(free, free)])
    return kinv, minv


@njit(cache=True, nogil=True)
def quasi_static_batch(kinv, minv, M, C, K, load, held, held_q, held_v, held_a, q, v, a):
    """The static solution for the held coordinates' position, moving with the velocity that
    solution has for their velocity; accelerations from the equation of motion (thesis
    Appendix B, step 1), for each case c (arrays with a leading case axis; kinv, minv from
    ``held_inverses``; ``held`` (n, n_q) bool, the prescribed coordinates, ``held_q``,
    ``held_v``, ``held_a`` their displacement [m], velocity [m/s] and acceleration [m/s²],
    other entries ignored), by plain loops so a case's result does not depend on its batch
    (a train of fewer coordinates than the batch's most is zero-padded: the padding adds
    exact zeros)."""
    n = held_q.shape[1]
    for c in range(held_q.shape[0]):
        for i in range(n):
            q[c, i] = held_q[c, i] if held[c, i] else 0.0
            v[c, i] = held_v[c, i] if held[c, i] else 0.0
            a[c, i] = held_a[c, i] if held[c, i] else 0.0
        rq = np.zeros(n)
        rv = np.zeros(n)
        for i in range(n):
            rq[i] = load[c, i]
            for j in range(n):
                rq[i] -= K[c, i, j] * q[c, j]
                rv[i] -= K[c, i, j] * v[c, j]
        for i in range(n):
            if not held[c, i]:
                sq = 0.0
                sv = 0.0
                for j in range(n):
                    sq += kinv[c, i, j] * rq[j]
                    sv += kinv[c, i, j] * rv[j]
                q[c, i] = sq
                v[c, i] = sv
        ra = np.zeros(n)
        for i in range(n):
            ra[i] = load[c, i]
            for j in range(n):
                ra[i] -= K[c, i, j] * q[c, j] + C[c, i, j] * v[c, j] + M[c, i, j] * a[c, j]
        for i in range(n):
            if not held[c, i]:
                s = 0.0
                for j in range(n):
                    s += minv[c, i, j] * ra[j]
                a[c, i] = s
