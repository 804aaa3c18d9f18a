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
(the consistent mass carries the impulse). With a coefficient of restitution e the impulse is
(1 + e) times that and the struck coordinate leaves at e·v_closing, until a bounce slower than
the capture velocity, or after a flight below ``MICRO_FLIGHT``, is plastic. A velocity jump
of the profile at a break (a flat's edges) releases the follower where the surface falls away,
and is an impact where it rises into it. The contact rules are the engine's, written again
here: an impact needs a positive closing velocity; with the other contact held, it releases
where the impact would separate it faster than the capture velocity; an impact slower than
that leaves its contact resting (held as any other: it releases where its force reaches
zero, to ``common.RESTING_LEVEL`` of the force level), and a release it closes again at once
is taken back. The run starts where the engine's does (``campipe.engine.start_states``): the
scenario is the same, the integration independent.

A chain's lash adjuster rides along (``campipe.model.hla``; its parameters from
``engine.plunger.plunger_state``, its law written here): the plunger's u is the state's last
entry, u̇ = −(F − F_c)/c in the regime its check valve gives, F_c/c_P where the link would
pull it (F < 0: it only pushes), each switch of the check valve and of its load through 0
(with the engine's dead bands) and each end of its travel a terminal event.

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from campipe.constants import TWO_PI
from campipe.engine.batch import start_states
from campipe.engine.common import MICRO_FLIGHT, RESTING_LEVEL
from campipe.engine.plunger import (
    BOTTOMED,
    CLOSED,
    HELD,
    HYSTERESIS,
    OPEN,
    TOPPED,
    UNLOADED,
    PlungerState,
    plunger_state,
)
from campipe.engine.settings import (
    DEFAULT_CAPTURE_VELOCITY,
    Case,
    RunSettings,
    sample_count,
    turn_count,
)
from campipe.errors import CampipeError
from campipe.model import system_matrices
from campipe.model.hla import adjuster
from campipe.profiles import Lift
from campipe.vocabulary import (
    CAM,
    CAM_IMPACT,
    CAM_SEPARATION,
    CHECK_VALVE_CLOSES,
    CHECK_VALVE_OPENS,
    CONFIGURATIONS,
    PLUNGER_BOTTOMS,
    PLUNGER_TOPS,
    SEAT,
    SEAT_IMPACT,
    SEAT_SEPARATION,
    configuration,
    holds_cam,
    holds_seat,
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
    separation_per_rev: np.ndarray  # (n_rev,) cam angle in configuration II per turn [rad]
    seated_off_cam_per_rev: np.ndarray  # (n_rev,) cam angle in configuration IV per turn [rad]
    max_cam_impact_velocity: float  # [m/s]
    max_seating_velocity: float  # [m/s]
    events: np.ndarray  # (n_ev, 6) as the engine's: time, kind, from, to, velocity, impulse
    nfev: int  # right-hand-side evaluations
    segments: int  # solve_ivp calls
    #: a chain's lash adjuster: its plunger's u = e − e₀ at the samples [m], and each turn's
    #: leak-down and pump-up [m] (zeros without one)
    plunger: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    plunger_ledger: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))

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


class _Peer:
    """One case's run: its state between events and what it has recorded."""

    def __init__(self, case: Case, revolutions: float, output_every: float, method: str,
                 rtol: float, atol: float | None, start: str, capture: float) -> None:  # fmt: skip
        sm = system_matrices(case.train)
        self.M, self.C, self.K, self.f = sm.mass, sm.damping, sm.stiffness, sm.preload
        self.case, self.w, self.cam = case, case.speed, Lift(case.profile, case.speed)
        self.method, self.rtol = method, rtol
        self.q_ref = _static(self.K, self.f, {CAM: 0.0})[SEAT]
        self.seat_q = self.q_ref + (case.seat if case.has_seat else 0.0)
        self.form = case.closure == "form"
        self.configs = {
            c: _configuration(self.M, self.C, self.K, self.f, c, self.seat_q)
            for c in CONFIGURATIONS
        }
        self.eps_force = FORCE_LEVEL * (abs(self.f).max() + 1.0)
        self.capture = capture
        # Newton's restitution at the cam and the seat, and when each last bounced [s].
        self.restitution = (case.train.cam_restitution, case.train.seat_restitution)
        self.bounced = [-math.inf, -math.inf]
        # The other contact's separation velocity per unit velocity change of the struck one,
        # if released: the valve opening after a cam impact (configuration I), the follower
        # lifting off the cam after a seat impact (configuration IV).
        self.separation = (self.configs[1].kick[0][SEAT], -self.configs[4].kick[1][CAM])
        profile = case.profile
        lift_max = float(np.abs(profile.poly[:, 0]).max() + np.abs(profile.trig).sum(axis=1).max())
        self.scale = np.full(7, max(lift_max, 1e-6))
        self.scale[[2, 4, 5]] /= case.train.rocker_pushrod_arm_length
        self.atol_frac = rtol if atol is None else atol
        settings = RunSettings(
            revolutions=revolutions, start=start, warmup=0, integrator="modal-exact"
        )
        begin = start_states([case], settings)
        self.t = float(begin.t0[0])
        self.q = begin.q0[0].copy()
        self.v = begin.v0[0].copy()
        self.cfg = int(begin.cfg0[0])
        self.rev = math.floor(self.w * self.t / TWO_PI)
        phi = self.w * self.t - self.rev * TWO_PI
        piece = int(np.searchsorted(profile.breaks, phi, side="right") - 1)
        self.piece = min(max(piece, 0), profile.n_pieces - 1)
        self.t_end = revolutions * TWO_PI / self.w
        n_out = sample_count(revolutions, output_every)
        self.t_out = np.arange(n_out) * output_every / self.w
        self.q_out = np.zeros((n_out, 7))
        self.v_out = np.zeros((n_out, 7))
        self.k_out = 0
        n_rev = turn_count(revolutions)
        self.off_cam = {False: np.zeros(n_rev), True: np.zeros(n_rev)}  # by seat held
        self.events: list[tuple[float, ...]] = []
        self.v_max = [0.0, 0.0]  # cam, seat
        self.nfev = 0
        self.segments = 0
        self.stalled = 0
        self.resting = {CAM: False, SEAT: False}  # captured by a slow impact (``impact``)
        # A chain's lash adjuster: its plunger's u = e − e₀ the state's last entry, held until
        # t = 0, then in the regime its load gives (see ``plunger_rate``).
        self.p = plunger_state(case.train, np.linalg.inv(self.M)) if adjuster(case.train) else None
        self.u = 0.0
        self.regime = HELD
        self.push = {
            c: (np.linalg.solve(self.M[np.ix_(g.free, g.free)], self.p.k * self.p.d[g.free])
                if self.p is not None else None)
            for c, g in self.configs.items()
        }  # fmt: skip
        self.u_out = np.zeros(n_out)
        self.ledger = np.zeros((n_rev, 2))  # each turn's leak-down, pump-up [m]

    # -- a chain's plunger (``plunger_state`` gives its parameters; its law written here) ----

    @property
    def law(self) -> PlungerState:
        """The adjuster's parameters (a case with one)."""
        assert self.p is not None
        return self.p

    def link_force(self, qq, u):
        """The force through the adjuster [N]: the link's, k·(d·q + u)."""
        return self.law.k * (float(self.law.d @ qq) + u)

    def plunger_rate(self, tt, z):
        """u̇ [m/s]: −(F − F_c)/c, c the leak-down's with the check valve closed and the
        pump-up's with it open; F_c/c_P unloaded (the link pulling: no load on it); 0 held at
        an end of its travel, or until t = 0."""
        nf = self.configs[self.cfg].free.size
        if self.regime == UNLOADED:
            return self.law.check_force / self.law.pump_up
        if self.regime not in (CLOSED, OPEN):
            return 0.0
        qq, _, _ = self.held_state(tt, z[:nf], z[nf : 2 * nf])
        c = self.law.leak_down if self.regime == CLOSED else self.law.pump_up
        return -(self.link_force(qq, z[2 * nf]) - self.law.check_force) / c

    def plunger_monitors(self):
        """(g, regime after, event kind) of the plunger's switches out of its regime, each
        an event where g rises through 0 (the check valve with its dead band HYSTERESIS)."""
        p, reg = self.p, self.regime
        if p is None or reg == HELD:
            return []
        nf = self.configs[self.cfg].free.size

        def force(tt, z):
            qq, _, _ = self.held_state(tt, z[:nf], z[nf : 2 * nf])
            return self.link_force(qq, z[2 * nf])

        opens = (lambda tt, z: p.check_force * (1.0 - HYSTERESIS) - force(tt, z), OPEN,
                 CHECK_VALVE_OPENS)  # fmt: skip
        closes = (lambda tt, z: force(tt, z) - p.check_force * (1.0 + HYSTERESIS), CLOSED,
                  CHECK_VALVE_CLOSES)  # fmt: skip
        tops = (lambda tt, z: z[2 * nf] - p.high, TOPPED, PLUNGER_TOPS)
        band = p.check_force * HYSTERESIS
        if reg == CLOSED:
            return [opens, (lambda tt, z: p.low - z[2 * nf], BOTTOMED, PLUNGER_BOTTOMS)]
        if reg == OPEN:
            return [closes, tops, (lambda tt, z: -band - force(tt, z), UNLOADED, None)]
        if reg == UNLOADED:
            return [(lambda tt, z: force(tt, z) - band, OPEN, None), tops]
        return [opens] if reg == BOTTOMED else [closes]

    def release_plunger(self):
        """Held until t = 0: the regime the load there gives."""
        if self.p is None or self.regime != HELD or self.t < 0.0:
            return
        load = self.link_force(self.q, self.u)
        if load > self.p.check_force:
            self.regime = BOTTOMED if self.u <= self.p.low else CLOSED
        elif self.u >= self.p.high:
            self.regime = TOPPED
        else:
            self.regime = UNLOADED if load < 0.0 else OPEN

    # -- the equations in the current configuration ------------------------------------------

    def held_state(self, tt, x, xd):
        """q, q̇ with the held coordinates on the cam and the seat; the cam's q̈1."""
        fr = self.configs[self.cfg].free
        qq = np.empty(7)
        vv = np.empty(7)
        qq[fr] = x
        vv[fr] = xd
        lift, dlift, ddlift = self.cam.at(self.piece, self.rev, tt)
        if holds_cam(self.cfg):
            qq[CAM], vv[CAM] = -lift, -dlift
        if holds_seat(self.cfg):
            qq[SEAT], vv[SEAT] = self.seat_q, 0.0
        return qq, vv, -ddlift

    def rhs(self, tt, z):
        conf = self.configs[self.cfg]
        nf = conf.free.size
        out = conf.a @ z[: 2 * nf]
        out[nf:] += conf.constant
        if holds_cam(self.cfg):
            lift, dlift, ddlift = self.cam.at(self.piece, self.rev, tt)
            out[nf:] += conf.cam_terms.T @ (-lift, -dlift, -ddlift)
        if self.p is None:
            return out
        out[nf:] -= self.push[self.cfg] * z[2 * nf]
        return np.append(out, self.plunger_rate(tt, z))

    def force(self, tt, z, row):
        """Contact force at coordinate ``row``: row of M·q̈ + C·q̇ + K·q − f."""
        conf = self.configs[self.cfg]
        nf = conf.free.size
        qq, vv, acam = self.held_state(tt, z[:nf], z[nf : 2 * nf])
        acc = np.zeros(7)
        acc[conf.free] = self.rhs(tt, z)[nf : 2 * nf]
        if holds_cam(self.cfg):
            acc[CAM] = acam
        out = self.M[row] @ acc + self.C[row] @ vv + self.K[row] @ qq - self.f[row]
        if self.p is not None:
            out += self.p.k * self.p.d[row] * z[2 * nf]
        return out

    def monitors(self):
        """solve_ivp's events (terminal, upward), their kinds, and for a gap its closing
        velocity."""
        fr = self.configs[self.cfg].free
        nf = fr.size
        cam_held, seat_held = holds_cam(self.cfg), holds_seat(self.cfg)
        out: list[tuple[Any, int, Any]] = []
        if not (cam_held and self.form):
            if cam_held:
                lv = self.eps_force * (RESTING_LEVEL if self.resting[CAM] else 1.0)
                out.append((lambda tt, z: self.force(tt, z, CAM) - lv, CAM_SEPARATION, None))
            else:
                i1 = int(np.flatnonzero(fr == CAM)[0])
                out.append((
                    lambda tt, z: z[i1] + self.cam.at(self.piece, self.rev, tt)[0] - GAP_LEVEL,
                    CAM_IMPACT,
                    lambda tt, z: z[nf + i1] + self.cam.at(self.piece, self.rev, tt)[1],
                ))  # fmt: skip
        if seat_held:
            lv7 = self.eps_force * (RESTING_LEVEL if self.resting[SEAT] else 1.0)
            out.append((lambda tt, z: -self.force(tt, z, SEAT) - lv7, SEAT_SEPARATION, None))
        elif self.case.has_seat:
            i7 = int(np.flatnonzero(fr == SEAT)[0])
            out.append((
                lambda tt, z: self.seat_q - z[i7] - GAP_LEVEL,
                SEAT_IMPACT,
                lambda tt, z: -z[nf + i7],
            ))  # fmt: skip
        for g, _, _ in out:
            g.terminal = True
            g.direction = 1.0
        return out

    # -- one segment, up to an event or a break ----------------------------------------------

    def segment(self, t_stop):
        """Integrate to an event or ``t_stop``; returns (the event's kind or None, its time)."""
        conf = self.configs[self.cfg]
        fr = conf.free
        nf = fr.size
        self.release_plunger()
        monitors = self.monitors() + [
            (g, ("plunger", regime, kind), None) for g, regime, kind in self.plunger_monitors()
        ]
        for g, _, _ in monitors:
            g.terminal = True
            g.direction = 1.0
        z0 = np.concatenate([self.q[fr], self.v[fr], [self.u] if self.p is not None else []])
        # A monitor already above its level at the segment start is an event here (a gap
        # only if it closes).
        for g, kind, closing in monitors:
            if g(self.t, z0) > 0.0 and (closing is None or closing(self.t, z0) > 0.0):
                self.stalled += 1
                if self.stalled > MAX_STALLED:
                    raise ChatterError(f"contact events kept recurring at t = {self.t:.9g} s")
                return kind, self.t
        if t_stop - self.t <= 1e-15 * (1.0 + abs(self.t)):
            self.t = t_stop
            return None, t_stop
        tol = self.atol_frac * np.concatenate([self.scale[fr], self.w * self.scale[fr]])
        if self.p is not None:
            tol = np.append(tol, self.atol_frac * (self.p.high - self.p.low))
        constant = self.method in IMPLICIT and self.p is None  # (a plunger's: left to solve_ivp)
        kw = {"jac": lambda tt, z, a=conf.a: a} if constant else {}
        sol = solve_ivp(
            self.rhs, (self.t, t_stop), z0, method=self.method, rtol=self.rtol, atol=tol,
            events=[m[0] for m in monitors], dense_output=True, **kw,
        )  # fmt: skip
        self.segments += 1
        self.nfev += sol.nfev
        t_seg = sol.t[-1]
        kind = None
        if sol.status == -1:
            # Radau can stop an ulp short of the end, where the last step is below its
            # minimum; that is the end.
            if t_stop - t_seg > 8 * np.spacing(t_stop):
                raise RuntimeError(f"solve_ivp failed at t = {t_seg:.9g} s: {sol.message}")
            t_seg = t_stop
        if sol.status == 1:
            hit = [k for k, te in enumerate(sol.t_events) if len(te)]
            k = min(hit, key=lambda k: sol.t_events[k][0])
            kind = monitors[k][1]
            t_seg = float(sol.t_events[k][0])
            z_end = sol.y_events[k][0]
            self.stalled = self.stalled + 1 if t_seg - self.t < STALL_WINDOW else 0
            if self.stalled > MAX_STALLED:
                raise ChatterError(
                    f"contact events kept recurring within {STALL_WINDOW:g} s of each other "
                    f"at t = {self.t:.9g} s (method {self.method}, rtol {self.rtol:g})"
                )
        else:
            z_end = sol.y[:, -1]
        while self.k_out < self.t_out.size and self.t_out[self.k_out] <= t_seg * (1.0 + 1e-14):
            zs = sol.sol(self.t_out[self.k_out])
            qv = self.held_state(self.t_out[self.k_out], zs[:nf], zs[nf : 2 * nf])
            self.q_out[self.k_out], self.v_out[self.k_out] = qv[0], qv[1]
            if self.p is not None:
                self.u_out[self.k_out] = zs[2 * nf]
            self.k_out += 1
        if not holds_cam(self.cfg):
            self.add_off_cam(self.t, t_seg, self.cfg == 4)
        if self.p is not None:
            self.add_plunger_motion(self.t, self.u, z_end[2 * nf])
            self.u = float(z_end[2 * nf])
        self.q, self.v, _ = self.held_state(t_seg, z_end[:nf], z_end[nf : 2 * nf])
        self.t = t_seg
        return kind, t_seg

    def add_plunger_motion(self, ta: float, u_a: float, u_b: float) -> None:
        """The plunger's motion over a segment (within one piece: one turn) from ta [s]:
        leak-down where its check valve is closed, pump-up where open."""
        r = int(math.floor(self.w * ta / TWO_PI + 1e-12))
        if ta < 0.0 or r >= self.ledger.shape[0]:
            return
        if self.regime == CLOSED:
            self.ledger[r, 0] += u_a - u_b
        elif self.regime in (OPEN, UNLOADED):
            self.ledger[r, 1] += u_b - u_a

    def add_off_cam(self, ta: float, tb: float, seat_held: bool, sign: float = 1.0) -> None:
        """Add (``sign`` 1) or take back (-1) the cam angle of [ta, tb] ∩ [0, ∞) [s] off the
        cam, seated or not, to each turn it overlaps."""
        sums = self.off_cam[seat_held]
        a, b = max(self.w * ta, 0.0), self.w * tb
        r = int(a / TWO_PI)
        while a < b and r < sums.size:
            end = min(b, (r + 1) * TWO_PI)
            sums[r] = max(sums[r] + sign * (end - a), 0.0)
            a = end
            r += 1

    # -- events ------------------------------------------------------------------------------

    def apply(self, kind, t_ev):
        """A monitor fired at t_ev: release the contact, or (a closing gap) the impact; a
        plunger's: its next regime (held at an end, put there)."""
        cfg = self.cfg
        if isinstance(kind, tuple):
            _, self.regime, code = kind
            if self.regime == BOTTOMED:
                self.u = self.law.low
            elif self.regime == TOPPED:
                self.u = self.law.high
            if t_ev >= 0.0 and code is not None:
                self.events.append((t_ev, code, cfg, cfg, 0.0, 0.0))
            return
        cam_held, seat_held = holds_cam(cfg), holds_seat(cfg)
        lift, dlift, _ = self.cam.at(self.piece, self.rev, t_ev)
        if kind in (CAM_SEPARATION, SEAT_SEPARATION):
            seat = kind == SEAT_SEPARATION
            new = configuration(cam_held, False) if seat else configuration(False, seat_held)
            self.resting[SEAT if seat else CAM] = False
            if t_ev >= 0.0:
                self.events.append((t_ev, kind, cfg, new, 0.0, 0.0))
            self.cfg = new
            return
        seat = kind == SEAT_IMPACT
        closing = -self.v[SEAT] if seat else self.v[CAM] + dlift
        if closing <= 0.0:
            return  # a touch that does not close is no event
        e = self.impact(t_ev, seat, closing)
        if not seat:
            self.q[CAM], self.v[CAM] = -lift, -dlift - e * closing

    def impact(self, t_ev, seat, closing):
        """The impact at the cam or the seat, closing at ``closing`` > 0 [m/s]: plastic, or
        with a coefficient of restitution e > 0 a bounce that leaves at e·closing, unless it is
        slower than the capture velocity or its flight since the last bounce there stayed
        below ``MICRO_FLIGHT`` (the series has converged): then plastic, and resting. A
        landing slower than the capture velocity right after its contact's release, closing ×
        flight below ``MICRO_FLIGHT``, never left: the release, and its flight's angle off the
        cam, are taken back (the engine's rule, ``common.record_impact``). Returns the e it
        bounced with (0: plastic)."""
        cfg = self.cfg
        side, coord = (1, SEAT) if seat else (0, CAM)
        other_held = holds_cam(cfg) if seat else holds_seat(cfg)
        elastic = self.restitution[side] > 0.0
        converged = closing * (t_ev - self.bounced[side]) < MICRO_FLIGHT
        rest = closing < self.capture or (elastic and converged)
        bounce = elastic and not rest
        e = self.restitution[side] if bounce else 0.0
        dv = (closing if seat else -closing) * (1.0 + e)
        if other_held and self.separation[side] * dv > self.capture:
            other_held = False  # the impact separates the other contact: it releases
            self.resting[CAM if seat else SEAT] = False
        held = configuration(other_held, True) if seat else configuration(True, other_held)
        self.v = self.v + self.configs[held].kick[side] * dv
        if seat:
            self.q[SEAT] = self.seat_q
        new = held
        if bounce:
            new = configuration(other_held, False) if seat else configuration(False, other_held)
            self.bounced[side] = t_ev
            self.resting[coord] = False
        self.cfg = new
        if rest:
            self.resting[coord] = True
            last = self.events[-1] if self.events else None
            release = SEAT_SEPARATION if seat else CAM_SEPARATION
            taken_back = (
                last is not None
                and last[1] == release
                and last[3] == cfg
                and closing * (t_ev - last[0]) < MICRO_FLIGHT
            )
            if closing < self.capture and taken_back:
                t_left = self.events.pop()[0]  # it never really left: the release is taken
                if not seat:  # back, and so is its flight's angle off the cam
                    self.add_off_cam(t_left, t_ev, holds_seat(cfg), -1.0)
                elif not holds_cam(cfg):  # a seat flight off the cam: seated all along
                    self.add_off_cam(t_left, t_ev, False, -1.0)
                    self.add_off_cam(t_left, t_ev, True)
                return e
        if t_ev >= 0.0:
            self.v_max[side] = max(self.v_max[side], closing)
            mass = self.configs[held].impact_mass[side]
            kind = SEAT_IMPACT if seat else CAM_IMPACT
            self.events.append((t_ev, kind, cfg, new, closing, mass * (1.0 + e) * closing))
        return e

    def cross_break(self, nxt, rev_next):
        """A break of the profile: any jump in the surface's velocity, with the cam held."""
        t, cfg = self.t, self.cfg
        l_left, dl_left, _ = self.cam.at(self.piece, self.rev, t)
        l_right, dl_right, _ = self.cam.at(nxt, rev_next, t)
        seat_held = holds_seat(cfg)
        if not holds_cam(cfg):
            return
        jump = dl_right - dl_left  # lift-rate jump [m/s]
        # Rounding, or slower than an impact that would count (the capture velocity).
        small = max(1e-9 * (abs(dl_left) + abs(dl_right) + 1e-12), self.capture)
        if (jump < -small or l_right < l_left - 1e-12) and not self.form:
            self.cfg = configuration(False, seat_held)
            self.resting[CAM] = False
            if t >= 0.0:
                self.events.append((t, CAM_SEPARATION, cfg, self.cfg, -jump, 0.0))
            return
        if abs(jump) > small:
            # With restitution, a surface jumping into a force-closed follower throws it off.
            bounce = jump > 0.0 and self.restitution[0] > 0.0 and not self.form
            e = self.restitution[0] if bounce else 0.0
            dv = -jump * (1.0 + e)
            if seat_held and self.separation[0] * dv > self.capture:
                seat_held = False
                self.resting[SEAT] = False
            held = configuration(True, seat_held)
            self.v = self.v + self.configs[held].kick[0] * dv
            self.cfg = configuration(False, seat_held) if bounce else held
            if bounce:
                self.bounced[0] = t
                self.resting[CAM] = False
            if t >= 0.0:
                self.v_max[0] = max(self.v_max[0], abs(jump))
                mass = self.configs[held].impact_mass[0] * (1.0 + e)
                self.events.append((t, CAM_IMPACT, cfg, self.cfg, abs(jump), mass * abs(jump)))
            self.q[CAM], self.v[CAM] = -l_right, -dl_right - e * jump

    def run(self, max_events: int) -> IvpResult:
        profile = self.case.profile
        while self.t < self.t_end:
            if self.piece + 1 < profile.n_pieces:
                nxt, rev_next = self.piece + 1, self.rev
            else:
                nxt, rev_next = 0, self.rev + 1
            t_break = (self.rev * TWO_PI + profile.breaks[self.piece + 1]) / self.w
            kind, t_ev = self.segment(min(t_break, self.t_end))
            if kind is not None:
                self.apply(kind, t_ev)
                continue
            if self.t >= self.t_end:
                break
            self.cross_break(nxt, rev_next)
            self.piece, self.rev = nxt, rev_next
        events = self.events[:max_events]
        n_out = self.t_out.size
        return IvpResult(
            cam_angle=self.t_out * self.w,
            q=self.q_out[: self.k_out] if self.k_out < n_out else self.q_out,
            v=self.v_out[: self.k_out] if self.k_out < n_out else self.v_out,
            valve_reference=float(self.q_ref),
            separation_per_rev=self.off_cam[False],
            seated_off_cam_per_rev=self.off_cam[True],
            max_cam_impact_velocity=self.v_max[0],
            max_seating_velocity=self.v_max[1],
            events=np.array(events, dtype=float).reshape(-1, 6),
            nfev=self.nfev,
            segments=self.segments,
            plunger=self.u_out[: self.k_out],
            plunger_ledger=self.ledger,
        )


def solve_case(
    case: Case,
    revolutions: float = 2.0,
    output_every: float = math.radians(1.0),
    *,
    method: str = "Radau",
    rtol: float = 1e-8,
    atol: float | None = None,
    max_events: int = 4096,
    start: str = "periodic",
    capture_velocity: float = DEFAULT_CAPTURE_VELOCITY,
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
    start : {"periodic", "quasi-static"}
        Where the run starts (the engine's ``run.start``).
    capture_velocity : float
        An impact closing slower than this [m/s] leaves its contact resting.

    Raises
    ------
    ChatterError
        If events keep recurring at one instant.
    RuntimeError
        If ``solve_ivp`` fails.
    """
    peer = _Peer(case, revolutions, output_every, method, rtol, atol, start, capture_velocity)
    return peer.run(max_events)
