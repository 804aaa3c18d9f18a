"""The closed forms modal-exact and the periodic steady state share: the data they take, the
forcing and particular solution on a piece of the profile, and the blocks' basis functions.

See ``campipe.engine.modal`` for the equations and ``campipe.engine.exact`` for the notation.
"""

from __future__ import annotations

import threading
from typing import NamedTuple

import numpy as np
from numba import njit

from campipe.engine.common import HELPER, holds_cam, holds_seat
from campipe.engine.modal import ModalData, pad_stack
from campipe.profiles.packed import degree, horner
from campipe.vocabulary import N_COORDINATES

# Rows of the per-block work array ``MC`` (one column per active block, fastest first): the
# basis functions (f1, f2) at the current grid point, their values at the grid step h (the
# step's factors), the envelope e^{rate·τ} and its step factor, the block's largest share of a
# coordinate or velocity (with f1, with f2) and of the contact forces (likewise) at the segment
# start, and the block's constants λ̄, δ², 1/|δ| (inf at δ = 0) and slowest rate.
# Then the block's coefficients of f1 and f2 in the time derivative of the cam's and the seat's
# velocity rows: their accelerations where free (``exact.segment._block_columns``).
F1, F2, D1, D2, EABS, DABS, AMP_QA, AMP_QB, AMP_FA, AMP_FB, LBAR, DSQ, INVD, RATE = range(14)
ACC_CAM1, ACC_CAM2, ACC_SEAT1, ACC_SEAT2 = range(14, 18)
N_MC = 18
# Rows of the monitor coefficients ``WC`` (row, monitor, block): the coefficients of f1 and f2
# in the monitor, in its time derivative and in its second derivative, then |W1|, |W2|,
# |WL1|, |WL2|.
W1, W2, WL1, WL2, WLL1, WLL2, W1_ABS, W2_ABS, WL1_ABS, WL2_ABS = range(10)
N_WC = 10
#: Monitors: 0 the cam's, 1 the seat's; 2, 3 and 4 a carried plunger's (its check valve, or
#: its load rising through 0 unloaded; its travel; its load falling through 0 open), watched
#: only where a case has one (``STATE.n_mon``).
N_MON = 5
#: A carried plunger's regimes (``engine.plunger``: CLOSED … UNLOADED), a train row each.
N_REGIMES = 6
#: Rows of the particular solution's polynomial Z (and of the monitors' G): degree up to
#: Z_ROWS − 1, the forcing's 7 and a slow block's series (``particular``) beyond it.
Z_ROWS = 33
#: A slow block's series ends where a term over its piece is below this share of the
#: largest (``_slow_series``).
SERIES_EPS = 1e-18


class ModalTrains(NamedTuple):
    """The distinct trains of a batch: preload and ``modal.ModalData`` per configuration
    (leading axes (n_trains, 4); see ``modal.ModalData`` for each field)."""

    load: np.ndarray  # (n_trains, n) preload [N] (n: the batch's most coordinates, 0-padded)
    n_coordinates: np.ndarray  # (n_trains,) int: each train's coordinates (7: the thesis's)
    n_free: np.ndarray
    free: np.ndarray
    a_mat: np.ndarray
    a_inv: np.ndarray
    slow: np.ndarray
    any_slow: np.ndarray
    b_in: np.ndarray
    b_load: np.ndarray
    rho: np.ndarray
    sigma: np.ndarray
    sigma0: np.ndarray
    impulse: np.ndarray
    n_blocks: np.ndarray
    bstart: np.ndarray
    bdim: np.ndarray
    lam_bar: np.ndarray
    delta2: np.ndarray
    rate: np.ndarray
    speed: np.ndarray
    basis: np.ndarray
    basis_inv: np.ndarray
    basis_n: np.ndarray
    block_n: np.ndarray
    rho_x: np.ndarray
    rho_xn: np.ndarray


def stack_trains(data: list[ModalData], loads: list[np.ndarray]) -> ModalTrains:
    """The kernels' ``ModalTrains`` of a batch's distinct trains (their ``modal.ModalData``
    and preload vectors), each padded to the batch's most coordinates (``modal.pad_stack``):
    a train of the thesis's seven coordinates keeps its numbers whatever it is batched with."""
    fields = {
        f: pad_stack([getattr(d, f) for d in data], -1 if f == "free" else 0)
        for f in ModalTrains._fields
        if f not in ("load", "n_coordinates")
    }
    return ModalTrains(
        load=pad_stack(loads),
        n_coordinates=np.array([d.free.shape[1] for d in data], np.int64),
        **fields,
    )


class ExactRuns(NamedTuple):
    """How each case is run: its train, sampling, end, harmonic responses, and the settings
    shared by the batch."""

    train: np.ndarray  # (n,) int64 index into ModalTrains
    t_sample: np.ndarray  # (n,) output spacing in time [s]
    t_end: np.ndarray  # (n,) the run's end [s]
    zeta: np.ndarray  # (n, 4, ns) complex ``modal.harmonic_responses`` at the case's speed
    dt_cap: float  # largest step [s]; 0: none
    tolerance: float  # event-time tolerance [s]
    full_state: bool  # sample every coordinate (else q1 and q7 only)
    #: A chain's lash adjuster's plunger carried as a coordinate (``plunger_modes``), per
    #: case (−1 / 0 rows without one): its coordinate, the train row of each regime
    #: (``plunger.CLOSED`` … ``UNLOADED``), the force through it as a row over the coordinates
    #: (F = row·q), its check force, its damper per regime (inf: held) and where each held
    #: regime holds it (NaN: not held)
    plunger_coord: np.ndarray  # (n,) int64
    plunger_train: np.ndarray  # (n, 6) int64
    plunger_force: np.ndarray  # (n, n_q) [N/m]
    plunger_check: np.ndarray  # (n,) [N]
    plunger_damper: np.ndarray  # (n, 6) [N·s/m]
    plunger_end: np.ndarray  # (n, 6) [m]


def no_plungers(n: int, n_q: int) -> dict[str, np.ndarray]:
    """``ExactRuns``' plunger fields of ``n`` cases without a carried plunger (``n_q`` the
    batch's most coordinates)."""
    return {
        "plunger_coord": np.full(n, -1, np.int64),
        "plunger_train": np.full((n, N_REGIMES), -1, np.int64),
        "plunger_force": np.zeros((n, n_q)),
        "plunger_check": np.zeros(n),
        "plunger_damper": np.full((n, N_REGIMES), np.inf),
        "plunger_end": np.full((n, N_REGIMES), np.nan),
    }


class Workspace(NamedTuple):
    """Work arrays of one case's segment, allocated once per batch (``make_workspace``) for
    the batch's most coordinates n and largest state ns = 2n (``modal.NS`` for the thesis's
    train)."""

    q: np.ndarray  # (n,) coordinates at the segment start / an event [m, rad]
    v: np.ndarray  # (n,) velocities
    z: np.ndarray  # (ns,) a state z
    zh: np.ndarray  # (ns,) the homogeneous part at the segment start
    zb: np.ndarray  # (ns,) scratch
    Z: np.ndarray  # (Z_ROWS, ns) polynomial particular solution Z_k (row k)
    ZT: np.ndarray  # (ns,) complex harmonic particular solution Z_T
    bpoly: np.ndarray  # (8, ns) the forcing's polynomial coefficients b_k
    u: np.ndarray  # (ns,) the state's homogeneous part in the blocks' basis at t_s: X⁻¹ zh
    act: np.ndarray  # (ns,) int64 the block of each active column
    MC: np.ndarray  # (N_MC, ns) per-block work, rows F1 … ACC_SEAT2
    WC: np.ndarray  # (N_WC, N_MON, ns) monitor coefficients per block, rows W1 … WL2_ABS
    VY: np.ndarray  # (2, ns, ns) the state's coefficients of f1 and f2: X_b u_b, X_b N_b u_b
    gval: np.ndarray  # (N_MON,) monitors at the latest point
    dval: np.ndarray  # (N_MON,) their time derivatives
    gprev: np.ndarray  # (N_MON,) monitors at the previous grid point
    dprev: np.ndarray  # (N_MON,) their time derivatives
    G: np.ndarray  # (N_MON, Z_ROWS) monitors' polynomial part G_mk
    GT: np.ndarray  # (N_MON,) complex monitors' harmonic part
    ready: np.ndarray  # (N_MON,) bool: monitor prepared (its value is computed)
    watch: np.ndarray  # (N_MON,) bool: monitor can end the segment
    level: np.ndarray  # (N_MON,) the level each monitor rises through at an event
    #: (2, n) a plunger's monitors (2: its check valve, 3: its travel) as rows over the
    #: coordinates: g = row·q (``segment._plunger_monitors``)
    prow: np.ndarray
    inp: np.ndarray  # (3, 2, 8) held coordinates' (q, q̇, q̈) polynomials in x
    inp_t: np.ndarray  # (3, 2) complex held coordinates' harmonic parts
    cm: np.ndarray  # (ns, ns) complex (iωI − A), eliminated (``harmonic_response``)


def _workspace_layout(n_coordinates: int) -> dict[str, tuple[tuple[int, ...], type]]:
    """Each work array's shape and type, for trains of up to ``n_coordinates`` coordinates."""
    n, ns = n_coordinates, 2 * n_coordinates
    f8, c16, i8, b1 = np.float64, np.complex128, np.int64, np.bool_
    shapes = {
        "q": ((n,), f8), "v": ((n,), f8), "z": ((ns,), f8), "zh": ((ns,), f8),
        "zb": ((ns,), f8), "Z": ((Z_ROWS, ns), f8), "ZT": ((ns,), c16), "bpoly": ((8, ns), f8),
        "u": ((ns,), f8), "act": ((ns,), i8), "MC": ((N_MC, ns), f8),
        "WC": ((N_WC, N_MON, ns), f8), "VY": ((2, ns, ns), f8), "gval": ((N_MON,), f8),
        "dval": ((N_MON,), f8), "gprev": ((N_MON,), f8), "dprev": ((N_MON,), f8),
        "G": ((N_MON, Z_ROWS), f8), "GT": ((N_MON,), c16), "ready": ((N_MON,), b1),
        "watch": ((N_MON,), b1), "level": ((N_MON,), f8), "prow": ((3, n), f8),
        "inp": ((3, 2, 8), f8), "inp_t": ((3, 2), c16), "cm": ((ns, ns), c16),
    }  # fmt: skip
    return {name: shapes[name] for name in Workspace._fields}


#: Each thread's workspaces by size: (the memory they share, the workspace).
_WORKSPACES = threading.local()


def make_workspace(n_coordinates: int = N_COORDINATES) -> Workspace:
    """A zeroed workspace for trains of up to ``n_coordinates`` coordinates.

    One per thread and size, its arrays views of one block that is cleared at each call
    (instead of two dozen arrays allocated a call: a tenth of a one-case run's overhead). A
    kernel's workspace is scratch for that call only: a second call on the same thread clears
    it again."""
    held = _WORKSPACES.__dict__.setdefault("by_size", {})
    if n_coordinates not in held:
        layout = _workspace_layout(n_coordinates)
        sizes = [int(np.prod(shape)) * np.dtype(t).itemsize for shape, t in layout.values()]
        spans = [-(-size // 64) * 64 for size in sizes]  # each array on its own cache line
        memory = np.zeros(sum(spans) + 64, np.uint8)
        base = -memory.ctypes.data % 64
        arrays: dict[str, np.ndarray] = {}
        for (name, (shape, t)), size, span in zip(layout.items(), sizes, spans, strict=True):
            arrays[name] = memory[base : base + size].view(t).reshape(shape)
            base += span
        held[n_coordinates] = (memory, Workspace(**arrays))
    memory, ws = held[n_coordinates]
    memory.fill(0)
    return ws


#: The scalars of one case's run and of its current segment (a record, so the steps below
#: share them by name).
STATE = np.dtype(
    [
        ("c", "i8"),  # the case
        ("tr", "i8"),  # its train
        ("w", "f8"),  # its speed ω [rad/s]
        ("eps_force", "f8"),  # force monitors' level [N]
        ("cfg", "i8"),  # configuration
        ("p", "i8"),  # piece of the profile, of turn ``rev``
        ("rev", "i8"),
        ("t_s", "f8"),  # segment start [s]
        ("th0", "f8"),  # cam angle where the piece starts [rad]
        ("nb", "i8"),  # the next piece, of turn ``revb``, starting at ``t_break`` [s]
        ("revb", "i8"),
        ("t_break", "f8"),
        ("nf", "i8"),  # free coordinates; the state has ns = 2·nf entries
        ("ns", "i8"),
        ("kmax", "i8"),  # degree of the held inputs' polynomials
        ("deg", "i8"),  # degree of the particular solution's polynomial
        ("pdeg", "i8"),  # degree of the piece's polynomial (``profiles.packed.degree``)
        ("gdeg", "i8"),  # degree of the monitors' polynomials
        ("nact", "i8"),  # active block columns
        ("k_out", "i8"),  # the next output sample
        ("per_turn", "i8"),  # samples a turn when every turn is sampled alike, else 0
        ("stalled", "i8"),  # events in a row without time advancing
        ("done", "?"),  # the run reached its end
        # Resting contact: a contact captured by a slow impact (``common.captured``), whose
        # force may hover about zero: it releases at ``common.RESTING_LEVEL`` of the level.
        ("rest_cam", "?"),
        ("rest_seat", "?"),
        # Restitution: when the follower (the valve) last bounced off the cam (the seat) [s];
        # −inf: not since the case began.
        ("bounced_cam", "f8"),
        ("bounced_seat", "f8"),
        ("n_mon", "i8"),  # monitors the case watches: 2, or 5 with a carried plunger
        ("reg", "i8"),  # a carried plunger's regime (``plunger.CLOSED`` …), −1 without one
    ],
    align=True,
)


def make_state() -> np.ndarray:
    """A zeroed (1,) record of ``STATE`` for a kernel's call: one per thread, cleared at each
    call as ``make_workspace``'s (``np.zeros`` of a record type costs a microsecond, twice a
    ``run_batch`` call; clearing its bytes a tenth of that)."""
    held = _WORKSPACES.__dict__.get("state")
    if held is None:
        record = np.zeros(1, STATE)
        held = _WORKSPACES.state = (record, record.view(np.uint8))
    record, raw = held
    raw.fill(0)
    return record


@njit(**HELPER)
def held_inputs(poly, trig, c, p, w, seat_q, cam_held, seat_held, inp, inp_t):
    """Held coordinates' (q, q̇, q̈) as polynomials in the piece's local angle x (inp, shape
    (3, 2, 8)) and harmonic parts Re(inp_t·e^{iθ}) (inp_t (3, 2) complex), from the packed
    profiles' ``poly`` and ``trig`` (arrays, not the named tuple: ``common.by_ref``)."""
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


@njit(inline="always", nogil=True)
def block_basis(lbar, d2, tau):
    """The block's basis functions f1 = e^{λ̄τ}·C(τ) and f2 = e^{λ̄τ}·S(τ) (``modal``): C, S
    from cos, sin (δ² < 0), cosh, sinh (δ² > 0, as two exponentials, which cannot overflow on a
    decaying block) or the Jordan limit 1, τ, by series where δτ is small."""
    e = np.exp(lbar * tau)
    if d2 < 0.0:
        nu = np.sqrt(-d2)
        x = nu * tau
        if x > 1e-3:
            return e * np.cos(x), e * np.sin(x) / nu
        x2 = x * x
        return e * (1.0 - x2 / 2.0 + x2 * x2 / 24.0), e * tau * (1.0 - x2 / 6.0 + x2 * x2 / 120.0)
    if d2 > 0.0:
        d = np.sqrt(d2)
        x = d * tau
        if x > 1e-3:
            ep = np.exp((lbar + d) * tau)
            em = np.exp((lbar - d) * tau)
            return 0.5 * (ep + em), 0.5 * (ep - em) / d
        x2 = x * x
        return e * (1.0 + x2 / 2.0 + x2 * x2 / 24.0), e * tau * (1.0 + x2 / 6.0 + x2 * x2 / 120.0)
    return e, e * tau


@njit(inline="always", nogil=True)
def forcing(cases, trains, profiles, ws, st):
    """The held inputs on the segment's piece (ws.inp, ws.inp_t) and the forcing's polynomial
    coefficients b_k (ws.bpoly) in the segment's configuration; sets st.kmax and st.deg."""
    c, tr, ci, ns = st.c, st.tr, st.cfg - 1, st.ns
    cam_held = holds_cam(st.cfg)
    held_inputs(
        profiles.poly, profiles.trig, c, st.p, st.w, cases.seat_q[c], cam_held,
        holds_seat(st.cfg), ws.inp, ws.inp_t,
    )  # fmt: skip
    # The held inputs are polynomials of the piece's degree at most (the seat's a constant),
    # and so is the forcing.
    kmax = degree(profiles, c, st.p) if cam_held else 0
    deg = 0
    for k in range(kmax + 1):
        for s in range(ns):
            acc = trains.b_load[tr, ci, s] if k == 0 else 0.0
            for kind in range(3):
                for hc in range(2):
                    acc += trains.b_in[tr, ci, s, kind, hc] * ws.inp[kind, hc, k]
            ws.bpoly[k, s] = acc
            if acc != 0.0:
                deg = k
    st.kmax = kmax
    st.deg = deg


@njit(inline="always", nogil=True)
def harmonic_response(trains, runs, ws, st, ci):
    """ζ of configuration ``ci`` (0: I, 2: III; the cam held) at case st.c's speed ω, written
    to ``runs.zeta[c, ci]``: (iωI − A) ζ = −b_q − iω b_v + ω² b_a (``modal.harmonic_responses``,
    the same equation through numpy), by Gaussian elimination with partial pivoting, as
    LAPACK's zgesv (unblocked): 1e-14 of ζ on the thesis's train, where the block form
    X (iωI − B)⁻¹ X⁻¹ loses 5e-12 to its basis. Uses ws.cm and ws.ZT as scratch."""
    tr, w = st.tr, st.w
    ns = 2 * trains.n_free[tr, ci]
    m = ws.cm
    y = ws.ZT
    for i in range(ns):
        for j in range(ns):
            m[i, j] = -trains.a_mat[tr, ci, i, j]
        m[i, i] += 1j * w
        b = trains.b_in[tr, ci, i]
        y[i] = -b[0, 0] - 1j * w * b[1, 0] + w * w * b[2, 0]
    for k in range(ns):
        p = k
        for i in range(k + 1, ns):
            if abs(m[i, k]) > abs(m[p, k]):
                p = i
        if p != k:
            for j in range(ns):
                m[k, j], m[p, j] = m[p, j], m[k, j]
            y[k], y[p] = y[p], y[k]
        for i in range(k + 1, ns):
            f = m[i, k] / m[k, k]
            for j in range(k + 1, ns):
                m[i, j] -= f * m[k, j]
            y[i] -= f * y[k]
    for i in range(ns - 1, -1, -1):
        acc = y[i]
        for j in range(i + 1, ns):
            acc -= m[i, j] * y[j]
        y[i] = acc / m[i, i]
    for s in range(runs.zeta.shape[2]):
        runs.zeta[st.c, ci, s] = y[s] if s < ns else 0.0


@njit(inline="always", nogil=True)
def particular(trains, profiles, runs, ws, st):
    """Particular solutions: Z_k = A⁻¹(ω(k+1) Z_{k+1} − b_k) from the forcing's degree down;
    the harmonic one Z_T = β·ζ (``modal.harmonic_responses``). A slow block's part
    (``modal.SLOW_RATE``; A⁻¹ then the fast blocks' inverse) is ``_slow_series``', which
    raises st.deg."""
    tr, ci, ns, deg, w = st.tr, st.cfg - 1, st.ns, st.deg, st.w
    Z = ws.Z
    for k in range(deg + 1, 9):
        for s in range(ns):
            Z[k, s] = 0.0
    for k in range(deg, -1, -1):
        for s in range(ns):
            ws.zb[s] = w * (k + 1) * Z[k + 1, s] - ws.bpoly[k, s]
        for s in range(ns):
            acc = 0.0
            for j in range(ns):
                acc += trains.a_inv[tr, ci, s, j] * ws.zb[j]
            Z[k, s] = acc
    if trains.any_slow[tr, ci]:
        span = profiles.breaks[st.c, st.p + 1] - profiles.breaks[st.c, st.p]
        _slow_series(
            trains.slow[tr, ci], trains.bstart[tr, ci], trains.bdim[tr, ci],
            trains.lam_bar[tr, ci], trains.block_n[tr, ci], trains.basis_inv[tr, ci],
            trains.basis[tr, ci], trains.n_blocks[tr, ci], span, ws.Z, ws.bpoly, st,
        )  # fmt: skip
    c, p = st.c, st.p
    trig = profiles.trig
    has_trig = holds_cam(st.cfg) and (trig[c, p, 0] != 0.0 or trig[c, p, 1] != 0.0)
    beta = trig[c, p, 1] - 1j * trig[c, p, 0]
    for s in range(ws.ZT.shape[0]):
        ws.ZT[s] = beta * runs.zeta[c, ci, s] if has_trig else 0.0


@njit(**HELPER)
def _slow_series(slow, bstart, bdim, lam_bar, block_n, basis_inv, basis, n_blocks, span, Z,
                 bpoly, st):  # fmt: skip
    """The slow blocks' part of the particular solution, added to Z. In block b's
    coordinates y (z = X_b·y + …) the forcing's share β_k = (X⁻¹ b_k)_b drives
    ẏ = B_b·y + Σ β_k x^k (x = ωt − θ₀); with Y_0 = 0, Y_{k+1} = (B_b·Y_k + β_k)/(ω(k+1))
    is a solution (the homogeneous part takes the rest of the start), a series whose terms
    shrink as (|λ|·x/ω)^k/k! where A⁻¹'s recursion would grow as (ω/|λ|)^k: summed until a
    term over the piece (of ``span`` [rad]) is below rounding (SERIES_EPS of the largest),
    to degree Z_ROWS − 1 at most. The train's blocks in its configuration as arrays (compiled
    apart: only a slow block runs it, and no named tuple crosses by value)."""
    ns, deg, w = st.ns, st.deg, st.w
    top = deg
    for k in range(deg + 1, Z.shape[0]):
        for s in range(ns):
            Z[k, s] = 0.0
    for b in range(n_blocks):
        if not slow[b]:
            continue
        i0 = bstart[b]
        two = bdim[b] == 2
        i1 = i0 + 1 if two else i0
        lbar = lam_bar[b]
        n00 = block_n[i0, i0]
        n01 = block_n[i0, i1] if two else 0.0
        n10 = block_n[i1, i0] if two else 0.0
        n11 = block_n[i1, i1] if two else 0.0
        y0 = 0.0
        y1 = 0.0
        largest = 0.0
        for k in range(Z.shape[0] - 1):
            b0 = 0.0
            b1 = 0.0
            if k <= deg:
                for s in range(ns):
                    b0 += basis_inv[i0, s] * bpoly[k, s]
                    if two:
                        b1 += basis_inv[i1, s] * bpoly[k, s]
            f = 1.0 / (w * (k + 1))
            y0, y1 = (
                (lbar * y0 + n00 * y0 + n01 * y1 + b0) * f,
                (lbar * y1 + n10 * y0 + n11 * y1 + b1) * f if two else 0.0,
            )
            term = (abs(y0) + abs(y1)) * span ** (k + 1)
            largest = max(largest, term)
            if k >= deg and term <= SERIES_EPS * largest:
                break
            for s in range(ns):
                Z[k + 1, s] += basis[s, i0] * y0
                if two:
                    Z[k + 1, s] += basis[s, i1] * y1
            top = max(top, k + 1)
    st.deg = top


@njit(inline="always", nogil=True)
def block_derivative(w1, w2, lbar, d2):
    """The coefficients of f1 and f2 in d/dτ (w1·f1 + w2·f2): f1' = λ̄f1 + δ²f2, f2' = λ̄f2 + f1."""
    return lbar * w1 + w2, d2 * w1 + lbar * w2


@njit(inline="always", nogil=True)
def monitor_envelope(WC, MC, m, jj, s2):
    """The most block column jj adds to monitor m from where its envelope ``MC[EABS]`` is, up
    to τ after the segment start, ``s2`` = min(τ, MC[INVD, jj]) (a defective block's secular
    term grows until 1/δ)."""
    return (WC[W1_ABS, m, jj] + WC[W2_ABS, m, jj] * s2) * MC[EABS, jj]


@njit(**HELPER)
def eval_monitor(WC, MC, nact, G, GT, m, tau, w, x, th, gdeg):
    """Monitor m and its first two time derivatives τ after the segment start (local angle x,
    cam angle θ), exactly: the active blocks, the polynomial (of degree gdeg) and the harmonic
    part."""
    g = 0.0
    dg = 0.0
    d2g = 0.0
    for jj in range(nact):
        f1, f2 = block_basis(MC[LBAR, jj], MC[DSQ, jj], tau)
        g += WC[W1, m, jj] * f1 + WC[W2, m, jj] * f2
        dg += WC[WL1, m, jj] * f1 + WC[WL2, m, jj] * f2
        d2g += WC[WLL1, m, jj] * f1 + WC[WLL2, m, jj] * f2
    p0, p1, p2 = horner(G[m], x, gdeg)
    g += p0
    dg += w * p1
    d2g += w * w * p2
    if GT[m] != 0.0:
        ct = np.cos(th)
        sn = np.sin(th)
        g += GT[m].real * ct - GT[m].imag * sn
        dg -= w * (GT[m].real * sn + GT[m].imag * ct)
        d2g -= w * w * (GT[m].real * ct - GT[m].imag * sn)
    return g, dg, d2g


@njit(inline="always", nogil=True)
def force_monitor(trains, ws, st, m, sign, level):
    """Monitor m as a held contact's force (sign·F: F1 for the cam, −F7 for the seat):
    thesis Eqs. 26, 27 through ``modal.ModalData``'s ρ, σ; its forced part (the blocks' part
    is ``exact._block_columns``')."""
    tr, ci, ns = st.tr, st.cfg - 1, st.ns
    ws.level[m] = level
    for k in range(max(st.kmax, st.deg) + 1):  # (a slow block's series beyond the inputs')
        acc = 0.0
        for s in range(ns):
            acc += trains.rho[tr, ci, m, s] * ws.Z[k, s]
        if k <= st.kmax:
            for kind in range(3):
                for hc in range(2):
                    acc += trains.sigma[tr, ci, m, kind, hc] * ws.inp[kind, hc, k]
        ws.G[m, k] = sign * acc
    ws.G[m, 0] += sign * trains.sigma0[tr, ci, m]
    acc_c = 0.0 + 0.0j
    for s in range(ns):
        acc_c += trains.rho[tr, ci, m, s] * ws.ZT[s]
    for kind in range(3):
        acc_c += trains.sigma[tr, ci, m, kind, 0] * ws.inp_t[kind, 0]
    ws.GT[m] = sign * acc_c
