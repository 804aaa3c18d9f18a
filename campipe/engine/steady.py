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
from campipe.engine.closed_form import (
    D1,
    D2,
    DSQ,
    F1,
    F2,
    LBAR,
    W1,
    W2,
    WL1,
    WL2,
    WLL1,
    WLL2,
    block_basis,
    block_derivative,
    eval_monitor,
    force_monitor,
    forcing,
    harmonic_response,
    particular,
)
from campipe.engine.common import (
    HELPER,
    KERNEL,
    SMOOTH,
    by_ref,
    classify_break,
    deref,
    start_piece,
)
from campipe.engine.kernel_call import start_structures
from campipe.profiles.packed import N_COEFFS, evaluate_packed, horner, piece_eval
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
def _apply_block(trains, st, u, b, f1, f2):
    """u_b ← f1·u_b + f2·N_b u_b: e^{B_b τ} u_b from the block's basis functions at τ."""
    tr, ci = st.tr, st.cfg - 1
    i0 = trains.bstart[tr, ci, b]
    if trains.bdim[tr, ci, b] == 1:
        u[i0] *= f1
    else:
        a0 = u[i0]
        a1 = u[i0 + 1]
        n = trains.block_n
        u[i0] = f1 * a0 + f2 * (n[tr, ci, i0, i0] * a0 + n[tr, ci, i0, i0 + 1] * a1)
        u[i0 + 1] = f1 * a1 + f2 * (n[tr, ci, i0 + 1, i0] * a0 + n[tr, ci, i0 + 1, i0 + 1] * a1)


@njit(inline="always", nogil=True)
def _propagate(trains, ws, st, u, tau):
    """u ← e^{Bτ} u, block by block."""
    tr, ci = st.tr, st.cfg - 1
    for b in range(trains.n_blocks[tr, ci]):
        f1, f2 = block_basis(trains.lam_bar[tr, ci, b], trains.delta2[tr, ci, b], tau)
        _apply_block(trains, st, u, b, f1, f2)


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


@njit(**HELPER)
def _on_piece(ref, st, p):
    """Prepare piece p of turn 0 in configuration I: its particular solution."""
    cases, trains, profiles, runs, ws = deref(ref)
    st.p = p
    st.rev = 0
    st.th0 = profiles.breaks[st.c, p]
    forcing(cases, trains, profiles, ws, st)
    particular(trains, profiles, runs, ws, st)


@njit(inline="always", nogil=True)
def _advance_piece(ref, st, p, z):
    """z at the start of piece p → z at its end (the next break), exactly (in place: z is
    read into the workspace before it is written)."""
    cases, trains, profiles, runs, ws = deref(ref)
    theta_b = profiles.breaks[st.c, p + 1]
    _state_in_piece(ref, st, p, z, theta_b, z)


@njit(**HELPER)
def _state_in_piece(ref, st, p, z_start, theta, z):
    """z at angle θ inside piece p of the periodic turn, from the state at its start."""
    _on_piece(ref, st, p)
    _state_in_prepared_piece(ref, st, z_start, theta, z)


@njit(**HELPER)
def _state_in_prepared_piece(ref, st, z_start, theta, z):
    """z at angle θ inside the piece ``_on_piece`` prepared, from the state at its start."""
    _, trains, profiles, _, ws = deref(ref)
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
def _compression(trains, profiles, st, z, theta):
    """The cam's compression −F1 [N] at angle θ with state z in configuration I (thesis
    Eq. 26 with ẍ eliminated: ``modal.ModalData.rho``, ``sigma``, ``sigma0``)."""
    tr, ci = st.tr, st.cfg - 1
    w = st.w
    lift, dlift, ddlift = evaluate_packed(profiles, st.c, theta)
    f1 = trains.sigma0[tr, ci, 0]
    for s in range(st.ns):
        f1 += trains.rho[tr, ci, 0, s] * z[s]
    f1 += trains.sigma[tr, ci, 0, 0, 0] * -lift
    f1 += trains.sigma[tr, ci, 0, 1, 0] * -w * dlift
    f1 += trains.sigma[tr, ci, 0, 2, 0] * -w * w * ddlift
    return -f1


@njit(inline="always", nogil=True)
def _seat_row(trains, st):
    """The row of q7 among configuration I's free coordinates."""
    row = 0
    for k in range(st.nf):
        if trains.free[st.tr, st.cfg - 1, k] == SEAT:
            row = k
    return row


@njit(inline="always", nogil=True)
def _margin(cases, trains, profiles, st, z, theta):
    """Whether configuration I holds at angle θ with state z, as a number that is negative
    where it does not: the smaller of the cam's compression −F1 [N] (not with form closure)
    and the valve's height above its seat q7 − q7_seat [m] (times 1e5 N/m: only the sign of
    either matters)."""
    c = st.c
    margin = np.inf
    if not cases.form[c]:
        margin = _compression(trains, profiles, st, z, theta)
    if cases.has_seat[c]:
        margin = min(margin, 1e5 * (z[_seat_row(trains, st)] - cases.seat_q[c]))
    return margin


@njit(**HELPER)
def _margin_in_piece(ref, st, z_start, theta, z):
    """``_margin`` at angle θ inside the piece ``_on_piece`` prepared, its state (from z_start
    at the piece's start) left in z. Compiled once for ``_latest_hold``'s scan and bisection."""
    cases, trains, profiles, runs, ws = deref(ref)
    _state_in_prepared_piece(ref, st, z_start, theta, z)
    return _margin(cases, trains, profiles, st, z, theta)


@njit(inline="always", nogil=True)
def _begin_case(cases, trains, runs, st, c):
    """Point the scalars at case c in configuration I."""
    tr = runs.train[c]
    st.c = c
    st.tr = tr
    st.w = cases.omega[c]
    st.cfg = CAM_CONTACT
    st.nf = trains.n_free[tr, CAM_CONTACT - 1]
    st.ns = 2 * st.nf


@njit(inline="always", nogil=True)
def _break_impulse(cases, trains, profiles, st, p, z):
    """At the break that ends piece p (the last piece's: the turn's, to piece 0 of the next),
    a cam rate jump into the held follower (``common.classify_break``'s JUMP, plastic: the
    kernel's ``_cross_break``) changes the free velocities in z by the impulse's share
    (``modal.ModalData.impulse``), as in a run; the turn's map stays affine. A jump that
    throws the follower off (restitution) or a release leaves configuration I in a run; the
    held orbit, the run's start, drags the follower through it all the same, its free
    coordinates taking the same share, so that the orbit solves the held equations at every
    break (a form-closed follower's is the same). Left out there, a one-mass chain's mirror
    rang: its valve started 1.4 mm off its follower under the thesis's flat at 6000 rpm."""
    c, tr, ci, nf = st.c, st.tr, st.cfg - 1, st.nf
    last = p + 1 == profiles.n_pieces[c]
    theta_b = profiles.breaks[c, p + 1]
    # (int64 turns, not literals: ``piece_eval`` is compiled once, ``steady_samples``'s.)
    l_left, dl_left, _ = piece_eval(profiles, c, p, np.int64(0), theta_b)
    nxt = np.int64(0) if last else np.int64(p + 1)
    l_right, dl_right, _ = piece_eval(profiles, c, nxt, np.int64(1 if last else 0), theta_b)
    kind, jump = classify_break(
        l_left, dl_left, l_right, dl_right, st.w, cases.form[c], cases.capture[c]
    )
    if kind == SMOOTH:
        return
    for k in range(nf):
        z[nf + k] -= trains.impulse[tr, CAM_CONTACT - 1, 0, trains.free[tr, ci, k]] * jump


@njit(**HELPER)
def _periodic_turn(ref, st, zt):
    """The periodic state of configuration I at each break of the turn: zt (P + 1, ns), row P
    (at 2π) the same as row 0, each just after its break (a rate jump's impulse applied:
    ``_break_impulse``). z(0) = (I − e^{AT})⁻¹ b, b the turn's response from rest."""
    cases, trains, profiles, runs, ws = deref(ref)
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    n_p = profiles.n_pieces[st.c]
    period = TWO_PI / st.w
    z = ws.z
    for s in range(ns):
        z[s] = 0.0
    for p in range(n_p):
        _advance_piece(ref, st, p, z)
        _break_impulse(cases, trains, profiles, st, p, z)
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
        zt[0, s] = z[s]
    for p in range(n_p):
        _advance_piece(ref, st, p, z)
        _break_impulse(cases, trains, profiles, st, p, z)
        for s in range(ns):
            zt[p + 1, s] = z[s]


@njit(**KERNEL)
def periodic_starts(cases, trains, profiles, runs, ws, state, snap, z_turn, t_start, q, v):
    """For each case: the periodic state of configuration I, and where a run starts on it.

    Parameters
    ----------
    cases, trains, profiles, runs, ws, state
        As ``exact.modal_exact_batch``'s, plain tuples named on entry (``cases.t0``, ``q0``,
        ``v0`` are not read).
    snap : (n,) float
        A step [s] the start must be a whole number of (newmark-linear's), or 0.
    z_turn : (n, P + 1, ns)
        Out: the periodic state at each break of the turn (row P: at 2π, the same as row 0).
    t_start : (n,)
        Out: the start time [s], ≤ 0; NaN where configuration I holds nowhere on the turn.
    q, v : (n, n_coordinates)
        Out: the coordinates and velocities there [m, m/s, rad, rad/s].
    """
    cases, trains, profiles, runs, ws = start_structures(cases, trains, profiles, runs, ws)
    st = state[0]
    ref = by_ref((cases, trains, profiles, runs, ws))
    z = ws.z
    for c in range(cases.omega.shape[0]):
        _begin_case(cases, trains, runs, st, c)
        tr, ci = st.tr, st.cfg - 1
        harmonic_response(trains, runs, ws, st, ci)
        _periodic_turn(ref, st, z_turn[c])
        # Where the run starts: θ = 0 (2π) if configuration I holds there, else the latest
        # earlier angle where it does.
        theta_s = _latest_hold(ref, st, z_turn, snap[c])
        t_start[c] = (theta_s - TWO_PI) / st.w if theta_s >= 0.0 else np.nan
        before = -1  # at a break the held follower cannot cross smoothly: the piece it ends
        if theta_s >= 0.0:
            th_run = theta_s - TWO_PI  # the run's angle there
            _, p_s, crosses = start_piece(profiles, c, th_run, CAM_CONTACT, st.w, cases.form[c],
                                          cases.capture[c])  # fmt: skip
            if crosses:
                before = p_s
        if before >= 0:
            # The state before the break (the run's start crosses it: common.start_piece),
            # on the piece that ends there, as the cam's lift and rate.
            _state_in_piece(ref, st, before, z_turn[c, before], theta_s, z)
        elif theta_s >= TWO_PI:
            # θ = 0: the state just after the turn's break, row P.
            for s in range(st.ns):
                z[s] = z_turn[c, profiles.n_pieces[c], s]
        elif theta_s >= 0.0:
            p = _piece_of(profiles, c, theta_s)
            _state_in_piece(ref, st, p, z_turn[c, p], theta_s, z)
        if theta_s >= 0.0:
            if before >= 0:
                lift, dlift, _ = piece_eval(profiles, c, before, np.int64(0), theta_s)
            else:
                lift, dlift, _ = evaluate_packed(profiles, c, theta_s)
            for i in range(q.shape[1]):
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


#: The scan's monitors are summed from their terms in another order than ``_margin``'s: a
#: sample whose monitor is within this fraction of its terms' magnitudes of zero is looked at
#: again with ``_margin`` itself, so the scan finds the sample ``_margin`` would.
RECHECK = 1e-7


@njit(inline="always", nogil=True)
def _margin_monitors(ref, st, z_start):
    """The prepared piece's (``_on_piece``) margins as monitors in exact's form, the blocks'
    λ̄, δ² in ws.MC: slot 0 the cam's compression −F1 (not with form closure), slot 1 the
    valve's height above its seat (with a seat), Σ_b (W1 f1 + W2 f2)(τ) + Σ_k G_k x^k +
    Re(GT e^{iθ}), τ and x from the piece's start (``_piece_monitor``'s, both at once)."""
    cases, trains, profiles, runs, ws = deref(ref)
    tr, ci, ns, c = st.tr, st.cfg - 1, st.ns, st.c
    theta_a = profiles.breaks[c, st.p]
    _particular_at(ws, st, theta_a)
    for s in range(ns):
        ws.zh[s] = z_start[s] - ws.zb[s]
    _to_basis(trains, st, ws.zh, ws.u)
    row = _seat_row(trains, st)
    for m in range(2):
        for k in range(8):
            ws.G[m, k] = 0.0
        ws.GT[m] = 0.0
    if not cases.form[c]:
        force_monitor(trains, ws, st, 0, -1.0, 0.0)
    if cases.has_seat[c]:
        for k in range(st.deg + 1):
            ws.G[1, k] = ws.Z[k, row]
        ws.G[1, 0] -= cases.seat_q[c]
        ws.GT[1] = ws.ZT[row]
    for b in range(trains.n_blocks[tr, ci]):
        i0 = trains.bstart[tr, ci, b]
        w1 = 0.0
        w2 = 0.0
        h1 = 0.0
        h2 = 0.0
        for j in range(i0, i0 + trains.bdim[tr, ci, b]):
            w1 -= trains.rho_x[tr, ci, 0, j] * ws.u[j]
            w2 -= trains.rho_xn[tr, ci, 0, j] * ws.u[j]
            h1 += trains.basis[tr, ci, row, j] * ws.u[j]
            h2 += trains.basis_n[tr, ci, row, j] * ws.u[j]
        ws.MC[LBAR, b] = trains.lam_bar[tr, ci, b]
        ws.MC[DSQ, b] = trains.delta2[tr, ci, b]
        ws.WC[W1, 0, b] = w1
        ws.WC[W2, 0, b] = w2
        ws.WC[W1, 1, b] = h1
        ws.WC[W2, 1, b] = h2


@njit(**HELPER)
def _scan_piece(ref, st, z_start, lo, theta_b, n):
    """The first i in 1 … n where configuration I holds at θ_i = θ_b − (θ_b − lo)·i/n on the
    prepared piece (``_on_piece``, z_start at its start), as ``_margin_in_piece`` finds it;
    0 if at none. The samples' margins come from ``_margin_monitors``, the blocks' basis
    functions and (cos θ, sin θ) stepped back by their step factors (no exp, sin or cos a
    sample); a sample within ``RECHECK`` of zero, and the one found, are evaluated again by
    ``_margin_in_piece``."""
    cases, trains, profiles, runs, ws = deref(ref)
    c, w = st.c, st.w
    watch_force = not cases.form[c]
    watch_seat = cases.has_seat[c]
    _margin_monitors(ref, st, z_start)
    nb = trains.n_blocks[st.tr, st.cfg - 1]
    theta_a = profiles.breaks[c, st.p]
    d = (theta_b - lo) / n
    tau = (theta_b - theta_a) / w
    for jj in range(nb):
        ws.MC[F1, jj], ws.MC[F2, jj] = block_basis(ws.MC[LBAR, jj], ws.MC[DSQ, jj], tau)
        # A step back: f1(−h) = e^{−λ̄h}C(h), f2(−h) = −e^{−λ̄h}S(h) (``block_basis`` takes
        # τ ≥ 0).
        back1, back2 = block_basis(-ws.MC[LBAR, jj], ws.MC[DSQ, jj], d / w)
        ws.MC[D1, jj] = back1
        ws.MC[D2, jj] = -back2
    ct, sn = np.cos(theta_b), np.sin(theta_b)
    cd, sd = np.cos(d), np.sin(d)
    for i in range(1, n + 1):
        for jj in range(nb):
            f1 = ws.MC[F1, jj]
            f2 = ws.MC[F2, jj]
            ws.MC[F1, jj] = f1 * ws.MC[D1, jj] + ws.MC[DSQ, jj] * f2 * ws.MC[D2, jj]
            ws.MC[F2, jj] = f2 * ws.MC[D1, jj] + f1 * ws.MC[D2, jj]
        ct, sn = ct * cd + sn * sd, sn * cd - ct * sd
        theta = theta_b - (theta_b - lo) * i / n
        x = theta - st.th0
        holds = True
        near = False
        for m in range(2):
            if not (watch_force if m == 0 else watch_seat):
                continue
            g = 0.0
            size = 0.0
            for jj in range(nb):
                a = ws.WC[W1, m, jj] * ws.MC[F1, jj]
                b = ws.WC[W2, m, jj] * ws.MC[F2, jj]
                g += a + b
                size += abs(a) + abs(b)
            pk = 0.0
            xk = 1.0
            for k in range(8):
                pk += abs(ws.G[m, k]) * xk
                xk *= abs(x)
            g += horner(ws.G[m], x)[0] + ws.GT[m].real * ct - ws.GT[m].imag * sn
            size += pk + abs(ws.GT[m])
            if g < 0.0:
                holds = False
            if abs(g) <= RECHECK * size:
                near = True
        if (holds or near) and _margin_in_piece(ref, st, z_start, theta, ws.z) >= 0.0:
            return i
    return 0


@njit(**HELPER)
def _latest_hold(ref, st, z_turn, step):
    """The latest angle θ ∈ [0, 2π] of the periodic turn where configuration I holds, on a
    step's grid (``step`` > 0) or to SEARCH_TOLERANCE of a turn; −1 if it holds nowhere.
    Looks back piece by piece at SEARCH_SAMPLES a turn, then bisects to the boundary."""
    cases, trains, profiles, runs, ws = deref(ref)
    c, w = st.c, st.w
    z = ws.z
    d_theta = TWO_PI / SEARCH_SAMPLES
    theta_b = _snapped(TWO_PI, w, step)
    for p in range(profiles.n_pieces[c] - 1, -1, -1):
        lo = profiles.breaks[c, p]
        if theta_b < lo:
            continue
        _on_piece(ref, st, p)
        z_start = z_turn[c, p]
        n = max(1, int(np.ceil((theta_b - lo) / d_theta)))
        if _margin_in_piece(ref, st, z_start, theta_b, z) >= 0.0:
            return theta_b  # holds at the latest angle looked at
        i = _scan_piece(ref, st, z_start, lo, theta_b, n)
        if i > 0:
            theta_a = theta_b - (theta_b - lo) * i / n
            theta_hi = theta_b - (theta_b - lo) * (i - 1) / n
            while theta_hi - theta_a > SEARCH_TOLERANCE * TWO_PI:
                mid = 0.5 * (theta_a + theta_hi)
                if _margin_in_piece(ref, st, z_start, mid, z) >= 0.0:
                    theta_a = mid
                else:
                    theta_hi = mid
            snapped = _snapped(theta_a, w, step)
            return snapped if snapped >= 0.0 else -1.0
        theta_b = lo
    return -1.0


# --------------------------------------------------------------------------- the turn's extremes

#: Samples per turn at which ``steady_extremes`` scans for the contact force's and the valve's
#: least values (at least two per piece); the least sample is then refined by a safeguarded
#: Newton search on the closed form's derivative between the samples beside it, to
#: REFINE_TOLERANCE of the bracket.
EXTREME_SAMPLES = 256
REFINE_STEPS = 40
REFINE_TOLERANCE = 1e-13
#: Columns of ``steady_extremes``'s output.
MIN_FORCE, MIN_FORCE_ANGLE, MAX_FORCE, MIN_HEIGHT, MIN_HEIGHT_ANGLE = range(5)
N_EXTREMES = 5
#: What ``_piece_monitor`` prepares: the cam's compression −F1 [N], F1, the valve's height
#: above its seat q7 − q7_seat [m]. NumPy integers, not Python's: numba compiles a kernel
#: called with a Python int constant once per value (a literal type), ``_turn_minimum`` three
#: times over.
COMPRESSION, TENSION, HEIGHT = np.int64(0), np.int64(1), np.int64(2)


@njit(inline="always", nogil=True)
def _piece_monitor(ref, st, zt, p, which):
    """On piece p of the periodic turn, ``which`` as a monitor in exact's form (slot 0 of
    ws.G, ws.GT, ws.WC; the blocks' λ̄, δ² in ws.MC): Σ_b (W1_b f1 + W2_b f2)(τ) + Σ_k G_k x^k
    + Re(GT e^{iθ}), τ and x from the piece's start."""
    cases, trains, profiles, runs, ws = deref(ref)
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    _on_piece(ref, st, p)
    theta_a = profiles.breaks[st.c, p]
    _particular_at(ws, st, theta_a)
    for s in range(ns):
        ws.zh[s] = zt[p, s] - ws.zb[s]
    _to_basis(trains, st, ws.zh, ws.u)
    for k in range(8):
        ws.G[0, k] = 0.0
    if which == HEIGHT:
        row = _seat_row(trains, st)
        for k in range(st.deg + 1):
            ws.G[0, k] = ws.Z[k, row]
        ws.G[0, 0] -= cases.seat_q[st.c]
        ws.GT[0] = ws.ZT[row]
    else:
        force_monitor(trains, ws, st, 0, 1.0 if which == TENSION else -1.0, 0.0)
    sign = -1.0 if which == COMPRESSION else 1.0
    for b in range(trains.n_blocks[tr, ci]):
        i0 = trains.bstart[tr, ci, b]
        w1 = 0.0
        w2 = 0.0
        for j in range(i0, i0 + trains.bdim[tr, ci, b]):
            if which == HEIGHT:
                w1 += trains.basis[tr, ci, _seat_row(trains, st), j] * ws.u[j]
                w2 += trains.basis_n[tr, ci, _seat_row(trains, st), j] * ws.u[j]
            else:
                w1 += sign * trains.rho_x[tr, ci, 0, j] * ws.u[j]
                w2 += sign * trains.rho_xn[tr, ci, 0, j] * ws.u[j]
        lbar = trains.lam_bar[tr, ci, b]
        d2 = trains.delta2[tr, ci, b]
        ws.MC[LBAR, b] = lbar
        ws.MC[DSQ, b] = d2
        ws.WC[W1, 0, b] = w1
        ws.WC[W2, 0, b] = w2
        ws.WC[WL1, 0, b], ws.WC[WL2, 0, b] = block_derivative(w1, w2, lbar, d2)
        ws.WC[WLL1, 0, b], ws.WC[WLL2, 0, b] = block_derivative(
            ws.WC[WL1, 0, b], ws.WC[WL2, 0, b], lbar, d2
        )


@njit(inline="always", nogil=True)
def _monitor_value(ws, nb, st, theta_a, theta):
    """The prepared monitor, its first and second derivatives in time, at θ."""
    return eval_monitor(
        ws.WC,
        ws.MC,
        nb,
        ws.G,
        ws.GT,
        np.int64(0),
        (theta - theta_a) / st.w,
        st.w,
        theta - theta_a,
        theta,
        np.int64(N_COEFFS - 1),  # (its G: the piece's degree at most)
    )


#: Samples a period of the fastest block that matters to a monitor on a piece
#: (``_ringing_samples``): the sampled least value is then within 1 − cos(π/8), 8 %, of that
#: block's amplitude of the least, before the refinement.
RINGING_SAMPLES = 8
#: A block matters to a monitor on a piece when its amplitude there is above this fraction
#: of the monitor's particular part (0.01 N of a kilonewton force: about 0.02 rpm of an onset
#: where the least force falls 0.4 N an rpm). A smooth polydyne's scan costs a quarter more
#: (its fast modes are above it after the breaks), a ramped one's five times.
RINGING_FLOOR = 1e-5


@njit(inline="always", nogil=True)
def _ringing_samples(trains, ws, st, width, nb):
    """The samples a piece ``width`` [rad] wide needs for ``RINGING_SAMPLES`` a period of the
    fastest block whose amplitude in the prepared monitor (``_piece_monitor``) is above
    ``RINGING_FLOOR`` of its particular part: an impact at a rate jump (a ramp's) sets the
    train's fast modes ringing, and a scan at a fixed spacing steps over their dips."""
    scale = abs(ws.G[0, 0]) + abs(ws.GT[0])
    duration = width / st.w
    fastest = 0.0
    for jj in range(nb):
        d2 = ws.MC[DSQ, jj]
        reach = min(duration, 1.0 / np.sqrt(abs(d2))) if d2 != 0.0 else duration
        amp = abs(ws.WC[W1, 0, jj]) + abs(ws.WC[W2, 0, jj]) * reach
        if amp > RINGING_FLOOR * scale:
            fastest = max(fastest, trains.speed[st.tr, st.cfg - 1, jj])
    return int(np.ceil(duration * fastest * RINGING_SAMPLES / TWO_PI))


@njit(inline="always", nogil=True)
def _piece_samples(trains, ws, st, width, nb):
    """The scan's samples on a piece ``width`` [rad] wide, its monitor prepared
    (``_piece_monitor``): EXTREME_SAMPLES a turn, at least two, and its ringing's."""
    by_turn = int(np.ceil(width / (TWO_PI / EXTREME_SAMPLES)))
    return max(2, by_turn, _ringing_samples(trains, ws, st, width, nb))


@njit(inline="always", nogil=True)
def _refined(ref, st, zt, which, p, lo, hi):
    """(θ, value) of the least of ``which`` on piece p between the samples lo and hi [rad]:
    the least of the bracket's ends and the derivative's zero between them, by Newton's
    method on the derivative kept inside the bracket by bisection."""
    cases, trains, profiles, runs, ws = deref(ref)
    nb = trains.n_blocks[st.tr, st.cfg - 1]
    _piece_monitor(ref, st, zt, p, which)
    a = profiles.breaks[st.c, p]
    g_lo, d_lo, _ = _monitor_value(ws, nb, st, a, lo)
    g_hi, _, _ = _monitor_value(ws, nb, st, a, hi)
    best, theta_best = (g_lo, lo) if g_lo <= g_hi else (g_hi, hi)
    if d_lo < 0.0:
        x = 0.5 * (lo + hi)
        width = hi - lo
        for _ in range(REFINE_STEPS):
            g, dg, d2g = _monitor_value(ws, nb, st, a, x)
            if g < best:
                best, theta_best = g, x
            if dg < 0.0:
                lo = x
            else:
                hi = x
            if hi - lo <= REFINE_TOLERANCE * width:
                break
            # Newton in θ: the derivatives are in τ, d/dθ = d/dτ / ω.
            nxt = x - st.w * dg / d2g if d2g > 0.0 else 0.5 * (lo + hi)
            x = nxt if lo < nxt < hi else 0.5 * (lo + hi)
        g, _, _ = _monitor_value(ws, nb, st, a, x)
        if g < best:
            best, theta_best = g, x
    return theta_best, best


@njit(**HELPER)
def _turn_minimum(ref, st, zt, which):
    """(θ, value) of the least value of ``which`` over the periodic turn: scanned at
    EXTREME_SAMPLES a turn (the breaks included; the blocks and the harmonic advanced by their
    step factors), then refined between the samples beside the least (``_refined``). A least
    sample on a break is refined on both its sides: the least may lie just before the break,
    on the piece that ends there, where the scan's tie at the break took the next piece's
    sample (a helper's bucket: a peak force 0.2° before the rise's end read at the end, 7e-5
    low), or just before the turn's end where it took the turn's first."""
    cases, trains, profiles, runs, ws = deref(ref)
    c = st.c
    nb = trains.n_blocks[st.tr, st.cfg - 1]
    best = np.inf
    best_p = np.int64(0)  # not a literal: ``_on_piece`` is compiled for int64 pieces
    edge = 0  # the least sample at its piece's start (-1), its end (+1), inside (0)
    lo = 0.0
    hi = 0.0
    n_pieces = profiles.n_pieces[c]
    for p in range(n_pieces):
        a = profiles.breaks[c, p]
        b = profiles.breaks[c, p + 1]
        _piece_monitor(ref, st, zt, p, which)
        n = _piece_samples(trains, ws, st, b - a, nb)
        step = (b - a) / n
        for jj in range(nb):
            ws.MC[F1, jj] = 1.0
            ws.MC[F2, jj] = 0.0
            ws.MC[D1, jj], ws.MC[D2, jj] = block_basis(ws.MC[LBAR, jj], ws.MC[DSQ, jj], step / st.w)
        ct, sn = np.cos(a), np.sin(a)
        ch, sh = np.cos(step), np.sin(step)
        gt = ws.GT[0]
        for i in range(n + 1):
            g = horner(ws.G[0], step * i)[0] + gt.real * ct - gt.imag * sn
            for jj in range(nb):
                f1 = ws.MC[F1, jj]
                f2 = ws.MC[F2, jj]
                g += ws.WC[W1, 0, jj] * f1 + ws.WC[W2, 0, jj] * f2
                ws.MC[F1, jj] = f1 * ws.MC[D1, jj] + ws.MC[DSQ, jj] * f2 * ws.MC[D2, jj]
                ws.MC[F2, jj] = f1 * ws.MC[D2, jj] + f2 * ws.MC[D1, jj]
            ct, sn = ct * ch - sn * sh, sn * ch + ct * sh
            if g < best:
                best = g
                best_p = np.int64(p)
                edge = -1 if i == 0 else (1 if i == n else 0)
                lo = a + step * max(i - 1, 0)
                hi = a + step * min(i + 1, n)
    theta_best, best = _refined(ref, st, zt, which, best_p, lo, hi)
    if edge != 0:  # the break's other side: the neighbouring piece's interval beside it
        q = np.int64((best_p + edge) % n_pieces)
        a = profiles.breaks[c, q]
        b = profiles.breaks[c, q + 1]
        _piece_monitor(ref, st, zt, q, which)
        step = (b - a) / _piece_samples(trains, ws, st, b - a, nb)
        lo, hi = (b - step, b) if edge < 0 else (a, a + step)
        theta, g = _refined(ref, st, zt, which, q, lo, hi)
        if g < best:
            theta_best, best = theta, g
    return theta_best, best


@njit(**KERNEL)
def steady_extremes(cases, trains, profiles, runs, ws, state, z_turn, with_max, active, out):
    """For each case at its speed ``cases.omega``: configuration I's periodic state and its
    extremes over the turn.

    Parameters
    ----------
    cases, trains, profiles, runs, ws, state
        As ``periodic_starts``'s; ``runs.zeta[:, 0]`` is overwritten with configuration I's
        harmonic responses at each case's speed.
    z_turn : (n, P + 1, ns)
        Out: the periodic state at each break of the turn.
    with_max : bool
        Also find the largest compression (else MAX_FORCE is NaN).
    active : (n,) bool
        The cases to compute (the others' rows are left as they are).
    out : (n, N_EXTREMES)
        Out, by column: the least cam compression −F1 over the turn [N] (MIN_FORCE: the
        no-follow margin; +inf with form closure) and its angle [rad], the largest [N], the
        valve's least height above its seat [m] (+inf without a seat) and its angle [rad].
    """
    st = state[0]
    ref = by_ref((cases, trains, profiles, runs, ws))
    for c in range(cases.omega.shape[0]):
        if not active[c]:
            continue
        _begin_case(cases, trains, runs, st, c)
        harmonic_response(trains, runs, ws, st, CAM_CONTACT - 1)
        _periodic_turn(ref, st, z_turn[c])
        out[c, MIN_FORCE] = np.inf
        out[c, MIN_FORCE_ANGLE] = np.nan
        out[c, MAX_FORCE] = np.nan
        if not cases.form[c]:
            theta, f = _turn_minimum(ref, st, z_turn[c], COMPRESSION)
            out[c, MIN_FORCE] = f
            out[c, MIN_FORCE_ANGLE] = theta
        if with_max:
            theta, f = _turn_minimum(ref, st, z_turn[c], TENSION)
            out[c, MAX_FORCE] = -f
        out[c, MIN_HEIGHT] = np.inf
        out[c, MIN_HEIGHT_ANGLE] = np.nan
        if cases.has_seat[c]:
            theta, f = _turn_minimum(ref, st, z_turn[c], HEIGHT)
            out[c, MIN_HEIGHT] = f
            out[c, MIN_HEIGHT_ANGLE] = theta
