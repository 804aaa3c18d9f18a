"""The plunger as a coordinate (campipe.engine.plunger_modes): the embedded train's motion
against the plunger's own first-order law integrated by solve_ivp, its eigenvalues against
the Maxwell element's, a held plunger that does not move."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from campipe.engine.modal import modal_data, state_matrix
from campipe.engine.plunger import BOTTOMED, CLOSED, HELD, OPEN, TOPPED, plunger_state
from campipe.engine.plunger_modes import baumgarte_rate, embedded
from campipe.model import system_matrices, valve_train
from campipe.vocabulary import CAM, CAM_CONTACT, CONFIGURATIONS, FREE, SEATED, free_coordinates
from tests.unit.test_plunger_kernel import BUCKET


def _chain():
    """The bundled lash-adjuster study's bucket (test_plunger_kernel), 0.3 mm out."""
    train = valve_train("thesis-1971", {**BUCKET, "hla_extension": "0.3 mm"})
    sm = system_matrices(train)
    return sm, plunger_state(train, np.linalg.inv(sm.mass))


def _maxwell(sm, p, regime, held=()):
    """The plunger's own law, first order (as the compliant integrator states it): z = (q,
    q̇, u), M q̈ + C q̇ + K q + k·d·u = f + reactions, u̇ = −(k·(d·q + u) − F_c)/c, the
    coordinates ``held`` fixed where they start."""
    n = sm.mass.shape[0]
    fr = np.setdiff1d(np.arange(n), held)
    mff_inv = np.linalg.inv(sm.mass[np.ix_(fr, fr)])

    def rhs(t, z):
        q, v, u = z[:n], z[n : 2 * n], z[2 * n]
        force = sm.preload - sm.stiffness @ q - sm.damping @ v - p.k * p.d * u
        a = np.zeros(n)
        a[fr] = mff_inv @ force[fr]
        return np.concatenate([v, a, [p.rate(z, regime)]])

    return rhs


def _rate(p, regime, q, u):
    """The plunger's rate its law gives at coordinates q and u (``PlungerState.rate``)."""
    return p.rate(np.concatenate([q, np.zeros(q.size), [u]]), regime)


@pytest.mark.parametrize("regime", [CLOSED, OPEN])
def test_the_embedded_train_moves_as_the_plunger_s_law(regime):
    """The follower held on a base circle (configuration I), from a state off equilibrium
    (the link compressed beyond the check force, the valve moving): the embedded train's
    exact solution e^{A·t} (A its state matrix, what modal_data puts in blocks) against
    solve_ivp on the first-order law at rtol 1e-12, over 20 ms (the closed regime's
    leak-down, the open one's pump-up and its relaxation at k/c_P):
    coordinates, velocities and u to 1e-9 of their scale; the law's residual stays at
    rounding. Fails on a copy without the link's k·d·u, or with β's sign turned."""
    sm, p = _chain()
    n = sm.mass.shape[0]
    beta = baumgarte_rate(sm)
    e = embedded(sm, p, regime, beta)
    fr = np.array(free_coordinates(CAM_CONTACT, n + 1))
    nf = fr.size
    a = state_matrix(e.mass, e.damping, e.stiffness, fr)
    q0 = np.linalg.solve(sm.stiffness, sm.preload) + 2e-5 * p.d  # the link squeezed
    q0[CAM] = 0.0  # the base circle
    v0 = np.linspace(0.0, 0.2, n)
    u0 = 1e-5
    w0 = _rate(p, regime, q0, u0)
    # The held cam's constant q1 and the preload as one constant forcing.
    force = e.preload - e.stiffness[:, CAM] * q0[CAM]
    b = np.zeros(2 * nf)
    b[nf:] = np.linalg.solve(e.mass[np.ix_(fr, fr)], force[fr])
    zp = -np.linalg.solve(a, b)  # its particular solution
    z0 = np.concatenate([q0, [u0]])[fr]
    z0 = np.concatenate([z0, np.concatenate([v0, [w0]])[fr]])
    ref = solve_ivp(
        _maxwell(sm, p, regime, held=[CAM]), (0.0, 0.02), np.concatenate([q0, v0, [u0]]),
        method="DOP853", rtol=1e-12, atol=1e-16, dense_output=True,
    )  # fmt: skip
    for t in (1e-4, 2e-3, 0.02):
        z = expm(a * t) @ (z0 - zp) + zp
        want = np.concatenate([ref.sol(t)[:n], [ref.sol(t)[2 * n]]])[fr]
        want_v = np.concatenate([ref.sol(t)[n : 2 * n], [p.rate(ref.sol(t), regime)]])[fr]
        scale = np.abs(np.concatenate([ref.y[:n], ref.y[2 * n :]])).max(axis=1)[fr] + 1e-12
        vscale = np.abs(ref.y[n : 2 * n + 1]).max(axis=1).max() + abs(w0)
        assert_allclose(z[:nf] / scale, want / scale, atol=1e-9)
        assert_allclose(z[nf:] / vscale, want_v / vscale, atol=1e-9)
        q = np.zeros(n)
        q[fr[:-1]] = z[: nf - 1]
        residual = z[-1] - _rate(p, regime, q, z[nf - 1])
        assert abs(residual) < 1e-9 * max(abs(w0), 1e-9)


@pytest.mark.parametrize("regime", [CLOSED, OPEN])
def test_its_eigenvalues_are_the_maxwell_element_s_and_beta(regime):
    """The embedded state matrix (every coordinate free) has the first-order law's
    eigenvalues, the link's relaxation −k/c among them (and the drift's 0, below), and −β
    besides. Fails on a copy with another β in the plunger's row than in its residual."""
    sm, p = _chain()
    n = sm.mass.shape[0]
    beta = baumgarte_rate(sm)
    e = embedded(sm, p, regime, beta)
    a = state_matrix(e.mass, e.damping, e.stiffness, np.arange(n + 1))
    rhs = _maxwell(sm, p, regime)
    z = np.zeros(2 * n + 1)
    law = np.column_stack([rhs(0.0, z + np.eye(2 * n + 1)[j]) - rhs(0.0, z)
                           for j in range(2 * n + 1)])  # fmt: skip
    want = np.sort_complex(np.append(np.linalg.eigvals(law), -beta))
    got = np.sort_complex(np.linalg.eigvals(a))
    assert_allclose(got, want, rtol=1e-8, atol=1e-12 * np.abs(want).max())  # the drift's 0


@pytest.mark.parametrize("regime", [BOTTOMED, TOPPED, HELD])
def test_a_held_plunger_stays_where_it_is_held(regime):
    """At an end of its travel (or held) the plunger's coordinate keeps its value exactly
    through the chain's motion, and modal_data builds every configuration (its double −β one
    block)."""
    sm, p = _chain()
    n = sm.mass.shape[0]
    beta = baumgarte_rate(sm)
    e = embedded(sm, p, regime, beta)
    end = {BOTTOMED: p.low, TOPPED: p.high, HELD: 0.0}[regime]
    md = modal_data(e)
    for cfg in CONFIGURATIONS:
        assert md.n_free[cfg - 1] == len(free_coordinates(cfg, n + 1))
    fr = np.arange(n + 1)
    a = state_matrix(e.mass, e.damping, e.stiffness, fr)
    b = np.zeros(2 * n + 2)
    b[n + 1 :] = np.linalg.solve(e.mass, e.preload)
    zp = -np.linalg.solve(a, b)
    z0 = np.concatenate([np.linalg.solve(sm.stiffness, sm.preload) + 1e-5, [end],
                         np.full(n, 0.1), [0.0]])  # fmt: skip
    for t in (1e-3, 1e-2):
        z = expm(a * t) @ (z0 - zp) + zp
        assert abs(z[n] - end) < 1e-15 + 1e-12 * abs(end)
        assert abs(z[-1]) < 1e-9


@pytest.mark.parametrize("regime", [CLOSED, OPEN])
def test_off_the_cam_the_follower_floats_on_the_dashpot(regime):
    """With the follower off the cam (configurations II and IV) and the plunger free, the
    chain's first mass hangs on the link through the dashpot alone: the state matrix has an
    eigenvalue 0 (a drift, not a mode of the embedding: the first-order law has it too), so
    modal-exact's particular solutions need their drift form there (``plunger_modes``);
    with the follower on the cam (I, III) it has none."""
    sm, p = _chain()
    n = sm.mass.shape[0]
    e = embedded(sm, p, regime, baumgarte_rate(sm))
    scale = np.abs(np.linalg.eigvals(state_matrix(sm.mass, sm.damping, sm.stiffness,
                                                  np.arange(n)))).max()  # fmt: skip
    for cfg in CONFIGURATIONS:
        fr = np.array(free_coordinates(cfg, n + 1))
        least = np.abs(np.linalg.eigvals(state_matrix(e.mass, e.damping, e.stiffness, fr))).min()
        if cfg in (FREE, SEATED):
            assert least < 1e-12 * scale
        else:
            assert least > 1e-8 * scale
