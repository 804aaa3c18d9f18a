"""``modal-exact``: closed-form propagation between events, events located inside the step.

Between events the solution is exact (``campipe.engine.modal``): the state at any time is
V·(y₀ ∘ e^{λτ}) plus the exact particular solution of the piece's polynomial and harmonic
forcing. The integrator walks a grid (steps sized by the modes that can still matter, so that
the output angles fall on it), watches each configuration's monitors (thesis Table I) at the
grid points, and on a sign change locates the event by a bracketed root search (Newton with
Illinois) on the closed form, to ``tolerance`` in time. A segment ends at an event or at a
break of the cam profile; the next starts from the exact state there.

Monitors, each an event when it rises through its level (direction: upward only):

- cam held (I, III), force closure: F1 (the cam would pull) → release the cam;
- cam free (II, IV): q1 + lift(θ) (the follower reaches the cam surface) → cam impact;
- seat free (I, II), with a seat: q7_seat − q7 (the valve reaches the seat) → seat impact;
- seat held (III, IV): −F7 (the seat would pull) → release the seat.

Impacts are the thesis's: infinite cam (seat) mass, perfectly plastic; the struck coordinate
takes the obstacle's velocity and, through the consistent mass, the free coordinates change
velocity by −M_ff⁻¹ M_fp Δv_p: the impulse m_eff·v_closing is applied at the instant of
contact, so no force measures 1/Δt. With a coefficient of restitution e (``cam_restitution``,
``seat_restitution``) the impulse is (1 + e) times that and the contact is left open, the
struck coordinate leaving at e·v_closing, until a series of bounces is captured
(``_impact``).

There is no step-size limit to trip: a step is at most ``RESOLUTION``·π/|λ| of the fastest
mode that could bring a monitor to its level, so a monitor's maximum inside a step shows as a
sign change of its derivative; ``run.dt`` only caps the step.

Notation (``campipe.engine.modal`` for the equations)
-----------------------------------------------------
==============  ===========================================================================
z = [x; ẋ]      state of the free coordinates (2·n_f entries, ``ns``); ż = A z + forcing
X, B_b          A = X·blockdiag(B_b)·X⁻¹: block b (1×1 or 2×2) and its basis X_b
λ̄, δ², N_b      tr B_b / 2, (tr B_b / 2)² − det B_b, B_b − λ̄I
f1, f2          the block's basis functions e^{λ̄τ}C(τ), e^{λ̄τ}S(τ): e^{B_b τ} = f1 I + f2 N_b
t_s, τ          the segment's start [s]; τ = t − t_s
θ, x            cam angle ωt [rad]; x = θ − θ0, the angle from the piece's start θ0
z_p             particular solution Σ_k Z_k x^k + Re(Z_T e^{iθ}) (``Z``, ``ZT``)
u               X⁻¹ (z(t_s) − z_p(t_s)), the homogeneous part in the blocks' basis
z(t)            Σ_b (f1 X_b u_b + f2 X_b N_b u_b) + z_p(t)
g_m             monitor m (0: cam, 1: seat) = Σ_b (W1_mb f1 + W2_mb f2) + Σ_k G_mk x^k
                + Re(GT_m e^{iθ}); an event where g_m rises through ``level[m]``
h, D1, D2       grid step [s] and the blocks' f1(h), f2(h), which advance f1, f2 a step
column          one block each, fastest first
==============  ===========================================================================

The per-block work arrays: ``MC`` rows F1 … RATE (f1, f2, their step factors, the envelope,
the block's shares of coordinates and forces, its constants), ``WC`` rows W1 … WL2_ABS (the
coefficients of f1, f2 in a monitor and its derivatives, and their magnitudes),
``VY[:, jj, s]`` the state's coefficients of f1, f2.

The kernel's steps, each a function below: begin a segment (``_begin_segment``: forcing,
particular solution, modal start, monitors, mode pairs), walk the grid (``_walk``: plan the
steps, advance, watch the monitors), locate an event (``_earliest_crossing``, ``_root``), apply
it (``_apply_event``), cross a profile break (``_cross_break``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, types

from campipe.constants import TWO_PI
from campipe.engine.closed_form import (
    AMP_FA,
    AMP_FB,
    AMP_QA,
    AMP_QB,
    D1,
    D2,
    DABS,
    DSQ,
    EABS,
    F1,
    F2,
    INVD,
    LBAR,
    RATE,
    W1,
    W1_ABS,
    W2,
    W2_ABS,
    WL1,
    WL1_ABS,
    WL2,
    WL2_ABS,
    WLL1,
    WLL2,
    block_basis,
    block_derivative,
    eval_monitor,
    force_monitor,
    forcing,
    particular,
)
from campipe.engine.common import (
    GAP_LEVEL,
    HELPER,
    KERNEL,
    RELEASE,
    SMOOTH,
    by_ref,
    classify_break,
    configuration,
    deref,
    holds_cam,
    holds_seat,
    turn_of,
)
from campipe.engine.metrics import (
    MAX_CAM_FORCE,
    MAX_SEAT_FORCE,
    SEATED_OFF_CAM,
    SEPARATION,
    THESIS_IMPACT_FORCE,
)
from campipe.engine.policy import release, strike, strike_at_break
from campipe.profiles.packed import horner, locate, next_break, piece_eval
from campipe.vocabulary import CAM, CHATTER, EVENTS_TRUNCATED, NONFINITE, OK, SEAT, UNBOUNDED

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


# --------------------------------------------------------------------------- closed forms


@njit(inline="always", nogil=True)
def _at(deriv, WC, MC, nact, G, GT, m, t_s, t, w, th0):
    """Monitor m (deriv False) or its time derivative (deriv True) at time t, and the next
    derivative."""
    g, dg, d2g = eval_monitor(WC, MC, nact, G, GT, m, t - t_s, w, w * t - th0, w * t)
    return (dg, d2g) if deriv else (g, dg)


@njit(**HELPER)
def _root(
    deriv, sgn, WC, MC, nact, G, GT, m, t_s, ta, tb, level, w, th0, tolerance, known, fa, fb,
    dfb,
):  # fmt: skip
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
        f, _ = _at(deriv, WC, MC, nact, G, GT, m, t_s, ta, w, th0)
        fa = sgn * (f - lev)
        if fa > 0.0:
            return ta
        f, df = _at(deriv, WC, MC, nact, G, GT, m, t_s, tb, w, th0)
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
            t = t_last - f_last / df_last if df_last != 0.0 else np.nan  # nan: not in (ta, tb)
            if ta < t < tb:
                converged = abs(t - t_last) < 0.25 * tolerance
            else:
                t = (ta * fb - tb * fa) / (fb - fa)
                if not (ta < t < tb):
                    t = 0.5 * (ta + tb)
        f, df = _at(deriv, WC, MC, nact, G, GT, m, t_s, t, w, th0)
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


@njit(**HELPER)
def _state_at(ref, st, t):
    """The free coordinates and velocities at time t [s] of the segment, from every block,
    into ws.q, ws.v (the held ones are left as they are)."""
    _, trains, _, _, _, ws = deref(ref)
    tr = st.tr
    ci = st.cfg - 1
    ns = st.ns
    nf = st.nf
    tau = t - st.t_s
    x = st.w * t - st.th0
    ct = np.cos(st.w * t)
    sn = np.sin(st.w * t)
    for s in range(ns):
        ws.z[s] = horner(ws.Z[:, s], x, st.deg)[0] + ws.ZT[s].real * ct - ws.ZT[s].imag * sn
    for b in range(trains.n_blocks[tr, ci]):
        f1, f2 = block_basis(trains.lam_bar[tr, ci, b], trains.delta2[tr, ci, b], tau)
        i0 = trains.bstart[tr, ci, b]
        for i in range(i0, i0 + trains.bdim[tr, ci, b]):
            a = f1 * ws.u[i]
            bn = f2 * ws.u[i]
            for s in range(ns):
                ws.z[s] += trains.basis[tr, ci, s, i] * a + trains.basis_n[tr, ci, s, i] * bn
    for k in range(nf):
        ws.q[trains.free[tr, ci, k]] = ws.z[k]
        ws.v[trains.free[tr, ci, k]] = ws.z[nf + k]


@njit(inline="always", nogil=True)
def _state_active(q, v, z, VY, MC, Z, ZT, free, c, ci, nf, nact, x, ct, sn, deg, full_state):
    """Free coordinates and velocities from the blocks 0 … nact − 1 (an output sample):
    VY[:, jj, s] holds the state's coefficients of f1 and f2 in block column jj; plus the
    particular solution. Without ``full_state`` only
    the contact coordinates q1 and q7 (and their velocities) are computed: the others keep
    the values of the segment's start (``_write_sample`` shows them as NaN)."""
    ns = 2 * nf
    if full_state:
        for s in range(ns):
            z[s] = ZT[s].real * ct - ZT[s].imag * sn
        for jj in range(nact):
            f1 = MC[F1, jj]
            f2 = MC[F2, jj]
            for s in range(ns):
                z[s] += VY[0, jj, s] * f1 + VY[1, jj, s] * f2
    for k in range(nf):
        coord = free[c, ci, k]
        if not full_state:
            if coord != CAM and coord != SEAT:
                continue
            for s in (k, k + nf):
                acc = ZT[s].real * ct - ZT[s].imag * sn
                for jj in range(nact):
                    acc += VY[0, jj, s] * MC[F1, jj] + VY[1, jj, s] * MC[F2, jj]
                z[s] = acc
        q[coord] = z[k] + horner(Z[:, k], x, deg)[0]
        v[coord] = z[k + nf] + horner(Z[:, k + nf], x, deg)[0]


@njit(inline="always", nogil=True)
def _slope_bound(WC, G, GT, m, MC, nact, gdeg, w, xa, xb, tau_b):
    """An upper bound on |dg/dt| of monitor m over a step from local angle xa to xb (τ_b after
    the segment start at its end), with the block envelopes at its start (they only decay):
    Σ(|WL1| + |WL2|·min(τ_b, 1/|δ|))·e^{rate·τ} + max|P'| + ω|G_T|. The polynomial part is
    bounded by its derivative's values at the ends plus its second derivative's, which is ample
    for a step of at most one output interval."""
    bound = 0.0
    for jj in range(nact):
        s2 = min(tau_b, MC[INVD, jj])
        bound += (WC[WL1_ABS, m, jj] + WC[WL2_ABS, m, jj] * s2) * MC[EABS, jj]
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
def _free_acceleration(VY, MC, Z, ZT, s, nact, x, cth, sth, w, deg):
    """The time derivative of state row s (a velocity row: an acceleration) at the grid point,
    from the blocks 0 … nact − 1 and the particular solution."""
    acc = 0.0
    for jj in range(nact):
        a = VY[0, jj, s]
        b = VY[1, jj, s]
        lbar = MC[LBAR, jj]
        acc += (lbar * a + b) * MC[F1, jj] + (MC[DSQ, jj] * a + lbar * b) * MC[F2, jj]
    acc += w * horner(Z[:, s], x, deg)[1]
    return acc - w * (ZT[s].real * sth + ZT[s].imag * cth)


@njit(inline="always", nogil=True)
def _write_sample(
    out, c, k, q, v, gval, poly, trig, cfg, p, x, ct, sn, w, full_state, acc1, acc7, n_coord,
):  # fmt: skip
    """Output sample k of case c: coordinates and velocities q, v (held ones on the cam and
    seat; without ``full_state`` only q1 and q7, the others NaN; beyond the train's
    ``n_coord`` coordinates, in a batch of larger trains, NaN), forces from the monitors
    gval, the contact coordinates' accelerations (a free one's acc1, acc7; a held one's from
    the cam or the seat), and the cam lift on piece p at local angle x, cam angle with cosine
    ct and sine sn."""
    lift, dlift, ddlift = horner(poly[c, p], x)
    lift += trig[c, p, 0] * sn + trig[c, p, 1] * ct
    dlift += trig[c, p, 0] * ct - trig[c, p, 1] * sn
    ddlift -= trig[c, p, 0] * sn + trig[c, p, 1] * ct
    for i in range(out.q.shape[2]):
        shown = (full_state or i == CAM or i == SEAT) and i < n_coord
        out.q[c, k, i] = q[i] if shown else np.nan
        out.v[c, k, i] = v[i] if shown else np.nan
    cam_held = holds_cam(cfg)
    seat_held = holds_seat(cfg)
    if cam_held:
        out.q[c, k, CAM] = -lift
        out.v[c, k, CAM] = -w * dlift
    out.acc[c, k, 0] = -w * w * ddlift if cam_held else acc1
    out.acc[c, k, 1] = 0.0 if seat_held else acc7
    out.force[c, k, 0] = gval[0] if cam_held else 0.0
    out.force[c, k, 1] = -gval[1] if seat_held else 0.0
    out.cam[c, k] = lift
    out.cfg[c, k] = cfg


@njit(inline="always", nogil=True)
def _out_of_bounds(cases, c, q, v):
    """The valve's lift or speed beyond its physical bounds (``common.Cases``)."""
    return (
        abs(q[SEAT] - cases.valve_ref[c]) > cases.lift_bound[c]
        or abs(v[SEAT]) > cases.speed_bound[c]
    )


@njit(**HELPER)
def _sample(ref, st, nact, x, cth, sth):
    """The output sample at the grid point (local angle x, cam angle with cosine cth and sine
    sth) from the blocks 0 … nact − 1; a motion out of bounds ends the case (UNBOUNDED)."""
    cases, trains, profiles, runs, out, ws = deref(ref)
    tr, ci, nf, c, w, deg = st.tr, st.cfg - 1, st.nf, st.c, st.w, st.deg
    q, v = ws.q, ws.v
    _state_active(
        q, v, ws.z, ws.VY, ws.MC, ws.Z, ws.ZT, trains.free, tr, ci, nf, nact, x, cth, sth,
        deg, runs.full_state,
    )  # fmt: skip
    acc1 = 0.0  # q̈1, q̈7 where free (the held ones come from the cam and the seat)
    acc7 = 0.0
    for k in range(nf):
        coord = trains.free[tr, ci, k]
        if coord == CAM:
            acc1 = _free_acceleration(ws.VY, ws.MC, ws.Z, ws.ZT, nf + k, nact, x, cth, sth, w, deg)
        elif coord == SEAT:
            acc7 = _free_acceleration(ws.VY, ws.MC, ws.Z, ws.ZT, nf + k, nact, x, cth, sth, w, deg)
    _write_sample(
        out, c, st.k_out, q, v, ws.gval, profiles.poly, profiles.trig, st.cfg, st.p, x, cth,
        sth, w, runs.full_state, acc1, acc7, trains.n_coordinates[tr],
    )  # fmt: skip
    st.k_out += 1
    if _out_of_bounds(cases, c, q, v):
        out.status[c] = UNBOUNDED


@njit(inline="always", nogil=True)
def _advance(MC, nact, cth, sth, cwh, swh):
    """One grid step: the basis functions of the blocks 0 … nact − 1 by their addition
    theorems (f1 ← f1·D1 + δ²·f2·D2, f2 ← f2·D1 + f1·D2) and (cos θ, sin θ) by rotation."""
    for jj in range(nact):
        f1 = MC[F1, jj]
        f2 = MC[F2, jj]
        MC[F1, jj] = f1 * MC[D1, jj] + MC[DSQ, jj] * f2 * MC[D2, jj]
        MC[F2, jj] = f2 * MC[D1, jj] + f1 * MC[D2, jj]
        MC[EABS, jj] *= MC[DABS, jj]
    return cth * cwh - sth * swh, sth * cwh + cth * swh


@njit(inline="always", nogil=True)
def _monitor_at_grid(WC, MC, nact, G, GT, m, gdeg, w, x, cth, sth):
    """Monitor m and its time derivative at the current grid point from the blocks
    0 … nact − 1 and their advanced basis functions (no exp or sin/cos)."""
    g = 0.0
    dg = 0.0
    for jj in range(nact):
        f1 = MC[F1, jj]
        f2 = MC[F2, jj]
        g += WC[W1, m, jj] * f1 + WC[W2, m, jj] * f2
        dg += WC[WL1, m, jj] * f1 + WC[WL2, m, jj] * f2
    p0, p1, _ = horner(G[m], x, gdeg)
    g += p0 + GT[m].real * cth - GT[m].imag * sth
    dg += w * (p1 - GT[m].real * sth - GT[m].imag * cth)
    return g, dg


@njit(**HELPER)
def _keep_column(MC, WC, VY, act, ns, src, dst):
    """Move block column ``src``'s data to column ``dst`` (dropping the columns between)."""
    act[dst] = act[src]
    for r in range(MC.shape[0]):
        MC[r, dst] = MC[r, src]
    for r in range(WC.shape[0]):
        for m in range(2):
            WC[r, m, dst] = WC[r, m, src]
    for s in range(ns):
        VY[0, dst, s] = VY[0, src, s]
        VY[1, dst, s] = VY[1, src, s]


@njit(inline="always", nogil=True)
def _off_cam(out, cfg, c, w, ta, tb):
    """Count [ta, tb] in configuration ``cfg``: no-follow (II) or seated off the cam (IV)."""
    if not holds_cam(cfg):
        _separation(out.per_rev, SEATED_OFF_CAM if holds_seat(cfg) else SEPARATION, c, w, ta, tb)


@njit(**HELPER)
def _separation(per_rev, k, c, w, ta, tb):
    """Add the cam angle of [ta, tb] ∩ [0, ∞) off the cam to each revolution it overlaps, in
    metric column k."""
    n_rev = per_rev.shape[1]
    a = max(w * ta, 0.0)
    b = w * tb
    r = int(a / TWO_PI)
    while a < b and r < n_rev:
        end = min(b, (r + 1) * TWO_PI)
        per_rev[c, r, k] += end - a
        a = end
        r += 1


# --------------------------------------------------------------------------- begin a segment


@njit(inline="always", nogil=True)
def _forcing(cases, trains, profiles, ws, st):
    """The state's homogeneous start zh (the free coordinates' q, v for now), the held
    inputs on the piece, and the forcing's polynomial coefficients b_k (ws.bpoly); sets
    st.kmax and st.deg."""
    tr, ci, nf = st.tr, st.cfg - 1, st.nf
    for k in range(nf):
        ws.zh[k] = ws.q[trains.free[tr, ci, k]]
        ws.zh[nf + k] = ws.v[trains.free[tr, ci, k]]
    forcing(cases, trains, profiles, ws, st)


@njit(inline="always", nogil=True)
def _modal_start(trains, ws, st, x_s, ct, sn):
    """u = X⁻¹ (z(t_s) − z_p(t_s)): the homogeneous part in the blocks' basis at the segment
    start."""
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    for s in range(ns):
        ws.zh[s] -= horner(ws.Z[:, s], x_s, st.deg)[0] + ws.ZT[s].real * ct - ws.ZT[s].imag * sn
    for j in range(ns):
        acc = 0.0
        for s in range(ns):
            acc += trains.basis_inv[tr, ci, j, s] * ws.zh[s]
        ws.u[j] = acc


@njit(inline="always", nogil=True)
def _row_of(trains, st, coord):
    """The state row of free coordinate ``coord`` in the segment's configuration."""
    row = 0
    for k in range(st.nf):
        if trains.free[st.tr, st.cfg - 1, k] == coord:
            row = k
    return row


@njit(inline="always", nogil=True)
def _gap_monitor(cases, trains, profiles, ws, st, m, sign):
    """Monitor m as a free contact's gap: q1 + lift (the cam) or q7_seat − q7 (the seat); its
    forced part (the blocks' part is ``_block_columns``')."""
    c, p = st.c, st.p
    ws.level[m] = GAP_LEVEL
    row = _row_of(trains, st, CAM if m == 0 else SEAT)
    for k in range(8):
        ws.G[m, k] = sign * ws.Z[k, row]
    ws.GT[m] = sign * ws.ZT[row]
    if m == 0:
        for k in range(8):
            ws.G[m, k] += profiles.poly[c, p, k]
        ws.GT[m] += profiles.trig[c, p, 1] - 1j * profiles.trig[c, p, 0]
    else:
        ws.G[m, 0] += cases.seat_q[c]


@njit(inline="always", nogil=True)
def _monitors(cases, trains, profiles, ws, st):
    """The monitors' coefficients g_m(τ) = Re Σ_j W_mj e^{λ_j τ} + Σ_k G_mk x^k
    + Re(GT_m e^{iθ}), which of them can end the segment, and st.gdeg."""
    c = st.c
    cam_held = holds_cam(st.cfg)
    seat_held = holds_seat(st.cfg)
    ws.ready[0] = True
    ws.watch[0] = not (cam_held and cases.form[c])
    ws.ready[1] = cases.has_seat[c] or seat_held
    ws.watch[1] = ws.ready[1]
    for m in range(2):
        if not ws.ready[m]:
            continue
        held = cam_held if m == 0 else seat_held
        sign = 1.0 if m == 0 else -1.0  # F1, q1 + lift; −F7, q7_seat − q7
        for k in range(8):
            ws.G[m, k] = 0.0
        if held:
            # A resting contact releases only when it pulls beyond its hold.
            rest = st.rest_cam if m == 0 else st.rest_seat
            hold = st.hold_cam if m == 0 else st.hold_seat
            level = max(st.eps_force, hold) if rest else st.eps_force
            force_monitor(trains, ws, st, m, sign, level)
        else:
            _gap_monitor(cases, trains, profiles, ws, st, m, sign)
    gdeg = 0
    for m in range(2):
        if ws.ready[m]:
            for k in range(8):
                if ws.G[m, k] != 0.0:
                    gdeg = max(gdeg, k)
    st.gdeg = gdeg


@njit(inline="always", nogil=True)
def _block_columns(cases, trains, runs, ws, st):
    """One column per block, fastest first: the state's coefficients of f1 and f2 (VY), the
    monitors' (WC) and their derivatives', the block's shares of coordinates and forces (MC);
    sets st.nact."""
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    cam_held = holds_cam(st.cfg)
    seat_held = holds_seat(st.cfg)
    rows = (_row_of(trains, st, CAM), _row_of(trains, st, SEAT))
    MC, WC, VY, u = ws.MC, ws.WC, ws.VY, ws.u
    nb = trains.n_blocks[tr, ci]
    for jj in range(nb):
        i0 = trains.bstart[tr, ci, jj]
        i1 = i0 + trains.bdim[tr, ci, jj]
        lbar = trains.lam_bar[tr, ci, jj]
        d2 = trains.delta2[tr, ci, jj]
        ws.act[jj] = jj
        amp_a = 0.0
        amp_b = 0.0
        for s in range(ns):
            a = 0.0
            b = 0.0
            for i in range(i0, i1):
                a += trains.basis[tr, ci, s, i] * u[i]
                b += trains.basis_n[tr, ci, s, i] * u[i]
            VY[0, jj, s] = a
            VY[1, jj, s] = b
            amp_a = max(amp_a, abs(a))
            amp_b = max(amp_b, abs(b))
        # (ρX u, ρXN u) of the cam's force and of the seat's
        fa0 = 0.0
        fb0 = 0.0
        fa1 = 0.0
        fb1 = 0.0
        for i in range(i0, i1):
            fa0 += trains.rho_x[tr, ci, 0, i] * u[i]
            fb0 += trains.rho_xn[tr, ci, 0, i] * u[i]
            fa1 += trains.rho_x[tr, ci, 1, i] * u[i]
            fb1 += trains.rho_xn[tr, ci, 1, i] * u[i]
        MC[F1, jj] = 1.0
        MC[F2, jj] = 0.0
        MC[EABS, jj] = 1.0
        MC[AMP_QA, jj] = amp_a
        MC[AMP_QB, jj] = amp_b
        MC[AMP_FA, jj] = abs(fa0) + abs(fa1)
        MC[AMP_FB, jj] = abs(fb0) + abs(fb1)
        MC[LBAR, jj] = lbar
        MC[DSQ, jj] = d2
        MC[INVD, jj] = 1.0 / np.sqrt(abs(d2)) if d2 != 0.0 else np.inf
        MC[RATE, jj] = trains.rate[tr, ci, jj]
        for m in range(2):
            w1 = 0.0
            w2 = 0.0
            if ws.ready[m]:
                sign = 1.0 if m == 0 else -1.0  # F1, q1 + lift; −F7, q7_seat − q7
                if m == 0 and cam_held:
                    w1 = fa0
                    w2 = fb0
                elif m == 1 and seat_held:
                    w1 = -fa1
                    w2 = -fb1
                else:
                    w1 = sign * VY[0, jj, rows[m]]
                    w2 = sign * VY[1, jj, rows[m]]
            wl1, wl2 = block_derivative(w1, w2, lbar, d2)
            wll1, wll2 = block_derivative(wl1, wl2, lbar, d2)
            WC[W1, m, jj] = w1
            WC[W2, m, jj] = w2
            WC[WL1, m, jj] = wl1
            WC[WL2, m, jj] = wl2
            WC[WLL1, m, jj] = wll1
            WC[WLL2, m, jj] = wll2
            WC[W1_ABS, m, jj] = abs(w1)
            WC[W2_ABS, m, jj] = abs(w2)
            WC[WL1_ABS, m, jj] = abs(wl1)
            WC[WL2_ABS, m, jj] = abs(wl2)
    st.nact = nb


@njit(**HELPER)
def _begin_segment(ref, st):
    """Begin a segment at st.t_s in configuration st.cfg on piece st.p, from the state in
    ws.q, ws.v: forcing, particular solution, modal start, monitors, the break ahead, the mode
    pairs; the monitors' values there, and the sample due there, if any."""
    cases, trains, profiles, runs, out, ws = deref(ref)
    ci = st.cfg - 1
    st.nf = trains.n_free[st.tr, ci]
    st.ns = 2 * st.nf
    _forcing(cases, trains, profiles, ws, st)
    particular(trains, profiles, runs, ws, st)
    th_s = st.w * st.t_s
    st.th0 = st.rev * TWO_PI + profiles.breaks[st.c, st.p]
    x_s = th_s - st.th0
    ct = np.cos(th_s)
    sn = np.sin(th_s)
    _modal_start(trains, ws, st, x_s, ct, sn)
    _monitors(cases, trains, profiles, ws, st)
    # The segment ends at the next break of the profile at the latest.
    nb, revb, th_b = next_break(profiles, st.c, st.p, st.rev)
    st.nb = nb
    st.revb = revb
    st.t_break = th_b / st.w
    _block_columns(cases, trains, runs, ws, st)
    for m in range(2):
        if ws.ready[m]:
            ws.gval[m], ws.dprev[m], _ = eval_monitor(
                ws.WC, ws.MC, st.nact, ws.G, ws.GT, m, 0.0, st.w, x_s, th_s
            )
            ws.gprev[m] = ws.gval[m]
    k_out = st.k_out
    if k_out < out.q.shape[1] and k_out * runs.t_sample[st.c] <= st.t_s * (1.0 + 1e-13):
        # A sample due at the segment start (the initial state, or a break or event that
        # falls on an output angle) is the state here (gval holds its monitors).
        # (The blocks' basis functions are at τ = 0: f1 = 1, f2 = 0; every block counts.)
        _sample(ref, st, st.nact, x_s, ct, sn)


# --------------------------------------------------------------------------- walk the grid


@njit(inline="always", nogil=True)
def _drop_decayed(MC, WC, VY, act, nact, ns, eps_force, tau):
    """Drop the blocks that have decayed below what any output can show (τ after the segment
    start), keeping the fastest-first order; returns the new count."""
    kept = np.int64(0)  # not a literal: one compiled ``_keep_column`` (``common``)
    for jj in range(nact):
        s2 = min(tau, MC[INVD, jj])
        env = MC[EABS, jj]
        if (MC[AMP_QA, jj] + MC[AMP_QB, jj] * s2) * env < MODE_FLOOR and (
            MC[AMP_FA, jj] + MC[AMP_FB, jj] * s2
        ) * env < eps_force:
            continue
        if kept != jj:
            _keep_column(MC, WC, VY, act, ns, jj, kept)
        kept += 1
    return kept


@njit(inline="always", nogil=True)
def _fastest_needed(WC, MC, watch, level, gval, nact, tau):
    """The first column whose block could bring a watched monitor to its level (nact if
    none) up to τ after the segment start: the fastest blocks are skipped while their summed
    amplitudes (which only decay) stay under half of every monitor's distance from its level."""
    margin = np.inf
    for m in range(2):
        if watch[m]:
            margin = min(margin, level[m] - gval[m])
    k = 0
    spent = 0.0
    while k < nact:
        s2 = min(tau, MC[INVD, k])
        amp = 0.0
        for m in range(2):
            if watch[m]:
                amp = max(amp, (WC[W1_ABS, m, k] + WC[W2_ABS, m, k] * s2) * MC[EABS, k])
        if spent + amp >= 0.5 * margin:
            break
        spent += amp
        k += 1
    return k


@njit(inline="always", nogil=True)
def _refresh(MC, nact, h, tau):
    """Exact basis functions at the grid step h and at τ (from the segment start to the next
    grid point) of the blocks 0 … nact − 1, and their envelopes."""
    for jj in range(nact):
        MC[D1, jj], MC[D2, jj] = block_basis(MC[LBAR, jj], MC[DSQ, jj], h)
        MC[F1, jj], MC[F2, jj] = block_basis(MC[LBAR, jj], MC[DSQ, jj], tau)
        MC[DABS, jj] = np.exp(MC[RATE, jj] * h)
        MC[EABS, jj] = np.exp(MC[RATE, jj] * tau)


@njit(inline="always", nogil=True)
def _suspect(watch, level, gval, dval, dprev):
    """A watched monitor above its level at the grid point, or past a maximum inside the
    step (its derivative turned from + to −): ``_earliest_crossing`` must look."""
    for m in range(2):
        if watch[m] and (gval[m] > level[m] or (dprev[m] > 0.0 and dval[m] < 0.0)):
            return True
    return False


@njit(**HELPER)
def _earliest_crossing(ref, st, nact, t_prev, t_eval):
    """The earliest monitor to rise through its level in (t_prev, t_eval] [s] and when,
    from its values at both ends, or from a maximum inside the step that the bound on its
    slope cannot rule out (found by a root of its derivative). Returns (monitor or −1, time).
    """
    _, _, _, runs, _, ws = deref(ref)
    tolerance = runs.tolerance
    w, t_s, th0, gdeg = st.w, st.t_s, st.th0, st.gdeg
    WC, G, GT, MC = ws.WC, ws.G, ws.GT, ws.MC
    first = -1
    t_ev = t_eval
    for m in range(2):
        if not ws.watch[m]:
            continue
        level = ws.level[m]
        t_hi = np.nan  # where the monitor is known above its level (times may be < 0)
        g_hi = ws.gval[m]
        dg_hi = ws.dval[m]
        if ws.gval[m] > level:
            t_hi = t_eval
        elif (
            ws.dprev[m] > 0.0
            and ws.dval[m] < 0.0
            and max(ws.gprev[m], ws.gval[m])
            + (t_eval - t_prev)
            * _slope_bound(
                WC,
                G,
                GT,
                m,
                MC,
                nact,
                gdeg,
                w,
                w * t_prev - th0,
                w * t_eval - th0,
                t_eval - t_s,
            )
            > level
        ):
            t_max = _root(
                np.bool_(True), -1.0, WC, MC, nact, G, GT, m, t_s, t_prev, t_eval, 0.0, w, th0,
                tolerance, np.bool_(False), 0.0, 0.0, 0.0,
            )  # fmt: skip
            g_hi, dg_hi = _at(False, WC, MC, nact, G, GT, m, t_s, t_max, w, th0)
            if g_hi > level:
                t_hi = t_max
        if not np.isnan(t_hi):
            # The value root starts from what the grid (or the maximum's search) has.
            te = _root(
                np.bool_(False), 1.0, WC, MC, nact, G, GT, m, t_s, t_prev, t_hi, level, w, th0,
                tolerance, np.bool_(True), ws.gprev[m] - level, g_hi - level, dg_hi,
            )  # fmt: skip
            if first < 0 or te < t_ev:
                t_ev = te
                first = m
    return first, t_ev


@njit(inline="always", nogil=True)
def _walk(ref, st):
    """Walk the segment's grid from st.t_s until an event, a profile break or the run's end,
    and handle what ended it (``_apply_event``, ``_cross_break``, or st.done).

    The grid step's work is inlined and makes no calls, on arrays and scalars held in locals:
    numba reference-counts a named tuple's arrays (or an array handed to an inlined helper)
    on every pass otherwise. Anything rarer (replanning with dropped pairs, a suspected
    crossing, a sample, an event, a break) is a compiled function of its own.
    """
    cases, trains, profiles, runs, out, ws = deref(ref)
    c, w, t_s, th0, t_break = st.c, st.w, st.t_s, st.th0, st.t_break
    nact, ns, gdeg, eps_force = st.nact, st.ns, st.gdeg, st.eps_force
    speed_row = trains.speed[st.tr, st.cfg - 1]
    cam_held = holds_cam(st.cfg)
    seat_held = holds_seat(st.cfg)
    n_out = out.q.shape[1]
    t_sample = runs.t_sample[c]
    t_end = runs.t_end[c]
    dt_cap = runs.dt_cap
    steps = out.steps
    per_rev = out.per_rev
    n_rev = per_rev.shape[1]
    MC, WC, G, GT, act = ws.MC, ws.WC, ws.G, ws.GT, ws.act
    gval, dval, gprev, dprev = ws.gval, ws.dval, ws.gprev, ws.dprev
    watch, ready, level = ws.watch, ws.ready, ws.level
    # A monitor already above its level at the segment start (a contact that pulls the
    # instant after an impact; a gap that closes) is an event there.
    for m in range(2):
        held = cam_held if m == 0 else seat_held
        if watch[m] and gval[m] > level[m] and (held or dprev[m] > 0.0):
            _apply_event(ref, st, m, t_s)
            return
    t_prev = t_s
    h = -1.0
    since_refresh = 0
    since_check = 0
    replan = True
    i_step = n_steps = 0
    t_from = t_next = cth = sth = cwh = swh = 0.0
    to_sample = False
    while True:
        if replan:
            if since_check >= 32:
                since_check = 0
                nact = _drop_decayed(MC, WC, ws.VY, act, nact, ns, eps_force, t_prev - t_s)
            # The step need only resolve the modes that could bring a watched monitor to its
            # level.
            t_from = t_prev
            k_out = st.k_out
            to_sample = k_out < n_out and k_out * t_sample < t_end * (1.0 + 1e-13)
            t_next = k_out * t_sample if to_sample else t_end
            k = _fastest_needed(WC, MC, watch, level, gval, nact, t_next - t_s)
            fastest = speed_row[act[k]] if k < nact else 0.0
            h_allow = RESOLUTION * np.pi / fastest if fastest > 0.0 else np.inf
            if dt_cap > 0.0:
                h_allow = min(h_allow, dt_cap)
            n_steps = max(1, int(np.ceil((t_next - t_from) / h_allow - 1e-9)))
            h_new = (t_next - t_from) / n_steps
            i_step = 0
            since_refresh += n_steps
            since_check += n_steps
            # (A step within 1e-12 of the last one keeps D: the difference is rounding.)
            if abs(h_new - h) > 1e-12 * h or since_refresh > 256 or t_from == t_s:
                # New step, a fresh segment, or time to refresh: exact exponentials.
                h = h_new
                _refresh(MC, nact, h, t_from + h - t_s)
                cwh = np.cos(w * h)
                swh = np.sin(w * h)
                cth = np.cos(w * (t_from + h))
                sth = np.sin(w * (t_from + h))
                since_refresh = 0
            else:
                # Same step: E and (cos θ, sin θ) advance from the sample point.
                cth, sth = _advance(MC, nact, cth, sth, cwh, swh)
            replan = False
        i_step += 1
        steps[c] += 1
        t_n = t_next if i_step == n_steps else t_from + i_step * h
        at_break = t_break <= t_n
        if at_break:
            t_eval = t_break
            for m in range(2):
                if ready[m]:
                    gval[m], dval[m] = _at(False, WC, MC, nact, G, GT, m, t_s, t_break, w, th0)
        else:
            t_eval = t_n
            x_n = w * t_n - th0
            for m in range(2):
                if ready[m]:
                    gval[m], dval[m] = _monitor_at_grid(
                        WC, MC, nact, G, GT, m, gdeg, w, x_n, cth, sth
                    )
        if t_eval > t_s and _suspect(watch, level, gval, dval, dprev):
            first, t_ev = _earliest_crossing(ref, st, nact, t_prev, t_eval)
            if first >= 0:
                st.nact = nact
                _apply_event(ref, st, first, t_ev)
                return
        if at_break:
            st.nact = nact
            _cross_break(ref, st)
            return
        # Accept the grid point: force maxima, output sample, end of run.
        for m in range(2):
            dprev[m] = dval[m]
            gprev[m] = gval[m]
        turn = turn_of(w, t_n)
        if 0 <= turn < n_rev:
            if cam_held:
                per_rev[c, turn, MAX_CAM_FORCE] = max(per_rev[c, turn, MAX_CAM_FORCE], -gval[0])
            if seat_held:
                per_rev[c, turn, MAX_SEAT_FORCE] = max(per_rev[c, turn, MAX_SEAT_FORCE], -gval[1])
        t_prev = t_n
        if i_step < n_steps:
            cth, sth = _advance(MC, nact, cth, sth, cwh, swh)
            continue
        if to_sample:
            _sample(ref, st, nact, w * t_n - th0, cth, sth)
            if out.status[c] != 0:
                st.done = True
                return
        if t_n >= t_end:
            _off_cam(out, st.cfg, c, w, t_s, t_n)
            st.nact = nact
            st.done = True
            return
        replan = True


# --------------------------------------------------------------------------- events, breaks


@njit(inline="always", nogil=True)
def _impact(cases, trains, out, ws, st, seat, closing, t, vcam, lift):
    """The impact of a closing contact (the cam, or with ``seat`` the seat) at time t [s],
    closing at ``closing`` > 0 [m/s], under Table I's policy (``policy.strike``, with
    restitution): the struck coordinate takes the obstacle's velocity (or, bouncing, leaves
    it at e times its closing velocity) and the free ones change by the impulse's share
    (``modal.ModalData.impulse``). Returns the configuration after it."""
    c, tr, cfg = st.c, st.tr, st.cfg
    q, v = ws.q, ws.v
    side = 1 if seat else 0
    other_held = holds_cam(cfg) if seat else holds_seat(cfg)
    held, new, other_held, e, dv = strike(
        cases, out, st, c, st.w, t, seat, other_held, cfg, closing, True
    )
    for i in range(trains.n_coordinates[tr]):
        v[i] += trains.impulse[tr, held - 1, side, i] * dv
    if seat:
        q[SEAT] = cases.seat_q[c]
        if e > 0.0:
            v[SEAT] = e * closing
    else:
        q[CAM] = -lift
        v[CAM] = vcam - e * closing if e > 0.0 else vcam
    return new


@njit(**HELPER)
def _apply_event(ref, st, first, t_ev):
    """Monitor ``first`` rose through its level at t_ev [s]: take the exact state there, and
    release the contact (a force monitor) or, if the contact closes, apply the plastic impact
    (a gap monitor; ``_impact``): a touch that does not close is no event. Starts the next
    segment there."""
    cases, trains, profiles, runs, out, ws = deref(ref)
    c, w, cfg = st.c, st.w, st.cfg
    cam_held = holds_cam(cfg)
    seat_held = holds_seat(cfg)
    q, v = ws.q, ws.v
    _state_at(ref, st, t_ev)
    lift_e, dl_e, _ = piece_eval(profiles, c, st.p, st.rev, w * t_ev)
    vcam = -w * dl_e
    if cam_held:
        q[CAM] = -lift_e
        v[CAM] = vcam
    if seat_held:
        q[SEAT] = cases.seat_q[c]
        v[SEAT] = 0.0
    _off_cam(out, cfg, c, w, st.t_s, t_ev)
    new = cfg
    if first == 0 and cam_held:
        new = configuration(False, seat_held)
        release(out, st, c, t_ev, False, cfg, new, 0.0)
    elif first == 1 and seat_held:
        new = configuration(cam_held, False)
        release(out, st, c, t_ev, True, cfg, new, 0.0)
    else:
        seat = first == 1
        closing = -v[SEAT] if seat else v[CAM] - vcam
        if closing > 0.0:
            new = _impact(cases, trains, out, ws, st, seat, closing, t_ev, vcam, lift_e)
    st.cfg = new
    st.stalled = st.stalled + 1 if t_ev - st.t_s <= 1e-15 * (1.0 + abs(st.t_s)) else 0
    st.t_s = t_ev


@njit(**HELPER)
def _cross_break(ref, st):
    """The segment reached the next break of the profile: take the exact state there, and
    with the cam held apply what the break does (``common.classify_break``): release, an
    impact of the cam's rate jump (the seat, if held, releasing where it would separate),
    or nothing. Starts the next segment on the next piece."""
    cases, trains, profiles, runs, out, ws = deref(ref)
    c, tr, w, cfg, t_break = st.c, st.tr, st.w, st.cfg, st.t_break
    cam_held = holds_cam(cfg)
    seat_held = holds_seat(cfg)
    q, v = ws.q, ws.v
    _state_at(ref, st, t_break)
    _off_cam(out, cfg, c, w, st.t_s, t_break)
    l_left, dl_left, _ = piece_eval(profiles, c, st.p, st.rev, w * t_break)
    l_right, dl_right, _ = piece_eval(profiles, c, st.nb, st.revb, w * t_break)
    if seat_held:
        q[SEAT] = cases.seat_q[c]
        v[SEAT] = 0.0
    if cam_held:
        kind, jump = classify_break(
            l_left, dl_left, l_right, dl_right, w, cases.form[c], cases.capture[c]
        )
        q[CAM] = -l_left
        v[CAM] = -w * dl_left
        if kind == RELEASE:
            new = configuration(False, seat_held)
            release(out, st, c, t_break, False, cfg, new, -jump)
            st.cfg = new
        else:
            held, new, seat_held, e, dv = strike_at_break(
                cases, out, st, c, w, t_break, seat_held, cfg, kind, jump, True
            )
            if kind != SMOOTH:
                for i in range(trains.n_coordinates[tr]):
                    v[i] += trains.impulse[tr, held - 1, 0, i] * dv
                st.cfg = new
            q[CAM] = -l_right
            v[CAM] = -w * dl_right - e * jump if e > 0.0 else -w * dl_right
    st.p = st.nb
    st.rev = st.revb
    st.t_s = t_break
    st.stalled = 0


@njit(inline="always", nogil=True)
def _start_case(cases, trains, profiles, ws, st, c, tr):
    """Case c's run from its start state at t0 ≤ 0."""
    st.c = c
    st.tr = tr
    st.w = cases.omega[c]
    st.eps_force = 1e-9 * (abs(trains.load[tr, 3]) + 1.0)
    for i in range(trains.n_coordinates[tr]):
        ws.q[i] = cases.q0[c, i]
        ws.v[i] = cases.v0[c, i]
    st.cfg = cases.cfg0[c]
    st.t_s = cases.t0[c]
    rev, p = locate(profiles, c, st.w * st.t_s)
    st.rev = rev
    st.p = p
    st.k_out = 0
    st.stalled = 0
    st.done = False
    st.rest_cam = False
    st.rest_seat = False
    st.bounced_cam = -np.inf
    st.bounced_seat = -np.inf
    st.hold_cam = 0.0
    st.hold_seat = 0.0


@njit(**KERNEL)
def modal_exact_batch(cases, trains, profiles, runs, out, ws, state):
    """Advance every case of a batch exactly between events; fill ``out`` in place.

    Parameters
    ----------
    cases : common.Cases
    trains : ModalTrains
        The distinct trains; case c runs train ``runs.train[c]``.
    profiles : campipe.profiles.PackedProfiles
    runs : ExactRuns
    out : common.Outputs
    ws : Workspace
        Work arrays (``make_workspace``).
    state : (1,) array of STATE
        The run's scalars.
    """
    st = state[0]
    ref = by_ref((cases, trains, profiles, runs, out, ws))
    for c in range(cases.omega.shape[0]):
        _start_case(cases, trains, profiles, ws, st, c, runs.train[c])
        while not st.done:
            _begin_segment(ref, st)
            _walk(ref, st)
            if out.status[c] != OK:
                break
            if st.stalled > MAX_STALLED_EVENTS:
                out.status[c] = CHATTER
                break
            finite = True
            for i in range(trains.n_coordinates[st.tr]):
                if not (np.isfinite(ws.q[i]) and np.isfinite(ws.v[i])):
                    finite = False
            if not finite:
                out.status[c] = NONFINITE
                break
        for turn in range(out.per_rev.shape[1]):  # no force measures a step: impulses are instant
            out.per_rev[c, turn, THESIS_IMPACT_FORCE] = out.per_rev[c, turn, MAX_CAM_FORCE]
        if out.n_events[c] > out.events.shape[1] and out.status[c] == OK:
            out.status[c] = EVENTS_TRUNCATED


def ahead_signatures(kernel_types: tuple) -> dict[Any, tuple]:
    """The helpers of :func:`modal_exact_batch` that a first run compiles in its second
    process (``kernels.compile_kernels``), each with the types the kernel calls it with, given
    the kernel's own argument types (``batch.integrator_types``): ``_sample``,
    ``_apply_event`` and ``_earliest_crossing``, about a quarter of the kernel's compile, there
    before the periodic start, so that the two processes end together. The kernel, compiled in
    the first, loads them from the cache: it reaches ``_sample`` most of a second after the
    second process has it (typing ``_begin_segment`` first), the others seconds after.
    ``_sample`` comes first: reached sooner, it would be compiled twice. Types that differ
    from the kernel's call would cost a second compile, not a wrong result."""
    *tuples, state = kernel_types
    ref = types.CPointer(types.BaseTuple.from_types(tuples))  # the kernel's ``by_ref``
    st = state.dtype  # the kernel's ``state[0]``
    i8, f8 = types.int64, types.float64
    return {
        _sample: (ref, st, i8, f8, f8, f8),
        _apply_event: (ref, st, i8, f8),
        _earliest_crossing: (ref, st, i8, f8, f8),
    }
