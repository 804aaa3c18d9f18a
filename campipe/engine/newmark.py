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

A step is two small matrix products fixed by the train, the step and the configuration
(``contact.newmark_step_maps``): the force left after the predictors, then the step-end
accelerations and contact forces from it, applied with the corrector in AVX2 registers
(``_newmark_step``).

State arrays have a leading case axis; each case runs to its own end inside one compiled call,
which releases the GIL so dask threads run batches in parallel.
"""

from __future__ import annotations

import functools

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

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
#: The state x = (q, v, a) a step reads (``_newmark_step``, ``contact.newmark_step_maps``): each
#: block padded to N_Z = 8 lanes (two AVX2 registers of LANES doubles) and starting at these
#: offsets; N_X lanes in all. Padding lanes stay zero.
X_Q, X_V, X_A = 0, 8, 16
N_X, N_Z = 24, 8
LANES = 4
#: LLVM flags of ``_newmark_step``'s arithmetic: multiplies and adds fuse, nothing reassociates.
FUSE = ("contract",)
#: A profile break whose lift rate jumps by less than this [m/s] (beyond 1e-9 relative) is
#: smooth: rounding in re-expanded polynomial pieces, not a velocity jump.
JUMP_FLOOR = 1e-9
#: Turns [-] by which an angle may fall short of a turn's start and still count to that turn.
TURN_GUARD = 1e-9


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


@njit(cache=True, nogil=True, inline="always")
def horner2(coef, x, deg=7):
    """Σ_{k ≤ deg} coef[k]·x^k and its first two derivatives in x, by Horner's scheme.
    Inlined, so a caller's view ``poly[c, p]`` costs no reference counting per call."""
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


@njit(cache=True, nogil=True)
def _impact(events, n_events, counts, vmax, meff, c, t, seat, other_held, c_from, c_to, closing):
    """Count a plastic impact of case c on the cam (``seat`` False) or the seat, keep its
    largest closing velocity [m/s] and record the event with its impulse m_eff·v_closing;
    ``other_held``: the other contact is held (``contact.impact_masses`` order)."""
    side = 1 if seat else 0
    counts[c, side] += 1
    vmax[c, side] = max(vmax[c, side], closing)
    mass = meff[c, 2 * side + (1 if other_held else 0)]
    _record(
        events,
        n_events,
        c,
        t,
        SEAT_IMPACT if seat else CAM_IMPACT,
        c_from,
        c_to,
        closing,
        mass * closing,
    )


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
def _revolution(theta):
    """The cam turn holding angle ``theta`` [rad]. An angle on a turn's start to rounding
    (a round speed and step) counts to that turn, however LLVM reassociates θ = ω·n·Δt."""
    return int(theta / TWO_PI + TURN_GUARD)


@njit(cache=True, nogil=True, fastmath=FAST)
def _next_break(breaks, n_pieces, c, piece, rev):
    """The piece after ``piece`` of turn ``rev``, its turn, and the cam angle [rad] where it
    starts."""
    pn = piece + 1
    revn = rev
    if pn == n_pieces:
        pn = 0
        revn = rev + 1
    return pn, revn, revn * TWO_PI + breaks[c, pn]


@njit(cache=True, nogil=True)
def _add_turn(sep_rev, c, turn, angle):
    """Add one turn's separation angle [rad] to case c's record, if that turn is recorded."""
    if turn < sep_rev.shape[1]:
        sep_rev[c, turn] += angle


@njit(cache=True, nogil=True)
def _config(cam, seat):
    if cam:
        return 3 if seat else 1
    return 4 if seat else 2


@intrinsic
def _newmark_step(typingctx, A, G, c, k, load, h, x, xn, z):
    """One step of Newmark's linear-acceleration method for case c in configuration k + 1,
    on all N_Z lanes of the state x = (q, v, a) (thesis Appendix B, steps 2–6):

        r = load − A·x,   z = G·r,
        xn = (q + Δt·v + Δt²/3·a + Δt²/6·z,  v + Δt/2·a + Δt/2·z,  z),

    with A, G from ``contact.newmark_step_maps`` (z: the step-end accelerations, and in a held
    coordinate's row its contact force), Δt = h and ``load`` the case's (N_Z,). The caller
    puts the held coordinates' prescribed values back into xn.

    Written out as vector instructions, LANES rows to a register: numba compiles with LLVM's
    SLP vectoriser off and its loop vectoriser leaves loops this short alone, so as loops the
    multiply-adds stay scalar and take most of a step. A (n, 4, N_X, N_Z) and G
    (n, 4, N_Z, N_Z) are stored by columns; each column is scaled by its x[j] (r[j]) and added
    into one of a few accumulators, summed at the end. Multiplies and adds fuse; nothing is
    reassociated.
    """
    f8 = types.float64
    vector = types.Array(f8, 1, "C")
    if (A, G, load, h, x, xn, z) != (
        types.Array(f8, 4, "C"),
        types.Array(f8, 4, "C"),
        vector,
        f8,
        vector,
        vector,
        vector,
    ):
        raise TypingError(
            "_newmark_step: expected C-contiguous float64 arrays A (n, 4, N_X, "
            "N_Z), G (n, 4, N_Z, N_Z), load, z (N_Z,), x, xn (N_X,) and a "
            "float64 step"
        )

    def codegen(context, builder, sig, args):
        f64 = ir.DoubleType()
        vec = ir.VectorType(f64, LANES)
        intp = context.get_value_type(types.intp)
        zero = ir.Constant(intp, 0)

        def start(i, *index):  # pointer to element ``index`` of array argument i
            array = context.make_array(sig.args[i])(context, builder, args[i])
            return cgutils.get_item_pointer(
                context, builder, sig.args[i], array, index, wraparound=False
            )

        def element(ptr, offset):
            return builder.gep(ptr, [ir.Constant(intp, offset)], source_etype=f64)

        def load(ptr, offset):  # the LANES doubles from ptr[offset] on
            return builder.load(
                builder.bitcast(element(ptr, offset), vec.as_pointer()), align=8, typ=vec
            )

        def store(value, ptr, offset):
            builder.store(value, builder.bitcast(element(ptr, offset), vec.as_pointer()), align=8)

        def add(u, v):
            return builder.fadd(u, v, flags=FUSE)

        def mul(u, v):
            return builder.fmul(u, v, flags=FUSE)

        def lane(u, i):  # lane i of vector u in every lane
            return builder.shuffle_vector(
                u, u, ir.Constant(ir.VectorType(ir.IntType(32), LANES), [i] * LANES)
            )

        def splat(value):
            return lane(builder.insert_element(ir.Constant(vec, None), value, zero), 0)

        halves = range(0, N_Z, LANES)

        def product(M, chains, scale):
            """Σ_j M[:, j]·scale(j) over the columns j of ``chains`` (ranges, each summed in
            its own registers, then added in order), as N_Z // LANES vectors."""
            sums = []
            for cols in chains:
                acc = None
                for j in cols:
                    s = scale(j)
                    terms = [mul(load(M, j * N_Z + i), s) for i in halves]
                    acc = (
                        terms
                        if acc is None
                        else [add(u, t) for u, t in zip(acc, terms, strict=True)]
                    )
                sums.append(acc)
            return [functools.reduce(add, parts) for parts in zip(*sums, strict=True)]

        case, cfg = (context.cast(builder, args[i], sig.args[i], types.intp) for i in (2, 3))
        A_at = start(0, case, cfg, zero, zero)
        G_at = start(1, case, cfg, zero, zero)
        load_at, x_at, xn_at, z_at = (start(i, zero) for i in (4, 6, 7, 8))
        # r = load − A·x, each block's columns in two chains; z = G·r; the corrector.
        chains = [
            range(b + part, b + min(part + 4, NP)) for part in (0, 4) for b in (X_Q, X_V, X_A)
        ]
        ax = product(A_at, chains, lambda j: splat(builder.load(element(x_at, j), typ=f64)))
        r = [builder.fsub(load(load_at, i), u, flags=FUSE) for i, u in zip(halves, ax, strict=True)]
        zs = product(G_at, (range(0, 4), range(4, NP)), lambda j: lane(r[j // LANES], j % LANES))
        dt = splat(args[5])
        dt2 = mul(dt, dt)
        dt2_3 = builder.fdiv(dt2, ir.Constant(vec, [3.0] * LANES), flags=FUSE)
        dt2_6 = builder.fdiv(dt2, ir.Constant(vec, [6.0] * LANES), flags=FUSE)
        dt_2 = mul(ir.Constant(vec, [0.5] * LANES), dt)
        for i, zi in zip(halves, zs, strict=True):
            q, v, a = (load(x_at, b + i) for b in (X_Q, X_V, X_A))
            store(zi, z_at, i)
            store(add(add(add(q, mul(dt, v)), mul(dt2_3, a)), mul(dt2_6, zi)), xn_at, X_Q + i)
            store(add(add(v, mul(dt_2, a)), mul(dt_2, zi)), xn_at, X_V + i)
            store(zi, xn_at, X_A + i)
        return context.get_dummy_value()

    return types.void(A, G, c, k, load, h, x, xn, z), codegen


@njit(cache=True, nogil=True, fastmath=FAST)
def newmark_linear_batch(
    M,
    C,
    K,
    load,
    step_A,
    step_G,
    meff,
    q0,
    v0,
    a0,
    cfg0,
    seat_q,
    has_seat,
    form,
    omega,
    dt,
    n_steps,
    breaks,
    poly,
    trig,
    n_pieces,
    d_theta_out,
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
    """Advance every case of a batch; fill the output arrays in place.

    Shapes: M, C, K (n, 7, 7); load, q0, v0, a0 (n, 7); step_A (n, 4, N_X, N_Z), step_G
    (n, 4, N_Z, N_Z) from ``contact.newmark_step_maps`` at the case's step (C-contiguous);
    meff (n, 4) from ``impact_masses``;
    per-case vectors (n,); q_out, v_out (n, n_out, 7); force_out (n, n_out, 2) = (F1, F7),
    thesis signs; cam_out (n, n_out) cam lift; cfg_out (n, n_out) int8; sep_rev (n, n_rev)
    [rad]; counts (n, 2) cam and seat impacts; vmax (n, 2) largest cam and seat closing
    velocity; fmax (n, 2) largest compressive cam and seat force between impacts, and the cam
    force including the steps an impulse passes through (the thesis's "impact force", which
    measures 1/Δt); events (n, max_events, 6).
    """
    if step_A.shape[2:] != (N_X, N_Z) or step_G.shape[2:] != (N_Z, N_Z):
        raise ValueError("step_A, step_G: expected (n, 4, N_X, N_Z) and (n, 4, N_Z, N_Z)")
    n_cases = M.shape[0]
    n_out = q_out.shape[1]
    # The state (q, v, a) at the step start and end, in the step's layout (X_Q, X_V, X_A).
    x = np.zeros(N_X)
    xn = np.zeros(N_X)
    z = np.zeros(N_Z)
    f = np.zeros(N_Z)
    qt = np.zeros(NP)
    vt = np.zeros(NP)
    at = np.zeros(NP)
    for c in range(n_cases):
        h = dt[c]
        w = omega[c]
        qs = seat_q[c]
        for i in range(N_X):
            x[i] = 0.0
            xn[i] = 0.0
        for i in range(NP):
            f[i] = load[c, i]
            x[X_Q + i] = q0[c, i]
            x[X_V + i] = v0[c, i]
            x[X_A + i] = a0[c, i]
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
        pn, revn, thb = _next_break(breaks, npc, c, p, rev)
        fmax_cam = 0.0
        fmax_seat = 0.0
        fmax_raw = 0.0
        sep_turn = 0  # the turn whose separation [rad] ``sep`` sums
        sep = 0.0
        sd = np.sin(w * h)
        cd = np.cos(w * h)
        sn = 0.0
        cs = 1.0
        for n in range(n_steps[c]):
            t0 = n * h
            t1 = (n + 1) * h
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
            while th1 >= thb:
                if cam_held:
                    l_left, dl_left, _ = piece_eval(breaks, poly, trig, c, p, rev, thb)
                    l_right, dl_right, _ = piece_eval(breaks, poly, trig, c, pn, revn, thb)
                    jump = w * (dl_right - dl_left)  # lift-rate jump [m/s]
                    scale = 1e-9 * (abs(w * dl_left) + abs(w * dl_right)) + JUMP_FLOOR
                    drop = l_right < l_left - 1e-12  # a step down in lift (the engine refuses up)
                    if (jump < -scale or drop) and not form[c]:
                        # The surface falls away: the follower keeps its velocity.
                        new = _config(False, seat_held)
                        _record(events, n_events, c, thb / w, CAM_SEPARATION, cfg, new, -jump, 0.0)
                        cfg = new
                        cam_held = False
                    elif abs(jump) > scale:
                        # The surface jumps into the follower (or, form-closed, drags it).
                        impulse_cam = True
                        _impact(
                            events,
                            n_events,
                            counts,
                            vmax,
                            meff,
                            c,
                            thb / w,
                            False,
                            seat_held,
                            cfg,
                            cfg,
                            abs(jump),
                        )
                p = pn
                rev = revn
                pdeg = _degree(poly, c, p)
                pn, revn, thb = _next_break(breaks, npc, c, p, rev)
            x1 = th1 - rev * TWO_PI - breaks[c, p]
            lift1, dl1, ddl1 = horner2(poly[c, p], x1, pdeg)
            ta = trig[c, p, 0]
            tb = trig[c, p, 1]
            if ta != 0.0 or tb != 0.0:
                lift1 += ta * sn + tb * cs
                dl1 += ta * cs - tb * sn
                ddl1 -= ta * sn + tb * cs
            qc = -lift1
            vc = -w * dl1
            ac = -w * w * ddl1
            # Thesis Appendix B, steps 2–6: the held coordinates take their step-end values
            # (over an impulse's first step, its velocity change over Δt: Eq. 28); one step
            # map advances the free coordinates and gives the contact forces at the step end.
            if cam_held:
                x[X_A] = (vc - x[X_V]) / h if impulse_cam else ac
                x[X_Q] = qc
                x[X_V] = vc
            if seat_held:
                x[X_A + 6] = (0.0 - x[X_V + 6]) / h if impulse_seat else 0.0
                x[X_Q + 6] = qs
                x[X_V + 6] = 0.0
            _newmark_step(step_A, step_G, c, cfg - 1, f, h, x, xn, z)
            f1 = 0.0
            f7 = 0.0
            if cam_held:
                xn[X_Q] = x[X_Q]
                xn[X_V] = x[X_V]
                xn[X_A] = x[X_A]
                f1 = z[0]
            if seat_held:
                xn[X_Q + 6] = x[X_Q + 6]
                xn[X_V + 6] = x[X_V + 6]
                xn[X_A + 6] = x[X_A + 6]
                f7 = z[6]
            if impulse_cam:
                quiet_cam = 2
            if impulse_seat:
                quiet_seat = 2
            impulse_cam = False
            impulse_seat = False
            # Metrics over this step.
            if not cam_held:
                rev_i = _revolution(w * t0)
                if rev_i != sep_turn:
                    _add_turn(sep_rev, c, sep_turn, sep)
                    sep_turn = rev_i
                    sep = 0.0
                sep += w * h
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
            # Output samples inside (t0, t1], from the step's cubic (thesis Eqs. 55–57); the
            # held coordinates from the cam and the seat.
            while k_out < n_out and t_sample <= t1 * (1.0 + 1e-12):
                tau = t_sample - t0
                if k_out == 0:
                    tau = 0.0
                r = tau / h
                for i in range(NP):
                    q = x[X_Q + i]
                    v = x[X_V + i]
                    a = x[X_A + i]
                    da = xn[X_A + i] - a
                    qt[i] = q + v * tau + 0.5 * a * tau * tau + da * tau * tau * r / 6.0
                    vt[i] = v + a * tau + 0.5 * da * tau * r
                    at[i] = a + da * r
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
                _record(
                    events,
                    n_events,
                    c,
                    t1,
                    CAM_SEPARATION,
                    cfg,
                    _config(False, seat_held and not f7 < 0.0),
                    0.0,
                    0.0,
                )
            if seat_held and f7 < 0.0:
                seat_next = False
                _record(
                    events,
                    n_events,
                    c,
                    t1,
                    SEAT_SEPARATION,
                    cfg,
                    _config(cam_next, False),
                    0.0,
                    0.0,
                )
            if not cam_held and xn[X_Q] > qc:
                closing = xn[X_V] - vc
                cam_next = True
                impulse_cam = True
                _impact(
                    events,
                    n_events,
                    counts,
                    vmax,
                    meff,
                    c,
                    t1,
                    False,
                    seat_next,
                    cfg,
                    _config(True, seat_next),
                    closing,
                )
            if has_seat[c] and not seat_held and xn[X_Q + 6] < qs:
                closing = -xn[X_V + 6]
                seat_next = True
                impulse_seat = True
                _impact(
                    events,
                    n_events,
                    counts,
                    vmax,
                    meff,
                    c,
                    t1,
                    True,
                    cam_next,
                    cfg,
                    _config(cam_next, True),
                    closing,
                )
            cfg = _config(cam_next, seat_next)
            x, xn = xn, x
            if n % 1024 == 0 or n == n_steps[c] - 1:
                finite = True
                for i in range(N_X):
                    if not np.isfinite(x[i]):
                        finite = False
                if not finite:
                    status[c] = NONFINITE
                    break
        _add_turn(sep_rev, c, sep_turn, sep)
        fmax[c, 0] = fmax_cam
        fmax[c, 1] = fmax_seat
        fmax[c, 2] = fmax_raw
        if n_events[c] > events.shape[1] and status[c] == OK:
            status[c] = EVENTS_TRUNCATED
