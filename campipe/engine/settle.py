"""Run length by convergence (``RunSettings.revolutions`` None, a study's ``run.revolutions:
auto``): each case runs turn by turn until its
response repeats, and its metrics are the settled response's.

The periodic start is the steady state of a train that *follows* the cam. A case that does
follow it repeats from its first turn; a case past the onset leaves it, and its first
turns are a transient away from it, which a fixed run of a few turns averages into its
metrics. Here a batch runs one turn at a time (``batch.run_batch`` on the cases not yet
settled, each turn started from the state its last ended in), and after each turn every case's
state at the turn boundaries is compared with the one p turns before (p = 1 … max_period):

- a case whose last turns repeat with a period p, to ``settle_tolerance`` (see
  :func:`repeats`), and have kept repeating for ``SETTLE_CONFIRM`` further periods (see
  :func:`confirmed`), has settled; its metrics are taken over the whole periods of its settled
  window (``settled_turn`` on), and it runs no more once it has the turns it records;
- a case that has not repeated within ``max_revolutions`` turns never settled
  (``period_turns`` 0): its metrics are statistics (mean per turn, largest) over the second
  half of its run, its window.

The histories kept are those of each case's last ``history_turns`` turns (the settled
window's last period when it is at least the period), from the turn ``recorded_from``; the
events kept are those of the same turns. Times are from the start of the run.

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine import metrics
from campipe.engine.case import Case, sample_count
from campipe.engine.result import BatchResult, blank_failures
from campipe.engine.settings import SETTLE_CONFIRM, check_settling, whole_turns
from campipe.model.assembly import SystemMatrices
from campipe.model.layouts import placeholders
from campipe.profiles import evaluate
from campipe.vocabulary import CAM, EV_TIME, FAILURES, N_EVENT_FIELDS, SEAT, holds_cam, holds_seat

#: A boundary state's difference below this fraction of the tolerance is a repetition at
#: once, whatever the estimated contraction (a case that follows the cam from the periodic
#: start repeats to rounding in its first turn).
AT_ONCE = 1e-3


class Boundary(NamedTuple):
    """The states at a case's turn boundaries (``run_settled``'s bookkeeping)."""

    q: np.ndarray  # (n, max_revolutions + 1, n_q) coordinates at θ = 2πk [m, rad]
    v: np.ndarray  # (n, max_revolutions + 1, n_q) velocities [m/s, rad/s]
    scale: np.ndarray  # (n, 2, n_q) each coordinate's and velocity's range over a turn


def boundary_difference(boundary: Boundary, c, k: int, p: int):
    """Case c's (or each of an array of cases') largest difference between its states at
    turns k and k − p, each coordinate and velocity relative to its range over a turn [-]."""
    dq = np.abs(boundary.q[c, k] - boundary.q[c, k - p]) / boundary.scale[c, 0]
    dv = np.abs(boundary.v[c, k] - boundary.v[c, k - p]) / boundary.scale[c, 1]
    return np.fmax(np.nanmax(dq, axis=-1), np.nanmax(dv, axis=-1))


def repeats(boundary: Boundary, c, k: int, p: int, tolerance: float):
    """Has case c (or each of an array of cases), after k turns, settled with period p? Its
    state at turn k differs from the one at k − p by at most ``tolerance`` (relative,
    :func:`boundary_difference`), and so will every later one: where two differences p apart
    are known, their ratio r is the transient's contraction per period, and the distance left
    to the periodic response, d·r/(1 − r), must be within the tolerance too (a slowly
    decaying transient changes little per turn long before it has settled)."""
    if k < p:
        return np.zeros(np.shape(c), np.bool_)[()]
    d = boundary_difference(boundary, c, k, p)
    before = boundary_difference(boundary, c, k - p, p) if k >= 2 * p else None
    return _repeats(d, before, tolerance)


def _repeats(d, before, tolerance: float):
    """:func:`repeats` from the difference ``d`` at a turn and ``before``, the one a period
    earlier (None where that is not known yet)."""
    at_once = d <= AT_ONCE * tolerance
    if before is None:
        return at_once
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(before > 0, d / before, 1.0)
        left = d * r / (1.0 - r)
    return at_once | ((d <= tolerance) & (r < 1.0) & (left <= tolerance))


def confirmed(boundary: Boundary, c, k: int, p: int, tolerance: float):
    """Has case c (or each of an array of cases), after k turns, settled with period p, its
    repetition confirmed? :func:`repeats` holds at turn k and at each of the SETTLE_CONFIRM
    checks a period apart before it (k − p, …, k − SETTLE_CONFIRM·p): the differences p
    turns apart stay within the tolerance and keep contracting for SETTLE_CONFIRM periods
    after they first pass. A chaotic response passing near an unstable periodic one has its
    differences shrink for a turn or two and then grow again: one small difference with a
    ratio below 1 does not show that they stay small. The exception is the first comparison
    (k = p), with the run's start: a difference within AT_ONCE of the tolerance there is a
    repetition at once (a case that follows the cam from the periodic start repeats it to
    rounding in its first turn, and runs that one turn only)."""
    if k < p:
        return np.zeros(np.shape(c), np.bool_)[()]
    if k == p:
        return boundary_difference(boundary, c, k, p) <= AT_ONCE * tolerance
    # The differences at turns k, k − p, …, k − (SETTLE_CONFIRM + 1)·p, each once (None
    # before turn p): :func:`repeats` at turn k − j·p reads the j-th and the one after it.
    d = [
        boundary_difference(boundary, c, k - j * p, p) if k - j * p >= p else None
        for j in range(SETTLE_CONFIRM + 2)
    ]
    held = _repeats(d[0], d[1], tolerance)
    for j in range(1, SETTLE_CONFIRM + 1):
        if d[j] is None:  # before turn p: no repetition there
            return held & np.zeros(np.shape(c), np.bool_)[()]
        held = held & _repeats(d[j], d[j + 1], tolerance)
    return held


def least_period(boundary: Boundary, c: int, k: int, p: int, tolerance: float) -> int:
    """The period to report for case c, settled with period p after k turns: the least
    divisor q of p whose differences q turns apart head to within the tolerance, else p. A
    response that repeats every turn but whose transient alternates (a mode whose multiplier
    per turn is near −1) has its differences 2 turns apart settle long before those 1 turn
    apart; it is p-periodic to the tolerance, and q-periodic when the q-differences at turns
    k − 2q, k − q, k fall to a limit within it, their Aitken extrapolation
    d₂ − (d₂ − d₁)²/(d₂ − 2d₁ + d₀) (a difference that is already within it counts too)."""
    for q in range(1, p):
        if p % q or k < 3 * q:
            continue
        d0, d1, d2 = (float(boundary_difference(boundary, c, k - j * q, q)) for j in (2, 1, 0))
        if d2 <= tolerance:
            return q
        curvature = d2 - 2.0 * d1 + d0
        if d2 < d1 < d0 and curvature > 0 and d2 - (d2 - d1) ** 2 / curvature <= tolerance:
            return q
    return p


def settled_from(
    boundary: Boundary, c: int, k: int, p: int, tolerance: float, per_rev: np.ndarray | None = None
) -> int:
    """The first turn of case c's settled window after k turns with period p: back from k in
    whole periods while the states p apart still agree to the tolerance, and (``per_rev``,
    case c's (turns, metrics) per-turn metrics) so do the turns' metrics: a turn's metric
    within the tolerance of the same turn a period later, relative to that metric's largest
    over the k turns (:func:`metrics_repeat`). Near a grazing landing a turn's no-follow
    moves with its start state without bound: a helper's two-mass chain 1.4 rpm past its
    onset left the periodic start for 6.068° its first turn and 6.044° every turn after,
    its state at the turn's end within 1e-5 of the next."""
    start = k - p
    while (
        start - p >= 0
        and boundary_difference(boundary, c, start, p) <= tolerance
        and (per_rev is None or metrics_repeat(per_rev[:k], start - p, p, tolerance))
    ):
        start -= p
    return start


def metrics_repeat(per_rev: np.ndarray, turn: int, p: int, tolerance: float) -> bool:
    """Do the per-turn metrics ``per_rev`` (turns, metrics) of turns ``turn`` … turn + p − 1
    equal those p turns later, each to ``tolerance`` of its metric's largest magnitude over
    ``per_rev`` (a count exactly; NaN, a metric a turn did not have, equal to NaN)?"""
    a, b = per_rev[turn : turn + p], per_rev[turn + p : turn + 2 * p]
    scale = np.fmax.reduce(np.abs(per_rev), axis=0)  # (NaN only where every turn's is)
    same = (np.abs(a - b) <= tolerance * scale) | (np.isnan(a) & np.isnan(b))
    return bool(np.all(same))


def consistent_accelerations(
    cases: Sequence[Case], matrices: Sequence[SystemMatrices], q, v, cfg
) -> np.ndarray:
    """(n, n_q) accelerations from the equation of motion at θ = 0 of a turn, with the
    contacts that ``cfg`` holds prescribed (the cam's surface accelerating the follower, the
    seat at rest): the start an integrator that carries accelerations takes."""
    n, n_q = q.shape
    a = np.zeros((n, n_q))
    for i, (case, sm) in enumerate(zip(cases, matrices, strict=True)):
        k = sm.mass.shape[0]
        held = np.zeros(k, np.bool_)
        if holds_cam(int(cfg[i])):
            held[CAM] = True
            a[i, CAM] = -(case.speed**2) * float(evaluate(case.profile, np.zeros(1))[2][0])
        if holds_seat(int(cfg[i])):
            held[SEAT] = True
        free = ~held
        force = sm.preload - sm.stiffness @ q[i, :k] - sm.damping @ v[i, :k] - sm.mass @ a[i, :k]
        a[i, :k][free] = np.linalg.solve(sm.mass[np.ix_(free, free)], force[free])
    return a


class _Kept(NamedTuple):
    """The last turns' histories of every case, in a ring of ``turns`` slots by turn."""

    q: np.ndarray  # (n, turns, per_turn + 1, n_q)
    v: np.ndarray
    acc: np.ndarray  # (n, turns, per_turn + 1, 2)
    cam: np.ndarray  # (n, turns, per_turn + 1)
    cam_force: np.ndarray
    seat_force: np.ndarray
    cfg: np.ndarray  # int8
    events: list[list[np.ndarray]]  # per case, per slot: that turn's events (times absolute)
    #: (n, turns, per_turn + 1) an adjuster's extension (``BatchResult.extension``); or
    #: empty, where the turns have none
    extension: np.ndarray


def _keep(kept: _Kept, rows: np.ndarray, slot: np.ndarray, part: BatchResult) -> None:
    kept.q[rows, slot] = part.q
    kept.v[rows, slot] = part.v
    kept.acc[rows, slot] = part.acc
    kept.cam[rows, slot] = part.cam_lift
    kept.cam_force[rows, slot] = part.cam_force
    kept.seat_force[rows, slot] = part.seat_force
    kept.cfg[rows, slot] = part.contact_state
    if kept.extension.size:
        kept.extension[rows, slot] = part.extension


def run_settled(
    cases: Sequence[Case],
    settings,
    run_turn: Callable[..., BatchResult],
    matrices: Sequence[SystemMatrices],
    **options,
) -> BatchResult:
    """Run every case until its response repeats (see the module's docstring).

    ``run_turn(cases, settings, start=..., full_state=..., **options)`` runs one turn
    (``batch.run_batch``; ``start`` None or (t0, q0, v0, a0, cfg0) arrays), ``matrices`` are
    each case's train's; the options are run_batch's. The result's ``per_rev`` has
    ``max_revolutions`` turns (NaN beyond a case's last), ``measured`` each case's window,
    and ``period_turns``, ``settled_turn``, ``turns_run`` and ``recorded_from`` say how each
    settled."""
    check_settling(settings)
    turns = whole_turns(settings)
    options.pop("full_state", None)  # every coordinate: a turn's end is the next's start
    n = len(cases)
    cap, tol, p_max = settings.max_revolutions, settings.settle_tolerance, settings.max_period
    one = dataclasses.replace(settings, revolutions=1.0, warmup=0)
    per_turn = sample_count(1.0, settings.output_every) - 1
    omega = np.array([c.speed for c in cases])
    compliant = np.array([c.compliant for c in cases], np.bool_)  # (their starts: below)
    period = np.zeros(n, np.int64)
    settled = np.zeros(n, np.int64)
    done = np.zeros(n, np.int64)  # turns run
    status = np.zeros(n, np.int64)
    steps = np.zeros(n, np.int64)
    per_rev = np.full((n, cap, metrics.N_ENGINE), np.nan)
    active = np.arange(n)
    start: tuple | None = None
    first_start = reference = np.zeros(n)
    boundary = kept = None
    for k in range(cap):
        members = [cases[i] for i in active.tolist()]
        part = run_turn(members, one, start=start, full_state=True, **options)
        if boundary is None:  # the first turn: the arrays' shapes
            n_q = part.q.shape[2]
            boundary = Boundary(
                np.full((n, cap + 1, n_q), np.nan),
                np.full((n, cap + 1, n_q), np.nan),
                np.ones((n, 2, n_q)),
            )
            # a short chain's placeholders (decoupled, at rest to rounding) compare as equal
            spare = np.zeros((n, n_q), np.bool_)
            for i, case in enumerate(cases):
                spare[i, placeholders(case.train)] = True
            boundary.q[:, 0], boundary.v[:, 0] = part.q[:, 0], part.v[:, 0]
            first_start = part.start_time.copy()
            reference = part.valve_reference.copy()
            samples = (n, turns, per_turn + 1)
            kept = _Kept(
                np.full((*samples, n_q), np.nan),
                np.full((*samples, n_q), np.nan),
                np.full((*samples, 2), np.nan),
                np.full(samples, np.nan),
                np.full(samples, np.nan),
                np.full(samples, np.nan),
                np.zeros(samples, np.int8),
                [[np.zeros((0, N_EVENT_FIELDS))] * turns for _ in range(n)],
                np.full(samples if part.extension.size else (0, 0, 0), np.nan),
            )
        assert kept is not None
        boundary.q[active, k + 1] = part.q[:, -1]
        boundary.v[active, k + 1] = part.v[:, -1]
        ranges = np.stack([np.ptp(part.q, axis=1), np.ptp(part.v, axis=1)], axis=1)
        floor = (
            np.array([1e-9, 1e-9])[None, :, None]
            * np.maximum(omega[active], 1.0)[:, None, None] ** np.array([0.0, 1.0])[None, :, None]
        )
        boundary.scale[active] = np.where(spare[active, None, :], np.inf, np.fmax(ranges, floor))
        per_rev[active, k] = part.per_rev[:, 0]
        steps[active] += part.steps
        _keep(kept, active, np.full(active.size, k % turns), part)
        offset = k * TWO_PI / omega
        for j, i in enumerate(active.tolist()):
            events = part.events[j].copy()
            events[:, EV_TIME] += offset[i]
            kept.events[i][k % turns] = events
        done[active] = k + 1
        failed = np.isin(part.status, FAILURES)
        status[active] = np.where(part.status != 0, part.status, status[active])
        # the least period each case not yet settled repeats with, all cases at once
        open_ = ~failed & (period[active] == 0)
        for p in range(1, p_max + 1):
            hit = open_ & confirmed(boundary, active, k + 1, p, tol)
            for i in active[hit].tolist():
                period[i] = least_period(boundary, i, k + 1, p, tol)
                settled[i] = settled_from(boundary, i, k + 1, p, tol, per_rev[i])
            open_ &= ~hit
        # a settled case runs on until it has the turns it records
        go_on = ~failed & (k + 1 < cap) & ((period[active] == 0) | (k + 1 < turns))
        rows = np.flatnonzero(go_on)
        if not rows.size:
            break
        active = active[rows]
        q0, v0 = part.q[rows, -1], part.v[rows, -1]
        cfg0 = part.contact_state[rows, -1].astype(np.int64)
        a0 = (
            np.zeros_like(q0)  # modal-exact starts from the coordinates and velocities alone
            if settings.method == "modal-exact"
            else consistent_accelerations(
                [cases[i] for i in active.tolist()],
                [matrices[i] for i in active.tolist()],
                q0,
                v0,
                cfg0,
            )
        )
        # A compliant case's start is its compliant state, its contacts already compressed:
        # NaN accelerations say so, and it is taken as it is (compressing its held contacts
        # as a rigid start's, ``compliant.compliant_start``, would kick it every turn).
        a0[compliant[active]] = np.nan
        start = (np.zeros(active.size), q0, v0, a0, cfg0)
    never = period == 0
    settled[never] = done[never] // 2
    measured = np.zeros((n, cap), np.bool_)
    for i in range(n):
        last = int(done[i] - (done[i] - settled[i]) % period[i]) if period[i] else int(done[i])
        measured[i, int(settled[i]) : last] = True
    return _result(cases, settings, kept, per_rev, measured, period, settled, done, status,
                   steps, first_start, reference)  # fmt: skip


def _result(cases, settings, kept, per_rev, measured, period, settled, done, status, steps,
            first_start, reference) -> BatchResult:  # fmt: skip
    """The settled run's BatchResult: each case's last recorded turns in order (a failed
    case's histories and metrics NaN, as ``run_batch`` records them)."""
    n, turns = kept.cfg.shape[:2]
    recorded_from = np.maximum(done - turns, 0)
    # slot of the j-th recorded turn: (recorded_from + j) % turns
    order = (recorded_from[:, None] + np.arange(turns)) % turns
    rows = np.arange(n)[:, None]

    def join(array):
        ring = array[rows, order]  # (n, turns, per_turn + 1, ...)
        head = ring[:, :, :-1].reshape(n, -1, *ring.shape[3:])
        return np.concatenate([head, ring[:, -1, -1:]], axis=1)

    angles = np.arange(join(kept.cam).shape[1]) * settings.output_every
    omega = np.array([c.speed for c in cases])
    events = [np.concatenate([kept.events[i][s] for s in order[i]]) for i in range(n)]
    result = BatchResult(
        cam_angle=angles,
        time=(recorded_from[:, None] * TWO_PI + angles[None, :]) / omega[:, None],
        q=join(kept.q),
        v=join(kept.v),
        acc=join(kept.acc),
        cam_lift=join(kept.cam),
        cam_force=join(kept.cam_force),
        seat_force=join(kept.seat_force),
        contact_state=join(kept.cfg),
        valve_reference=reference,
        measured=measured,
        per_rev=per_rev,
        trains=[c.train for c in cases],
        events=events,
        steps=steps,
        status=status,
        start_time=first_start,
        period_turns=period,
        settled_turn=settled,
        turns_run=done,
        recorded_from=recorded_from,
        extension=join(kept.extension) if kept.extension.size else np.zeros(0),
    )
    return blank_failures(result)
