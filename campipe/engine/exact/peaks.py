"""modal-exact's contact-force maxima: each turn's largest held force at the grid's points and
at the peaks between them, located by Newton steps on the force's derivative where a peak may
be the turn's largest, and the rule that keeps the grid fine enough there (docs/engine.md,
"Force maxima are peaks, not samples"). A lever layout's roller force on the cam, the cam's
held force times the lever ratio r(θ) (``profiles.ratio``, a cubic on each piece), is
followed the same way into its own column (``MAX_ROLLER_FORCE``)."""

from __future__ import annotations

import numpy as np
from numba import njit

from campipe.engine.closed_form import DABS, INVD, eval_monitor, monitor_envelope
from campipe.engine.common import HELPER, deref, turn_of
from campipe.engine.exact.state import ROOT_ITERATIONS, _at
from campipe.engine.metrics import MAX_CAM_FORCE, MAX_ROLLER_FORCE, MAX_SEAT_FORCE
from campipe.profiles.packed import horner, ratio_bound


@njit(inline="always", nogil=True)
def _force_maxima(per_rev, c, turn, cam_held, seat_held, gval):
    """The held contacts' forces (monitors ``gval``) into the turn's force maxima (a lever's
    roller force: ``_force_peaks``, off the grid's step)."""
    if 0 <= turn < per_rev.shape[1]:
        if cam_held:
            per_rev[c, turn, MAX_CAM_FORCE] = max(per_rev[c, turn, MAX_CAM_FORCE], -gval[0])
        if seat_held:
            per_rev[c, turn, MAX_SEAT_FORCE] = max(per_rev[c, turn, MAX_SEAT_FORCE], -gval[1])


@njit(inline="always", nogil=True)
def _roller_maximum(per_rev, c, w, t, force):
    """A lever's roller force [N] at t [s] into its turn's largest."""
    turn = turn_of(w, t)
    if 0 <= turn < per_rev.shape[1]:
        per_rev[c, turn, MAX_ROLLER_FORCE] = max(per_rev[c, turn, MAX_ROLLER_FORCE], force)


@njit(**HELPER)
def _at_event(ref, st, nact, t_ev, first, cam_held, seat_held):
    """The held contacts' forces at the instant t_ev [s] of monitor ``first``'s event, an
    impact, before its impulse, into the turn's force maxima: a force that rises until an
    impact elsewhere (the cam's as the valve strikes its seat) is largest there, at its
    segment's end, where no turn of its derivative marks a peak. Nothing for any other event
    (a release, a plunger's switch): the forces do not jump there, and the next segment's
    start counts them."""
    if not ((first == 0 and not cam_held) or (first == 1 and not seat_held)):
        return
    _, _, profiles, _, out, ws = deref(ref)
    c, w, th0 = st.c, st.w, st.th0
    g0 = g1 = 0.0
    if cam_held:
        g0 = _at(False, ws.WC, ws.MC, nact, ws.G, ws.GT, np.int64(0), st.t_s, t_ev, w, th0,
                 st.gdeg)[0]  # fmt: skip
    if seat_held:
        g1 = _at(False, ws.WC, ws.MC, nact, ws.G, ws.GT, np.int64(1), st.t_s, t_ev, w, th0,
                 st.gdeg)[0]  # fmt: skip
    _force_maxima(out.per_rev, c, turn_of(w, t_ev), cam_held, seat_held, (g0, g1))
    if cam_held and ratio_bound(profiles, c) > 0.0:
        r = horner(profiles.ratio[c, st.p], w * t_ev - th0, 3)[0]
        _roller_maximum(out.per_rev, c, w, t_ev, -g0 * r)


@njit(inline="always", nogil=True)
def _ringing(WC, MC, nact, m, tau, back):
    """The most the blocks 0 … nact − 1 add to monitor m up to τ after the segment start from
    where their envelopes are (with ``back``, from a grid step before: the envelopes, which
    only decay, divided by the step's decay)."""
    amp = 0.0
    for jj in range(nact):
        a = monitor_envelope(WC, MC, m, jj, min(tau, MC[INVD, jj]))
        if back:  # (a block that decays past the floating point in a step: no bound)
            a = a / MC[DABS, jj] if MC[DABS, jj] > 0.0 else np.inf
        amp += a
    return amp


@njit(inline="always", nogil=True)
def _so_far(per_rev, c, w, t_a, t_b, col):
    """The least of the running maxima in per-turn column ``col`` (a held force's: the
    cam's, the seat's, a lever's roller's) in the turns holding t_a and t_b."""
    n_rev = per_rev.shape[1]
    so_far = np.inf
    for turn in (turn_of(w, t_a), turn_of(w, t_b)):
        if 0 <= turn < n_rev:
            so_far = min(so_far, per_rev[c, turn, col])
    return so_far


@njit(inline="always", nogil=True)
def _above(f_a, f_b, ring, w, h, so_far):
    """A held force ending an interval of length h [s] at f_a and f_b [N], its blocks adding
    at most ``ring`` [N], may exceed ``so_far`` inside it: by at most twice the blocks'
    amplitudes plus its forced part's bulge, taken as 8·(ωh)² of the force (a forced part up
    to the cam's eighth harmonic)."""
    end = max(f_a, f_b)
    return end + 2.0 * ring + 8.0 * (w * h) ** 2 * abs(end) >= so_far


@njit(inline="always", nogil=True)
def _near_peak(WC, MC, G, GT, nact, per_rev, c, w, th0, gdeg, gval, m, t_s, t_from, t_next,
               ratio_max):  # fmt: skip
    """Held contact m's force may exceed its turn's largest so far between the grid's plan
    from t_from (its force −gval[m], the blocks' envelopes there) to t_next, where its forced
    part ends at −(polynomial + harmonic), in the segment from t_s; or, the cam's on a lever
    whose ratio is at most ``ratio_max`` (0: no lever), the roller's force its own largest."""
    p = horner(G[m], w * t_next - th0, gdeg)[0]  # the monitor's forced part alone
    p += GT[m].real * np.cos(w * t_next) - GT[m].imag * np.sin(w * t_next)
    ring = _ringing(WC, MC, nact, m, t_next - t_s, False)
    so_far = _so_far(per_rev, c, w, t_from, t_next, MAX_CAM_FORCE if m == 0 else MAX_SEAT_FORCE)
    if m == 0 and ratio_max > 0.0:  # the roller's force is at most ratio_max times it
        so_far = min(so_far, _so_far(per_rev, c, w, t_from, t_next, MAX_ROLLER_FORCE) / ratio_max)
    return _above(-gval[m], -p, ring, w, t_next - t_from, so_far)


@njit(inline="always", nogil=True)
def _peak(runs, out, ws, st, ratio, nact, m, ta, tb, da, db):
    """Locate held contact m's force peak where its monitor's derivative rises through zero
    in (ta, tb] (da < 0 < db its values there) and count it in its turn's maximum: Newton
    steps on the derivative from the secant's point, kept inside the bracket (bisection
    otherwise), to ``run.tolerance`` (the force's error is second order in the time's). Not
    ``state._root``: each of its steps here gives the force with the derivatives
    (``eval_monitor``), the last one the peak's, where ``_root`` closes its bracket to the
    tolerance and the force would take one evaluation more (a peak is located at every
    turning of a ringing force that may be the turn's largest).

    With a lever's ``ratio`` (its cubic on the segment's piece; None otherwise) the cam's
    roller force −g·r is followed instead: da, db and the steps are (g·r)'s."""
    t_s, w, th0 = st.t_s, st.w, st.th0
    t = ta - da * (tb - ta) / (db - da)
    value = 0.0
    for _ in range(ROOT_ITERATIONS):
        g, dg, d2g = eval_monitor(ws.WC, ws.MC, nact, ws.G, ws.GT, m, t - t_s, w, w * t - th0,
                                  w * t, st.gdeg)  # fmt: skip
        value = -g
        if ratio is not None:
            r, r1, r2 = horner(ratio, w * t - th0, 3)
            value = -g * r
            d2g = d2g * r + 2.0 * dg * r1 * w + g * r2 * w * w
            dg = dg * r + g * r1 * w
        if dg < 0.0:
            ta = t
        else:
            tb = t
        t_new = t - dg / d2g if d2g > 0.0 else np.nan
        if not (ta < t_new < tb):
            t_new = 0.5 * (ta + tb)
        if abs(t_new - t) <= runs.tolerance or tb - ta <= runs.tolerance:
            break
        t = t_new
    turn = turn_of(w, t)
    col = MAX_CAM_FORCE if m == 0 else MAX_SEAT_FORCE
    if ratio is not None:
        col = MAX_ROLLER_FORCE
    if 0 <= turn < out.per_rev.shape[1]:
        out.per_rev[st.c, turn, col] = max(out.per_rev[st.c, turn, col], value)


@njit(**HELPER)
def _force_peaks(ref, st, nact, t_prev, t_to, h, cam_held, seat_held, known):
    """The held contacts' greatest forces inside (t_prev, t_to] (a grid step of length h [s]
    from t_prev; with ``known``, ws.gval and ws.dval hold the monitors at t_to) into the
    turn's force maxima: where a force's derivative turns from + to − across the step (its
    monitor's from − to +), the peak is located (``_peak``), so that a ringing the grid
    samples coarsely is read at its peak, if it may exceed the turn's largest so far
    (``_above``). The grid resolves every block that could move a peak by more than the
    peak tolerance (``_near_peak``). A lever's roller force the same way, its derivative's
    turn located on (g·r)'."""
    _, _, profiles, runs, out, ws = deref(ref)
    c, w, th0 = st.c, st.w, st.th0
    for m in range(2):
        if not (cam_held if m == 0 else seat_held):
            continue
        lever = m == 0 and ratio_bound(profiles, c) > 0.0
        if not (lever or ws.dprev[m] < 0.0):
            continue
        if known:
            g_to, db = ws.gval[m], ws.dval[m]
        else:
            g_to, db = _at(False, ws.WC, ws.MC, nact, ws.G, ws.GT, m, st.t_s, t_to, w, th0,
                           st.gdeg)  # fmt: skip
        if ws.dprev[m] < 0.0 and db > 0.0:
            ring = _ringing(ws.WC, ws.MC, nact, m, t_to - st.t_s, True)
            so_far = _so_far(out.per_rev, c, w, t_prev, t_to,
                             MAX_CAM_FORCE if m == 0 else MAX_SEAT_FORCE)  # fmt: skip
            if _above(-ws.gprev[m], -g_to, ring, w, h, so_far):
                _peak(runs, out, ws, st, None, nact, m, t_prev, t_to, ws.dprev[m], db)
        if lever:  # its roller's force at both ends, and its peak between
            ratio = profiles.ratio[c, st.p]
            r_a, r1_a, _ = horner(ratio, w * t_prev - th0, 3)
            r_b, r1_b, _ = horner(ratio, w * t_to - th0, 3)
            _roller_maximum(out.per_rev, c, w, t_prev, -ws.gprev[m] * r_a)
            _roller_maximum(out.per_rev, c, w, t_to, -g_to * r_b)
            da = ws.dprev[m] * r_a + ws.gprev[m] * r1_a * w
            dr = db * r_b + g_to * r1_b * w
            if da < 0.0 and dr > 0.0:
                so_far = _so_far(out.per_rev, c, w, t_prev, t_to, MAX_ROLLER_FORCE)
                ring = _ringing(ws.WC, ws.MC, nact, m, t_to - st.t_s, True)
                ring_r = ring * ratio_bound(profiles, c)
                if _above(-ws.gprev[m] * r_a, -g_to * r_b, ring_r, w, h, so_far):
                    _peak(runs, out, ws, st, ratio, nact, m, t_prev, t_to, da, dr)
