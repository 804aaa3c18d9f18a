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

A velocity jump in the profile (a flat's edges) is a break of the piecewise profile, classified
by ``common.classify_break``: crossing one with the cam held, a surface that falls away releases
the follower for that step (the cam never pulls it along); a surface that jumps into the
follower is a cam impact.

A step is two small matrix products fixed by the train, the step and the configuration
(``contact.newmark_step_maps``): the force left after the predictors, then the step-end
accelerations and contact forces from it, applied with the corrector in AVX2 registers
(``_newmark_step``).

Notation (thesis Appendix B): x = (q, q̇, q̈) the state at a step's start, xn at its end, in the
lane layout X_Q, X_V, X_A; z the step-end accelerations, and in a held coordinate's row its
contact force (F1 at q1, F7 at q7); h = Δt; θ1 = ω·t1 the cam angle at the step end; qc, vc,
ac the cam's prescribed q1, q̇1, q̈1 there (q1 = −lift).

Each case runs to its own end inside one compiled call, which releases the GIL so dask threads
run batches in parallel.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from campipe.constants import TWO_PI
from campipe.engine.common import (
    AT_BREAK,
    GAP_LEVEL,
    HELPER,
    JUMP,
    KERNEL,
    RELEASE,
    SMOOTH,
    TURN_GUARD,
    by_ref,
    classify_break,
    configuration,
    deref,
    holds_cam,
    holds_seat,
    start_piece,
)
from campipe.engine.metrics import (
    MAX_CAM_FORCE,
    MAX_ROLLER_FORCE,
    MAX_SEAT_FORCE,
    SEATED_OFF_CAM,
    SEPARATION,
    THESIS_IMPACT_FORCE,
)
from campipe.engine.policy import release, strike, strike_at_break
from campipe.profiles.packed import (
    degree,
    evaluate_packed,
    horner,
    next_break,
    piece_eval,
    ratio_bound,
)
from campipe.vocabulary import (
    CAM,
    EVENTS_TRUNCATED,
    N_COORDINATES,
    NONFINITE,
    OK,
    SEAT,
    UNBOUNDED,
)

#: Let LLVM reassociate and fuse floating-point operations, but keep NaN and inf semantics:
#: the kernel's finiteness check must keep working.
FAST = {"contract", "reassoc", "nsz", "arcp"}
NP = N_COORDINATES
#: The state x = (q, v, a) a step reads (``_newmark_step``, ``contact.newmark_step_maps``): each
#: block padded to N_Z = 8 lanes (two AVX2 registers of LANES doubles) and starting at these
#: offsets; N_X lanes in all. Padding lanes stay zero.
X_Q, X_V, X_A = 0, 8, 16
N_X, N_Z = 24, 8
LANES = 4
#: LLVM flags of ``_newmark_step``'s arithmetic: multiplies and adds fuse, nothing reassociates.
FUSE = ("contract",)


class NewmarkTrains(NamedTuple):
    """Each case's train at its step (leading axis: case; C-contiguous)."""

    M: np.ndarray  # (n, 7, 7) mass [kg, kg·m, kg·m²]
    C: np.ndarray  # (n, 7, 7) damping
    K: np.ndarray  # (n, 7, 7) stiffness
    load: np.ndarray  # (n, 7) preload [N]
    step_A: np.ndarray  # (n, 4, N_X, N_Z) ``contact.newmark_step_maps``: forces
    step_G: np.ndarray  # (n, 4, N_Z, N_Z) and step-end accelerations and contact forces


class NewmarkWork(NamedTuple):
    """Work arrays of one case's step (``make_work``): the state (q, v, a) at the step start
    and end in the step's layout (X_Q, X_V, X_A), the step map's output, the load, and a
    sample's state."""

    x: np.ndarray  # (N_X,)
    xn: np.ndarray  # (N_X,)
    z: np.ndarray  # (N_Z,)
    f: np.ndarray  # (N_Z,)
    qt: np.ndarray  # (7,)
    vt: np.ndarray  # (7,)
    at: np.ndarray  # (7,)


def make_work() -> NewmarkWork:
    """Zeroed work arrays."""
    return NewmarkWork(
        np.zeros(N_X), np.zeros(N_X), np.zeros(N_Z), np.zeros(N_Z), np.zeros(NP), np.zeros(NP),
        np.zeros(NP),
    )  # fmt: skip


class NewmarkRuns(NamedTuple):
    """How each case is stepped and sampled."""

    dt: np.ndarray  # (n,) step [s]
    n_steps: np.ndarray  # (n,) int64 steps to take
    d_theta_out: float  # output spacing in cam angle [rad]
    t_end: np.ndarray  # (n,) the run's end [s] (its last step may end after it)


@njit(**HELPER, fastmath=FAST)
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


#: A case's contact state between steps (a record): resting contacts (``common.captured``;
#: not read: a held contact releases where its force at a step end pulls, resting or not).
CONTACT_STATE = np.dtype(
    [
        ("rest_cam", "?"),
        ("rest_seat", "?"),
        ("bounced_cam", "f8"),  # not read: newmark-linear's impacts are plastic
        ("bounced_seat", "f8"),
    ],
    align=True,
)


@njit(**HELPER, fastmath=FAST)
def _cross_breaks(ref, ct, c, w, th1, th_end, cfg, p, rev, pn, revn, thb):
    """Move case c's piece cursor (piece p of turn rev; the next break thb [rad] starts piece
    pn of turn revn) up to the step end θ1 [rad], classifying each break crossed with the cam
    held (``common.classify_break``): a surface falling away releases the follower, one
    jumping into it is a cam impact (the seat, if held, releasing where it would separate).
    One of those at the run's end θ_end [rad] (to ``common.AT_BREAK``) is left to the next
    run's start (``common.start_piece``). Returns the configuration, whether that impact's
    impulse starts now, and the cursor."""
    cases, _, profiles, _, out = deref(ref)
    impulse_cam = False
    while th1 >= thb:
        if holds_cam(cfg):
            l_left, dl_left, _ = piece_eval(profiles, c, p, rev, thb)
            l_right, dl_right, _ = piece_eval(profiles, c, pn, revn, thb)
            kind, jump = classify_break(
                l_left, dl_left, l_right, dl_right, w, cases.form[c], cases.capture[c]
            )
            if kind != SMOOTH and thb >= th_end * (1.0 - AT_BREAK):
                break
            seat_held = holds_seat(cfg)
            if kind == RELEASE:
                # The surface falls away: the follower keeps its velocity.
                new = configuration(False, seat_held)
                release(out, ct, c, thb / w, False, cfg, new, -jump)
                cfg = new
            elif kind == JUMP:
                # The surface jumps into the follower (or, form-closed, drags it).
                impulse_cam = True
                _, cfg, _, _, _ = strike_at_break(
                    cases, out, ct, c, w, thb / w, seat_held, cfg, kind, jump, False
                )
        p = pn
        rev = revn
        pn, revn, thb = next_break(profiles, c, p, rev)
    return cfg, impulse_cam, p, rev, pn, revn, thb


@njit(**HELPER, fastmath=FAST)
def _write_samples(ref, c, k_out, t_sample, t0, t1, h, x, xn, qt, vt, at, cfg):
    """Output samples of case c inside the step (t0, t1] [s], from the step's cubic (thesis
    Eqs. 55–57); the held coordinates from the cam and the seat. A valve out of its bounds ends
    the case (UNBOUNDED). Returns the next sample's index and time."""
    cases, trains, profiles, runs, out = deref(ref)
    w = cases.omega[c]
    n_out = out.q.shape[1]
    cam_held = holds_cam(cfg)
    seat_held = holds_seat(cfg)
    while k_out < n_out and t_sample <= t1 * (1.0 + 1e-12):
        tau = t_sample - t0
        if k_out == 0 and t0 == 0.0:
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
        ls, dls, ddls = evaluate_packed(profiles, c, w * t_sample)
        if cam_held:
            qt[0] = -ls
            vt[0] = -w * dls
            at[0] = -w * w * ddls
        if seat_held:
            qt[SEAT] = cases.seat_q[c]
            vt[SEAT] = 0.0
            at[SEAT] = 0.0
        for i in range(NP):
            out.q[c, k_out, i] = qt[i]
            out.v[c, k_out, i] = vt[i]
        out.acc[c, k_out, 0] = at[0]
        out.acc[c, k_out, 1] = at[SEAT]
        # A contact that the step end releases may show a little tension inside the step; a
        # force-closed contact cannot pull, so it reports zero there.
        M, C, K, load = trains.M, trains.C, trains.K, trains.load
        # (NumPy integers: a Python-int constant would compile ``_row_force`` once per row.)
        fs1 = _row_force(M, C, K, load, c, np.int64(0), at, vt, qt) if cam_held else 0.0
        fs7 = _row_force(M, C, K, load, c, np.int64(SEAT), at, vt, qt) if seat_held else 0.0
        out.force[c, k_out, 0] = fs1 if cases.form[c] else min(fs1, 0.0)
        out.force[c, k_out, 1] = max(fs7, 0.0)
        out.cam[c, k_out] = ls
        out.cfg[c, k_out] = cfg
        k_out += 1
        t_sample = k_out * runs.d_theta_out / w
        if (
            abs(qt[SEAT] - cases.valve_ref[c]) > cases.lift_bound[c]
            or abs(vt[SEAT]) > cases.speed_bound[c]
        ):
            out.status[c] = UNBOUNDED
    return k_out, t_sample


@njit(inline="always")
def _tripped(cfg, form, has_seat, impulsive, f1, f7, q1, q7, v1, v7, qc, vc, qs):
    """The monitors of thesis Table I at a step end (F1, F7 the contact forces, q1, q7 and
    v1, v7 the contact coordinates and velocities, qc, vc the cam's q1 and q̇1, qs the seat's
    q7): the cam or the seat would pull (a resting contact as any other),
    the follower passed the cam surface closing on it, the valve passed its seat closing on
    it (an impact needs a positive closing velocity).

    Not in a step an impulse passes through (``impulsive``): its contact forces measure the
    impulse over Δt, and which contacts hold after an impact was decided at the impact, on
    the impulses themselves (``common.other_releases``).

    Inlined and taking scalars only: it runs every step, and numba reference-counts an array
    handed to an inlined function on every call.
    """
    cam_held = holds_cam(cfg)
    seat_held = holds_seat(cfg)
    release_cam = cam_held and not form and not impulsive and f1 > 0.0
    release_seat = seat_held and not impulsive and f7 < 0.0
    hit_cam = not cam_held and q1 > qc + GAP_LEVEL and v1 - vc > 0.0
    hit_seat = has_seat and not seat_held and q7 < qs - GAP_LEVEL and v7 < 0.0
    return release_cam, release_seat, hit_cam, hit_seat


@njit(**HELPER, fastmath=FAST)
def _switch(ref, ct, c, t1, cfg, f7, xn, vc, release_cam, release_seat, hit_cam, hit_seat):
    """Apply what the monitors tripped at the step end t1 [s] (``_tripped``): record the
    releases and impacts, and return the next configuration and whether a cam or seat impulse
    starts. The other contact, if held, releases where the impact would separate it
    (``common.other_releases``); a slow impact leaves its contact resting (in the contact
    state ``ct``)."""
    cases, _, _, _, out = deref(ref)
    w = cases.omega[c]
    seat_held = holds_seat(cfg)
    cam_next = holds_cam(cfg)
    seat_next = seat_held
    if release_cam:
        cam_next = False
        release(out, ct, c, t1, False, cfg, configuration(False, seat_held and not f7 < 0.0), 0.0)
    if release_seat:
        seat_next = False
        release(out, ct, c, t1, True, cfg, configuration(cam_next, False), 0.0)
    if hit_cam:
        closing = xn[X_V] - vc
        seat_next = strike(
            cases, out, ct, c, w, t1, np.bool_(False), seat_next, cfg, closing, False
        )[2]
        cam_next = True
    if hit_seat:
        closing = -xn[X_V + SEAT]
        cam_next = strike(cases, out, ct, c, w, t1, np.bool_(True), cam_next, cfg, closing, False)[
            2
        ]
        seat_next = True
    return configuration(cam_next, seat_next), hit_cam, hit_seat


@njit(inline="always")
def _cam(profiles, c, p, pdeg, x1, sn, cs, w):
    """q1, q̇1, q̈1 of a follower held on piece p of case c's cam, x1 [rad] into the piece
    (sin θ, cos θ given for its harmonic part)."""
    lift1, dl1, ddl1 = horner(profiles.poly[c, p], x1, pdeg)
    ta = profiles.trig[c, p, 0]
    tb = profiles.trig[c, p, 1]
    if ta != 0.0 or tb != 0.0:
        lift1 += ta * sn + tb * cs
        dl1 += ta * cs - tb * sn
        ddl1 -= ta * sn + tb * cs
    return -lift1, -w * dl1, -w * w * ddl1


@njit(inline="always")
def _hold(x, cam_held, seat_held, impulse_cam, impulse_seat, qc, vc, ac, qs, h):
    """The held coordinates take their step-end values in the state x: the cam's (qc, vc,
    ac), the seat's (qs at rest); over an impulse's first step the acceleration is its
    velocity change over the step h [s] (thesis Eq. 28)."""
    if cam_held:
        x[X_A] = (vc - x[X_V]) / h if impulse_cam else ac
        x[X_Q] = qc
        x[X_V] = vc
    if seat_held:
        x[X_A + SEAT] = (0.0 - x[X_V + SEAT]) / h if impulse_seat else 0.0
        x[X_Q + SEAT] = qs
        x[X_V + SEAT] = 0.0


@njit(inline="always")
def _held_forces(x, xn, z, cam_held, seat_held):
    """The held coordinates carried to the step end xn, and the contact forces (F1, F7) the
    step map gave in z (0 for a contact not held)."""
    f1 = 0.0
    f7 = 0.0
    if cam_held:
        xn[X_Q] = x[X_Q]
        xn[X_V] = x[X_V]
        xn[X_A] = x[X_A]
        f1 = z[0]
    if seat_held:
        xn[X_Q + SEAT] = x[X_Q + SEAT]
        xn[X_V + SEAT] = x[X_V + SEAT]
        xn[X_A + SEAT] = x[X_A + SEAT]
        f7 = z[SEAT]
    return f1, f7


@njit(inline="always")
def _step_metrics(per_rev, c, turn, dtheta, cam_held, seat_held, cam_clean, seat_clean, f1, f7,
                  ratio):  # fmt: skip
    """A step's share of its turn's metrics: dtheta [rad] off the cam (no-follow, or seated),
    and the largest contact forces of the steps no impulse passes through (``cam_clean``,
    ``seat_clean``), a lever's roller force too (−f1 times its ``ratio`` at the step's end;
    0 for a case that is no lever's); the thesis's impact force counts every step."""
    if not cam_held:
        if seat_held:
            per_rev[c, turn, SEATED_OFF_CAM] += dtheta
        else:
            per_rev[c, turn, SEPARATION] += dtheta
    if cam_clean and cam_held:
        per_rev[c, turn, MAX_CAM_FORCE] = max(per_rev[c, turn, MAX_CAM_FORCE], -f1)
        if ratio > 0.0:
            per_rev[c, turn, MAX_ROLLER_FORCE] = max(
                per_rev[c, turn, MAX_ROLLER_FORCE], -f1 * ratio
            )
    if cam_held:
        per_rev[c, turn, THESIS_IMPACT_FORCE] = max(per_rev[c, turn, THESIS_IMPACT_FORCE], -f1)
    if seat_clean and seat_held:
        per_rev[c, turn, MAX_SEAT_FORCE] = max(per_rev[c, turn, MAX_SEAT_FORCE], f7)


@njit(inline="always")
def _finite(x):
    for i in range(N_X):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(**KERNEL, fastmath=FAST)
def newmark_linear_batch(cases, trains, profiles, runs, out, work, contact):
    """Advance every case of a batch; fill ``out`` (``common.Outputs``) in place.

    Parameters
    ----------
    cases : common.Cases
        A case starts at its ``t0`` (a whole number of steps before t = 0); nothing before
        t = 0 is recorded.
    trains : NewmarkTrains
    profiles : campipe.profiles.PackedProfiles
    runs : NewmarkRuns
    out : common.Outputs
        Its THESIS_IMPACT_FORCE column is the cam force including the steps an impulse
        passes through (the thesis's "impact force", which measures 1/Δt).
    work : NewmarkWork
    contact : (1,) array of CONTACT_STATE
    """
    if trains.step_A.shape[2:] != (N_X, N_Z) or trains.step_G.shape[2:] != (N_Z, N_Z):
        raise ValueError("step_A, step_G: expected (n, 4, N_X, N_Z) and (n, 4, N_Z, N_Z)")
    n_cases = cases.omega.shape[0]
    n_out = out.q.shape[1]
    n_rev = out.per_rev.shape[1]
    x, xn, z, f, qt, vt, at = work
    ct = contact[0]
    ref = by_ref((cases, trains, profiles, runs, out))
    for c in range(n_cases):
        h = runs.dt[c]
        w = cases.omega[c]
        qs = cases.seat_q[c]
        form_c = cases.form[c]
        has_seat_c = cases.has_seat[c]
        n_steps = runs.n_steps[c]
        n0 = int(np.round(cases.t0[c] / h))  # the start, a whole number of steps before 0
        out.steps[c] = n_steps - n0
        for i in range(N_X):
            x[i] = 0.0
            xn[i] = 0.0
        for i in range(NP):
            f[i] = trains.load[c, i]
            x[X_Q + i] = cases.q0[c, i]
            x[X_V + i] = cases.v0[c, i]
            x[X_A + i] = cases.a0[c, i]
        cfg = cases.cfg0[c]
        ct.rest_cam = False
        ct.rest_seat = False
        impulse_cam = False
        impulse_seat = False
        quiet_cam = 0  # steps left whose cam force measures an impulse, not the train
        quiet_seat = 0
        k_out = np.int64(0)  # not a literal: one compiled ``_write_samples`` (``common``)
        t_sample = 0.0
        rev, p, crosses = start_piece(profiles, c, w * n0 * h, cfg, w, form_c, cases.capture[c])
        if crosses:
            # The run crosses the break it starts on: the held cam's coordinate is its value
            # before the break, which the first step's impulse starts from (``_hold``).
            l_s, dl_s, _ = piece_eval(profiles, c, p, rev, w * n0 * h)
            x[X_Q + CAM] = -l_s
            x[X_V + CAM] = -w * dl_s
        th_end = w * runs.t_end[c]
        pdeg = degree(profiles, c, p)
        pn, revn, thb = next_break(profiles, c, p, rev)
        lever = ratio_bound(profiles, c) > 0.0  # its roller's force followed too
        turn = 0  # the turn of the current step, and where the next begins [s]
        t_turn = TWO_PI / w
        sd = np.sin(w * h)
        cd = np.cos(w * h)
        sn = 0.0
        cs = 1.0
        for n in range(n0, n_steps):
            t0 = n * h
            t1 = (n + 1) * h
            th1 = w * t1
            # sin θ1, cos θ1 by rotation, refreshed exactly every 256 steps.
            if (n - n0) % 256 == 0:
                sn = np.sin(th1)
                cs = np.cos(th1)
            else:
                sn, cs = sn * cd + cs * sd, cs * cd - sn * sd
            if th1 >= thb:
                p_was = p
                cfg, jumped, p, rev, pn, revn, thb = _cross_breaks(
                    ref, ct, c, w, th1, th_end, cfg, p, rev, pn, revn, thb
                )
                impulse_cam = impulse_cam or jumped
                if p != p_was:
                    pdeg = degree(profiles, c, p)
            cam_held = holds_cam(cfg)
            seat_held = holds_seat(cfg)
            qc, vc, ac = _cam(profiles, c, p, pdeg, th1 - rev * TWO_PI - profiles.breaks[c, p],
                              sn, cs, w)  # fmt: skip
            # Thesis Appendix B, steps 2–6: the held coordinates take their step-end values
            # (over an impulse's first step, its velocity change over Δt: Eq. 28); one step
            # map advances the free coordinates and gives the contact forces at the step end.
            _hold(x, cam_held, seat_held, impulse_cam, impulse_seat, qc, vc, ac, qs, h)
            _newmark_step(trains.step_A, trains.step_G, c, cfg - 1, f, h, x, xn, z)
            f1, f7 = _held_forces(x, xn, z, cam_held, seat_held)
            if impulse_cam:
                quiet_cam = 2
            if impulse_seat:
                quiet_seat = 2
            # Metrics over this step, from t = 0 on, in its turn.
            if n >= 0:
                while t0 >= t_turn * (1.0 - TURN_GUARD):
                    turn += 1
                    t_turn = (turn + 1) * TWO_PI / w
                if turn < n_rev:
                    ratio = 0.0
                    if lever and cam_held:
                        x_p = th1 - rev * TWO_PI - profiles.breaks[c, p]
                        ratio = horner(profiles.ratio[c, p], x_p, 3)[0]
                    _step_metrics(out.per_rev, c, turn, w * h, cam_held, seat_held,
                                  quiet_cam == 0, quiet_seat == 0, f1, f7, ratio)  # fmt: skip
            if quiet_cam > 0:
                quiet_cam -= 1
            if quiet_seat > 0:
                quiet_seat -= 1
            if k_out < n_out and t_sample <= t1 * (1.0 + 1e-12):
                k_out, t_sample = _write_samples(
                    ref, c, k_out, t_sample, t0, t1, h, x, xn, qt, vt, at, cfg
                )
            tripped = _tripped(
                cfg, form_c, has_seat_c, quiet_cam == 1 or quiet_seat == 1, f1, f7,
                xn[X_Q], xn[X_Q + SEAT], xn[X_V], xn[X_V + SEAT], qc, vc, qs,
            )  # fmt: skip
            if tripped[0] or tripped[1] or tripped[2] or tripped[3]:
                cfg, impulse_cam, impulse_seat = _switch(ref, ct, c, t1, cfg, f7, xn, vc, *tripped)
            else:
                impulse_cam = False
                impulse_seat = False
            x, xn = xn, x
            if ((n - n0) % 1024 == 0 or n == n_steps - 1) and not _finite(x):
                out.status[c] = NONFINITE
            if out.status[c] != OK:
                break
        if out.n_events[c] > out.events.shape[1] and out.status[c] == OK:
            out.status[c] = EVENTS_TRUNCATED
