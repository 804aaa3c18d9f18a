"""modal-exact's closed forms at a time: the state, the monitors and their roots, the
samples, the turn's metrics (``campipe.engine.exact``'s notation)."""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.constants import TWO_PI
from campipe.engine.closed_form import (
    ACC_CAM1,
    ACC_SEAT1,
    D1,
    D2,
    DABS,
    DSQ,
    EABS,
    F1,
    F2,
    INVD,
    W1,
    W2,
    WL1,
    WL1_ABS,
    WL2,
    WL2_ABS,
    block_basis,
    eval_monitor,
)
from campipe.engine.common import (
    HELPER,
    count_angle,
    deref,
    holds_cam,
    holds_seat,
)
from campipe.engine.metrics import (
    SEATED_OFF_CAM,
    SEPARATION,
)
from campipe.profiles.packed import horner
from campipe.vocabulary import CAM, SEAT, UNBOUNDED

#: Steps are at most RESOLUTION·π/|λ| of the fastest mode still present: under half its period,
#: so that mode's part of a monitor's derivative changes sign at most once per step, and a
#: maximum inside a step is seen as a + to − change of the derivative at the grid points.
RESOLUTION = 0.9
#: A mode is dropped once its share of every coordinate [m] and velocity [m/s] is below this
#: (4e-12 in: far below any output's resolution) and its share of the contact forces is below
#: the force level of the monitors.
MODE_FLOOR = 1e-13
#: A held contact's force peaks are found to PEAK_LEVEL times the force level (``eps_force``,
#: 1e-9 × (preload + 1 N)): 1e-5 × (preload + 1 N), 7 mN for the thesis's train. Where the
#: force may reach its turn's largest so far, the grid skips no block that adds more than
#: half of that to it (elsewhere a monitor's level alone decides, as for every monitor).
PEAK_LEVEL = 1e4
MAX_STALLED_EVENTS = 64
ROOT_ITERATIONS = 200


# --------------------------------------------------------------------------- closed forms


@njit(inline="always", nogil=True)
def _at(deriv, WC, MC, nact, G, GT, m, t_s, t, w, th0, gdeg):
    """Monitor m (deriv False) or its time derivative (deriv True) at time t, and the next
    derivative (its polynomial part of degree ``gdeg``)."""
    g, dg, d2g = eval_monitor(WC, MC, nact, G, GT, m, t - t_s, w, w * t - th0, w * t, gdeg)
    return (dg, d2g) if deriv else (g, dg)


@njit(inline="always", nogil=True)
def _column(Z, s, x, deg):
    """Σ_{k ≤ deg} Z[k, s]·x^k and its derivative in x: ``horner``'s first two on column s,
    in its order of operations, indexing Z itself (a view ``Z[:, s]`` per call, and the
    second derivative nobody reads, cost a sample a third of its time)."""
    p0 = 0.0
    p1 = 0.0
    for k in range(deg, -1, -1):
        p1 = p1 * x + p0
        p0 = p0 * x + Z[k, s]
    return p0, p1


@njit(inline="always", nogil=True)
def _two_columns(Z, s1, s2, x, deg):
    """Σ_{k ≤ deg} Z[k, s]·x^k of columns s1 and s2 (``horner``'s value, in its order of
    operations), in one loop."""
    p = 0.0
    r = 0.0
    for k in range(deg, -1, -1):
        p = p * x + Z[k, s1]
        r = r * x + Z[k, s2]
    return p, r


@njit(**HELPER)
def _root(
    deriv, sgn, WC, MC, nact, G, GT, m, t_s, ta, tb, level, w, th0, tolerance, known, fa, fb,
    dfb, gdeg,
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
        f, _ = _at(deriv, WC, MC, nact, G, GT, m, t_s, ta, w, th0, gdeg)
        fa = sgn * (f - lev)
        if fa > 0.0:
            return ta
        f, df = _at(deriv, WC, MC, nact, G, GT, m, t_s, tb, w, th0, gdeg)
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
        f, df = _at(deriv, WC, MC, nact, G, GT, m, t_s, t, w, th0, gdeg)
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
        pq, pv = _two_columns(Z, k, k + nf, x, deg)
        q[coord] = z[k] + pq
        v[coord] = z[k + nf] + pv


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
def _free_acceleration(MC, r, Z, ZT, s, nact, x, cth, sth, w, deg):
    """The time derivative of state row s (a velocity row: an acceleration) at the grid point,
    from the blocks 0 … nact − 1 (their coefficients of f1 and f2 in it, rows r and r + 1 of
    MC: ``segment._block_columns``) and the particular solution."""
    acc = 0.0
    for jj in range(nact):
        acc += MC[r, jj] * MC[F1, jj] + MC[r + 1, jj] * MC[F2, jj]
    acc += w * _column(Z, s, x, deg)[1]
    return acc - w * (ZT[s].real * sth + ZT[s].imag * cth)


@njit(inline="always", nogil=True)
def _write_sample(
    out, c, k, q, v, gval, poly, trig, cfg, p, x, ct, sn, w, full_state, acc1, acc7, n_coord,
    pdeg,
):  # fmt: skip
    """Output sample k of case c: coordinates and velocities q, v (held ones on the cam and
    seat; without ``full_state`` only q1 and q7, the others NaN; beyond the train's
    ``n_coord`` coordinates, in a batch of larger trains, NaN), forces from the monitors
    gval, the contact coordinates' accelerations (a free one's acc1, acc7; a held one's from
    the cam or the seat), and the cam lift on piece p at local angle x, cam angle with cosine
    ct and sine sn, of degree ``pdeg`` (its leading zeros add exact zeros: skipped)."""
    lift = 0.0  # horner(poly[c, p], x, pdeg), on poly itself (no view)
    dlift = 0.0
    ddlift = 0.0
    for j in range(pdeg, -1, -1):
        ddlift = ddlift * x + 2.0 * dlift
        dlift = dlift * x + lift
        lift = lift * x + poly[c, p, j]
    lift += trig[c, p, 0] * sn + trig[c, p, 1] * ct
    dlift += trig[c, p, 0] * ct - trig[c, p, 1] * sn
    ddlift -= trig[c, p, 0] * sn + trig[c, p, 1] * ct
    if full_state and n_coord == out.q.shape[2]:  # every coordinate shown
        for i in range(n_coord):
            out.q[c, k, i] = q[i]
        for i in range(n_coord):
            out.v[c, k, i] = v[i]
    else:
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
    q, v, MC, Z, ZT = ws.q, ws.v, ws.MC, ws.Z, ws.ZT
    _state_active(
        q, v, ws.z, ws.VY, ws.MC, ws.Z, ws.ZT, trains.free, tr, ci, nf, nact, x, cth, sth,
        deg, runs.full_state,
    )  # fmt: skip
    acc1 = 0.0  # q̈1, q̈7 where free (the held ones come from the cam and the seat)
    acc7 = 0.0
    for k in range(nf):
        coord = trains.free[tr, ci, k]
        if coord == CAM:
            acc1 = _free_acceleration(MC, ACC_CAM1, Z, ZT, nf + k, nact, x, cth, sth, w, deg)
        elif coord == SEAT:
            acc7 = _free_acceleration(MC, ACC_SEAT1, Z, ZT, nf + k, nact, x, cth, sth, w, deg)
    _write_sample(
        out, c, st.k_out, q, v, ws.gval, profiles.poly, profiles.trig, st.cfg, st.p, x, cth,
        sth, w, runs.full_state, acc1, acc7, trains.n_coordinates[tr], st.pdeg,
    )  # fmt: skip
    st.k_out += 1
    if _out_of_bounds(cases, c, q, v):
        out.status[c] = UNBOUNDED


#: A case repeats its first turn when its state at the turn's end equals its start to this
#: many units in the last place of each coordinate's and velocity's largest value over the turn.
REPEAT_ULPS = 64.0


@njit(inline="always", nogil=True)
def _turn_samples(w, t_sample, n_out, n_rev):
    """The output samples a turn spans when a run of whole turns samples every turn alike
    (the spacing divides the turn and the last sample closes the last turn), else 0."""
    every = w * t_sample
    per_turn = int(np.round(TWO_PI / every))
    if n_rev < 2 or abs(per_turn * every - TWO_PI) > 1e-9 * TWO_PI:
        return 0
    return per_turn if per_turn * n_rev == n_out - 1 else 0


@njit(inline="always", nogil=True)
def _same_to_rounding(a, c, k0, k1, n):
    """Rows k0 and k1 of a[c] equal to ``REPEAT_ULPS`` of each column's largest value over
    rows k0 … k1 (columns NaN in both rows, not computed, count as equal)."""
    for i in range(n):
        x0 = a[c, k0, i]
        x1 = a[c, k1, i]
        if np.isnan(x0) and np.isnan(x1):
            continue
        scale = 0.0
        for k in range(k0, k1 + 1):
            scale = max(scale, abs(a[c, k, i]))
        if not abs(x1 - x0) <= REPEAT_ULPS * 2.220446049250313e-16 * scale:
            return False
    return True


@njit(**HELPER)
def _repeat_first_turn(out, c, per_turn, n_coord):
    """Case c's first turn, closed with no event in configuration I, repeats: its state at
    the turn's end equals the start to rounding (a periodic start that follows the cam), so
    every later turn is the first again. Copies the first turn's samples and metrics to the
    others and returns True; False (nothing written) if the state did not repeat."""
    if not (
        _same_to_rounding(out.q, c, 0, per_turn, n_coord)
        and _same_to_rounding(out.v, c, 0, per_turn, n_coord)
    ):
        return False
    n_out = out.q.shape[1]
    for k in range(per_turn + 1, n_out):
        k0 = (k - 1) % per_turn + 1
        for i in range(out.q.shape[2]):
            out.q[c, k, i] = out.q[c, k0, i]
            out.v[c, k, i] = out.v[c, k0, i]
        for j in range(2):
            out.force[c, k, j] = out.force[c, k0, j]
            out.acc[c, k, j] = out.acc[c, k0, j]
        out.cam[c, k] = out.cam[c, k0]
        out.cfg[c, k] = out.cfg[c, k0]
    for r in range(1, out.per_rev.shape[1]):
        for j in range(out.per_rev.shape[2]):
            out.per_rev[c, r, j] = out.per_rev[c, 0, j]
    return True


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
    p0 = 0.0  # horner(G[m], x, gdeg)'s value and slope, on G itself (no view)
    p1 = 0.0
    for k in range(gdeg, -1, -1):
        p1 = p1 * x + p0
        p0 = p0 * x + G[m, k]
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
        for m in range(WC.shape[1]):
            WC[r, m, dst] = WC[r, m, src]
    for s in range(ns):
        VY[0, dst, s] = VY[0, src, s]
        VY[1, dst, s] = VY[1, src, s]


@njit(inline="always", nogil=True)
def _off_cam(out, cfg, c, w, ta, tb):
    """Count [ta, tb] in configuration ``cfg``: no-follow (II) or seated off the cam (IV)."""
    if not holds_cam(cfg):
        k = SEATED_OFF_CAM if holds_seat(cfg) else SEPARATION
        count_angle(out.per_rev, k, c, w, ta, tb, 1.0)
