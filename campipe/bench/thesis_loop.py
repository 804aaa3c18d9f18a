"""The thesis's algorithm as it is written: Appendix B's Newmark step, one case at a time, a
scalar loop compiled by numba: the reference the default's speed goal on the speed sweep is
measured against (``campipe.bench.sweep``).

Each step (thesis Eqs. 60–68) forms the predictors α = q̇ + q̈ΔT/2 and ψ = q + q̇ΔT + q̈ΔT²/3,
the step's matrix M̄ = M + (ΔT/2)C + (ΔT²/6)K over the free coordinates and its load
p̄ = p − Cα − Kψ (the held follower's terms moved to the right), solves M̄q̈ = p̄ by Gaussian
elimination, and corrects q̇ = α + q̈ΔT/2, q = ψ + q̈ΔT²/6. Configurations I (the follower on
the cam: q1 from the cam, F1 from row 1) and II (free): the cam releases where F1 would pull;
the follower that reaches the cam surface strikes it plastically (it takes the cam's velocity;
the free coordinates change by −M_ff⁻¹M_f1·Δv: thesis Ch. IV). No seat: the sweep has none.

It is campipe's newmark-linear (``engine/newmark.py``) without what makes that fast: no step
map precomputed per train and step, no batch. The bench checks the two agree (the valve's lift
at the samples).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from campipe.constants import TWO_PI
from campipe.engine import Case, RunSettings
from campipe.engine.batch import start_states, train_matrices
from campipe.engine.case import sample_count
from campipe.profiles import pack
from campipe.profiles.packed import evaluate_packed
from campipe.vocabulary import CAM, CAM_CONTACT, SEAT

#: The thesis's step [s].
STEP = 1e-6


@njit(cache=True, nogil=True)
def _solve(A, b, j0, n):
    """A x = b over rows and columns j0 … n − 1 by Gaussian elimination (M̄ is symmetric
    positive definite: no pivoting), in place; x left in b."""
    for k in range(j0, n):
        piv = A[k, k]
        for i in range(k + 1, n):
            f = A[i, k] / piv
            for j in range(k + 1, n):
                A[i, j] -= f * A[k, j]
            b[i] -= f * b[k]
    for i in range(n - 1, j0 - 1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


@njit(cache=True, nogil=True)
def thesis_run(M, C, K, P, profiles, w, h, n0, n_steps, q0, v0, a0, held0, d_theta, valve):
    """One case from step n0 (t = n0·h ≤ 0) to n_steps; the valve's coordinate q7 at the
    samples θ = k·d_theta (k ≥ 0) into ``valve``, from the step's cubic (thesis Eq. 57).
    Returns the number of impacts."""
    n = M.shape[0]
    q = q0.copy()
    v = v0.copy()
    a = a0.copy()
    qn = np.empty(n)
    vn = np.empty(n)
    an = np.empty(n)
    alpha = np.empty(n)
    psi = np.empty(n)
    A = np.empty((n, n))
    b = np.empty(n)
    held = held0
    impacts = 0
    k_out = 0
    n_out = valve.shape[0]
    t_sample = 0.0
    for step in range(n0, n_steps):
        t0 = step * h
        t1 = t0 + h
        lift, dlift, ddlift = evaluate_packed(profiles, 0, w * t1)
        for i in range(n):
            alpha[i] = v[i] + a[i] * h / 2.0
            psi[i] = q[i] + v[i] * h + a[i] * h * h / 3.0
        j0 = 0
        if held:
            qn[CAM] = -lift
            vn[CAM] = -w * dlift
            an[CAM] = -w * w * ddlift
            j0 = 1
        for i in range(j0, n):
            r = P[i]
            for j in range(j0, n):
                A[i, j] = M[i, j] + h / 2.0 * C[i, j] + h * h / 6.0 * K[i, j]
                r -= C[i, j] * alpha[j] + K[i, j] * psi[j]
            if held:
                r -= M[i, CAM] * an[CAM] + C[i, CAM] * vn[CAM] + K[i, CAM] * qn[CAM]
            b[i] = r
        _solve(A, b, j0, n)
        for i in range(j0, n):
            an[i] = b[i]
            vn[i] = alpha[i] + an[i] * h / 2.0
            qn[i] = psi[i] + an[i] * h * h / 6.0
        if held:
            f1 = -P[CAM]
            for j in range(n):
                f1 += M[CAM, j] * an[j] + C[CAM, j] * vn[j] + K[CAM, j] * qn[j]
            if f1 > 0.0:  # the cam would pull: it releases
                held = False
        elif qn[CAM] + lift > 0.0:  # the follower reaches the cam: a plastic impact
            dv = -w * dlift - vn[CAM]
            for i in range(1, n):
                for j in range(1, n):
                    A[i, j] = M[i, j]
                b[i] = M[i, CAM] * dv
            _solve(A, b, 1, n)
            for i in range(1, n):
                vn[i] -= b[i]
            qn[CAM] = -lift
            vn[CAM] = -w * dlift
            held = True
            impacts += 1
        while k_out < n_out and t_sample <= t1 * (1.0 + 1e-12):
            tau = t_sample - t0
            da = an[SEAT] - a[SEAT]
            valve[k_out] = (
                q[SEAT]
                + v[SEAT] * tau
                + 0.5 * a[SEAT] * tau * tau
                + da * tau * tau * tau / (6.0 * h)
            )
            k_out += 1
            t_sample = k_out * d_theta / w
        for i in range(n):
            q[i] = qn[i]
            v[i] = vn[i]
            a[i] = an[i]
    return impacts


def run_cases(cases: list[Case], revolutions: float, output_every: float) -> np.ndarray:
    """Every case (no seat, force closure) through :func:`thesis_run` from the periodic start
    campipe's newmark-linear takes at the thesis's step: the valve's coordinate q7 at the
    samples, (n, n_out) [m]."""
    settings = RunSettings(
        revolutions=revolutions, integrator="newmark-linear", dt=STEP, output_every=output_every
    )
    start = start_states(cases, settings)
    n_out = sample_count(revolutions, output_every)
    out = np.full((len(cases), n_out), math.nan)
    for c, case in enumerate(cases):
        sm = train_matrices(case.train)
        w = case.speed
        n0 = int(round(start.t0[c] / STEP))
        n_steps = int(math.ceil(revolutions * TWO_PI / w / STEP))
        k = sm.mass.shape[0]
        thesis_run(
            sm.mass, sm.damping, sm.stiffness, sm.preload, pack([case.profile]), w, STEP, n0,
            n_steps, start.q0[c, :k].copy(), start.v0[c, :k].copy(), start.a0[c, :k].copy(),
            start.cfg0[c] == CAM_CONTACT, output_every, out[c],
        )  # fmt: skip
    return out
