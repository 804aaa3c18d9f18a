"""modal-exact: begin a segment (forcing, particular solution, modal start, monitors, the
blocks' columns), in ``campipe.engine.exact``'s notation."""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.constants import TWO_PI
from campipe.engine.closed_form import (
    ACC_CAM1,
    ACC_CAM2,
    ACC_SEAT1,
    ACC_SEAT2,
    AMP_FA,
    AMP_FB,
    AMP_QA,
    AMP_QB,
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
    block_derivative,
    eval_monitor,
    force_monitor,
    forcing,
    harmonic_response,
    particular,
)
from campipe.engine.common import (
    GAP_LEVEL,
    HELPER,
    RESTING_LEVEL,
    deref,
    ends_on_a_break,
    holds_cam,
    holds_seat,
)
from campipe.engine.exact.state import _sample
from campipe.engine.plunger import BOTTOMED, CLOSED, HELD, HYSTERESIS, OPEN, TOPPED, UNLOADED
from campipe.profiles.packed import degree, horner, next_break
from campipe.vocabulary import CAM, CAM_AND_SEAT, CAM_CONTACT, SEAT

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
    for k in range(max(st.deg, 7) + 1):
        ws.G[m, k] = sign * ws.Z[k, row]
    ws.GT[m] = sign * ws.ZT[row]
    if m == 0:
        for k in range(8):
            ws.G[m, k] += profiles.poly[c, p, k]
        ws.GT[m] += profiles.trig[c, p, 1] - 1j * profiles.trig[c, p, 0]
    else:
        ws.G[m, 0] += cases.seat_q[c]


@njit(inline="always", nogil=True)
def _plunger_monitors(trains, runs, ws, st):
    """A carried plunger's monitors in its regime st.reg (``engine.plunger``'s, with its dead
    band HYSTERESIS): 2, its check valve (closed, or bottomed: −F rising through
    −F_c·(1 − HYSTERESIS), the valve opening; open, or topped: F through F_c·(1 + HYSTERESIS),
    closing), or unloaded its load coming back (F through HYSTERESIS·F_c); 3, its travel
    (closed: −u rising through −u_bottom; open or unloaded: u through u_top); 4, open, its
    load falling through 0 (−F through HYSTERESIS·F_c: unloaded). Each a row over the
    coordinates (ws.prow), its forced part from the particular solution and the held
    coordinates' inputs (``forcing``'s ws.inp); none while held (HELD)."""
    c, reg = st.c, st.reg
    for m in range(2, 5):
        ws.ready[m] = ws.watch[m] = False
    if reg == HELD:
        return
    closed = reg == CLOSED or reg == BOTTOMED
    sign = -1.0 if closed else 1.0
    for i in range(ws.prow.shape[1]):
        ws.prow[0, i] = sign * runs.plunger_force[c, i]
        ws.prow[1, i] = 0.0
        ws.prow[2, i] = -runs.plunger_force[c, i]
    band = HYSTERESIS * runs.plunger_check[c]
    ws.level[2] = band if reg == UNLOADED else sign * runs.plunger_check[c] + band
    ws.ready[2] = ws.watch[2] = True
    if reg == CLOSED or reg == OPEN or reg == UNLOADED:
        end = BOTTOMED if reg == CLOSED else TOPPED
        ws.prow[1, runs.plunger_coord[c]] = sign
        ws.level[3] = sign * runs.plunger_end[c, end]
        ws.ready[3] = ws.watch[3] = True
    if reg == OPEN:
        ws.level[4] = band
        ws.ready[4] = ws.watch[4] = True
    tr, ci, nf = st.tr, st.cfg - 1, st.nf
    top = max(st.deg, 7)
    for m in range(2, 5):
        if not ws.ready[m]:
            continue
        row = ws.prow[m - 2]
        ws.GT[m] = 0.0
        for k in range(top + 1):
            ws.G[m, k] = 0.0
        for j in range(nf):
            r = row[trains.free[tr, ci, j]]
            if r != 0.0:
                for k in range(st.deg + 1):
                    ws.G[m, k] += r * ws.Z[k, j]
                ws.GT[m] += r * ws.ZT[j]
        for hc in range(2):  # the held coordinates' inputs (zero where not held)
            r = row[CAM if hc == 0 else SEAT]
            for k in range(8):
                ws.G[m, k] += r * ws.inp[0, hc, k]
            ws.GT[m] += r * ws.inp_t[0, hc]


@njit(inline="always", nogil=True)
def _link_force(runs, ws, c):
    """The force through case c's adjuster [N] at the coordinates ws.q: k·(d·q + u)."""
    force = 0.0
    for i in range(ws.prow.shape[1]):
        force += runs.plunger_force[c, i] * ws.q[i]
    return force


@njit(inline="always", nogil=True)
def monitor_count(st, pl):
    """The monitors case st.c watches (st.n_mon): the constant 2 in a batch with no carried
    plunger (pl None), so that the compiled loops over them are the contacts' alone."""
    if pl is not None:
        return st.n_mon
    return 2


#: ``plunger_switch``'s regime for a plunger held until t = 0 (``plunger.HELD``): the one its
#: load gives there (``PlungerState.regime_at``).
RELEASED = -1


@njit(**HELPER)
def plunger_switch(ref, st, reg):
    """Case st.c's carried plunger into regime ``reg`` (RELEASED: the one its load gives):
    its train row, its velocity the one its law gives there (held: 0, at the end it is held
    at), and the harmonic responses of the configurations that hold the cam for that row.
    (Compiled apart, the plunger's code once; the batch's structures by reference,
    ``common.by_ref``.)"""
    _, trains, _, runs, _, ws = deref(ref)
    c = st.c
    iu = runs.plunger_coord[c]
    if reg == RELEASED:
        u = ws.q[iu]
        load = _link_force(runs, ws, c)
        if load > runs.plunger_check[c]:
            reg = BOTTOMED if u <= runs.plunger_end[c, BOTTOMED] else CLOSED
        elif u >= runs.plunger_end[c, TOPPED]:
            reg = TOPPED
        else:
            reg = UNLOADED if load < 0.0 else OPEN
    st.reg = reg
    st.tr = runs.plunger_train[c, reg]
    damper = runs.plunger_damper[c, reg]
    if np.isinf(damper):
        ws.q[iu] = runs.plunger_end[c, reg]
        ws.v[iu] = 0.0
    else:
        load = 0.0 if reg == UNLOADED else _link_force(runs, ws, c)
        ws.v[iu] = -(load - runs.plunger_check[c]) / damper
    harmonic_response(trains, runs, ws, st, CAM_CONTACT - 1)
    harmonic_response(trains, runs, ws, st, CAM_AND_SEAT - 1)


@njit(inline="always", nogil=True)
def _monitors(cases, trains, profiles, runs, ws, st, pl):
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
        for k in range(max(st.deg, 7) + 1):
            ws.G[m, k] = 0.0
        if held:
            # A held contact releases where its force reaches zero: to the force level, a
            # resting one (its force may hover about zero) to RESTING_LEVEL of it.
            rest = st.rest_cam if m == 0 else st.rest_seat
            level = RESTING_LEVEL * st.eps_force if rest else st.eps_force
            force_monitor(trains, ws, st, m, sign, level)
        else:
            _gap_monitor(cases, trains, profiles, ws, st, m, sign)
    if pl is not None:  # (None: a batch with no carried plunger compiles none of its code)
        if st.n_mon > 2:
            _plunger_monitors(trains, runs, ws, st)
    gdeg = 0
    for m in range(monitor_count(st, pl)):
        if ws.ready[m]:
            for k in range(max(st.deg, 7) + 1):
                if ws.G[m, k] != 0.0:
                    gdeg = max(gdeg, k)
    st.gdeg = gdeg


@njit(inline="always", nogil=True)
def _monitor_column(WC, m, jj, w1, w2, lbar, d2):
    """Monitor m's coefficients of f1 and f2 in block column jj (w1, w2), of its first and
    second time derivatives, and their magnitudes."""
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


@njit(inline="always", nogil=True)
def _block_columns(cases, trains, runs, ws, st, pl):
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
        # The contact coordinates' accelerations (``state._free_acceleration``): the time
        # derivative of their velocity rows, f1' = λ̄f1 + δ²f2, f2' = λ̄f2 + f1.
        a = VY[0, jj, rows[0] + st.nf]
        b = VY[1, jj, rows[0] + st.nf]
        MC[ACC_CAM1, jj] = lbar * a + b
        MC[ACC_CAM2, jj] = d2 * a + lbar * b
        a = VY[0, jj, rows[1] + st.nf]
        b = VY[1, jj, rows[1] + st.nf]
        MC[ACC_SEAT1, jj] = lbar * a + b
        MC[ACC_SEAT2, jj] = d2 * a + lbar * b
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
            _monitor_column(WC, m, jj, w1, w2, lbar, d2)
        if pl is not None:  # a carried plunger's (apart: the contacts' loop above is unrolled)
            if st.n_mon > 2:
                _plunger_columns(trains, ws, st, jj, lbar, d2)
    st.nact = nb


@njit(inline="always", nogil=True)
def _plunger_columns(trains, ws, st, jj, lbar, d2):
    """``_block_columns``' block column jj of a carried plunger's monitors (2–4): their
    rows (ws.prow) over the state's coefficients VY."""
    tr, ci = st.tr, st.cfg - 1
    for m in range(2, st.n_mon):
        w1 = 0.0
        w2 = 0.0
        if ws.ready[m]:
            for j in range(st.nf):
                r = ws.prow[m - 2, trains.free[tr, ci, j]]
                w1 += r * ws.VY[0, jj, j]
                w2 += r * ws.VY[1, jj, j]
        _monitor_column(ws.WC, m, jj, w1, w2, lbar, d2)


@njit(**HELPER)
def _begin_segment(ref, st, pl):
    """Begin a segment at st.t_s in configuration st.cfg on piece st.p, from the state in
    ws.q, ws.v: forcing, particular solution, modal start, monitors, the break ahead, the mode
    pairs; the monitors' values there, and the sample due there, if any."""
    cases, trains, profiles, runs, out, ws = deref(ref)
    if pl is not None:
        if st.reg == HELD and st.t_s >= 0.0:
            plunger_switch(ref, st, np.int64(RELEASED))  # int64, as the kernel passes
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
    _monitors(cases, trains, profiles, runs, ws, st, pl)
    # The segment ends at the next break of the profile at the latest.
    nb, revb, th_b = next_break(profiles, st.c, st.p, st.rev)
    st.nb = nb
    st.revb = revb
    st.t_break = th_b / st.w
    c = st.c
    if ends_on_a_break(profiles, c, st.p, st.rev, st.t_break, runs.t_end[c], st.cfg, st.w,
                       cases.form[c], cases.capture[c]):  # fmt: skip
        st.t_break = np.inf  # the run ends before it: the next run's start crosses it
    st.pdeg = degree(profiles, st.c, st.p)
    _block_columns(cases, trains, runs, ws, st, pl)
    for m in range(monitor_count(st, pl)):
        if ws.ready[m]:
            ws.gval[m], ws.dprev[m], _ = eval_monitor(
                ws.WC, ws.MC, st.nact, ws.G, ws.GT, m, 0.0, st.w, x_s, th_s, st.gdeg
            )
            ws.gprev[m] = ws.gval[m]
    k_out = st.k_out
    if k_out < out.q.shape[1] and k_out * runs.t_sample[st.c] <= st.t_s * (1.0 + 1e-13):
        # A sample due at the segment start (the initial state, or a break or event that
        # falls on an output angle) is the state here (gval holds its monitors).
        # (The blocks' basis functions are at τ = 0: f1 = 1, f2 = 0; every block counts.)
        _sample(ref, st, st.nact, x_s, ct, sn)
