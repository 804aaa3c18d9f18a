"""``newmark-linear``: the thesis's integrator (Appendix B) over a batch of cases, compiled.

Newmark's linear-acceleration method (β = 1/6, γ = 1/2) at a fixed step, with the contact
configuration switched at step ends from the monitored values of Table I, exactly as the
thesis does:

- I: the cam pushes (F1 ≤ 0); F1 > 0 at a step end → II (or IV). The valve passing the seat
  → III, a seat impact.
- II: q1 passing the cam surface → I (a cam impact); q7 passing the seat → IV.
- III: F1 > 0 → IV; F7 < 0 → I.
- IV: F7 < 0 → II; q1 passing the cam → III.

Impacts follow thesis Ch. IV: the cam (seat) has infinite mass and the impact is perfectly
plastic. The struck coordinate is prescribed from the next step on, and over that first step
its acceleration is the velocity change divided by Δt (thesis Eq. 28), which carries the
impulse into the free coordinates. The contact force in that step measures 1/Δt and is left
out of the force maxima; the impulse reported is the converged one, m_eff·v_closing.

A velocity jump in the profile (a flat's edges) is a break of the piecewise profile. Crossing
one with the cam held, a surface that falls away releases the follower for that step (the cam
never pulls it along); a surface that jumps into the follower is a cam impact.

State arrays have a leading case axis; each case runs to its own end inside one compiled call,
which releases the GIL so dask threads run batches in parallel.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Event kinds.
CAM_SEPARATION, CAM_IMPACT, SEAT_SEPARATION, SEAT_IMPACT = 1, 2, 3, 4
# Columns of the event array.
EV_TIME, EV_KIND, EV_FROM, EV_TO, EV_VELOCITY, EV_IMPULSE = range(6)
N_EVENT_FIELDS = 6
# Status codes.
OK, NONFINITE, EVENTS_TRUNCATED = 0, 1, 2

TWO_PI = 2.0 * np.pi
#: Let LLVM reassociate and fuse floating-point operations, but keep NaN and inf semantics:
#: the kernel's finiteness check must keep working.
FAST = {"contract", "reassoc", "nsz", "arcp"}
#: Number of coordinates.
NP = 7
#: A profile break whose lift rate jumps by less than this [m/s] (beyond 1e-9 relative) is
#: smooth: rounding in re-expanded polynomial pieces, not a velocity jump.
JUMP_FLOOR = 1e-9


@njit(cache=True, nogil=True)
def locate(breaks, n_pieces, c, theta):
    """(revolution, piece) holding cam angle ``theta`` [rad] for case ``c``."""
    rev = np.floor(theta / TWO_PI)
    phi = theta - rev * TWO_PI
    lo = 0
    hi = n_pieces[c] - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if breaks[c, mid] <= phi:
            lo = mid
        else:
            hi = mid - 1
    return int(rev), lo


@njit(cache=True, nogil=True)
def horner2(coef, x, deg=7):
    """Σ_{k ≤ deg} coef[k]·x^k and its first two derivatives in x, by Horner's scheme."""
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    for k in range(deg, -1, -1):
        p2 = p2 * x + 2.0 * p1
        p1 = p1 * x + p0
        p0 = p0 * x + coef[k]
    return p0, p1, p2


@njit(cache=True, nogil=True)
def piece_eval(breaks, poly, trig, c, piece, rev, theta):
    """Lift [m] and its first two θ-derivatives on one piece."""
    x = theta - rev * TWO_PI - breaks[c, piece]
    p0, p1, p2 = horner2(poly[c, piece], x)
    s = np.sin(theta)
    co = np.cos(theta)
    a = trig[c, piece, 0]
    b = trig[c, piece, 1]
    return p0 + a * s + b * co, p1 + a * co - b * s, p2 - a * s - b * co


@njit(cache=True, nogil=True)
def _degree(poly, c, piece):
    """Highest power with a nonzero coefficient on a piece (Horner need go no higher)."""
    for k in range(7, 0, -1):
        if poly[c, piece, k] != 0.0:
            return k
    return 0


@njit(cache=True, nogil=True)
def cam_eval(breaks, poly, trig, n_pieces, c, theta):
    rev, piece = locate(breaks, n_pieces, c, theta)
    return piece_eval(breaks, poly, trig, c, piece, rev, theta)


@njit(cache=True, nogil=True)
def _record(events, n_events, c, t, kind, c_from, c_to, velocity, impulse):
    k = n_events[c]
    if k < events.shape[1]:
        events[c, k, EV_TIME] = t
        events[c, k, EV_KIND] = kind
        events[c, k, EV_FROM] = c_from
        events[c, k, EV_TO] = c_to
        events[c, k, EV_VELOCITY] = velocity
        events[c, k, EV_IMPULSE] = impulse
    n_events[c] = k + 1


@njit(cache=True, nogil=True, fastmath=FAST)
def _row_force(M, C, K, load, c, i, a, v, q):
    """Contact force at coordinate i: row i of M·a + C·v + K·q − load (thesis Eqs. 26, 27)."""
    fm = 0.0
    fc = 0.0
    fk = 0.0
    for j in range(NP):
        fm += M[c, i, j] * a[j]
        fc += C[c, i, j] * v[j]
        fk += K[c, i, j] * q[j]
    return fm + fc + fk - load[c, i]


@njit(cache=True, nogil=True)
def _config(cam, seat):
    if cam:
        return 3 if seat else 1
    return 4 if seat else 2


@njit(cache=True, nogil=True, fastmath=FAST)
def newmark_linear_batch(
    M, C, K, load, minv, meff, q0, v0, a0, cfg0,
    seat_q, has_seat, form, omega, dt, n_steps,
    breaks, poly, trig, n_pieces,
    d_theta_out, q_out, v_out, force_out, cam_out, cfg_out,
    sep_rev, counts, vmax, fmax, events, n_events, status,
):
    """Advance every case of a batch; fill the output arrays in place.

    Shapes: M, C, K (n, 7, 7); load, q0, v0, a0 (n, 7); minv (n, 4, 7, 7) from
    ``effective_mass_inverses``; meff (n, 4) from ``impact_masses``; per-case vectors (n,);
    q_out, v_out (n, n_out, 7); force_out (n, n_out, 2) = (F1, F7), thesis signs; cam_out (n, n_out)
    cam lift; cfg_out (n, n_out) int8; sep_rev (n, n_rev) [rad]; counts (n, 2) cam and seat
    impacts; vmax (n, 2) largest cam and seat closing velocity; fmax (n, 2) largest
    compressive cam and seat force between impacts, and the cam force including the steps an
    impulse passes through (the thesis's "impact force", which measures 1/Δt); events
    (n, max_events, 6).
    """
    n_cases = M.shape[0]
    n_out = q_out.shape[1]
    n_rev = sep_rev.shape[1]
    q = np.zeros(NP)
    v = np.zeros(NP)
    a = np.zeros(NP)
    qn = np.zeros(NP)
    vn = np.zeros(NP)
    an = np.zeros(NP)
    qt = np.zeros(NP)
    vt = np.zeros(NP)
    at = np.zeros(NP)
    al = np.zeros(NP)
    ps = np.zeros(NP)
    rhs = np.zeros(NP)
    for c in range(n_cases):
        h = dt[c]
        w = omega[c]
        Kc = K[c]
        Cc = C[c]
        Mc = M[c]
        fc = load[c]
        qs = seat_q[c]
        for i in range(NP):
            q[i] = q0[c, i]
            v[i] = v0[c, i]
            a[i] = a0[c, i]
        cfg = cfg0[c]
        impulse_cam = False
        impulse_seat = False
        quiet_cam = 0  # steps left whose cam force measures an impulse, not the train
        quiet_seat = 0
        k_out = 0
        t_sample = 0.0
        rev, p = locate(breaks, n_pieces, c, 0.0)
        pdeg = _degree(poly, c, p)
        npc = n_pieces[c]
        fmax_cam = 0.0
        fmax_seat = 0.0
        fmax_raw = 0.0
        sd = np.sin(w * h)
        cd = np.cos(w * h)
        sn = 0.0
        cs = 1.0
        for n in range(n_steps[c]):
            t0 = n * h
            t1 = (n + 1) * h
            th0 = w * t0
            th1 = w * t1
            cam_held = cfg == 1 or cfg == 3
            seat_held = cfg == 3 or cfg == 4
            # sin θ1, cos θ1 by rotation, refreshed exactly every 256 steps.
            if n % 256 == 0:
                sn = np.sin(th1)
                cs = np.cos(th1)
            else:
                sn, cs = sn * cd + cs * sd, cs * cd - sn * sd
            # Move the piece cursor to θ1; a velocity jump of the profile is a break crossed.
            while True:
                pn = p + 1
                revn = rev
                if pn == npc:
                    pn = 0
                    revn = rev + 1
                thb = revn * TWO_PI + breaks[c, pn]
                if th1 < thb:
                    break
                if cam_held:
                    l_left, dl_left, _ = piece_eval(breaks, poly, trig, c, p, rev, thb)
                    l_right, dl_right, _ = piece_eval(breaks, poly, trig, c, pn, revn, thb)
                    jump = w * (dl_right - dl_left)  # lift-rate jump [m/s]
                    scale = 1e-9 * (abs(w * dl_left) + abs(w * dl_right)) + JUMP_FLOOR
                    drop = l_right < l_left - 1e-12  # a step down in lift (the engine refuses up)
                    if (jump < -scale or drop) and not form[c]:
                        # The surface falls away: the follower keeps its velocity.
                        new = _config(False, seat_held)
                        _record(events, n_events, c, thb / w, CAM_SEPARATION, cfg, new,
                                -jump, 0.0)
                        cfg = new
                        cam_held = False
                    elif abs(jump) > scale:
                        # The surface jumps into the follower (or, form-closed, drags it).
                        impulse_cam = True
                        counts[c, 0] += 1
                        vmax[c, 0] = max(vmax[c, 0], abs(jump))
                        mi = 1 if seat_held else 0
                        _record(events, n_events, c, thb / w, CAM_IMPACT, cfg, cfg,
                                abs(jump), meff[c, mi] * abs(jump))
                p = pn
                rev = revn
                pdeg = _degree(poly, c, p)
            x = th1 - rev * TWO_PI - breaks[c, p]
            lift1, dl1, ddl1 = horner2(poly[c, p], x, pdeg)
            ta = trig[c, p, 0]
            tb = trig[c, p, 1]
            if ta != 0.0 or tb != 0.0:
                lift1 += ta * sn + tb * cs
                dl1 += ta * cs - tb * sn
                ddl1 -= ta * sn + tb * cs
            qc = -lift1
            vc = -w * dl1
            ac = -w * w * ddl1
            # Thesis Appendix B, steps 2–6, over the free coordinates of this configuration.
            for i in range(NP):
                al[i] = v[i] + 0.5 * h * a[i]
                ps[i] = q[i] + h * v[i] + h * h / 3.0 * a[i]
                qt[i] = ps[i]
                vt[i] = al[i]
                at[i] = 0.0
            if cam_held:
                qt[0] = qc
                vt[0] = vc
                at[0] = (vc - v[0]) / h if impulse_cam else ac
            if seat_held:
                qt[6] = qs
                vt[6] = 0.0
                at[6] = (0.0 - v[6]) / h if impulse_seat else 0.0
            # Column by column (the matrices are symmetric), so the seven row sums advance
            # together instead of as seven serial chains. Only the contact coordinates can
            # carry a prescribed acceleration.
            a0h = at[0]
            a6h = at[6]
            for i in range(NP):
                rhs[i] = fc[i] - Mc[0, i] * a0h - Mc[6, i] * a6h
            for j in range(NP):
                qj = qt[j]
                vj = vt[j]
                for i in range(NP):
                    rhs[i] -= Kc[j, i] * qj + Cc[j, i] * vj
            mi_c = minv[c, cfg - 1]
            for i in range(NP):
                an[i] = 0.0
            for j in range(NP):
                rj = rhs[j]
                for i in range(NP):
                    an[i] += mi_c[j, i] * rj
            for i in range(NP):
                vn[i] = al[i] + 0.5 * h * an[i]
                qn[i] = ps[i] + h * h / 6.0 * an[i]
            if cam_held:
                qn[0] = qt[0]
                vn[0] = vt[0]
                an[0] = at[0]
            if seat_held:
                qn[6] = qt[6]
                vn[6] = vt[6]
                an[6] = at[6]
            f1 = 0.0
            f7 = 0.0
            if cam_held:
                f1 = _row_force(M, C, K, load, c, 0, an, vn, qn)
            if seat_held:
                f7 = _row_force(M, C, K, load, c, 6, an, vn, qn)
            if impulse_cam:
                quiet_cam = 2
            if impulse_seat:
                quiet_seat = 2
            impulse_cam = False
            impulse_seat = False
            # Metrics over this step.
            if not cam_held:
                rev_i = int(th0 / TWO_PI)
                if rev_i < n_rev:
                    sep_rev[c, rev_i] += w * h
            if quiet_cam > 0:
                quiet_cam -= 1
            elif cam_held:
                fmax_cam = max(fmax_cam, -f1)
            if cam_held:
                fmax_raw = max(fmax_raw, -f1)
            if quiet_seat > 0:
                quiet_seat -= 1
            elif seat_held:
                fmax_seat = max(fmax_seat, f7)
            # Output samples inside (t0, t1], from the step's cubic (thesis Eqs. 55–57).
            while k_out < n_out and t_sample <= t1 * (1.0 + 1e-12):
                tau = t_sample - t0
                if k_out == 0:
                    tau = 0.0
                r = tau / h
                for i in range(NP):
                    da = an[i] - a[i]
                    qt[i] = q[i] + v[i] * tau + 0.5 * a[i] * tau * tau + da * tau * tau * r / 6.0
                    vt[i] = v[i] + a[i] * tau + 0.5 * da * tau * r
                    at[i] = a[i] + da * r
                ls, dls, ddls = cam_eval(breaks, poly, trig, n_pieces, c, w * t_sample)
                if cam_held:
                    qt[0] = -ls
                    vt[0] = -w * dls
                    at[0] = -w * w * ddls
                if seat_held:
                    qt[6] = qs
                    vt[6] = 0.0
                    at[6] = 0.0
                for i in range(NP):
                    q_out[c, k_out, i] = qt[i]
                    v_out[c, k_out, i] = vt[i]
                # A contact that the step end releases may show a little tension inside the
                # step; a force-closed contact cannot pull, so it reports zero there.
                fs1 = _row_force(M, C, K, load, c, 0, at, vt, qt) if cam_held else 0.0
                fs7 = _row_force(M, C, K, load, c, 6, at, vt, qt) if seat_held else 0.0
                force_out[c, k_out, 0] = fs1 if form[c] else min(fs1, 0.0)
                force_out[c, k_out, 1] = max(fs7, 0.0)
                cam_out[c, k_out] = ls
                cfg_out[c, k_out] = cfg
                k_out += 1
                t_sample = k_out * d_theta_out / w
            # Monitors at the step end (thesis Table I, Figure 4).
            cam_next = cam_held
            seat_next = seat_held
            if cam_held and not form[c] and f1 > 0.0:
                cam_next = False
                _record(events, n_events, c, t1, CAM_SEPARATION, cfg,
                        _config(False, seat_held and not f7 < 0.0), 0.0, 0.0)
            if seat_held and f7 < 0.0:
                seat_next = False
                _record(events, n_events, c, t1, SEAT_SEPARATION, cfg,
                        _config(cam_next, False), 0.0, 0.0)
            if not cam_held and qn[0] > qc:
                closing = vn[0] - vc
                cam_next = True
                impulse_cam = True
                counts[c, 0] += 1
                vmax[c, 0] = max(vmax[c, 0], closing)
                mi = 1 if seat_next else 0
                _record(events, n_events, c, t1, CAM_IMPACT, cfg, _config(True, seat_next),
                        closing, meff[c, mi] * closing)
            if has_seat[c] and not seat_held and qn[6] < qs:
                closing = -vn[6]
                seat_next = True
                impulse_seat = True
                counts[c, 1] += 1
                vmax[c, 1] = max(vmax[c, 1], closing)
                mi = 3 if cam_next else 2
                _record(events, n_events, c, t1, SEAT_IMPACT, cfg, _config(cam_next, True),
                        closing, meff[c, mi] * closing)
            cfg = _config(cam_next, seat_next)
            for i in range(NP):
                q[i] = qn[i]
                v[i] = vn[i]
                a[i] = an[i]
            if n % 1024 == 0 or n == n_steps[c] - 1:
                finite = True
                for i in range(NP):
                    if not (np.isfinite(q[i]) and np.isfinite(v[i]) and np.isfinite(a[i])):
                        finite = False
                if not finite:
                    status[c] = NONFINITE
                    break
        fmax[c, 0] = fmax_cam
        fmax[c, 1] = fmax_seat
        fmax[c, 2] = fmax_raw
        if n_events[c] > events.shape[1] and status[c] == OK:
            status[c] = EVENTS_TRUNCATED
