"""``modal-exact``: closed-form propagation between events, events located inside the step.

Between events the solution is exact (``campipe.engine.modal``): the state at any time is
V·(y₀ ∘ e^{λτ}) plus the exact particular solution of the piece's polynomial and harmonic
forcing. The integrator walks a grid of ``h`` (``dt`` rounded down so that the output angles
fall on the grid), watches each configuration's monitors (thesis Table I) at the grid points,
and on a sign change locates the event by a bracketed root search (Illinois) on the closed
form, to ``tolerance`` in time. A segment ends at an event or at a break of the cam profile;
the next starts from the exact state there.

Monitors, each an event when it rises through zero (direction: upward only):

- cam held (I, III), force closure: F1 (the cam would pull) → release the cam;
- cam free (II, IV): q1 + lift(θ) (the follower reaches the cam surface) → cam impact;
- seat free (I, II), with a seat: q7_seat − q7 (the valve reaches the seat) → seat impact;
- seat held (III, IV): −F7 (the seat would pull) → release the seat.

Impacts are the thesis's: infinite cam (seat) mass, perfectly plastic; the struck coordinate
takes the obstacle's velocity and, through the consistent mass, the free coordinates change
velocity by −M_ff⁻¹ M_fp Δv_p: the impulse m_eff·v_closing is applied at the instant of
contact, so no force measures 1/Δt.

The only step-size limit is event resolution: a monitor that rises and falls back within one
step is not seen. ``dt`` is therefore refused above half the shortest natural period of any
configuration the case can visit (``event_resolution_limit``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.modal import NS
from campipe.engine.newmark import (
    CAM_SEPARATION,
    EVENTS_TRUNCATED,
    JUMP_FLOOR,
    NONFINITE,
    OK,
    SEAT_SEPARATION,
    TWO_PI,
    _config,
    _degree,
    _impact,
    _record,
    horner2,
    locate,
    piece_eval,
)

CHATTER = 3  # status: events kept recurring without time advancing
#: Steps are at most RESOLUTION·π/|λ| of the fastest mode still present: under half its period,
#: so that mode's part of a monitor's derivative changes sign at most once per step, and a
#: maximum inside a step is seen as a + to − change of the derivative at the grid points.
RESOLUTION = 0.9
#: A mode is dropped once its share of every coordinate [m] and velocity [m/s] is below this
#: (4e-12 in: far below any output's resolution) and its share of the contact forces is below
#: the force level of the monitors.
MODE_FLOOR = 1e-13
MAX_STALLED_EVENTS = 64
ROOT_ITERATIONS = 200


@njit(cache=True, nogil=True)
def _zpoly(Z, s, x, deg):
    """Σ_{k ≤ deg} Z[k, s]·x^k: entry s of the particular solution's polynomial part."""
    acc = 0.0
    for k in range(deg, -1, -1):
        acc = acc * x + Z[k, s]
    return acc


@njit(cache=True, nogil=True)
def _held_inputs(poly, trig, c, p, w, seat_q, cam_held, seat_held, inp, inp_t):
    """Held coordinates' (q, q̇, q̈) as polynomials in the piece's local angle x (inp, shape
    (3, 2, 8)) and harmonic parts Re(inp_t·e^{iθ}) (inp_t (3, 2) complex)."""
    for kind in range(3):
        for hc in range(2):
            inp_t[kind, hc] = 0.0
            for k in range(8):
                inp[kind, hc, k] = 0.0
    if cam_held:
        for k in range(8):
            inp[0, 0, k] = -poly[c, p, k]
            if k + 1 < 8:
                inp[1, 0, k] = -w * (k + 1) * poly[c, p, k + 1]
            if k + 2 < 8:
                inp[2, 0, k] = -w * w * (k + 1) * (k + 2) * poly[c, p, k + 2]
        # a·sin θ + b·cos θ = Re((b − i·a)·e^{iθ})
        beta = trig[c, p, 1] - 1j * trig[c, p, 0]
        inp_t[0, 0] = -beta
        inp_t[1, 0] = -1j * w * beta
        inp_t[2, 0] = w * w * beta
    if seat_held:
        inp[0, 1, 0] = seat_q


# Rows of the per-mode work array ``MC`` (one column per active mode pair, fastest first):
# e^{λτ} at the current grid point (real, imaginary), the grid step's factor e^{λh}, their
# magnitudes, and the pair's largest share of a coordinate or velocity and of the contact
# forces at the segment start.
ER, EI, DR, DI, EABS, DABS, AMP_Q, AMP_F = range(8)
# Rows of the monitor coefficients ``WC`` (row, monitor, pair): W, W·λ, W·λ² as (real,
# imaginary), then |W| and |W·λ|.
W_R, W_I, WL_R, WL_I, WLL_R, WLL_I, W_ABS, WL_ABS = range(8)


@njit(cache=True, nogil=True)
def _exps(lam, c, ci, ns, tau, ev):
    for j in range(ns):
        ev[j] = np.exp(lam[c, ci, j] * tau)


@njit(inline="always", nogil=True)
def _eval3(WC, lamc, nact, G, GT, m, tau, w, x, th):
    """Monitor m and its first two time derivatives τ after the segment start (local angle x,
    cam angle θ), exactly: the active mode pairs, the polynomial and the harmonic part."""
    g = 0.0
    dg = 0.0
    d2g = 0.0
    for jj in range(nact):
        e = np.exp(lamc[jj] * tau)
        er = e.real
        ei = e.imag
        g += WC[W_R, m, jj] * er - WC[W_I, m, jj] * ei
        dg += WC[WL_R, m, jj] * er - WC[WL_I, m, jj] * ei
        d2g += WC[WLL_R, m, jj] * er - WC[WLL_I, m, jj] * ei
    p0, p1, p2 = horner2(G[m], x)
    g += p0
    dg += w * p1
    d2g += w * w * p2
    if GT[m] != 0.0:
        ct = np.cos(th)
        st = np.sin(th)
        g += GT[m].real * ct - GT[m].imag * st
        dg -= w * (GT[m].real * st + GT[m].imag * ct)
        d2g -= w * w * (GT[m].real * ct - GT[m].imag * st)
    return g, dg, d2g


@njit(inline="always", nogil=True)
def _at(deriv, WC, lamc, nact, G, GT, m, t_s, t, w, th0):
    """Monitor m (deriv False) or its time derivative (deriv True) at time t, and the next
    derivative."""
    g, dg, d2g = _eval3(WC, lamc, nact, G, GT, m, t - t_s, w, w * t - th0, w * t)
    return (dg, d2g) if deriv else (g, dg)


@njit(cache=True, nogil=True)
def _root(
    deriv, sgn, WC, lamc, nact, G, GT, m, t_s, ta, tb, level, w, th0, tolerance, known, fa, fb, dfb
):
    """Time in [ta, tb] where f = sgn·(monitor − level) (or, with deriv, sgn·its derivative)
    rises through zero: Newton steps from the latest point, kept inside the bracket, with
    Illinois (regula falsi) and bisection as fall-backs. Returns the bracket's left end once
    the bracket is narrower than ``tolerance``: the last time known to be before the crossing
    (no penetration, no tension beyond ``level``), or its right end if the left one is the
    segment start. With ``known``, f(ta) = fa, f(tb) = fb and f'(tb) = dfb are given (the
    grid has them) and not evaluated again.
    """
    lev = 0.0 if deriv else level
    if not known:
        f, _ = _at(deriv, WC, lamc, nact, G, GT, m, t_s, ta, w, th0)
        fa = sgn * (f - lev)
        if fa > 0.0:
            return ta
        f, df = _at(deriv, WC, lamc, nact, G, GT, m, t_s, tb, w, th0)
        fb = sgn * (f - lev)
        dfb = sgn * df
    elif fa > 0.0:
        return ta
    t_last = tb
    f_last = fb
    df_last = dfb
    side = 0
    converged = False
    for _ in range(ROOT_ITERATIONS):
        if tb - ta <= tolerance:
            break
        if converged:
            # Newton has the root to within the tolerance: close the bracket around it.
            t = t_last - 0.5 * tolerance if side != 1 else t_last + 0.5 * tolerance
            if not (ta < t < tb):
                t = 0.5 * (ta + tb)
        else:
            t = t_last - f_last / df_last if df_last != 0.0 else -1.0
            if ta < t < tb:
                converged = abs(t - t_last) < 0.25 * tolerance
            else:
                t = (ta * fb - tb * fa) / (fb - fa)
                if not (ta < t < tb):
                    t = 0.5 * (ta + tb)
        f, df = _at(deriv, WC, lamc, nact, G, GT, m, t_s, t, w, th0)
        f = sgn * (f - lev)
        df = sgn * df
        if f > 0.0:
            tb = t
            fb = f
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            ta = t
            fa = f
            if side == 1:
                fb *= 0.5
            side = 1
        if not converged:
            t_last = t
            f_last = f
            df_last = df
    # The left end, unless that is the segment start: a segment must advance.
    return ta if ta > t_s else tb


@njit(cache=True, nogil=True)
def _state(q, v, z, ya, vec, ev, y0, Z, ZT, free, c, ci, nf, ns, x, ct, st, rows, deg):
    """Free coordinates at local angle x, cam angle θ (ct = cos θ, st = sin θ), with
    ev_j = e^{λ_j τ}, from every mode: the first ``rows`` entries of z (nf: positions only;
    ns: positions and velocities), then q, v."""
    for j in range(ns):
        ya[j] = y0[j] * ev[j]
    for s in range(rows):
        acc = 0.0
        for j in range(ns):
            acc += vec[c, ci, s, j].real * ya[j].real - vec[c, ci, s, j].imag * ya[j].imag
        z[s] = acc + _zpoly(Z, s, x, deg) + ZT[s].real * ct - ZT[s].imag * st
    for k in range(nf):
        q[free[c, ci, k]] = z[k]
        if rows == ns:
            v[free[c, ci, k]] = z[nf + k]


@njit(inline="always", nogil=True)
def _state_active(q, v, z, VY, MC, Z, ZT, free, c, ci, nf, lo, nact, x, ct, st, deg, full_state):
    """Free coordinates and velocities from the mode pairs lo … nact − 1 (an output sample):
    VY[:, jj, s] holds (Re, Im) of V_sj·y0_j (doubled for a pair), so each term is the real
    part of one complex product; plus the particular solution. Without ``full_state`` only
    the contact coordinates q1 and q7 (and their velocities) are computed: the others keep
    the values of the segment's start (``_write_sample`` shows them as NaN)."""
    ns = 2 * nf
    if full_state:
        for s in range(ns):
            z[s] = ZT[s].real * ct - ZT[s].imag * st
        for jj in range(lo, nact):
            er = MC[ER, jj]
            ei = MC[EI, jj]
            for s in range(ns):
                z[s] += VY[0, jj, s] * er - VY[1, jj, s] * ei
    for k in range(nf):
        coord = free[c, ci, k]
        if not full_state:
            if coord != 0 and coord != 6:
                continue
            for s in (k, k + nf):
                acc = ZT[s].real * ct - ZT[s].imag * st
                for jj in range(lo, nact):
                    acc += VY[0, jj, s] * MC[ER, jj] - VY[1, jj, s] * MC[EI, jj]
                z[s] = acc
        pq = 0.0
        pv = 0.0
        for kz in range(deg, -1, -1):
            pq = pq * x + Z[kz, k]
            pv = pv * x + Z[kz, k + nf]
        q[coord] = z[k] + pq
        v[coord] = z[k + nf] + pv


@njit(inline="always", nogil=True)
def _slope_bound(WC, G, GT, m, MC, lo, nact, gdeg, w, xa, xb):
    """An upper bound on |dg/dt| of monitor m over a step from local angle xa to xb, with the
    modal magnitudes at its start (they only decay): Σ|W_j λ_j||E_j| + max|P'| + ω|G_T|.
    The polynomial part is bounded by its derivative's values at the ends plus its second
    derivative's, which is ample for a step of at most one output interval."""
    bound = 0.0
    for jj in range(lo, nact):
        bound += WC[WL_ABS, m, jj] * MC[EABS, jj]
    pa = 0.0
    pb = 0.0
    p2 = 0.0
    for k in range(gdeg, 0, -1):
        pa = pa * xa + k * G[m, k]
        pb = pb * xb + k * G[m, k]
    for k in range(gdeg, 1, -1):
        p2 = max(p2, abs(k * (k - 1) * G[m, k]) * (abs(xa) + abs(xb) + 1.0) ** (k - 2))
    bound += w * (max(abs(pa), abs(pb)) + p2 * abs(xb - xa))
    bound += w * abs(GT[m])
    return bound


@njit(inline="always", nogil=True)
def _write_sample(
    q_out,
    v_out,
    force_out,
    cam_out,
    cfg_out,
    c,
    k,
    q,
    v,
    gval,
    cam_held,
    seat_held,
    poly,
    trig,
    p,
    x,
    ct,
    st,
    w,
    cfg,
    full_state,
):
    """Output sample k: coordinates and velocities (held ones on the cam and seat; without
    ``full_state`` only q1 and q7, the others NaN), forces, cam lift."""
    lift = 0.0
    dlift = 0.0
    for kk in range(7, -1, -1):
        dlift = dlift * x + lift
        lift = lift * x + poly[c, p, kk]
    lift += trig[c, p, 0] * st + trig[c, p, 1] * ct
    dlift += trig[c, p, 0] * ct - trig[c, p, 1] * st
    for i in range(7):
        shown = full_state or i == 0 or i == 6
        q_out[c, k, i] = q[i] if shown else np.nan
        v_out[c, k, i] = v[i] if shown else np.nan
    if cam_held:
        q_out[c, k, 0] = -lift
        v_out[c, k, 0] = -w * dlift
    force_out[c, k, 0] = gval[0] if cam_held else 0.0
    force_out[c, k, 1] = -gval[1] if seat_held else 0.0
    cam_out[c, k] = lift
    cfg_out[c, k] = cfg


@njit(inline="always", nogil=True)
def _advance(MC, lo, nact, cth, sth, cwh, swh):
    """One grid step: e^{λτ} of the mode pairs lo … nact − 1 and (cos θ, sin θ) by
    rotation."""
    for jj in range(lo, nact):
        er = MC[ER, jj]
        ei = MC[EI, jj]
        MC[ER, jj] = er * MC[DR, jj] - ei * MC[DI, jj]
        MC[EI, jj] = er * MC[DI, jj] + ei * MC[DR, jj]
        MC[EABS, jj] *= MC[DABS, jj]
    return cth * cwh - sth * swh, sth * cwh + cth * swh


@njit(inline="always", nogil=True)
def _monitor_at_grid(WC, MC, lo, nact, G, GT, m, gdeg, w, x, cth, sth):
    """Monitor m and its time derivative at the current grid point from the mode pairs
    lo … nact − 1 and their advanced exponentials (no exp or sin/cos)."""
    g = 0.0
    dg = 0.0
    for jj in range(lo, nact):
        er = MC[ER, jj]
        ei = MC[EI, jj]
        g += WC[W_R, m, jj] * er - WC[W_I, m, jj] * ei
        dg += WC[WL_R, m, jj] * er - WC[WL_I, m, jj] * ei
    p0 = 0.0
    p1 = 0.0
    for k in range(gdeg, -1, -1):
        p1 = p1 * x + p0
        p0 = p0 * x + G[m, k]
    g += p0 + GT[m].real * cth - GT[m].imag * sth
    dg += w * (p1 - GT[m].real * sth - GT[m].imag * cth)
    return g, dg


@njit(cache=True, nogil=True)
def _keep_column(MC, WC, VY, lamc, act, ns, src, dst):
    """Move mode pair ``src``'s data to column ``dst`` (dropping the pairs between)."""
    act[dst] = act[src]
    lamc[dst] = lamc[src]
    for r in range(MC.shape[0]):
        MC[r, dst] = MC[r, src]
    for r in range(WC.shape[0]):
        for m in range(2):
            WC[r, m, dst] = WC[r, m, src]
    for s in range(ns):
        VY[0, dst, s] = VY[0, src, s]
        VY[1, dst, s] = VY[1, src, s]


@njit(cache=True, nogil=True)
def _separation(sep_rev, c, n_rev, w, ta, tb):
    """Add the cam angle of [ta, tb] off the cam to each revolution it overlaps."""
    a = w * ta
    b = w * tb
    r = int(a / TWO_PI)
    while a < b and r < n_rev:
        end = min(b, (r + 1) * TWO_PI)
        sep_rev[c, r] += end - a
        a = end
        r += 1


@njit(cache=True, nogil=True)
def modal_exact_batch(
    train,
    load,
    n_free,
    free,
    lam,
    vec,
    vec_inv,
    a_inv,
    b_in,
    b_load,
    rho,
    sigma,
    sigma0,
    impulse,
    rho_vec,
    vnorm,
    lam_abs,
    zeta,
    meff,
    q0,
    v0,
    cfg0,
    seat_q,
    has_seat,
    form,
    omega,
    t_sample_all,
    t_end_all,
    dt_cap,
    tolerance,
    mode_cutoff,
    full_state,
    steps_taken,
    breaks,
    poly,
    trig,
    n_pieces,
    q_out,
    v_out,
    force_out,
    cam_out,
    cfg_out,
    sep_rev,
    counts,
    vmax,
    fmax,
    events,
    n_events,
    status,
):
    """Advance every case of a batch exactly between events; fill the outputs in place.

    Per case: ``train`` the index of its train in the per-train arrays, ``t_sample_all`` the
    output spacing in time [s], ``t_end_all`` the run's end [s]; ``dt_cap`` the largest step
    [s] (0: none). Per train: ``load`` (n_trains, 7) and the modal data per configuration as
    ``ModalData`` (leading axes (n_trains, 4)); ``zeta`` (n, 4, NS) per case (it depends on
    the speed). Outputs as ``newmark.newmark_linear_batch``.
    """
    n_cases = q0.shape[0]
    n_out = q_out.shape[1]
    n_rev = sep_rev.shape[1]
    q = np.zeros(7)
    v = np.zeros(7)
    z = np.zeros(NS)
    zh = np.zeros(NS)
    zb = np.zeros(NS)
    Z = np.zeros((9, NS))
    ZT = np.zeros(NS, np.complex128)
    bpoly = np.zeros((8, NS))
    y0 = np.zeros(NS, np.complex128)
    ev = np.zeros(NS, np.complex128)
    ya = np.zeros(NS, np.complex128)
    W = np.zeros((2, NS), np.complex128)
    order = np.zeros(NS, np.int64)  # the modes, fastest first
    # The active mode pairs, fastest first (column jj): the mode index, λ, per-mode work
    # (rows ER … AMP_F), monitor coefficients (rows W_R … WL_ABS), and (Re, Im) of V_sj·y0_j
    # (VY[:, jj, s]).
    act = np.zeros(NS, np.int64)
    lamc = np.zeros(NS, np.complex128)
    MC = np.zeros((8, NS))
    WC = np.zeros((8, 2, NS))
    VY = np.zeros((2, NS, NS))
    dval = np.zeros(2)
    dprev = np.zeros(2)
    gprev = np.zeros(2)
    G = np.zeros((2, 8))
    GT = np.zeros(2, np.complex128)
    ready = np.zeros(2, np.bool_)  # monitor prepared (its value is computed)
    watch = np.zeros(2, np.bool_)  # monitor can end the segment
    level = np.zeros(2)
    gval = np.zeros(2)
    inp = np.zeros((3, 2, 8))
    inp_t = np.zeros((3, 2), np.complex128)
    for c in range(n_cases):
        tr = train[c]
        w = omega[c]
        t_sample = t_sample_all[c]
        t_end = t_end_all[c]
        qs = seat_q[c]
        eps_force = 1e-9 * (abs(load[tr, 3]) + 1.0)
        for i in range(7):
            q[i] = q0[c, i]
            v[i] = v0[c, i]
        cfg = cfg0[c]
        rev, p = locate(breaks, n_pieces, c, 0.0)
        t_s = 0.0
        k_out = 0
        stalled = 0
        done = False
        while not done:
            # ---- begin a segment at t_s in configuration cfg on piece p ----
            ci = cfg - 1
            nf = n_free[tr, ci]
            ns = 2 * nf
            cam_held = cfg == 1 or cfg == 3
            seat_held = cfg == 3 or cfg == 4
            for k in range(nf):
                zh[k] = q[free[tr, ci, k]]
                zh[nf + k] = v[free[tr, ci, k]]
            _held_inputs(poly, trig, c, p, w, qs, cam_held, seat_held, inp, inp_t)
            has_trig = cam_held and (trig[c, p, 0] != 0.0 or trig[c, p, 1] != 0.0)
            # The held inputs are polynomials of the piece's degree at most (the seat's a
            # constant), and so is the forcing.
            kmax = _degree(poly, c, p) if cam_held else 0
            deg = 0
            for k in range(kmax + 1):
                for s in range(ns):
                    acc = b_load[tr, ci, s] if k == 0 else 0.0
                    for kind in range(3):
                        for hc in range(2):
                            acc += b_in[tr, ci, s, kind, hc] * inp[kind, hc, k]
                    bpoly[k, s] = acc
                    if acc != 0.0:
                        deg = k
            # Particular solutions: Z_k = A⁻¹(ω(k+1) Z_{k+1} − b_k) from the forcing's degree
            # down; the harmonic one Z_T = β·ζ (campipe.engine.modal.harmonic_response).
            for k in range(deg + 1, 9):
                for s in range(ns):
                    Z[k, s] = 0.0
            for k in range(deg, -1, -1):
                for s in range(ns):
                    zb[s] = w * (k + 1) * Z[k + 1, s] - bpoly[k, s]
                for s in range(ns):
                    acc = 0.0
                    for j in range(ns):
                        acc += a_inv[tr, ci, s, j] * zb[j]
                    Z[k, s] = acc
            beta = trig[c, p, 1] - 1j * trig[c, p, 0]
            for s in range(NS):
                ZT[s] = beta * zeta[c, ci, s] if has_trig else 0.0
            th_s = w * t_s
            th0 = rev * TWO_PI + breaks[c, p]
            x_s = th_s - th0
            ct = np.cos(th_s)
            st = np.sin(th_s)
            for s in range(ns):
                zh[s] -= _zpoly(Z, s, x_s, deg) + ZT[s].real * ct - ZT[s].imag * st
            for j in range(ns):
                acc_c = 0.0 + 0.0j
                for s in range(ns):
                    acc_c += vec_inv[tr, ci, j, s] * zh[s]
                y0[j] = acc_c
            # Monitors: g_m(τ) = Re Σ_j W_mj e^{λ_j τ} + Σ_k G_mk x^k + Re(GT_m e^{iθ}).
            ready[0] = True
            watch[0] = not (cam_held and form[c])
            ready[1] = has_seat[c] or seat_held
            watch[1] = ready[1]
            for m in range(2):
                if not ready[m]:
                    continue
                held = cam_held if m == 0 else seat_held
                sign = 1.0 if m == 0 else -1.0  # F1, q1 + lift; −F7, q7_seat − q7
                for k in range(8):
                    G[m, k] = 0.0
                if held:
                    level[m] = eps_force
                    for j in range(ns):
                        W[m, j] = sign * rho_vec[tr, ci, m, j] * y0[j]
                    for k in range(kmax + 1):
                        acc = 0.0
                        for s in range(ns):
                            acc += rho[tr, ci, m, s] * Z[k, s]
                        for kind in range(3):
                            for hc in range(2):
                                acc += sigma[tr, ci, m, kind, hc] * inp[kind, hc, k]
                        G[m, k] = sign * acc
                    G[m, 0] += sign * sigma0[tr, ci, m]
                    acc_c = 0.0 + 0.0j
                    for s in range(ns):
                        acc_c += rho[tr, ci, m, s] * ZT[s]
                    for kind in range(3):
                        acc_c += sigma[tr, ci, m, kind, 0] * inp_t[kind, 0]
                    GT[m] = sign * acc_c
                else:
                    level[m] = 1e-13  # [m] of penetration
                    coord = 0 if m == 0 else 6
                    row = 0
                    for k in range(nf):
                        if free[tr, ci, k] == coord:
                            row = k
                    for j in range(ns):
                        W[m, j] = sign * vec[tr, ci, row, j] * y0[j]
                    for k in range(8):
                        G[m, k] = sign * Z[k, row]
                    GT[m] = sign * ZT[row]
                    if m == 0:
                        for k in range(8):
                            G[m, k] += poly[c, p, k]
                        GT[m] += trig[c, p, 1] - 1j * trig[c, p, 0]
                    else:
                        G[m, 0] += qs
            gdeg = 0
            for m in range(2):
                if ready[m]:
                    for k in range(8):
                        if G[m, k] != 0.0:
                            gdeg = max(gdeg, k)
            # The segment ends at the next break of the profile at the latest.
            nb = p + 1
            revb = rev
            if nb == n_pieces[c]:
                nb = 0
                revb = rev + 1
            t_break = (revb * TWO_PI + breaks[c, nb]) / w
            # The modes, fastest first (insertion sort; ns ≤ 14).
            for j in range(ns):
                k = j
                while k > 0 and lam_abs[tr, ci, order[k - 1]] < lam_abs[tr, ci, j]:
                    order[k] = order[k - 1]
                    k -= 1
                order[k] = j
            # The modes in conjugate pairs (a real state has conjugate modal coordinates):
            # one column per pair, its coefficients doubled, so every sum is Re Σ over half
            # the modes. Reduced fidelity leaves the pairs above the cut-off (the first
            # ``lo`` columns) out of the grid, the samples and the step size: there they keep
            # only their quasi-static part (inside the particular solution). Event location
            # and the state at events use every pair.
            nact = 0
            lo = 0
            for jj in range(ns):
                j = order[jj]
                lj = lam[tr, ci, j]
                if lj.imag < 0.0:
                    continue
                if mode_cutoff > 0.0 and lam_abs[tr, ci, j] > mode_cutoff:
                    lo += 1
                f = 2.0 if lj.imag > 0.0 else 1.0
                act[nact] = j
                lamc[nact] = lj
                ya_abs = f * abs(y0[j])
                MC[ER, nact] = 1.0
                MC[EI, nact] = 0.0
                MC[EABS, nact] = 1.0
                MC[AMP_Q, nact] = ya_abs * vnorm[tr, ci, j]
                MC[AMP_F, nact] = ya_abs * (abs(rho_vec[tr, ci, 0, j]) + abs(rho_vec[tr, ci, 1, j]))
                for m in range(2):
                    wv = f * W[m, j] if ready[m] else 0.0j
                    wl = wv * lj
                    wll = wl * lj
                    WC[W_R, m, nact] = wv.real
                    WC[W_I, m, nact] = wv.imag
                    WC[WL_R, m, nact] = wl.real
                    WC[WL_I, m, nact] = wl.imag
                    WC[WLL_R, m, nact] = wll.real
                    WC[WLL_I, m, nact] = wll.imag
                    WC[W_ABS, m, nact] = abs(wv)
                    WC[WL_ABS, m, nact] = abs(wl)
                for s2 in range(ns):
                    vy = f * vec[tr, ci, s2, j] * y0[j]
                    VY[0, nact, s2] = vy.real
                    VY[1, nact, s2] = vy.imag
                nact += 1
            for m in range(2):
                if ready[m]:
                    gval[m], dprev[m], _ = _eval3(WC, lamc, nact, G, GT, m, 0.0, w, x_s, th_s)
                    gprev[m] = gval[m]
            if k_out < n_out and k_out * t_sample <= t_s * (1.0 + 1e-13):
                # A sample due at the segment start (the initial state, or a break or event
                # that falls on an output angle) is the state here (gval holds its monitors).
                _write_sample(
                    q_out,
                    v_out,
                    force_out,
                    cam_out,
                    cfg_out,
                    c,
                    k_out,
                    q,
                    v,
                    gval,
                    cam_held,
                    seat_held,
                    poly,
                    trig,
                    p,
                    x_s,
                    ct,
                    st,
                    w,
                    cfg,
                    full_state,
                )
                k_out += 1
            t_prev = t_s
            replan = True
            start_check = True
            h = -1.0
            since_refresh = 0
            since_check = 0
            # ---- walk: steps sized by the fastest mode still present ----
            while True:
                if replan:
                    # Drop mode pairs that have decayed below what any output can show
                    # (keeping the fastest-first order).
                    if since_check >= 32:
                        since_check = 0
                        kept = lo
                        for jj in range(lo, nact):
                            if (
                                MC[AMP_Q, jj] * MC[EABS, jj] < MODE_FLOOR
                                and MC[AMP_F, jj] * MC[EABS, jj] < eps_force
                            ):
                                continue
                            if kept != jj:
                                _keep_column(MC, WC, VY, lamc, act, ns, jj, kept)
                            kept += 1
                        nact = kept
                    # The step need only resolve modes that could bring a watched monitor to its
                    # level: skip the fastest modes while their summed amplitudes (which only
                    # decay) stay under half of every monitor's distance from its level.
                    margin = np.inf
                    for m in range(2):
                        if watch[m]:
                            margin = min(margin, level[m] - gval[m])
                    k = lo
                    spent = 0.0
                    while k < nact:
                        amp = 0.0
                        for m in range(2):
                            if watch[m]:
                                amp = max(amp, WC[W_ABS, m, k] * MC[EABS, k])
                        if spent + amp >= 0.5 * margin:
                            break
                        spent += amp
                        k += 1
                    fastest = lam_abs[tr, ci, act[k]] if k < nact else 0.0
                    h_allow = RESOLUTION * np.pi / fastest if fastest > 0.0 else np.inf
                    if dt_cap > 0.0:
                        h_allow = min(h_allow, dt_cap)
                    t_from = t_prev
                    to_sample = k_out < n_out and k_out * t_sample < t_end * (1.0 + 1e-13)
                    t_next = k_out * t_sample if to_sample else t_end
                    n_steps = max(1, int(np.ceil((t_next - t_from) / h_allow - 1e-9)))
                    h_new = (t_next - t_from) / n_steps
                    i_step = 0
                    since_refresh += n_steps
                    since_check += n_steps
                    # (A step within 1e-12 of the last one keeps D: the difference is rounding.)
                    if abs(h_new - h) > 1e-12 * h or since_refresh > 256 or t_from == t_s:
                        # New step, a fresh segment, or time to refresh: exact exponentials.
                        h = h_new
                        for jj in range(lo, nact):
                            d = np.exp(lamc[jj] * h)
                            e = np.exp(lamc[jj] * (t_from + h - t_s))
                            MC[DR, jj] = d.real
                            MC[DI, jj] = d.imag
                            MC[ER, jj] = e.real
                            MC[EI, jj] = e.imag
                            MC[DABS, jj] = np.exp(lamc[jj].real * h)
                            MC[EABS, jj] = np.exp(lamc[jj].real * (t_from + h - t_s))
                        cwh = np.cos(w * h)
                        swh = np.sin(w * h)
                        cth = np.cos(w * (t_from + h))
                        sth = np.sin(w * (t_from + h))
                        since_refresh = 0
                    else:
                        # Same step: E and (cos θ, sin θ) advance from the sample point.
                        cth, sth = _advance(MC, lo, nact, cth, sth, cwh, swh)
                    replan = False
                if start_check:
                    # A monitor already above its level at the segment start (a contact that
                    # pulls the instant after an impact) is an event there.
                    start_check = False
                    first = -1
                    for m in range(2):
                        if watch[m] and first < 0 and gval[m] > level[m]:
                            first = m  # gval still holds the values at the segment start
                    if first < 0:
                        continue
                    t_ev = t_s
                    at_break = False
                else:
                    first = -1
                if first < 0:
                    i_step += 1
                    steps_taken[c] += 1
                t_n = t_next if i_step == n_steps else t_from + i_step * h
                at_break = t_break <= t_n if first < 0 else False
                if first >= 0:
                    pass
                elif at_break:
                    t_eval = t_break
                    for m in range(2):
                        if ready[m]:
                            gval[m], dval[m] = _at(
                                False, WC, lamc, nact, G, GT, m, t_s, t_break, w, th0
                            )
                else:
                    t_eval = t_n
                    x_n = w * t_n - th0
                    for m in range(2):
                        if ready[m]:
                            gval[m], dval[m] = _monitor_at_grid(
                                WC, MC, lo, nact, G, GT, m, gdeg, w, x_n, cth, sth
                            )
                # An event in (t_prev, t_eval]: the earliest monitor to rise through its level.
                if first < 0:
                    t_ev = t_eval
                if first < 0 and t_eval > t_s:
                    for m in range(2):
                        if not watch[m]:
                            continue
                        t_hi = -1.0
                        g_hi = gval[m]
                        dg_hi = dval[m]
                        if gval[m] > level[m]:
                            t_hi = t_eval
                        elif (
                            dprev[m] > 0.0
                            and dval[m] < 0.0
                            and (
                                max(gprev[m], gval[m])
                                + (t_eval - t_prev)
                                * _slope_bound(
                                    WC,
                                    G,
                                    GT,
                                    m,
                                    MC,
                                    lo,
                                    nact,
                                    gdeg,
                                    w,
                                    w * t_prev - th0,
                                    w * t_eval - th0,
                                )
                                > level[m]
                            )
                        ):
                            # A maximum inside the step that might rise above the level (the
                            # bound on |g'| over the step cannot rule it out): find it.
                            t_max = _root(
                                True,
                                -1.0,
                                WC,
                                lamc,
                                nact,
                                G,
                                GT,
                                m,
                                t_s,
                                t_prev,
                                t_eval,
                                0.0,
                                w,
                                th0,
                                tolerance,
                                False,
                                0.0,
                                0.0,
                                0.0,
                            )
                            g_hi, dg_hi = _at(False, WC, lamc, nact, G, GT, m, t_s, t_max, w, th0)
                            if g_hi > level[m]:
                                t_hi = t_max
                        if t_hi > 0.0:
                            # The value root starts from what the grid (or the maximum's
                            # search) has, unless reduced fidelity leaves pairs out of the grid.
                            te = _root(
                                False,
                                1.0,
                                WC,
                                lamc,
                                nact,
                                G,
                                GT,
                                m,
                                t_s,
                                t_prev,
                                t_hi,
                                level[m],
                                w,
                                th0,
                                tolerance,
                                lo == 0,
                                gprev[m] - level[m],
                                g_hi - level[m],
                                dg_hi,
                            )
                            if first < 0 or te < t_ev:
                                t_ev = te
                                first = m
                if first >= 0:
                    _exps(lam, tr, ci, ns, t_ev - t_s, ev)
                    _state(
                        q,
                        v,
                        z,
                        ya,
                        vec,
                        ev,
                        y0,
                        Z,
                        ZT,
                        free,
                        tr,
                        ci,
                        nf,
                        ns,
                        w * t_ev - th0,
                        np.cos(w * t_ev),
                        np.sin(w * t_ev),
                        ns,
                        deg,
                    )
                    lift_e, dl_e, _ = piece_eval(breaks, poly, trig, c, p, rev, w * t_ev)
                    vcam = -w * dl_e
                    if cam_held:
                        q[0] = -lift_e
                        v[0] = vcam
                    if seat_held:
                        q[6] = qs
                        v[6] = 0.0
                    if not cam_held:
                        _separation(sep_rev, c, n_rev, w, t_s, t_ev)
                    if first == 0 and cam_held:
                        new = _config(False, seat_held)
                        _record(events, n_events, c, t_ev, CAM_SEPARATION, cfg, new, 0.0, 0.0)
                    elif first == 0:
                        new = _config(True, seat_held)
                        closing = v[0] - vcam
                        dv = vcam - v[0]
                        for i in range(7):
                            v[i] += impulse[tr, new - 1, 0, i] * dv
                        q[0] = -lift_e
                        _impact(
                            events,
                            n_events,
                            counts,
                            vmax,
                            meff,
                            c,
                            t_ev,
                            False,
                            seat_held,
                            cfg,
                            new,
                            closing,
                        )
                    elif seat_held:
                        new = _config(cam_held, False)
                        _record(events, n_events, c, t_ev, SEAT_SEPARATION, cfg, new, 0.0, 0.0)
                    else:
                        new = _config(cam_held, True)
                        closing = -v[6]
                        dv = -v[6]
                        for i in range(7):
                            v[i] += impulse[tr, new - 1, 1, i] * dv
                        q[6] = qs
                        _impact(
                            events,
                            n_events,
                            counts,
                            vmax,
                            meff,
                            c,
                            t_ev,
                            True,
                            cam_held,
                            cfg,
                            new,
                            closing,
                        )
                    cfg = new
                    stalled = stalled + 1 if t_ev - t_s <= 1e-15 * (1.0 + t_s) else 0
                    t_s = t_ev
                    break
                if at_break:
                    _exps(lam, tr, ci, ns, t_break - t_s, ev)
                    _state(
                        q,
                        v,
                        z,
                        ya,
                        vec,
                        ev,
                        y0,
                        Z,
                        ZT,
                        free,
                        tr,
                        ci,
                        nf,
                        ns,
                        w * t_break - th0,
                        np.cos(w * t_break),
                        np.sin(w * t_break),
                        ns,
                        deg,
                    )
                    if not cam_held:
                        _separation(sep_rev, c, n_rev, w, t_s, t_break)
                    l_left, dl_left, _ = piece_eval(breaks, poly, trig, c, p, rev, w * t_break)
                    l_right, dl_right, _ = piece_eval(breaks, poly, trig, c, nb, revb, w * t_break)
                    if seat_held:
                        q[6] = qs
                        v[6] = 0.0
                    if cam_held:
                        jump = w * (dl_right - dl_left)  # lift-rate jump [m/s]
                        scale = 1e-9 * (abs(w * dl_left) + abs(w * dl_right)) + JUMP_FLOOR
                        drop = l_right < l_left - 1e-12
                        q[0] = -l_left
                        v[0] = -w * dl_left
                        if (jump < -scale or drop) and not form[c]:
                            new = _config(False, seat_held)
                            _record(
                                events, n_events, c, t_break, CAM_SEPARATION, cfg, new, -jump, 0.0
                            )
                            cfg = new
                        else:
                            if abs(jump) > scale:
                                dv = -jump
                                for i in range(7):
                                    v[i] += impulse[tr, cfg - 1, 0, i] * dv
                                _impact(
                                    events,
                                    n_events,
                                    counts,
                                    vmax,
                                    meff,
                                    c,
                                    t_break,
                                    False,
                                    seat_held,
                                    cfg,
                                    cfg,
                                    abs(jump),
                                )
                            q[0] = -l_right
                            v[0] = -w * dl_right
                    p = nb
                    rev = revb
                    t_s = t_break
                    stalled = 0
                    break
                # Accept the grid point: force maxima, output sample, end of run.
                for m in range(2):
                    dprev[m] = dval[m]
                    gprev[m] = gval[m]
                if cam_held:
                    fmax[c, 0] = max(fmax[c, 0], -gval[0])
                if seat_held:
                    fmax[c, 1] = max(fmax[c, 1], -gval[1])
                t_prev = t_n
                if i_step == n_steps:
                    if to_sample:
                        x_n = w * t_n - th0
                        _state_active(
                            q,
                            v,
                            z,
                            VY,
                            MC,
                            Z,
                            ZT,
                            free,
                            tr,
                            ci,
                            nf,
                            lo,
                            nact,
                            x_n,
                            cth,
                            sth,
                            deg,
                            full_state,
                        )
                        _write_sample(
                            q_out,
                            v_out,
                            force_out,
                            cam_out,
                            cfg_out,
                            c,
                            k_out,
                            q,
                            v,
                            gval,
                            cam_held,
                            seat_held,
                            poly,
                            trig,
                            p,
                            x_n,
                            cth,
                            sth,
                            w,
                            cfg,
                            full_state,
                        )
                        k_out += 1
                    if t_n >= t_end:
                        if not cam_held:
                            _separation(sep_rev, c, n_rev, w, t_s, t_n)
                        done = True
                        break
                    replan = True
                else:
                    cth, sth = _advance(MC, lo, nact, cth, sth, cwh, swh)
            if stalled > MAX_STALLED_EVENTS:
                status[c] = CHATTER
                break
            finite = True
            for i in range(7):
                if not (np.isfinite(q[i]) and np.isfinite(v[i])):
                    finite = False
            if not finite:
                status[c] = NONFINITE
                break
        fmax[c, 2] = fmax[c, 0]  # no force here measures a step: impulses are instantaneous
        if n_events[c] > events.shape[1] and status[c] == OK:
            status[c] = EVENTS_TRUNCATED
