"""newmark-linear's compiled step against thesis Appendix B, steps 2–6, written out in numpy."""

import numpy as np
import pytest
from numba import njit
from numpy.testing import assert_array_equal

from campipe.engine.batch import train_matrices
from campipe.engine.contact import HELD, effective_mass_inverses, newmark_step_maps
from campipe.engine.newmark import N_X, N_Z, NP, X_A, X_Q, X_V, _newmark_step
from campipe.model import thesis_train

DT = 1e-6
SM = train_matrices(thesis_train())
M, C, K, LOAD = SM.mass, SM.damping, SM.stiffness, SM.preload


@njit
def compiled_step(A, G, k, load, h, x):
    xn = np.zeros(N_X)
    z = np.zeros(N_Z)
    _newmark_step(A, G, 0, k, load, h, x, xn, z)
    return xn, z


def appendix_b(held, q, v, a, h):
    """One step as the thesis writes it: predictors, Eq. 67 over the free coordinates (held
    ones at their values in q, v, a), corrector, contact forces of the held rows. Returns the
    step-end (q, v, a), the contact forces, and for each the size of the terms summed."""
    free = ~held
    qt = np.where(free, q + h * v + h * h / 3.0 * a, q)
    vt = np.where(free, v + 0.5 * h * a, v)
    at = np.where(free, 0.0, a)
    terms = M * at + K * qt + C * vt  # row i, column j: the j-th term of row i
    rhs = LOAD - terms.sum(axis=1)
    meff = M + 0.5 * h * C + h * h / 6.0 * K
    an = at.copy()
    an[free] = np.linalg.solve(meff[np.ix_(free, free)], rhs[free])
    qn = np.where(free, qt + h * h / 6.0 * an, qt)
    vn = np.where(free, vt + 0.5 * h * an, vt)
    force = M @ an + C @ vn + K @ qn - LOAD
    # Scale of the accelerations: the inverse applied to the size of the forces summed.
    size = np.abs(terms).sum(axis=1) + np.abs(LOAD)
    a_size = np.zeros(7)
    a_size[free] = np.abs(np.linalg.inv(meff[np.ix_(free, free)])) @ size[free]
    f_size = np.abs(M) @ np.abs(an) + np.abs(C) @ np.abs(vn) + np.abs(K) @ np.abs(qn) + size
    return (qn, vn, an), force, a_size, f_size


@pytest.mark.parametrize("configuration", [1, 2, 3, 4])
def test_compiled_step_is_appendix_b_to_rounding(configuration):
    rng = np.random.default_rng(configuration)
    held = HELD[configuration - 1]
    A, G = newmark_step_maps(M, C, K, DT)
    load = np.zeros(N_Z)
    load[:NP] = LOAD
    for _ in range(20):
        # A state about the thesis train's static position, moving at cam-like speeds.
        q = np.linalg.solve(K + 1e3 * np.eye(7), LOAD) * (1 + 0.05 * rng.standard_normal(7))
        v = 10.0 * rng.standard_normal(7)
        a = 1e5 * rng.standard_normal(7)
        x = np.zeros(N_X)
        x[X_Q : X_Q + NP], x[X_V : X_V + NP], x[X_A : X_A + NP] = q, v, a
        xn, z = compiled_step(A[None], G[None], configuration - 1, load, DT, x)
        (qn, vn, an), force, a_size, f_size = appendix_b(held, q, v, a, DT)
        free = ~held
        got_q, got_v, got_a = (xn[b : b + NP] for b in (X_Q, X_V, X_A))
        assert np.all(np.abs(got_a - an)[free] <= 1e-14 * a_size[free])
        assert np.all(np.abs(got_v - vn)[free] <= 1e-14 * (np.abs(v) + DT * a_size)[free])
        assert np.all(
            np.abs(got_q - qn)[free] <= 1e-15 * np.abs(q)[free] + 1e-14 * DT * DT * a_size[free]
        )
        assert np.all(np.abs(z[:NP] - force)[held] <= 1e-14 * f_size[held])
        assert_array_equal(xn[[X_Q + NP, X_V + NP, X_A + NP]], 0.0)  # padding stays zero


def test_step_maps_have_the_effective_mass_inverse_in_the_free_rows():
    A, G = newmark_step_maps(M, C, K, DT)
    minv = effective_mass_inverses(M, C, K, DT)
    for k in range(4):
        free = ~HELD[k]
        assert_array_equal(G[k][:NP, :NP][np.ix_(free, free)], minv[k][np.ix_(free, free)].T)
        assert_array_equal(G[k][NP], 0.0)
        assert_array_equal(G[k][:, NP], 0.0)
        assert_array_equal(A[k][[X_Q + NP, X_V + NP, X_A + NP]], 0.0)
        assert_array_equal(A[k][:, NP], 0.0)
