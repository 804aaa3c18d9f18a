"""The SciPy peer: ``solve_ivp`` on the same model, event-driven and restarted through impacts.

This is the tool a Python engineer would reach for, written independently of campipe's
integrators: it takes only the model's matrices (:func:`campipe.model.system_matrices`) and the
cam profile's pieces (:class:`campipe.profiles.Profile`), and states the equations of motion
afresh in each contact configuration c (thesis Ch. III, Appendix A):

    M_ff ẍ_f + C_ff ẋ_f + K_ff x_f = f_f − (M_fp q̈_p + C_fp q̇_p + K_fp q_p)

with f the free coordinates, p the held ones (q1 on the cam, q7 on the seat), as a first-order
system z = [x_f; ẋ_f] with a constant Jacobian, integrated by an implicit method (Radau by
default) one profile piece at a time. Every contact switch is a terminal event, direction
upward, on a monitor (thesis Table I):

- cam held, force closure: F1 (the cam would pull) → the follower leaves the cam;
- cam free: q1 + lift(θ) (the follower reaches the cam surface) → cam impact;
- seat free, with a seat: q7_seat − q7 → seat impact;
- seat held: −F7 (the seat would pull) → the valve leaves the seat.

Impacts are the thesis's (Ch. IV): infinite cam (seat) mass, perfectly plastic; the struck
coordinate takes the obstacle's velocity and the free velocities jump by −M_ff⁻¹ M_fp Δv_p
(the consistent mass carries the impulse). A velocity jump of the profile at a break (a flat's
edges) releases the follower where the surface falls away, and is an impact where it rises
into it. The run starts at θ = 0 on the cam in quasi-static equilibrium, as the engine's.

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from campipe.constants import TWO_PI
from campipe.engine.batch import Case
from campipe.errors import CampipeError
from campipe.model import system_matrices
from campipe.vocabulary import (
    CAM,
    CAM_IMPACT,
    CAM_SEPARATION,
    CONFIGURATIONS,
    SEAT,
    SEAT_IMPACT,
    SEAT_SEPARATION,
    configuration,
)

#: Monitor levels, as a contact switch is decided: penetration [m] and tension [N per N of
#: spring preload] a monitor must exceed, so that a contact just made or just left is not
#: switched again by rounding at the segment's first point.
GAP_LEVEL = 1e-13
FORCE_LEVEL = 1e-9
#: Implicit methods get the constant Jacobian.
IMPLICIT = ("Radau", "BDF", "LSODA")
#: Events in a row at one instant, or each within STALL_WINDOW [s] of the last, before a run
#: is declared chattering (a grazing landing that an inaccurate event state turns into an
#: endless impact–release cycle).
MAX_STALLED = 64
STALL_WINDOW = 1e-9


class ChatterError(CampipeError, RuntimeError):
    """Contact events kept recurring at one instant."""


@dataclass(frozen=True)
class _Configuration:
    """One contact configuration's first-order system."""

    free: np.ndarray  # (nf,) free coordinates
    a: np.ndarray  # (2nf, 2nf) constant Jacobian [1/s]
    cam_terms: np.ndarray  # (3, nf) acceleration per unit q1, q̇1, q̈1 of a held cam
    constant: np.ndarray  # (nf,) acceleration from the preload and a held seat [m/s², rad/s²]
    kick: np.ndarray  # (2, 7) velocity change per unit Δv of q1 (row 0) or q7 (row 1) held
    impact_mass: np.ndarray  # (2,) mass an impulse at q1, q7 meets, the rest held [kg]


@dataclass
class IvpResult:
    """One case's run, in the engine's units and conventions (``BatchResult`` per case)."""

    cam_angle: np.ndarray  # (n_out,) [rad]
    q: np.ndarray  # (n_out, 7) [m, rad]
    v: np.ndarray  # (n_out, 7) [m/s, rad/s]
    valve_reference: float  # q7 at zero valve lift [m]
    separation_per_rev: np.ndarray  # (n_rev,) cam angle off the cam per turn [rad]
    max_cam_impact_velocity: float  # [m/s]
    max_seating_velocity: float  # [m/s]
    events: np.ndarray  # (n_ev, 6) as the engine's: time, kind, from, to, velocity, impulse
    nfev: int  # right-hand-side evaluations
    segments: int  # solve_ivp calls

    @property
    def valve_lift(self) -> np.ndarray:
        """(n_out,) valve opening from its base-circle static position [m]."""
        return self.q[:, SEAT] - self.valve_reference


def _configuration(M, C, K, f, cfg: int, seat_q: float) -> _Configuration:
    free = np.array(CONFIGURATIONS[cfg].free)
    nf = free.size
    minv = np.linalg.inv(M[np.ix_(free, free)])
    a = np.zeros((2 * nf, 2 * nf))
    a[:nf, nf:] = np.eye(nf)
    a[nf:, :nf] = -minv @ K[np.ix_(free, free)]
    a[nf:, nf:] = -minv @ C[np.ix_(free, free)]
    cam_held = CAM not in free
    seat_held = SEAT not in free
    cam_terms = np.zeros((3, nf))
    if cam_held:
        cam_terms = -np.stack([minv @ K[free, CAM], minv @ C[free, CAM], minv @ M[free, CAM]])
    load = f[free] - (K[free, SEAT] * seat_q if seat_held else 0.0)
    kick = np.zeros((2, 7))
    impact_mass = np.zeros(2)
    for row, p in enumerate((CAM, SEAT)):
        kick[row, free] = -minv @ M[free, p]
        kick[row, p] = 1.0
        impact_mass[row] = M[p, p] - M[p, free] @ minv @ M[free, p]
    return _Configuration(free, a, cam_terms, minv @ load, kick, impact_mass)


def _static(K, f, held_q: dict[int, float]) -> np.ndarray:
    """Static solution with the given coordinates held."""
    held = np.array(sorted(held_q))
    free = np.setdiff1d(np.arange(7), held)
    q = np.zeros(7)
    q[held] = [held_q[i] for i in held]
    q[free] = np.linalg.solve(K[np.ix_(free, free)], f[free] - K[np.ix_(free, held)] @ q[held])
    return q


class _Cam:
    """The profile's lift on one piece as a scalar function of time (Horner's scheme)."""

    def __init__(self, case: Case) -> None:
        self.profile = case.profile
        self.w = case.speed

    def at(self, piece: int, rev: int, t: float) -> tuple[float, float, float]:
        """Lift [m], its rate [m/s] and acceleration [m/s²] on ``piece`` of turn ``rev``."""
        pr = self.profile
        theta = self.w * t
        x = theta - rev * TWO_PI - pr.breaks[piece]
        c = pr.poly[piece]
        p0 = p1 = p2 = 0.0
        for k in range(7, -1, -1):
            p2 = p2 * x + 2.0 * p1
            p1 = p1 * x + p0
            p0 = p0 * x + c[k]
        s, co = math.sin(theta), math.cos(theta)
        ta, tb = pr.trig[piece]
        w = self.w
        return (p0 + ta * s + tb * co, w * (p1 + ta * co - tb * s), w * w * (p2 - ta * s - tb * co))


def solve_case(
    case: Case,
    revolutions: float = 2.0,
    output_every: float = math.radians(1.0),
    *,
    method: str = "Radau",
    rtol: float = 1e-8,
    atol: float | None = None,
    max_events: int = 4096,
) -> IvpResult:
    """Integrate one case with ``scipy.integrate.solve_ivp``, event by event.

    Parameters
    ----------
    case : Case
        The engine's case: train, profile, speed [rad/s], seat [m], closure.
    revolutions : float
        Cam turns from θ = 0.
    output_every : float
        Output spacing in cam angle [rad].
    method : str
        A ``solve_ivp`` method; Radau, BDF and LSODA are given the constant Jacobian.
    rtol : float
        Relative tolerance.
    atol : float, optional
        Absolute tolerance as a fraction of each state component's scale (the lift for
        translations, lift per rocker arm length for rotations, times ω for velocities);
        default ``rtol``.

    Raises
    ------
    ChatterError
        If events keep recurring at one instant.
    RuntimeError
        If ``solve_ivp`` fails.
    """
    sm = system_matrices(case.train)
    M, C, K, f = sm.mass, sm.damping, sm.stiffness, sm.preload
    w = case.speed
    cam = _Cam(case)
    profile = case.profile
    n_pieces = profile.n_pieces
    q_ref = _static(K, f, {CAM: 0.0})[SEAT]
    has_seat = case.has_seat
    seat_q = q_ref + (case.seat if has_seat else 0.0)
    form = case.closure == "form"
    configs = {c: _configuration(M, C, K, f, c, seat_q) for c in (1, 2, 3, 4)}
    eps_force = FORCE_LEVEL * (abs(f).max() + 1.0)

    lift_max = float(np.abs(profile.poly[:, 0]).max() + np.abs(profile.trig).sum(axis=1).max())
    scale = np.full(7, max(lift_max, 1e-6))
    scale[[2, 4, 5]] /= case.train.rocker_pushrod_arm_length
    atol_frac = rtol if atol is None else atol

    # Quasi-static start at θ = 0 on the cam (thesis Appendix B, step 1).
    piece = int(np.searchsorted(profile.breaks, 0.0, side="right") - 1)
    rev = 0
    lift0, dlift0, _ = cam.at(piece, rev, 0.0)
    q = _static(K, f, {CAM: -lift0})
    v = _static(K, np.zeros(7), {CAM: -dlift0})
    cfg = 1
    if has_seat and q[SEAT] < seat_q:
        q = _static(K, f, {CAM: -lift0, SEAT: seat_q})
        v = _static(K, np.zeros(7), {CAM: -dlift0, SEAT: 0.0})
        cfg = 3

    t_end = revolutions * TWO_PI / w
    n_out = int(math.floor(revolutions * TWO_PI / output_every + 1e-9)) + 1
    t_out = np.arange(n_out) * output_every / w
    q_out = np.zeros((n_out, 7))
    v_out = np.zeros((n_out, 7))
    k_out = 0
    n_rev = int(math.ceil(revolutions - 1e-12))
    sep = np.zeros(n_rev)
    events: list[tuple[float, ...]] = []
    v_cam_max = 0.0
    v_seat_max = 0.0
    nfev = 0
    segments = 0
    stalled = 0

    def add_separation(ta: float, tb: float) -> None:
        a, b = w * ta, w * tb
        r = int(a / TWO_PI)
        while a < b and r < n_rev:
            end = min(b, (r + 1) * TWO_PI)
            sep[r] += end - a
            a = end
            r += 1

    t = 0.0
    while t < t_end:
        cam_held = cfg in (1, 3)
        seat_held = cfg in (3, 4)
        conf = configs[cfg]
        fr = conf.free
        nf = fr.size
        nxt, rev_next = (piece + 1, rev) if piece + 1 < n_pieces else (0, rev + 1)
        t_break = (rev * TWO_PI + profile.breaks[piece + 1]) / w
        t_stop = min(t_break, t_end)
        pc, rc = piece, rev  # bind the piece for the closures below

        def held_state(tt, x, xd, pc=pc, rc=rc, cam_held=cam_held, seat_held=seat_held, fr=fr):
            qq = np.empty(7)
            vv = np.empty(7)
            qq[fr] = x
            vv[fr] = xd
            lift, dlift, ddlift = cam.at(pc, rc, tt)
            if cam_held:
                qq[CAM], vv[CAM] = -lift, -dlift
            if seat_held:
                qq[SEAT], vv[SEAT] = seat_q, 0.0
            return qq, vv, -ddlift, lift

        def rhs(tt, z, conf=conf, nf=nf, pc=pc, rc=rc, cam_held=cam_held):
            out = conf.a @ z
            out[nf:] += conf.constant
            if cam_held:
                lift, dlift, ddlift = cam.at(pc, rc, tt)
                out[nf:] += conf.cam_terms.T @ (-lift, -dlift, -ddlift)
            return out

        def force(tt, z, row, conf=conf, nf=nf, cam_held=cam_held, rhs=rhs, held_state=held_state):
            """Contact force at coordinate ``row``: row of M·q̈ + C·q̇ + K·q − f."""
            qq, vv, acam, _ = held_state(tt, z[:nf], z[nf:])
            acc = np.zeros(7)
            acc[conf.free] = rhs(tt, z)[nf:]
            if cam_held:
                acc[CAM] = acam
            return M[row] @ acc + C[row] @ vv + K[row] @ qq - f[row]

        monitors: list[Any] = []  # solve_ivp's events: callables with terminal, direction
        kinds = []
        if not (cam_held and form):
            if cam_held:
                monitors.append(lambda tt, z: force(tt, z, CAM) - eps_force)
                kinds.append(CAM_SEPARATION)
            else:
                i1 = int(np.flatnonzero(fr == CAM)[0])
                monitors.append(
                    lambda tt, z, i1=i1, pc=pc, rc=rc: z[i1] + cam.at(pc, rc, tt)[0] - GAP_LEVEL
                )
                kinds.append(CAM_IMPACT)
        if seat_held:
            monitors.append(lambda tt, z: -force(tt, z, SEAT) - eps_force)
            kinds.append(SEAT_SEPARATION)
        elif has_seat:
            i7 = int(np.flatnonzero(fr == SEAT)[0])
            monitors.append(lambda tt, z, i7=i7: seat_q - z[i7] - GAP_LEVEL)
            kinds.append(SEAT_IMPACT)
        for g in monitors:
            g.terminal = True
            g.direction = 1.0

        z0 = np.concatenate([q[fr], v[fr]])
        # A monitor already above its level at the segment start is an event here.
        fired = [k for k, g in enumerate(monitors) if g(t, z0) > 0.0]
        t_ev = t
        kind = None
        if fired:
            kind = kinds[fired[0]]
            stalled += 1
            if stalled > MAX_STALLED:
                raise ChatterError(f"contact events kept recurring at t = {t:.9g} s")
        elif t_stop - t > 1e-15 * (1.0 + t):
            tol = atol_frac * np.concatenate([scale[fr], w * scale[fr]])
            kw = {"jac": lambda tt, z, a=conf.a: a} if method in IMPLICIT else {}
            sol = solve_ivp(
                rhs,
                (t, t_stop),
                z0,
                method=method,
                rtol=rtol,
                atol=tol,
                events=monitors,
                dense_output=True,
                **kw,
            )
            segments += 1
            nfev += sol.nfev
            t_seg = sol.t[-1]
            if sol.status == -1:
                # Radau can stop an ulp short of the end, where the last step is below its
                # minimum; that is the end.
                if t_stop - t_seg > 8 * np.spacing(t_stop):
                    raise RuntimeError(f"solve_ivp failed at t = {t_seg:.9g} s: {sol.message}")
                t_seg = t_stop
            if sol.status == 1:
                hit = [k for k, te in enumerate(sol.t_events) if len(te)]
                k = min(hit, key=lambda k: sol.t_events[k][0])
                kind = kinds[k]
                t_ev = t_seg = float(sol.t_events[k][0])
                z_end = sol.y_events[k][0]
                stalled = stalled + 1 if t_ev - t < STALL_WINDOW else 0
                if stalled > MAX_STALLED:
                    raise ChatterError(
                        f"contact events kept recurring within "
                        f"{STALL_WINDOW:g} s of each other at t = {t:.9g} s "
                        f"(method {method}, rtol {rtol:g})"
                    )
            else:
                z_end = sol.y[:, -1]
            while k_out < n_out and t_out[k_out] <= t_seg * (1.0 + 1e-14):
                zs = sol.sol(t_out[k_out])
                q_out[k_out], v_out[k_out], _, _ = held_state(t_out[k_out], zs[:nf], zs[nf:])
                k_out += 1
            if not cam_held:
                add_separation(t, t_seg)
            q, v, _, _ = held_state(t_seg, z_end[:nf], z_end[nf:])
            t = t_seg
        else:
            t = t_stop
        if kind is not None:
            lift, dlift, _ = cam.at(piece, rev, t_ev)
            if kind == CAM_SEPARATION:
                new = configuration(False, seat_held)
                events.append((t_ev, kind, cfg, new, 0.0, 0.0))
            elif kind == SEAT_SEPARATION:
                new = configuration(cam_held, False)
                events.append((t_ev, kind, cfg, new, 0.0, 0.0))
            elif kind == CAM_IMPACT:
                new = configuration(True, seat_held)
                closing = v[CAM] + dlift
                v = v + configs[new].kick[0] * (-dlift - v[CAM])
                q[CAM] = -lift
                v_cam_max = max(v_cam_max, closing)
                events.append(
                    (t_ev, kind, cfg, new, closing, configs[new].impact_mass[0] * closing)
                )
            else:
                new = configuration(cam_held, True)
                closing = -v[SEAT]
                v = v + configs[new].kick[1] * closing
                q[SEAT] = seat_q
                v_seat_max = max(v_seat_max, closing)
                events.append(
                    (t_ev, kind, cfg, new, closing, configs[new].impact_mass[1] * closing)
                )
            cfg = new
            continue
        if t >= t_end:
            break
        # A break of the profile: the next piece, and any jump in the surface's velocity.
        l_left, dl_left, _ = cam.at(piece, rev, t)
        l_right, dl_right, _ = cam.at(nxt, rev_next, t)
        if cam_held:
            jump = dl_right - dl_left  # lift-rate jump [m/s]
            small = 1e-9 * (abs(dl_left) + abs(dl_right) + 1e-12)
            if (jump < -small or l_right < l_left - 1e-12) and not form:
                new = configuration(False, seat_held)
                events.append((t, CAM_SEPARATION, cfg, new, -jump, 0.0))
                cfg = new
            elif abs(jump) > small:
                v = v + configs[cfg].kick[0] * (-jump)
                v_cam_max = max(v_cam_max, abs(jump))
                events.append(
                    (t, CAM_IMPACT, cfg, cfg, abs(jump), configs[cfg].impact_mass[0] * abs(jump))
                )
                q[CAM], v[CAM] = -l_right, -dl_right
        piece, rev = nxt, rev_next
    if len(events) > max_events:
        events = events[:max_events]
    return IvpResult(
        cam_angle=t_out * w,
        q=q_out[:k_out] if k_out < n_out else q_out,
        v=v_out[:k_out] if k_out < n_out else v_out,
        valve_reference=float(q_ref),
        separation_per_rev=sep,
        max_cam_impact_velocity=v_cam_max,
        max_seating_velocity=v_seat_max,
        events=np.array(events, dtype=float).reshape(-1, 6),
        nfev=nfev,
        segments=segments,
    )
