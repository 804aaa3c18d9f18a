"""The periodic steady state of configuration I, in closed form, and the start a run takes
from it.

With the follower held on the cam (configuration I) the train is linear and driven with the
cam's period T = 2π/ω, so it has one periodic solution: over a turn the state maps as
z(T) = e^{AT} z(0) + b, where b is the turn's response from rest (the particular solutions
of each piece of the profile, joined by the exact homogeneous propagation between breaks), and
the periodic state is z(0) = (I − e^{AT})⁻¹ b, solved block by block in the real block form of
``campipe.engine.modal`` (1 − e^{B_b T} is invertible for any damped block, and for an undamped
one unless the cam's speed is a subharmonic of its frequency).

A run starts on that state at θ = 0 where configuration I holds there (the cam pushes; the
valve is off its seat). Where it does not, it starts at the latest earlier angle where it holds
and integrates, unrecorded, up to θ = 0 (``periodic_starts``): the train arrives at θ = 0 as it
would after many turns, not from a quasi-static state that no turn passes through.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.constants import TWO_PI
from campipe.engine.closed_form import block_basis, forcing, particular
from campipe.engine.common import KERNEL
from campipe.profiles.packed import evaluate_packed, horner
from campipe.vocabulary import CAM, CAM_CONTACT, SEAT

#: Samples per turn at which the start's search for an angle where configuration I holds
#: looks (it then bisects to ``SEARCH_TOLERANCE`` of a turn).
SEARCH_SAMPLES = 2048
SEARCH_TOLERANCE = 1e-12


@njit(inline="always", nogil=True)
def _particular_at(ws, st, theta):
    """z_p at cam angle θ [rad] on the segment's piece (``closed_form.particular``)."""
    x = theta - st.th0
    ct = np.cos(theta)
    sn = np.sin(theta)
    for s in range(st.ns):
        ws.zb[s] = horner(ws.Z[:, s], x, st.deg)[0] + ws.ZT[s].real * ct - ws.ZT[s].imag * sn


@njit(inline="always", nogil=True)
def _propagate(trains, ws, st, u, tau):
    """u ← e^{Bτ} u, block by block: f1·u_b + f2·N_b u_b."""
    tr, ci = st.tr, st.cfg - 1
    for b in range(trains.n_blocks[tr, ci]):
        f1, f2 = block_basis(trains.lam_bar[tr, ci, b], trains.delta2[tr, ci, b], tau)
        i0 = trains.bstart[tr, ci, b]
        k = trains.bdim[tr, ci, b]
        if k == 1:
            u[i0] *= f1
        else:
            a0 = u[i0]
            a1 = u[i0 + 1]
            n = trains.block_n
            u[i0] = f1 * a0 + f2 * (n[tr, ci, i0, i0] * a0 + n[tr, ci, i0, i0 + 1] * a1)
            u[i0 + 1] = f1 * a1 + f2 * (n[tr, ci, i0 + 1, i0] * a0 + n[tr, ci, i0 + 1, i0 + 1] * a1)


@njit(inline="always", nogil=True)
def _to_basis(trains, st, z, u):
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    for j in range(ns):
        acc = 0.0
        for s in range(ns):
            acc += trains.basis_inv[tr, ci, j, s] * z[s]
        u[j] = acc


@njit(inline="always", nogil=True)
def _from_basis(trains, st, u, z):
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    for s in range(ns):
        acc = 0.0
        for j in range(ns):
            acc += trains.basis[tr, ci, s, j] * u[j]
        z[s] = acc


@njit(inline="always", nogil=True)
def _on_piece(cases, trains, profiles, runs, ws, st, p):
    """Prepare piece p of turn 0 in configuration I: its particular solution."""
    st.p = p
    st.rev = 0
    st.th0 = profiles.breaks[st.c, p]
    forcing(cases, trains, profiles, ws, st)
    particular(trains, profiles, runs, ws, st)


@njit(inline="always", nogil=True)
def _advance_piece(cases, trains, profiles, runs, ws, st, p, z):
    """z at the start of piece p → z at its end (the next break), exactly."""
    _on_piece(cases, trains, profiles, runs, ws, st, p)
    theta_a = profiles.breaks[st.c, p]
    theta_b = profiles.breaks[st.c, p + 1]
    _particular_at(ws, st, theta_a)
    for s in range(st.ns):
        ws.zh[s] = z[s] - ws.zb[s]
    _to_basis(trains, st, ws.zh, ws.u)
    _propagate(trains, ws, st, ws.u, (theta_b - theta_a) / st.w)
    _from_basis(trains, st, ws.u, z)
    _particular_at(ws, st, theta_b)
    for s in range(st.ns):
        z[s] += ws.zb[s]


@njit(inline="always", nogil=True)
def _state_in_piece(cases, trains, profiles, runs, ws, st, p, z_start, theta, z):
    """z at angle θ inside piece p of the periodic turn, from the state at its start."""
    _on_piece(cases, trains, profiles, runs, ws, st, p)
    _state_in_prepared_piece(trains, profiles, ws, st, z_start, theta, z)


@njit(inline="always", nogil=True)
def _state_in_prepared_piece(trains, profiles, ws, st, z_start, theta, z):
    """z at angle θ inside the piece ``_on_piece`` prepared, from the state at its start."""
    theta_a = profiles.breaks[st.c, st.p]
    _particular_at(ws, st, theta_a)
    for s in range(st.ns):
        ws.zh[s] = z_start[s] - ws.zb[s]
    _to_basis(trains, st, ws.zh, ws.u)
    _propagate(trains, ws, st, ws.u, (theta - theta_a) / st.w)
    _from_basis(trains, st, ws.u, z)
    _particular_at(ws, st, theta)
    for s in range(st.ns):
        z[s] += ws.zb[s]


@njit(inline="always", nogil=True)
def _margin(cases, trains, profiles, st, z, theta):
    """Whether configuration I holds at angle θ with state z, as a number that is negative
    where it does not: the smaller of the cam's compression −F1 [N] (not with form closure)
    and the valve's height above its seat q7 − q7_seat [m] (times 1e5 N/m: only the sign of
    either matters)."""
    c, tr, ci = st.c, st.tr, st.cfg - 1
    w = st.w
    margin = np.inf
    if not cases.form[c]:
        lift, dlift, ddlift = evaluate_packed(profiles, c, theta)
        f1 = trains.sigma0[tr, ci, 0]
        for s in range(st.ns):
            f1 += trains.rho[tr, ci, 0, s] * z[s]
        f1 += trains.sigma[tr, ci, 0, 0, 0] * -lift
        f1 += trains.sigma[tr, ci, 0, 1, 0] * -w * dlift
        f1 += trains.sigma[tr, ci, 0, 2, 0] * -w * w * ddlift
        margin = -f1
    if cases.has_seat[c]:
        row = 0
        for k in range(st.nf):
            if trains.free[tr, ci, k] == SEAT:
                row = k
        margin = min(margin, 1e5 * (z[row] - cases.seat_q[c]))
    return margin


@njit(**KERNEL)
def periodic_starts(cases, trains, profiles, runs, ws, state, snap, z_turn, t_start, q, v):
    """For each case: the periodic state of configuration I, and where a run starts on it.

    Parameters
    ----------
    cases, trains, profiles, runs, ws, state
        As ``exact.modal_exact_batch``'s (``cases.t0``, ``q0``, ``v0`` are not read).
    snap : (n,) float
        A step [s] the start must be a whole number of (newmark-linear's), or 0.
    z_turn : (n, P + 1, NS)
        Out: the periodic state at each break of the turn (row P: at 2π, the same as row 0).
    t_start : (n,)
        Out: the start time [s], ≤ 0; NaN where configuration I holds nowhere on the turn.
    q, v : (n, 7)
        Out: the coordinates and velocities there [m, m/s, rad, rad/s].
    """
    st = state[0]
    z = ws.z
    for c in range(cases.omega.shape[0]):
        tr = runs.train[c]
        st.c = c
        st.tr = tr
        st.w = cases.omega[c]
        st.cfg = CAM_CONTACT
        ci = CAM_CONTACT - 1
        st.nf = trains.n_free[tr, ci]
        st.ns = 2 * st.nf
        ns = st.ns
        n_p = profiles.n_pieces[c]
        period = TWO_PI / st.w
        # The turn's response from rest, b = z(T) with z(0) = 0.
        for s in range(ns):
            z[s] = 0.0
        for p in range(n_p):
            _advance_piece(cases, trains, profiles, runs, ws, st, p, z)
        # z(0) = (I − e^{AT})⁻¹ b, block by block: u0 = (I − e^{BT})⁻¹ X⁻¹ b.
        _to_basis(trains, st, z, ws.u)
        for b in range(trains.n_blocks[tr, ci]):
            f1, f2 = block_basis(trains.lam_bar[tr, ci, b], trains.delta2[tr, ci, b], period)
            i0 = trains.bstart[tr, ci, b]
            if trains.bdim[tr, ci, b] == 1:
                ws.u[i0] /= 1.0 - f1
            else:
                n = trains.block_n
                m00 = 1.0 - f1 - f2 * n[tr, ci, i0, i0]
                m01 = -f2 * n[tr, ci, i0, i0 + 1]
                m10 = -f2 * n[tr, ci, i0 + 1, i0]
                m11 = 1.0 - f1 - f2 * n[tr, ci, i0 + 1, i0 + 1]
                det = m00 * m11 - m01 * m10
                a0 = ws.u[i0]
                a1 = ws.u[i0 + 1]
                ws.u[i0] = (m11 * a0 - m01 * a1) / det
                ws.u[i0 + 1] = (m00 * a1 - m10 * a0) / det
        _from_basis(trains, st, ws.u, z)
        for s in range(ns):
            z_turn[c, 0, s] = z[s]
        for p in range(n_p):
            _advance_piece(cases, trains, profiles, runs, ws, st, p, z)
            for s in range(ns):
                z_turn[c, p + 1, s] = z[s]
        # Where the run starts: θ = 0 (2π) if configuration I holds there, else the latest
        # earlier angle where it does.
        theta_s = _latest_hold(cases, trains, profiles, runs, ws, st, z_turn, snap[c])
        t_start[c] = (theta_s - TWO_PI) / st.w if theta_s >= 0.0 else np.nan
        if theta_s >= 0.0:
            p = _piece_of(profiles, c, theta_s)
            _state_in_piece(cases, trains, profiles, runs, ws, st, p, z_turn[c, p], theta_s, z)
            lift, dlift, _ = evaluate_packed(profiles, c, theta_s)
            for i in range(7):
                q[c, i] = 0.0
                v[c, i] = 0.0
            for k in range(st.nf):
                q[c, trains.free[tr, ci, k]] = z[k]
                v[c, trains.free[tr, ci, k]] = z[st.nf + k]
            q[c, CAM] = -lift
            v[c, CAM] = -st.w * dlift


@njit(inline="always", nogil=True)
def _piece_of(profiles, c, theta):
    """The piece of turn 0 holding θ ∈ [0, 2π] (the last at 2π)."""
    p = 0
    while p + 1 < profiles.n_pieces[c] and profiles.breaks[c, p + 1] <= theta:
        p += 1
    return p


@njit(inline="always", nogil=True)
def _snapped(theta, w, step):
    """θ moved back to a whole number of steps before the turn's end (2π)."""
    if step <= 0.0:
        return theta
    n = np.floor((theta - TWO_PI) / w / step)
    return TWO_PI + n * step * w


@njit(inline="always", nogil=True)
def _latest_hold(cases, trains, profiles, runs, ws, st, z_turn, step):
    """The latest angle θ ∈ [0, 2π] of the periodic turn where configuration I holds, on a
    step's grid (``step`` > 0) or to SEARCH_TOLERANCE of a turn; −1 if it holds nowhere.
    Looks back piece by piece at SEARCH_SAMPLES a turn, then bisects to the boundary."""
    c, w = st.c, st.w
    z = ws.z
    d_theta = TWO_PI / SEARCH_SAMPLES
    theta_b = _snapped(TWO_PI, w, step)
    for p in range(profiles.n_pieces[c] - 1, -1, -1):
        lo = profiles.breaks[c, p]
        if theta_b < lo:
            continue
        _on_piece(cases, trains, profiles, runs, ws, st, p)
        z_start = z_turn[c, p]
        theta_hi = theta_b
        n = max(1, int(np.ceil((theta_b - lo) / d_theta)))
        for i in range(n + 1):
            theta = theta_b - (theta_b - lo) * i / n
            _state_in_prepared_piece(trains, profiles, ws, st, z_start, theta, z)
            if _margin(cases, trains, profiles, st, z, theta) >= 0.0:
                if i == 0:
                    return theta  # holds at the latest angle looked at
                theta_a = theta
                while theta_hi - theta_a > SEARCH_TOLERANCE * TWO_PI:
                    mid = 0.5 * (theta_a + theta_hi)
                    _state_in_prepared_piece(trains, profiles, ws, st, z_start, mid, z)
                    if _margin(cases, trains, profiles, st, z, mid) >= 0.0:
                        theta_a = mid
                    else:
                        theta_hi = mid
                snapped = _snapped(theta_a, w, step)
                return snapped if snapped >= 0.0 else -1.0
            theta_hi = theta
        theta_b = lo
    return -1.0
