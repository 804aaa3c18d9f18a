"""Runs of trains with a hydraulic lash adjuster: turn by turn, the plunger's extension a slow
state advanced at each turn's end (:mod:`campipe.model.hla`).

A chain's adjuster sits in series with its link next to the cam, between the cam's mass (q1)
and the next. An extension e of the plunger lengthens that link by e; in the cam's mass's
coordinate x1' = x1 + e the link's force is the engine's with no extension, and the cam's
contact holds x1' on the cam's lift raised by e (the seat, the spring and every other mass
unchanged). So a turn with the extension e is, exactly, an engine run of the train on its
cam's profile raised by e (``raised``); its histories are brought back to the cam's own
lift (q1 + e, the cam's lift − e). At each turn's end the extension moves by the turn's
pump-up less its leak-down (``LashAdjuster.advance``), from the force through the adjuster
(the link's, k·(x1' − x2)) and the gap between cam and follower at the output samples; the
next turn starts where the last ended, the change applied there (``_move_follower``: a
follower on the cam stays on it, the link's force changing by k·Δe; one off it stays put,
its gap shrinking by Δe, and lands on the cam if that closes it). A finger follower's adjuster
is under its pivot: an extension raises the pivot, so a turn runs on the kinematic valve lift
of the raised pivot (``campipe.profiles.levers.pivot_raised``), the load through it is the
pivot's, g·F (``adjuster_load``), and its histories stay in that frame.

One :class:`Plunger` carries the adjusters from turn to turn, for a run of whole turns
(``run_adjusted``'s loop) and for one of automatic length (``engine.settle.run_settled``,
the extension then part of the state it compares): under newmark-linear, and for a finger's
pivot with rigid contacts. Elsewhere the plunger is carried within the turn instead
(:func:`run_carried`): with compliant contacts as a state of the compliant integrator
(``engine.plunger``), in a chain with rigid ones as a coordinate of modal-exact's train
(``engine.plunger_modes``, :func:`in_kernel`).

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import Case
from campipe.engine.plunger import (
    EXTENSION,
    LEAK_DOWN,
    PUMP_UP,
    carried,
    interpolated_switches,
)
from campipe.engine.plunger_modes import Embedded
from campipe.engine.result import BatchResult, blank_failures, merge_results, thinned
from campipe.engine.settings import adjuster_turns
from campipe.engine.settle import consistent_accelerations, run_settled
from campipe.model import system_matrices
from campipe.model.elements import chain_elements
from campipe.model.hla import LashAdjuster, adjuster, on_pivot
from campipe.model.layouts import chain_placement
from campipe.profiles import Profile, evaluate
from campipe.profiles.levers import ValveSideProfile, pivot_gains, pivot_raised
from campipe.vocabulary import (
    ADJUSTER_EVENTS,
    CAM,
    CAM_AND_SEAT,
    CAM_CONTACT,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    FAILURES,
    holds_cam,
    holds_seat,
)


def raised(profile: Profile, height: float) -> Profile:
    """``profile`` with its lift raised by ``height`` [m] at every angle."""
    poly = profile.poly.copy()
    poly[:, 0] += height
    return Profile(profile.breaks, poly, profile.trig, profile.label)


def extended(case: Case, extension: float) -> Case:
    """``case`` with its adjuster's plunger at ``extension`` [m] (the run's frame): a chain's
    cam lift raised by it (:func:`raised`); a finger follower's excitation with its pivot
    raised by it, derived exactly (:func:`campipe.profiles.levers.pivot_raised`)."""
    if not extension:
        return case
    if on_pivot(case.train) and isinstance(case.profile, ValveSideProfile):
        return dataclasses.replace(case, profile=pivot_raised(case.profile, extension))
    return dataclasses.replace(case, profile=raised(case.profile, extension))


def adjuster_load(case: Case, part: BatchResult, i: int) -> tuple[np.ndarray, np.ndarray]:
    """The force [N] through case ``i``'s adjuster at the turn's samples and the gap [m] its
    plunger would take up, in its own travel: a chain's, its link's force and the gap between
    cam and follower; a finger's, the pivot's load g·F (F the pallet's force, the link's; g
    the valve lift's change per unit of the pivot's rise at each sample's cam angle, which by
    virtual work on the lever is the pivot's load per unit of F, the lever's own momentum left
    out) and that gap over g (the extension that closes it)."""
    force = link_force(case, part.q[i])
    gap = -part.q[i, :, CAM] - part.cam_lift[i]
    if on_pivot(case.train) and isinstance(case.profile, ValveSideProfile):
        gain = pivot_gains(case.profile, part.cam_angle)
        return gain * force, gap / gain
    return force, gap


def _lift_at_zero(cases: Sequence[Case]) -> np.ndarray:
    """Each case's excitation at cam angle 0 (a turn's start) [m]."""
    return np.array([float(evaluate(c.profile, np.zeros(1))[0][0]) for c in cases])


def link_force(case: Case, q: np.ndarray) -> np.ndarray:
    """(..., ) the compressive force [N] through the chain's link next to the cam (with its
    adjuster in series) for coordinates ``q`` (..., n) in the run's own frame."""
    index, sign = chain_placement(len(case.train.masses))
    link = next(e for e in chain_elements(case.train) if e.name == "link")
    k = float(link.stiffness[0, 0])
    return k * (sign[0] * q[..., index[0]] - sign[1] * q[..., index[1]])


def run_adjusted(
    cases: Sequence[Case],
    settings,
    run: Callable[..., BatchResult],
    carried_run: Callable[..., BatchResult] | None = None,
    **options,
) -> BatchResult:
    """Run every case turn by turn (see the module), each turn by ``run`` (``run_batch`` of
    one turn from ``start``'s (t0, q0, v0, a0, cfg0) or, for the first, from the settings')
    with ``options`` (its own); cases without an adjuster run the same way with their
    extension 0. The result's ``lash_adjuster`` holds each turn's extension, leak-down and
    pump-up (NaN for a case without an adjuster). A run of automatic length
    (``revolutions`` None) is ``engine.settle.run_settled``'s, each turn through the same
    :class:`Plunger`, the extension part of the state it compares.

    Cases whose integrator carries the plunger as a state (``engine.plunger.carried``:
    compliant contacts, an adjuster in a chain) go instead through :func:`run_carried` with
    ``carried_run`` (``run_batch`` past its adjusters)."""
    flags = np.array([carried(c, settings.integrator) for c in cases], np.bool_)
    if flags.any() and carried_run is not None:
        return _split(
            cases, flags,
            lambda members: run_carried(members, settings, carried_run, **options),
            lambda members: run_adjusted(members, settings, run, **options),
        )  # fmt: skip
    turns = adjuster_turns(settings)
    if turns == 0:  # a part of a turn (a kernel's warm-up): no turn ends, the plunger stays
        return _part_of_a_turn(cases, settings, run, options)
    options.pop("full_state", None)  # every coordinate: a turn's end is the next's start
    if turns is None:
        plunger = Plunger(cases, settings, run, settings.max_revolutions, ledger=True)
        matrices = [system_matrices(c.train) for c in plunger.inner]
        result = run_settled(cases, settings, plunger, matrices, **options)
        return plunger.settled(result)
    return _whole_turns(cases, settings, Plunger(cases, settings, run, turns), turns, options)


def _whole_turns(cases, settings, carrier, turns: int, options) -> BatchResult:
    """``turns`` whole turns of ``cases``, one turn a call of ``carrier`` (a :class:`Plunger`
    or a :class:`Carried` without its ledger), each from the last one's end, joined."""
    n = len(cases)
    one = dataclasses.replace(settings, revolutions=1.0, warmup=0)
    parts: list[BatchResult] = []
    status = np.zeros(n, np.int64)
    start = None
    for _ in range(turns):
        part = carrier(cases, one, start=start, **options)
        status = np.where(part.status != 0, part.status, status)
        parts.append(part)
        cfg0 = part.contact_state[:, -1].astype(np.int64)
        start = (np.zeros(n), part.q[:, -1].copy(), part.v[:, -1].copy(), None, cfg0)
    return _joined(parts, cases, settings, carrier.table, status)


def run_carried(
    cases: Sequence[Case], settings, run: Callable[..., BatchResult], **options
) -> BatchResult:
    """Run cases whose plunger is a state of their run by ``run``: with compliant contacts
    under the compliant integrator (``engine.plunger``), with rigid ones (chains) by
    modal-exact (:func:`in_kernel`); each on its cam raised by its starting extension e₀ (the
    frame the plunger's state u = e − e₀ is measured in, so the settings' start is the train's
    with its plunger there; a finger's on the kinematic lift with its pivot raised by e₀),
    a chain's histories brought back to the cam's own lift: a chain's run of whole or part
    turns in one piece; a finger's (its pivot's gain linearised about e₀) and a run of
    automatic length turn by turn through a :class:`Carried` (``engine.settle.run_settled``
    for the latter), which starts each turn in the frame of the extension the last ended
    with."""
    rigid = np.array([not c.compliant for c in cases], np.bool_)
    if rigid.any() and not rigid.all():

        def each(members):
            return run_carried(members, settings, run, **options)

        return _split(cases, rigid, each, each)
    if rigid.all():  # modal-exact's, the plunger a coordinate of the chain's train
        one_law, run = settings, in_kernel(run)
    else:
        one_law = dataclasses.replace(settings, integrator="compliant")
    if settings.settle:
        carrier = Carried(cases, one_law, run, settings.max_revolutions, ledger=True)
        matrices = [system_matrices(c.train) for c in cases]
        result = run_settled(cases, one_law, carrier, matrices, **options)
        return without_ledger(result, carrier.table)
    turns = adjuster_turns(settings)
    pivots = ~_in_link(cases)
    if not (turns and turns > 1 and pivots.any()):
        return _in_one_piece(cases, one_law, run, options)
    return _split(
        cases, pivots,
        lambda members: _whole_turns(
            members, one_law, Carried(members, one_law, run, turns), turns, options
        ),
        lambda members: _in_one_piece(members, one_law, run, options),
    )  # fmt: skip


def _split(cases, which: np.ndarray, first, second) -> BatchResult:
    """``first`` run on the cases ``which`` picks, ``second`` on the others, merged."""
    pieces = []
    for picked, part_of in ((which, first), (~which, second)):
        index = np.flatnonzero(picked)
        if index.size:
            pieces.append((index, part_of([cases[int(i)] for i in index])))
    return merge_results(len(cases), pieces)


def _in_one_piece(cases, settings, run, options) -> BatchResult:
    """A carried run of ``cases`` in one piece on their cams raised by their starting
    extensions (a finger's pivot raised), a chain's histories back on its cam's own lift."""
    offset = np.array([c.train.hla_extension for c in cases])
    members = [extended(c, e) for c, e in zip(cases, offset, strict=True)]
    part = run(members, settings, **options)
    return _in_cam_frame(part, np.where(_in_link(cases), offset, 0.0), cases)


def in_kernel(run: Callable[..., BatchResult]) -> Callable[..., BatchResult]:
    """``run`` (``run_batch`` past its adjusters) of chains with rigid contacts, their
    plungers carried by modal-exact: each case's train with its plunger as its last
    coordinate u = e − e₀ (``plunger_modes.Embedded``; e₀ the train's ``hla_extension``, the
    frame its cam is raised by), a start handed in taking u = 0 there. Returns the run with
    u's column taken off the histories and made the turns' ledger (:func:`kernel_ledger`)."""

    def carried_run(cases, settings, start=None, **options) -> BatchResult:
        members = [dataclasses.replace(c, train=Embedded(c.train)) for c in cases]
        if start is not None:  # the plunger at 0 in this frame: u's column
            t0, q0, v0, a0, cfg0 = start
            pad = np.zeros((len(cases), 1))
            q0, v0 = np.hstack([q0, pad]), np.hstack([v0, pad])
            a0 = None if a0 is None else np.hstack([a0, np.full_like(pad, np.nan)])
            start = (t0, q0, v0, a0, cfg0)
        part = run(members, settings, start=start, **options)
        offset = np.array([c.train.hla_extension for c in cases])
        table = kernel_ledger(part, offset)
        for events in part.events:  # the kernel's u at each switch, read: cleared
            events[np.isin(events[:, EV_KIND], ADJUSTER_EVENTS), EV_IMPULSE] = 0.0
        return dataclasses.replace(
            part,
            q=part.q[:, :, :-1],
            v=part.v[:, :, :-1],
            lash_adjuster=table,
            extension=offset[:, None] + part.q[:, :, -1],
            _derived={},
        )

    return carried_run


def kernel_ledger(part: BatchResult, offset: np.ndarray) -> np.ndarray:
    """(n, n_turns, 3) each turn's extension at its start, leak-down and pump-up [m] of a
    carried run by modal-exact (:func:`in_kernel`): from u (the histories' last column,
    from the start's extension ``offset``) at each turn's start and end, and at each of the
    plunger's switches in between (the kernel's u there, in the event's impulse field).
    Between two of these the plunger is in one regime, so u moves one way: what it falls is
    leak-down, what it rises pump-up. Turns before the recorded window are NaN."""
    n, n_turns = part.per_rev.shape[:2]
    table = np.full((n, n_turns, 3), np.nan)
    theta = np.asarray(part.cam_angle, float)
    starts = np.searchsorted(theta, TWO_PI * np.arange(n_turns + 1) - 1e-9)
    for i in range(n):
        events = part.events[i]
        switch = events[np.isin(events[:, EV_KIND], ADJUSTER_EVENTS)]
        u = part.q[i, :, -1]
        first = int(part.recorded_from[i]) if part.recorded_from.size else 0
        for k in range(n_turns - first):
            a, b = starts[k], starts[k + 1]
            if b >= u.size or not np.isfinite(u[a]) or not np.isfinite(u[b]):
                continue
            t_a, t_b = part.time[i, a], part.time[i, b]
            inside = switch[(switch[:, EV_TIME] >= t_a) & (switch[:, EV_TIME] < t_b)]
            path = np.concatenate([[u[a]], inside[:, EV_IMPULSE], [u[b]]])
            moves = np.diff(path)
            table[i, first + k] = (
                offset[i] + u[a],
                -moves[moves < 0.0].sum(),
                moves[moves > 0.0].sum(),
            )
    return table


def held_extension(part: BatchResult, extension: np.ndarray) -> BatchResult:
    """``part`` with each case's adjuster's extension [m] held at ``extension`` (each case's;
    NaN where it is not in a chain's link) over its samples (``BatchResult.extension``)."""
    held = np.repeat(np.asarray(extension, float)[:, None], part.cam_angle.size, axis=1)
    return dataclasses.replace(part, extension=held)


def _in_link(cases) -> np.ndarray:
    """(n,) each case's adjuster lengthens a chain's link (its frame the cam's lift raised by
    the extension), not a finger's pivot (its frame the lever's own)."""
    return np.array([not on_pivot(c.train) for c in cases], np.bool_)


def _in_cam_frame(part: BatchResult, offset: np.ndarray, cases) -> BatchResult:
    """``part`` (run on cams raised by ``offset`` [m]) with its histories on the cams' own
    lifts and the cases' own trains."""
    _to_cam_lift(part, offset)
    return dataclasses.replace(part, trains=[c.train for c in cases])


def _to_cam_lift(part: BatchResult, shift: np.ndarray) -> None:
    """``part``'s histories, run on cams raised by ``shift`` [m] (each case's), back on the
    cams' own lifts: q1 + shift, the cam's lift − shift (in place)."""
    part.q[:, :, CAM] += shift[:, None]
    part.cam_lift[:] -= shift[:, None]


def without_ledger(result: BatchResult, table: np.ndarray) -> BatchResult:
    """``run_settled``'s result without the ledger's column (:func:`with_ledger`), with the
    adjusters' ``table``."""
    return dataclasses.replace(
        result, q=result.q[:, :, :-1], v=result.v[:, :, :-1], lash_adjuster=table
    )


def with_ledger(part: BatchResult, before, after, travel) -> BatchResult:
    """``part`` with one more coordinate, its plunger's extension: ``before`` and ``after``
    [m] at the turn's ends, e₀ + (e₁ − e₀)·θ/2π + travel·sin²(θ/2) between them (its range
    over the turn about its travel, so that ``run_settled`` compares it to
    ``settle_tolerance`` of that; :func:`without_ledger` takes it off)."""
    theta = np.asarray(part.cam_angle, float)[None, :]
    column = before[:, None] + (after - before)[:, None] * theta / TWO_PI
    column = column + travel[:, None] * np.sin(theta / 2) ** 2
    q = np.concatenate([part.q, column[:, :, None]], axis=2)
    v = np.concatenate([part.v, np.zeros_like(column)[:, :, None]], axis=2)
    return dataclasses.replace(part, q=q, v=v)


class Carried:
    """A batch's carried plungers turn by turn (the ``run_turn`` of
    ``engine.settle.run_settled`` for a run of automatic length; a finger's run of whole
    turns): each turn run on the cam raised by the extension the last one ended with
    (``train.hla_extension`` set to it: the plunger's state starts at 0 in that frame; a
    finger's kinematic lift with its pivot there), from the last turn's end moved into that
    frame (a finger's coordinates are its own in every frame: the lift with the pivot at the
    extension reached is, to the linearisation's 1e-5 of a turn's motion, the last frame's
    with g·u). With ``ledger`` each turn's coordinates carry one more column, the plunger's
    extension at the turn's ends (between them as :class:`Plunger`'s ledger), so a case
    settles only once its plunger repeats too."""

    def __init__(self, cases, settings, run, turns: int, ledger: bool = False) -> None:
        self.cases = list(cases)
        self.index = {id(c): i for i, c in enumerate(cases)}
        self.extension = np.array([c.train.hla_extension for c in cases])
        self.travel = np.array([c.train.hla_travel for c in cases])
        self.in_link = _in_link(cases)
        self.table = np.full((len(cases), turns, 3), np.nan)
        self.turn = np.zeros(len(cases), np.int64)
        self.run, self.ledger = run, ledger

    def __call__(self, members, one, start=None, full_state=True, **options) -> BatchResult:
        rows = np.array([self.index[id(m)] for m in members], np.int64)
        before = self.extension[rows].copy()
        shift = np.where(self.in_link[rows], before, 0.0)
        run_cases = []
        for i, e in zip(rows.tolist(), before, strict=True):
            case = self.cases[i]
            train = case.train.replace(hla_extension=float(e))
            run_cases.append(extended(dataclasses.replace(case, train=train), float(e)))
        if start is not None:  # the last turn's end, in this turn's frame
            t0, q0, v0, _, cfg0 = start
            width = q0.shape[1] - (1 if self.ledger else 0)
            q0, v0 = np.array(q0[:, :width], float), np.array(v0[:, :width], float)
            q0[:, CAM] -= shift
            a0 = np.full_like(q0, np.nan)  # its compliant state as it is (``settle.run_settled``)
            start = (t0, q0, v0, a0, np.array(cfg0, np.int64))
        part = self.run(run_cases, one, start=start, full_state=True, **options)
        part = _in_cam_frame(part, shift, [self.cases[i] for i in rows.tolist()])
        turn = part.lash_adjuster[:, 0]  # (rows, 3): this turn's
        after = np.clip(before - turn[:, LEAK_DOWN] + turn[:, PUMP_UP], 0.0, self.travel[rows])
        done = np.isfinite(turn[:, EXTENSION])
        self.table[rows[done], self.turn[rows[done]]] = turn[done]
        self.extension[rows] = np.where(done, after, before)
        self.turn[rows] += 1
        if not self.ledger:
            return part
        return with_ledger(part, before, self.extension[rows], self.travel[rows])


#: The per-turn model's integrals (a turn's leak-down and pump-up, its check valve's
#: switches: ``LashAdjuster.advance``, ``plunger.interpolated_switches``) are taken on
#: samples this far apart [rad] where ``run.output_every`` is a multiple of it (1°, 0.5°,
#: 0.25°, …: the same samples whatever the output), else on its largest divisor below it:
#: they converge as the spacing's square (the bundled finger on its adjuster at 9000 engine
#: rpm, its effective lash after 8 turns: 87.57, 79.32, 75.45, 75.41 µm at 5°, 1°, 0.1°,
#: 0.01°), and a turn's plunger must not move with the spacing its histories are stored at.
ADJUSTER_EVERY = math.radians(0.05)


class Plunger:
    """A batch's adjusters across its turns, one turn a call (``run_turn`` of
    ``engine.settle.run_settled``, and :func:`run_adjusted`'s loop): each case run with its
    plunger where the last turn left it (:func:`extended`), from the start the caller hands
    back (the last turn's end, in the histories' frame: :meth:`_next_start` applies the
    plunger's change there), its extension advanced by the turn's leak-down and pump-up
    (``LashAdjuster.advance``, on samples at most :data:`ADJUSTER_EVERY` apart: the turn runs on
    them, its histories thinned to the output's) and the turn's histories brought to one frame
    (a chain's to its cam's own lift). With ``ledger`` (a run of automatic length) each turn's
    coordinates carry one more column, the plunger's extension at the turn's ends (between them
    e₀ + (e₁ − e₀)·θ/2π + travel·sin²(θ/2), so that its range over a turn is about its travel):
    ``run_settled`` compares it with the rest of the state at the turn boundaries, so a case
    settles only once its plunger repeats to ``settle_tolerance`` of its travel too;
    :meth:`settled` takes the column off again."""

    def __init__(self, cases, settings, run, turns: int, ledger: bool = False) -> None:
        self.hlas: list[LashAdjuster | None] = [adjuster(c.train) for c in cases]
        self.inner = [
            dataclasses.replace(c, train=c.train.replace(hla_leak_down=math.nan)) if h else c
            for c, h in zip(cases, self.hlas, strict=True)
        ]
        pairs = zip(cases, self.hlas, strict=True)
        self.extension = np.array([c.train.hla_extension if h else 0.0 for c, h in pairs])
        self.members = [extended(c, e) for c, e in zip(self.inner, self.extension, strict=True)]
        # a chain's histories go back to the cam's own lift; a finger's stay (its pivot rises)
        self.in_link = _in_link(cases)
        self.index = {id(c): i for i, c in enumerate(cases)}
        n = len(cases)
        self.table = np.full((n, turns, 3), np.nan)
        self.turn = np.zeros(n, np.int64)
        self.status = np.zeros(n, np.int64)
        self.shift = np.zeros(n)  # the frame shift of each case's last turn
        self.change = np.zeros(n)  # the excitation's change at each case's next start [m]
        self.travel = np.array([h.travel if h else 0.0 for h in self.hlas])
        self.closed: list[bool | None] = [None] * n  # each check valve as its last turn left it
        self.run, self.method, self.ledger = run, settings.method, ledger
        self._matrices: dict[int, object] = {}

    def __call__(self, members, one, start=None, full_state=True, **options) -> BatchResult:
        rows = np.array([self.index[id(m)] for m in members], np.int64)
        if start is not None:
            start = self._next_start(rows, start)
        run_cases = [self.members[i] for i in rows.tolist()]
        every = math.ceil(one.output_every / ADJUSTER_EVERY - 1e-9)
        fine = dataclasses.replace(one, output_every=one.output_every / every)
        part = self.run(run_cases, fine, start=start, full_state=True, **options)
        before = self.extension[rows].copy()
        self._advance(rows, part)
        part = thinned(part, every)
        self.shift[rows] = np.where(self.in_link[rows], before, 0.0)
        _to_cam_lift(part, self.shift[rows])
        part = held_extension(part, np.where(self.in_link[rows], before, np.nan))
        if not self.ledger:
            return part
        return with_ledger(part, before, self.extension[rows], self.travel[rows])

    def _advance(self, rows: np.ndarray, part: BatchResult) -> None:
        """Each case's extension by the turn's leak-down and pump-up, its turn in
        :attr:`table`, its member for the next turn and the excitation's change there."""
        old = [self.members[i] for i in rows.tolist()]
        for j, i in enumerate(rows.tolist()):
            self.status[i] = part.status[j] if part.status[j] != 0 else self.status[i]
            h = self.hlas[i]
            if h is None or self.status[i] in FAILURES:
                continue
            force, gap = adjuster_load(old[j], part, j)
            switches = interpolated_switches(
                part.time[j], force, h.check_force, part.contact_state[j], self.closed[i],
                part.events[j],
            )  # fmt: skip
            if self.closed[i] is None:
                self.closed[i] = bool(force[0] > h.check_force)
            if len(switches) % 2:  # the valve as the turn leaves it
                self.closed[i] = not self.closed[i]
            if switches.size:  # among the turn's events, in time order
                both = np.concatenate([part.events[j], switches])
                part.events[j] = both[np.argsort(both[:, EV_TIME], kind="stable")]
            e = float(self.extension[i])
            after, leak, pump = h.advance(e, part.time[j], force, gap)
            self.table[i, self.turn[i]] = (e, leak, pump)
            if after != e:
                self.extension[i] = after
                self.members[i] = extended(self.inner[i], after)
            self.change[i] = after - e
        self.turn[rows] += 1
        new = [self.members[i] for i in rows.tolist()]
        moved = self.change[rows] != 0.0
        lever = moved & ~self.in_link[rows]
        if lever.any():  # a finger's excitation changes by its take-up at the start
            valve_side = _lift_at_zero(new) - _lift_at_zero(old)
            self.change[rows[lever]] = valve_side[lever]

    def _next_start(self, rows: np.ndarray, start: tuple) -> tuple:
        """The caller's start (the last turn's end, in the histories' frame) in the next
        turn's run frame, the plunger's change applied (:func:`_move_follower`)."""
        t0, q0, v0, _, cfg0 = start
        width = q0.shape[1] - (1 if self.ledger else 0)
        q0, v0 = np.array(q0[:, :width], float), np.array(v0[:, :width], float)
        cfg0 = np.array(cfg0, np.int64)
        q0[:, CAM] -= self.shift[rows]
        run_cases = [self.members[i] for i in rows.tolist()]
        change = self.change[rows]
        _move_follower(q0, v0, cfg0, change, _lift_at_zero(run_cases), run_cases)
        self.change[rows] = 0.0
        q0, v0 = np.nan_to_num(q0), np.nan_to_num(v0)
        if self.method == "modal-exact":
            a0 = np.zeros_like(q0)
        else:
            sms = [self._matrix(i) for i in rows.tolist()]
            a0 = consistent_accelerations(run_cases, sms, q0, v0, cfg0)
        a0[[c.compliant for c in run_cases]] = np.nan  # as it is (``settle.run_settled``)
        return (np.zeros(rows.size) if t0 is None else t0, q0, v0, a0, cfg0)

    def _matrix(self, i: int):
        if i not in self._matrices:
            self._matrices[i] = system_matrices(self.inner[i].train)
        return self._matrices[i]

    def settled(self, result: BatchResult) -> BatchResult:
        """``run_settled``'s result without the ledger's column, with the adjusters' table."""
        return without_ledger(result, self.table)


def _part_of_a_turn(cases, settings, run, options) -> BatchResult:
    """A run shorter than a turn: each case on its cam raised by its starting extension."""
    part = run(Plunger(cases, settings, run, 0).members, settings, start=None, **options)
    # a chain's back to the cam's own lift; a finger's pivot stays raised (see run_adjusted)
    shift = np.array([o.train.hla_extension if adjuster(o.train) else 0.0 for o in cases])
    shift[~_in_link(cases)] = 0.0
    table = np.full((len(cases), part.per_rev.shape[1], 3), np.nan)
    part = dataclasses.replace(_in_cam_frame(part, shift, cases), lash_adjuster=table)
    return held_extension(part, np.where(_in_link(cases), shift, np.nan))


def _move_follower(q0, v0, cfg0, change, cam, cases) -> None:
    """The next turn's start in its frame (the cam raised by ``change`` more): a follower on
    the cam rides it up (x1' = x1 + e, the link's force changing by k·Δe: the plunger's
    leak-down or pump-up under load); a follower off it stays where it is, the plunger's
    extension taking its gap up, and where that closes the gap it lands on the cam with the
    cam's velocity, the link compressed by the rest (the check force it pumps up to)."""
    for i in np.flatnonzero(change):
        if holds_cam(int(cfg0[i])):
            q0[i, CAM] -= change[i]
        elif q0[i, CAM] > -cam[i]:  # x1' below the raised cam: on it
            q0[i, CAM] = -cam[i]
            v0[i, CAM] = -cases[i].speed * float(evaluate(cases[i].profile, np.zeros(1))[1][0])
            cfg0[i] = CAM_AND_SEAT if holds_seat(int(cfg0[i])) else CAM_CONTACT


def _joined(parts: list[BatchResult], cases, settings, table, status) -> BatchResult:
    """The turns' results as one run's."""
    first = parts[0]
    omega = np.array([c.speed for c in cases])

    def join(name: str) -> np.ndarray:
        arrays = [getattr(p, name) for p in parts]
        return np.concatenate([a[:, :-1] for a in arrays[:-1]] + [arrays[-1]], axis=1)

    turns = len(parts)
    angles = np.arange(join("cam_lift").shape[1]) * settings.output_every
    events = []
    for i in range(len(omega)):
        shifted = []
        for k, p in enumerate(parts):
            e = p.events[i].copy()
            e[:, EV_TIME] += k * TWO_PI / omega[i]
            shifted.append(e)
        events.append(np.concatenate(shifted))
    result = BatchResult(
        cam_angle=angles,
        time=angles[None, :] / omega[:, None],
        q=join("q"),
        v=join("v"),
        acc=join("acc"),
        cam_lift=join("cam_lift"),
        cam_force=join("cam_force"),
        seat_force=join("seat_force"),
        contact_state=join("contact_state"),
        valve_reference=first.valve_reference,
        measured=settings.measured_turns(turns),
        per_rev=np.concatenate([p.per_rev for p in parts], axis=1),
        trains=[c.train for c in cases],
        events=events,
        steps=np.sum([p.steps for p in parts], axis=0),
        status=status,
        start_time=first.start_time,
        lash_adjuster=table,
        extension=join("extension") if first.extension.size else first.extension,
    )
    return blank_failures(result)
