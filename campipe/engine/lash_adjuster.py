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
its gap shrinking by Δe, and lands on the cam if that closes it).

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.case import Case
from campipe.engine.result import BatchResult, blank_failures
from campipe.engine.settings import adjuster_turns
from campipe.engine.settle import consistent_accelerations
from campipe.model import system_matrices
from campipe.model.elements import chain_elements
from campipe.model.hla import LashAdjuster, adjuster, on_pivot
from campipe.model.layouts import chain_placement
from campipe.profiles import Profile, evaluate
from campipe.profiles.levers import ValveSideProfile, pivot_gains, pivot_raised
from campipe.vocabulary import (
    CAM,
    CAM_AND_SEAT,
    CAM_CONTACT,
    EV_TIME,
    FAILURES,
    holds_cam,
    holds_seat,
)

#: The columns of ``BatchResult.lash_adjuster``: the plunger's extension at each turn's
#: start, the turn's leak-down and its pump-up [m].
EXTENSION, LEAK_DOWN, PUMP_UP = 0, 1, 2


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
    **options,
) -> BatchResult:
    """Run every case turn by turn (see the module), each turn by ``run`` (``run_batch`` of
    one turn from ``start``'s (t0, q0, v0, a0, cfg0) or, for the first, from the settings')
    with ``options`` (its own); cases without an adjuster run the same way with their
    extension 0. The result's ``lash_adjuster`` holds each turn's extension, leak-down and
    pump-up (NaN for a case without an adjuster)."""
    turns = adjuster_turns(settings)
    n = len(cases)
    hlas: list[LashAdjuster | None] = [adjuster(c.train) for c in cases]
    inner = [
        dataclasses.replace(c, train=c.train.replace(hla_leak_down=math.nan)) if h else c
        for c, h in zip(cases, hlas, strict=True)
    ]
    if not turns:  # a part of a turn (a kernel's warm-up): no turn ends, the plunger stays
        return _part_of_a_turn(cases, inner, settings, run, options)
    options.pop("full_state", None)  # every coordinate: a turn's end is the next's start
    one = dataclasses.replace(settings, revolutions=1.0, warmup=0)
    sms = [system_matrices(c.train) for c in inner]
    pairs = zip(cases, hlas, strict=True)
    extension = np.array([c.train.hla_extension if h else 0.0 for c, h in pairs])
    # a chain's histories go back to the cam's own lift; a finger's stay (its pivot truly rises)
    in_link = np.array([not on_pivot(c.train) for c in cases])
    table = np.full((n, turns, 3), np.nan)
    parts: list[BatchResult] = []
    status = np.zeros(n, np.int64)
    start = None
    members = [extended(c, e) for c, e in zip(inner, extension, strict=True)]
    for k in range(turns):
        part = run(members, one, start=start, full_state=True, **options)
        status = np.where(part.status != 0, part.status, status)
        change = np.zeros(n)
        for i, h in enumerate(hlas):
            if h is None or status[i] in FAILURES:
                continue
            force, gap = adjuster_load(members[i], part, i)
            after, leak, pump = h.advance(float(extension[i]), part.time[i], force, gap)
            table[i, k] = (extension[i], leak, pump)
            change[i] = after - extension[i]
        after_turn = [extended(c, e) if d else m for c, e, d, m in
                      zip(inner, extension + change, change, members, strict=True)]  # fmt: skip
        lift_change = np.where(in_link, change, _lift_at_zero(after_turn) - _lift_at_zero(members))
        q0, v0 = part.q[:, -1].copy(), part.v[:, -1].copy()
        cfg0 = part.contact_state[:, -1].astype(np.int64)
        cam_end = part.cam_lift[:, -1] + lift_change  # the cam's lift at the next turn's start
        _move_follower(q0, v0, cfg0, lift_change, cam_end, after_turn)
        # a chain's back to the cam's own lift (the histories of every turn in one frame)
        shift = np.where(in_link, extension, 0.0)
        part.q[:, :, CAM] += shift[:, None]
        part.cam_lift[:] -= shift[:, None]
        parts.append(part)
        extension, members = extension + change, after_turn
        a0 = (
            np.zeros_like(q0)
            if settings.method == "modal-exact"
            else consistent_accelerations(members, sms, q0, v0, cfg0)
        )
        start = (np.zeros(n), np.nan_to_num(q0), np.nan_to_num(v0), a0, cfg0)
    return _joined(parts, cases, settings, table, status)


def _part_of_a_turn(cases, inner, settings, run, options) -> BatchResult:
    """A run shorter than a turn: each case on its cam raised by its starting extension."""
    raised_cases = [
        extended(c, o.train.hla_extension) if adjuster(o.train) else c
        for c, o in zip(inner, cases, strict=True)
    ]
    part = run(raised_cases, settings, start=None, **options)
    # a chain's back to the cam's own lift; a finger's pivot stays raised (see run_adjusted)
    shift = np.array([o.train.hla_extension if adjuster(o.train) else 0.0 for o in cases])
    shift[[on_pivot(o.train) for o in cases]] = 0.0
    part.q[:, :, CAM] += shift[:, None]
    part.cam_lift[:] -= shift[:, None]
    table = np.full((len(cases), part.per_rev.shape[1], 3), np.nan)
    return dataclasses.replace(part, trains=[c.train for c in cases], lash_adjuster=table)


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
    )
    return blank_failures(result)
