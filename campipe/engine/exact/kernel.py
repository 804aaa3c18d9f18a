"""modal-exact's kernel: walk the grid of a segment, apply events, cross profile breaks,
and the batch loop (the package's docstring has the method and its notation)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, types

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
    block_basis,
    harmonic_response,
    monitor_envelope,
)
from campipe.engine.common import (
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
    record_event,
    start_piece,
    turn_of,
)
from campipe.engine.exact.peaks import _at_event, _force_maxima, _force_peaks, _near_peak
from campipe.engine.exact.segment import _begin_segment, monitor_count, plunger_switch
from campipe.engine.exact.state import (
    MAX_STALLED_EVENTS,
    MODE_FLOOR,
    PEAK_LEVEL,
    RESOLUTION,
    _advance,
    _at,
    _keep_column,
    _monitor_at_grid,
    _off_cam,
    _repeat_first_turn,
    _root,
    _sample,
    _slope_bound,
    _state_at,
    _turn_samples,
)
from campipe.engine.kernel_call import named_types, run_structures
from campipe.engine.metrics import (
    MAX_CAM_FORCE,
    THESIS_IMPACT_FORCE,
)
from campipe.engine.plunger import BOTTOMED, CLOSED, HELD, OPEN, TOPPED, UNLOADED
from campipe.engine.policy import release, strike, strike_at_break
from campipe.profiles.packed import piece_eval, ratio_bound
from campipe.vocabulary import (
    CAM,
    CAM_AND_SEAT,
    CAM_CONTACT,
    CHATTER,
    CHECK_VALVE_CLOSES,
    CHECK_VALVE_OPENS,
    EVENTS_TRUNCATED,
    NONFINITE,
    OK,
    PLUNGER_BOTTOMS,
    PLUNGER_TOPS,
    SEAT,
)

#: A carried plunger's event kinds, as NumPy scalars (``common``: one compile for all).
CHECK_OPENS, CHECK_CLOSES = np.int64(CHECK_VALVE_OPENS), np.int64(CHECK_VALVE_CLOSES)
BOTTOMS, TOPS = np.int64(PLUNGER_BOTTOMS), np.int64(PLUNGER_TOPS)
#: No event recorded (a carried plunger's load through 0).
NO_EVENT = np.int64(-1)

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
def _fastest_needed(WC, MC, watch, level, gval, nact, tau, n_mon, near):
    """The first column whose block could bring a watched monitor (of the first ``n_mon``)
    to its level (nact if none) up to τ after the segment start: the fastest blocks are
    skipped while their summed amplitudes (which only decay) stay under half of every
    monitor's distance from its level, and under half of ``near`` [N] (a held contact's
    force near its turn's largest, ``_near_peak``; ∞ otherwise)."""
    margin = near
    for m in range(2):
        if watch[m]:
            margin = min(margin, level[m] - gval[m])
    for m in range(2, n_mon):  # (apart: the contacts' loop of a literal length, unrolled)
        if watch[m]:
            margin = min(margin, level[m] - gval[m])
    k = 0
    spent = 0.0
    while k < nact:
        s2 = min(tau, MC[INVD, k])
        amp = 0.0
        for m in range(2):
            if watch[m]:
                amp = max(amp, monitor_envelope(WC, MC, m, k, s2))
        for m in range(2, n_mon):  # (apart, as above)
            if watch[m]:
                amp = max(amp, monitor_envelope(WC, MC, m, k, s2))
        if spent + amp >= 0.5 * margin:
            break
        spent += amp
        k += 1
    return k


@njit(inline="always", nogil=True)
def _shortest_allowed(speed_row, act, nact, dt_cap):
    """The shortest step any choice of blocks to resolve allows (``_walk``): the one of the
    fastest of the blocks 0 … nact − 1, or the step cap."""
    fastest = 0.0
    for jj in range(nact):
        fastest = max(fastest, speed_row[act[jj]])
    h_all = RESOLUTION * np.pi / fastest if fastest > 0.0 else np.inf
    if dt_cap > 0.0:
        h_all = min(h_all, dt_cap)
    return h_all


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
def _rising(watch, level, gval, dval, dprev, m):
    """Monitor m is watched and above its level at the grid point, or past a maximum inside
    the step (its derivative turned from + to −)."""
    return watch[m] and (gval[m] > level[m] or (dprev[m] > 0.0 and dval[m] < 0.0))


@njit(inline="always", nogil=True)
def _suspect(watch, level, gval, dval, dprev):
    """A contact monitor is ``_rising``: ``_earliest_crossing`` must look."""
    for m in range(2):
        if _rising(watch, level, gval, dval, dprev, m):
            return True
    return False


@njit(inline="always", nogil=True)
def _plunger_suspected(ws, n_mon, pl):
    """``_suspect`` for a carried plunger's monitors (2, 3), where the batch carries one (pl
    not None: with None numba prunes the branch on its type and compiles none of it)."""
    if pl is not None:
        for m in range(2, n_mon):
            if _rising(ws.watch, ws.level, ws.gval, ws.dval, ws.dprev, m):
                return True
    return False


@njit(inline="always", nogil=True)
def _plunger_grid(WC, MC, nact, G, GT, gdeg, w, x, cth, sth, ready, gval, dval, n_mon, pl):
    """A carried plunger's monitors (2, 3) at the grid point (``state._monitor_at_grid``),
    where the batch carries one (see ``_plunger_suspected``)."""
    if pl is not None:
        for m in range(2, n_mon):
            if ready[m]:
                gval[m], dval[m] = _monitor_at_grid(WC, MC, nact, G, GT, m, gdeg, w, x, cth, sth)


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
    for m in range(st.n_mon):
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
                tolerance, np.bool_(False), 0.0, 0.0, 0.0, gdeg,
            )  # fmt: skip
            g_hi, dg_hi = _at(False, WC, MC, nact, G, GT, m, t_s, t_max, w, th0, gdeg)
            if g_hi > level:
                t_hi = t_max
        if not np.isnan(t_hi):
            # The value root starts from what the grid (or the maximum's search) has.
            te = _root(
                np.bool_(False), 1.0, WC, MC, nact, G, GT, m, t_s, t_prev, t_hi, level, w, th0,
                tolerance, np.bool_(True), ws.gprev[m] - level, g_hi - level, dg_hi, gdeg,
            )  # fmt: skip
            if first < 0 or te < t_ev:
                t_ev = te
                first = m
    return first, t_ev


@njit(**HELPER)
def _walk(ref, st, pl):
    """Walk the segment's grid from st.t_s until an event, a profile break or the run's end,
    and handle what ended it (``_apply_event``, ``_cross_break``, or st.done).

    A helper of its own, called once a segment: inlined in the kernel (numba's IR inlining
    deep-copies an inlinee's IR block by block with its whole scope, for this helper's
    thousands of variables some 9 s of a first run's compile), it cost more compile than
    the rest of the kernel's inlining together.

    The grid step's work is inlined and makes no calls, on arrays and scalars held in locals:
    numba reference-counts a named tuple's arrays (or an array handed to an inlined helper)
    on every pass otherwise. Anything rarer (replanning with dropped pairs, a suspected
    crossing, a sample, an event, a break) is a compiled function of its own.
    """
    cases, trains, profiles, runs, out, ws = deref(ref)
    c, w, t_s, th0, t_break = st.c, st.w, st.t_s, st.th0, st.t_break
    nact, ns, gdeg, eps_force = st.nact, st.ns, st.gdeg, st.eps_force
    n_mon = monitor_count(st, pl)  # (2, a constant, where the batch carries no plunger)
    speed_row = trains.speed[st.tr, st.cfg - 1]
    cam_held = holds_cam(st.cfg)
    seat_held = holds_seat(st.cfg)
    n_out = out.q.shape[1]
    t_sample = runs.t_sample[c]
    t_end = runs.t_end[c]
    dt_cap = runs.dt_cap
    steps = out.steps
    per_rev = out.per_rev
    MC, WC, G, GT, act = ws.MC, ws.WC, ws.G, ws.GT, ws.act
    gval, dval, gprev, dprev = ws.gval, ws.dval, ws.gprev, ws.dprev
    watch, ready, level = ws.watch, ws.ready, ws.level
    peak_tol = PEAK_LEVEL * eps_force
    # A monitor already above its level at the segment start (a contact that pulls the
    # instant after an impact; a gap that closes) is an event there.
    for m in range(n_mon):
        held = cam_held if m == 0 else (seat_held if m == 1 else True)  # (2–4: a plunger's)
        if watch[m] and gval[m] > level[m] and (held or dprev[m] > 0.0):
            _apply_event(ref, st, m, t_s, pl)
            return
    # The segment's start counts for the force maxima as a grid point does (after an impact
    # the force may only fall).
    _force_maxima(per_rev, c, turn_of(w, t_s), cam_held, seat_held, gval)
    # A lever's ratio's bound (0: none): its roller force followed too, each grid step's in
    # ``_force_peaks``.
    ratio_max = ratio_bound(profiles, c)
    t_prev = t_s
    h = -1.0
    since_refresh = 0
    since_check = 0
    replan = True
    i_step = n_steps = 0
    t_from = t_next = cth = sth = cwh = swh = 0.0
    to_sample = False
    h_all = _shortest_allowed(speed_row, act, nact, dt_cap)
    while True:
        if replan:
            if since_check >= 32:
                since_check = 0
                nact = _drop_decayed(MC, WC, ws.VY, act, nact, ns, eps_force, t_prev - t_s)
                h_all = _shortest_allowed(speed_row, act, nact, dt_cap)
            # The step need only resolve the modes that could bring a watched monitor to its
            # level, or move a held force's peak by the peak tolerance (near its largest).
            t_from = t_prev
            k_out = st.k_out
            to_sample = k_out < n_out and k_out * t_sample < t_end * (1.0 + 1e-13)
            t_next = k_out * t_sample if to_sample else t_end
            if (t_next - t_from) / h_all - 1e-9 <= 1.0:
                # One step resolves every active block: which of them must be resolved
                # cannot change the step (h_allow ≥ h_all below).
                n_steps = 1
            else:
                near = np.inf
                if (cam_held and _near_peak(WC, MC, G, GT, nact, per_rev, c, w, th0, gdeg, gval,
                                            0, t_s, t_from, t_next, ratio_max)) or (
                    seat_held and _near_peak(WC, MC, G, GT, nact, per_rev, c, w, th0, gdeg,
                                             gval, 1, t_s, t_from, t_next, 0.0)
                ):  # fmt: skip
                    near = peak_tol
                k = _fastest_needed(WC, MC, watch, level, gval, nact, t_next - t_s, n_mon, near)
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
            for m in range(n_mon):
                if ready[m]:
                    gval[m], dval[m] = _at(
                        False, WC, MC, nact, G, GT, m, t_s, t_break, w, th0, gdeg
                    )
        else:
            t_eval = t_n
            x_n = w * t_n - th0
            for m in range(2):
                if ready[m]:
                    gval[m], dval[m] = _monitor_at_grid(
                        WC, MC, nact, G, GT, m, gdeg, w, x_n, cth, sth
                    )
            _plunger_grid(WC, MC, nact, G, GT, gdeg, w, x_n, cth, sth, ready, gval, dval, n_mon, pl)
        if t_eval > t_s and (
            _suspect(watch, level, gval, dval, dprev) or _plunger_suspected(ws, n_mon, pl)
        ):
            first, t_ev = _earliest_crossing(ref, st, nact, t_prev, t_eval)
            if first >= 0:
                # (A held force's peak before the event is its turn's, as on the grid.)
                _force_peaks(ref, st, nact, t_prev, t_ev, h, cam_held, seat_held, np.bool_(False))
                _at_event(ref, st, nact, t_ev, first, cam_held, seat_held)
                st.nact = nact
                _apply_event(ref, st, first, t_ev, pl)
                return
        if (cam_held and (ratio_max > 0.0 or (dprev[0] < 0.0 and dval[0] > 0.0))) or (
            seat_held and dprev[1] < 0.0 and dval[1] > 0.0
        ):
            _force_peaks(ref, st, nact, t_prev, t_eval, h, cam_held, seat_held, np.bool_(True))
        if at_break:
            # The break's point counts for the force maxima as a grid point does (a lift
            # table breaks every half degree: its steps seldom reach a grid point).
            _force_maxima(per_rev, c, turn_of(w, t_break), cam_held, seat_held, gval)
            st.nact = nact
            _cross_break(ref, st)
            return
        # Accept the grid point: force maxima, output sample, end of run.
        for m in range(2):
            dprev[m] = dval[m]
            gprev[m] = gval[m]
        for m in range(2, n_mon):  # a carried plunger's (none where n_mon is the constant 2)
            dprev[m] = dval[m]
            gprev[m] = gval[m]
        _force_maxima(per_rev, c, turn_of(w, t_n), cam_held, seat_held, gval)
        t_prev = t_n
        if i_step < n_steps:
            cth, sth = _advance(MC, nact, cth, sth, cwh, swh)
            continue
        if to_sample:
            _sample(ref, st, nact, w * t_n - th0, cth, sth)
            if out.status[c] != 0 or _repeated(out, st, trains.n_coordinates[st.tr]):
                st.done = True
                return
        if t_n >= t_end:
            _off_cam(out, st.cfg, c, w, t_s, t_n)
            st.nact = nact
            st.done = True
            return
        replan = True


@njit(inline="always", nogil=True)
def _repeated(out, st, n_coord):
    """The sample just written closes case st.c's first turn (``st.per_turn`` samples a turn,
    0: turns not sampled alike), reached in configuration I with no event, and the first
    turn repeats (``_repeat_first_turn``, which fills the later turns): the case is done."""
    c = st.c
    per_turn = st.per_turn
    if per_turn == 0 or st.k_out != per_turn + 1 or st.cfg != CAM_CONTACT:
        return False
    if out.n_events[c] != 0 or not _repeat_first_turn(out, c, per_turn, n_coord):
        return False
    st.done = True
    return True


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


@njit(inline="always", nogil=True)
def _plunger_event(ref, st, m, t_ev, pl):
    """A carried plunger's monitor m rose at t_ev [s] (2: its check valve's, or unloaded its
    load's; 3: its travel's; 4: open, its load falling through 0): the regime it leads to
    (``engine.plunger.SWITCHES``), recorded as an event of velocity 0 with the plunger's u
    there in the impulse field (which ``lash_adjuster`` reads for each turn's leak-down and
    pump-up, and clears); the load's switches, through which the plunger keeps rising, are
    not recorded. Nothing compiled for a batch with no carried plunger (pl None: numba prunes
    the branch)."""
    if pl is not None:
        _, _, _, runs, out, ws = deref(ref)
        reg = st.reg
        kind = NO_EVENT
        if reg == CLOSED:
            new, kind = (OPEN, CHECK_OPENS) if m == 2 else (BOTTOMED, BOTTOMS)
        elif reg == OPEN:
            if m == 4:
                new = UNLOADED
            else:
                new, kind = (CLOSED, CHECK_CLOSES) if m == 2 else (TOPPED, TOPS)
        elif reg == UNLOADED:
            if m == 2:
                new = OPEN
            else:
                new, kind = TOPPED, TOPS
        elif reg == BOTTOMED:
            new, kind = OPEN, CHECK_OPENS
        else:
            new, kind = CLOSED, CHECK_CLOSES
        if kind != NO_EVENT:
            c = st.c
            u = ws.q[runs.plunger_coord[c]]
            record_event(out.events, out.n_events, c, t_ev, kind, st.cfg, st.cfg, 0.0, u)
        plunger_switch(ref, st, new)


@njit(**HELPER)
def _apply_event(ref, st, first, t_ev, pl):
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
    if first >= 2:
        _plunger_event(ref, st, first, t_ev, pl)
    elif first == 0 and cam_held:
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
def _start_case(cases, trains, profiles, runs, ws, st, c, tr):
    """Case c's run from its start state at t0 ≤ 0, with the harmonic responses of the
    configurations that hold the cam (III only with a seat)."""
    st.c = c
    st.tr = tr
    st.w = cases.omega[c]
    carried = runs.plunger_coord[c] >= 0
    st.n_mon = 5 if carried else 2
    st.reg = HELD if carried else -1
    harmonic_response(trains, runs, ws, st, CAM_CONTACT - 1)
    if cases.has_seat[c]:
        harmonic_response(trains, runs, ws, st, CAM_AND_SEAT - 1)
    st.eps_force = 1e-9 * (abs(trains.load[tr, 3]) + 1.0)
    for i in range(trains.n_coordinates[tr]):
        ws.q[i] = cases.q0[c, i]
        ws.v[i] = cases.v0[c, i]
    st.cfg = cases.cfg0[c]
    st.t_s = cases.t0[c]
    rev, p, _ = start_piece(
        profiles, c, st.w * st.t_s, st.cfg, st.w, cases.form[c], cases.capture[c]
    )
    st.rev = rev
    st.p = p
    st.k_out = 0
    st.stalled = 0
    st.done = False
    st.rest_cam = False
    st.rest_seat = False
    st.bounced_cam = -np.inf
    st.bounced_seat = -np.inf


@njit(**KERNEL)
def modal_exact_batch(cases, trains, profiles, runs, out, ws, state, pl):
    """Advance every case of a batch exactly between events; fill ``out`` in place.

    Parameters
    ----------
    cases, trains, profiles, runs, out, ws
        Each as the plain tuple of its fields (``kernel_call.plain``), named on entry.
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
    pl : (n,) int64 array or None
        The cases' plunger coordinates (``runs.plunger_coord``) if any case carries a lash
        adjuster's plunger (``engine.plunger_modes``); None otherwise, for which numba prunes
        every branch of the plunger's code (``if pl is not None``) and compiles none of it:
        the batches of every other train run a kernel without it.
    """
    cases, trains, profiles, runs, out, ws = run_structures(cases, trains, profiles, runs, out, ws)
    st = state[0]
    ref = by_ref((cases, trains, profiles, runs, out, ws))
    for c in range(cases.omega.shape[0]):
        _start_case(cases, trains, profiles, runs, ws, st, c, runs.train[c])
        st.per_turn = _turn_samples(st.w, runs.t_sample[c], out.q.shape[1], out.per_rev.shape[1])
        while not st.done:
            _begin_segment(ref, st, pl)
            # (A segment may begin on the sample that closes the first turn.)
            if not _repeated(out, st, trains.n_coordinates[st.tr]):
                _walk(ref, st, pl)
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
    *tuples, state, pl = named_types(kernel_types)  # as the kernel names its plain tuples
    ref = types.CPointer(types.BaseTuple.from_types(tuples))  # the kernel's ``by_ref``
    st = state.dtype  # the kernel's ``state[0]``
    i8, f8 = types.int64, types.float64
    return {
        _sample: (ref, st, i8, f8, f8, f8),
        _apply_event: (ref, st, i8, f8, pl),
        _earliest_crossing: (ref, st, i8, f8, f8),
    }
