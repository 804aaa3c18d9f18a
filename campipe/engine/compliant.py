"""The compliant integrator: the contacts as force elements, integrated with error control.

With a compliant law at the cam (and at the seat, where there is one), no coordinate is held:
all of them are free, and the contacts act as forces of their approach δ and its rate
(:mod:`campipe.model.contact`):

    M q̈ + C q̇ + K q = f − F_cam(δ_c, δ̇_c)·e₁ + F_seat(δ_s, δ̇_s)·e₇,
    δ_c = q1 + lift(θ),  δ_s = q7_seat − q7,

(q1 points down, away from the cam; q7 down, away from the seat). A contact is closed while
its approach and its law's force are both positive: its monitor min(δ, F/k) (for hertz
min(δ, 1 + α·δ̇), the sign of its force) crosses zero upward where it closes (the surfaces
meet, or a relaxed damper's force turns compressive again) and downward where it opens (the
force reaches zero: no tension). Between these events, and between the profile's breaks,
the equations are smooth, and (hertz) ``scipy.integrate.solve_ivp`` (Radau, L-stable: the train's
highest modes and a stiff contact cost no stability limit) integrates them to the run's
tolerance, with the Jacobian given (constant per contact state for kelvin-voigt). Each event
is located on the step's dense output (a terminal event: the integration restarts from it
with the contact switched), and so is each maximum of a contact force (its rate's downward
zero): the peak contact force is a located extremum, not the largest sample, and it converges
as the tolerance shrinks.

Kelvin–Voigt is linear in each contact state, so it keeps exact propagation: with the cam's
polynomial and harmonic made states of one homogeneous linear system, e^{A·τ} (balanced, on a
grid of STEPS_PER_PERIOD steps a period of its fastest oscillation) propagates it to
rounding, whatever the tolerance, and its events are located on that exact state
(:mod:`campipe.engine.compliant_exact`). This is done in Python, not in modal-exact's compiled
kernel; hertz, being nonlinear in contact, goes through solve_ivp.

Results go into the same :class:`~campipe.engine.common.Outputs` the compiled kernels fill,
so ``run_batch`` returns the same ``BatchResult``: a closing is a cam (seat) impact event with
its closing velocity δ̇ and no impulse (the force is finite), an opening a separation; the
configuration number says which contacts are closed (thesis Table I). A chain's lash
adjuster rides along as the state's last entry, its switches events too
(:mod:`campipe.engine.plunger`).

Pure numerics: arrays in, arrays out. SciPy is imported where it is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from campipe.constants import TWO_PI
from campipe.engine.common import TURN_GUARD, is_captured
from campipe.engine.compliant_exact import UnresolvedSwitch, _Propagator, exact_segment
from campipe.engine.metrics import (
    CAM_IMPACTS,
    MAX_CAM_FORCE,
    MAX_CAM_IMPACT_VELOCITY,
    MAX_ROLLER_FORCE,
    MAX_SEAT_FORCE,
    MAX_SEATING_VELOCITY,
    SEAT_IMPACTS,
    SEATED_OFF_CAM,
    SEPARATION,
    THESIS_IMPACT_FORCE,
)
from campipe.engine.plunger import (
    BOTTOMED,
    CLOSED,
    HELD,
    LOAD,
    SWITCHES,
    TOPPED,
    TRAVEL,
    UNLOADED,
    VALVE,
    PlungerState,
    plunger_state,
)
from campipe.errors import CampipeError
from campipe.model import ValveTrain, coordinates, system_matrices
from campipe.model.contact import ContactLaw, contact_law
from campipe.profiles import Lift, Profile
from campipe.profiles.levers import is_valve_side, lever_tables
from campipe.vocabulary import (
    CAM,
    CAM_IMPACT,
    CAM_SEPARATION,
    CHATTER,
    EVENTS_TRUNCATED,
    NONFINITE,
    SEAT,
    SEAT_IMPACT,
    SEAT_SEPARATION,
    STEP_LIMIT,
    UNBOUNDED,
    configuration,
)

#: The solve_ivp method: implicit and L-stable, so a stiff contact or the train's top mode
#: (1.07e6 rad/s) sets no step limit.
METHOD = "Radau"
#: Events in a row each within STALL_WINDOW [s] of the last before a case is declared
#: chattering (a grazing contact switching at one instant).
MAX_STALLED = 64
STALL_WINDOW = 1e-12
#: How long after a switch a monitor reads its value at the end of this interval [s]
#: (``_Run.monitors``): far below any contact's time scale, far above rounding of t.
SWITCH_GUARD = 1e-11
#: The monitor tag of a lever's roller-force maxima (beyond the contacts' 0–3 and a plunger's
#: 4, 5: ``engine.plunger``).
ROLLER_PEAK = 7


@dataclass
class CompliantSystem:
    """One case's equations: the train's matrices, its contact laws, its cam."""

    mass: np.ndarray  # (n, n) [kg, kg·m, kg·m²]
    damping: np.ndarray  # (n, n)
    stiffness: np.ndarray  # (n, n)
    load: np.ndarray  # (n,) the spring's preload [N]
    cam: ContactLaw
    seat: ContactLaw | None  # None: no seat
    seat_q: float  # q7 where the valve meets its seat [m]
    lift: Lift
    scale: np.ndarray  # (2n,) each state component's scale (atol = rtol × scale)
    minv: np.ndarray = field(init=False)
    a_mat: np.ndarray = field(init=False)
    #: a lash adjuster's plunger carried as the state's last entry (``engine.plunger``)
    plunger: PlungerState | None = None
    #: a lever layout's ratio r(θ) over the turn (a ``Lift`` on the excitation's pieces):
    #: its cam law acts at the roller (``_Run.at_roller``); None for a follower on the cam
    ratio: Lift | None = None

    def __post_init__(self) -> None:
        n = self.load.size
        self.minv = np.linalg.inv(self.mass)
        self.a_mat = np.zeros((2 * n, 2 * n))
        self.a_mat[:n, n:] = np.eye(n)
        self.a_mat[n:, :n] = -self.minv @ self.stiffness
        self.a_mat[n:, n:] = -self.minv @ self.damping
        self.accel0 = self.minv @ self.load


class _Run:
    """One case through its segments: the state, the closed contacts, what is recorded."""

    def __init__(self, system: CompliantSystem, rtol: float, max_step: float) -> None:
        self.s = system
        self.n = system.load.size
        self.rtol = rtol
        self.max_step = max_step
        self.closed = [False, False]  # cam, seat
        self.valve = CLOSED  # the plunger's regime (``engine.plunger``), where there is one
        self.piece = 0
        self.rev = 0
        #: (closed, piece) → (grid step, propagator) of the exact kelvin-voigt propagation
        self.exact_cache: dict[tuple, tuple[float, _Propagator]] = {}

    # -- the equations in the current contact state -----------------------------------------

    def gain(self, t: float) -> tuple[float, float, float]:
        """A pivot's plunger's gain g, ġ, g̈ at t (``engine.plunger``); (1, 0, 0) otherwise."""
        p = self.s.plunger
        if p is None or p.gains is None:
            return 1.0, 0.0, 0.0
        return p.gains.at(self.piece, self.rev, t)

    def excitation(self, t: float, z: np.ndarray) -> tuple[float, float, float]:
        """The cam mass's excitation at t [m, m/s, m/s²]: the cam's lift (a lever's kinematic
        valve lift), with a pivot's plunger's g·u added (``engine.plunger``; its acceleration
        from g̈·u + 2ġ·u̇ + g·ü, ü from the link force's rate)."""
        lift, rate, acc = self.s.lift.at(self.piece, self.rev, t)
        p = self.s.plunger
        if p is None or p.gains is None:
            return lift, rate, acc
        n = self.n
        g, dg, ddg = p.gains.at(self.piece, self.rev, t)
        u = z[2 * n]
        du = p.rate(z, self.valve, g)
        c = p.damper(self.valve)
        still = math.isinf(c) or self.valve == UNLOADED  # (u̇ constant: F_c/c_P)
        ddu = 0.0 if still else -(dg * p.force(z) + g * p.k * (p.d @ z[n : 2 * n])) / c
        return lift + g * u, rate + dg * u + g * du, acc + ddg * u + 2.0 * dg * du + g * ddu

    def approaches(self, t: float, z: np.ndarray) -> tuple[float, float, float, float]:
        """(δ_cam, δ̇_cam, δ_seat, δ̇_seat) [m, m/s], the cam's on the valve side."""
        n = self.n
        lift, rate, _ = self.excitation(t, z)
        dc, rc = z[CAM] + lift, z[n + CAM] + rate
        if self.s.seat is None:
            return dc, rc, -1.0, 0.0
        return dc, rc, self.s.seat_q - z[SEAT], -z[n + SEAT]

    def at_roller(self, t: float, dc: float, rc: float) -> tuple[float, float, float, float]:
        """A valve-side cam approach δ and rate δ̇ at the roller of a lever layout (its law
        acts there): (δ/r, δ̇/r − δ·ṙ/r², r, ṙ), r(θ) the lever ratio; (δ, δ̇, 1, 0) for a
        follower on the cam."""
        if self.s.ratio is None:
            return dc, rc, 1.0, 0.0
        r, dr, _ = self.s.ratio.at(self.piece, self.rev, t)
        return dc / r, rc / r - dc * dr / (r * r), r, dr

    def forces(self, t: float, z: np.ndarray) -> tuple[float, float]:
        """Compressive cam (valve side) and seat forces [N] in the current contact state: a
        lever's cam force is the roller's law over the lever ratio (virtual work)."""
        dc, rc, ds, rs = self.approaches(t, z)
        fc = fs = 0.0
        if self.closed[0]:
            dn, rn, r, _ = self.at_roller(t, dc, rc)
            fc = self.s.cam.force(dn, rn) / r
        if self.closed[1] and self.s.seat:
            fs = self.s.seat.force(ds, rs)
        return fc, fs

    def rhs(self, t: float, z: np.ndarray) -> np.ndarray:
        s, n, p = self.s, self.n, self.s.plunger
        out = np.empty(z.size)
        np.dot(s.a_mat, z[: 2 * n], out=out[: 2 * n])
        out[n : 2 * n] += s.accel0
        fc, fs = self.forces(t, z)
        if fc != 0.0:
            out[n : 2 * n] -= s.minv[:, CAM] * fc
        if fs != 0.0:
            out[n : 2 * n] += s.minv[:, SEAT] * fs
        if p is None:
            return out
        out[n : 2 * n] -= p.push * z[2 * n]
        out[2 * n] = p.rate(z, self.valve, self.gain(t)[0])
        return out

    def jac(self, t: float, z: np.ndarray) -> np.ndarray:
        """The Jacobian (a pivot's plunger's ü in the cam's approach rate left out)."""
        s, n, p = self.s, self.n, self.s.plunger
        j = np.zeros((z.size, z.size))
        j[: 2 * n, : 2 * n] = s.a_mat
        dc, rc, ds, rs = self.approaches(t, z)
        g, dg, _ = self.gain(t)
        if self.closed[0]:
            dn, rn, r, dr = self.at_roller(t, dc, rc)
            kd, cd = s.cam.slopes(dn, rn)
            kd, cd = (kd / r - cd * dr / (r * r)) / r, cd / (r * r)  # per valve-side δ, δ̇
            j[n : 2 * n, CAM] -= s.minv[:, CAM] * kd
            j[n : 2 * n, n + CAM] -= s.minv[:, CAM] * cd
            if p is not None and p.gains is not None:  # δ = q1 + lift + g·u
                j[n : 2 * n, 2 * n] -= s.minv[:, CAM] * (kd * g + cd * dg)
        if self.closed[1] and s.seat is not None:
            kd, cd = s.seat.slopes(ds, rs)
            j[n : 2 * n, SEAT] -= s.minv[:, SEAT] * kd
            j[n : 2 * n, n + SEAT] -= s.minv[:, SEAT] * cd
        if p is not None:
            j[n : 2 * n, 2 * n] -= p.push
            j[2 * n, :n], j[2 * n, 2 * n], _ = p.row(self.valve, g)
        return j

    def force_rates(self, t: float, z: np.ndarray) -> tuple[float, float]:
        """dF/dt of the cam (valve side) and seat forces [N/s] (closed contacts)."""
        n = self.n
        acc = self.rhs(t, z)[n : 2 * n]
        ddlift = self.excitation(t, z)[2]
        dc, rc, ds, rs = self.approaches(t, z)
        out = [0.0, 0.0]
        if self.closed[0]:
            dn, rn, r, dr = self.at_roller(t, dc, rc)
            kd, cd = self.s.cam.slopes(dn, rn)
            a = acc[CAM] + ddlift  # δ̈ on the valve side
            if self.s.ratio is None:
                out[0] = kd * rn + cd * a
            else:  # the rate of F/r
                out[0] = self.roller_rate(t, z, acc) / r - self.s.cam.force(dn, rn) * dr / (r * r)
        if self.s.seat is not None and self.closed[1]:
            kd, cd = self.s.seat.slopes(ds, rs)
            out[1] = kd * rs + cd * (-acc[SEAT])
        return out[0], out[1]

    def monitors(self, t_a: float, z_a: np.ndarray) -> list[Any]:
        """solve_ivp's events from (t_a, z_a): each contact's switch (terminal), then each
        closed contact's force maximum (not terminal).

        A segment starts where a switch has just put a monitor at zero, so its value there
        has no sign to compare with; up to SWITCH_GUARD after t_a each switch reads its value
        at t_a + SWITCH_GUARD (the state extrapolated along its rate), so a monitor that turns
        back within the first step (a force that reaches zero and turns compressive again) is
        seen to cross rather than missed, which would leave a contact open in overlap."""
        out: list[Any] = []
        t_guard = t_a + SWITCH_GUARD
        z_guard = z_a + SWITCH_GUARD * self.rhs(t_a, z_a)
        for i, law in enumerate((self.s.cam, self.s.seat)):
            if law is None:
                continue

            def switch(t, z, i=i, law=law):
                if t < t_guard:
                    t, z = t_guard, z_guard
                d = self.approaches(t, z)
                if i == 0:  # a lever's law at its roller
                    return law.monitor(*self.at_roller(t, d[0], d[1])[:2])
                return law.monitor(d[2], d[3])

            switch.terminal = True  # type: ignore[attr-defined]
            switch.direction = -1.0 if self.closed[i] else 1.0  # type: ignore[attr-defined]
            switch.contact = i  # type: ignore[attr-defined]
            out.append(switch)
        if self.s.plunger is not None:  # the check valve's switch, the plunger's ends
            gain = self.gain
            for tag, direction, g in self.s.plunger.monitors(self.valve, lambda t: gain(t)[0]):

                def limit(t, z, g=g):
                    return g(t_guard, z_guard) if t < t_guard else g(t, z)

                limit.terminal = True  # type: ignore[attr-defined]
                limit.direction = direction  # type: ignore[attr-defined]
                limit.contact = tag  # type: ignore[attr-defined]
                out.append(limit)
        for i in (0, 1, 2):  # the cam's, the seat's, a lever's roller's (at the cam)
            if self.closed[i % 2] and (i < 2 or self.s.ratio is not None):

                def peak(t, z, i=i):
                    return self.roller_rate(t, z) if i == 2 else self.force_rates(t, z)[i]

                peak.terminal = False  # type: ignore[attr-defined]
                peak.direction = -1.0  # type: ignore[attr-defined]
                peak.contact = ROLLER_PEAK if i == 2 else i + 2  # type: ignore[attr-defined]
                out.append(peak)
        return out

    def roller_rate(self, t: float, z: np.ndarray, acc: np.ndarray | None = None) -> float:
        """A lever's roller force's rate [N/s]: its law's at the roller (the cam closed), from
        δ/r's second derivative; ``acc``: the coordinates' accelerations if already known."""
        n = self.n
        if acc is None:
            acc = self.rhs(t, z)[n : 2 * n]
        dc, rc, _, _ = self.approaches(t, z)
        dn, rn, r, dr = self.at_roller(t, dc, rc)
        assert self.s.ratio is not None
        ddr = self.s.ratio.at(self.piece, self.rev, t)[2]
        a = acc[CAM] + self.excitation(t, z)[2]  # δ̈ on the valve side, then at the roller
        an = a / r - 2.0 * rc * dr / r**2 - dc * ddr / r**2 + 2.0 * dc * dr * dr / r**3
        kd, cd = self.s.cam.slopes(dn, rn)
        return kd * rn + cd * an


@dataclass
class CaseOutputs:
    """One case's slices of the batch's Outputs, filled in place."""

    q: np.ndarray  # (n_out, 7)
    v: np.ndarray  # (n_out, 7)
    force: np.ndarray  # (n_out, 2) thesis signs
    cam: np.ndarray  # (n_out,)
    cfg: np.ndarray  # (n_out,)
    acc: np.ndarray  # (n_out, 2)
    per_rev: np.ndarray  # (n_rev, metrics.N_ENGINE) the engine's metrics per turn
    events: np.ndarray  # (max_events, 6)
    #: (n_rev, 3) a carried plunger's extension at each turn's start, its leak-down and
    #: pump-up over the turn [m] (``engine.plunger``); None without one
    adjuster: np.ndarray | None = None
    #: (n_out,) a plunger's extension at each sample [m] where it lengthens a chain's link:
    #: ``extension_start`` (the run's frame) plus its state u; None else
    extension: np.ndarray | None = None
    extension_start: float = 0.0
    n_events: int = 0
    status: int = 0
    steps: int = 0


class _Recorder:
    """What ``integrate`` records of a case beside its samples: each turn's peak forces, the
    events, the closings counted as impacts, the time off the cam."""

    def __init__(self, run: _Run, out: CaseOutputs) -> None:
        self.run = run
        self.out = out
        self.w = run.s.lift.w
        self.n_rev = out.per_rev.shape[0]

    def turn(self, tt: float) -> int:
        return min(max(int(math.floor(self.w * tt / TWO_PI + TURN_GUARD)), 0), self.n_rev - 1)

    def peak(self, tt: float, zz: np.ndarray) -> None:
        if tt < 0.0:
            return
        out = self.out
        fc, fs = self.run.forces(tt, zz)
        r = self.turn(tt)
        out.per_rev[r, MAX_CAM_FORCE] = max(out.per_rev[r, MAX_CAM_FORCE], fc)
        ratio = self.run.s.ratio
        if ratio is not None and fc > 0.0:  # a lever's roller force, the cam's times r
            roller = fc * ratio.at(self.run.piece, self.run.rev, tt)[0]
            out.per_rev[r, MAX_ROLLER_FORCE] = max(out.per_rev[r, MAX_ROLLER_FORCE], roller)
        out.per_rev[r, THESIS_IMPACT_FORCE] = out.per_rev[r, MAX_CAM_FORCE]
        out.per_rev[r, MAX_SEAT_FORCE] = max(out.per_rev[r, MAX_SEAT_FORCE], fs)

    def peaks(self, sol: Any, events: list[Any], t_seg: float) -> None:
        """The force maxima located in a segment up to its end ``t_seg`` [s]."""
        for k, te in enumerate(sol.t_events):
            if not events[k].terminal:
                for j, tt in enumerate(te):
                    if tt <= t_seg:
                        self.peak(float(tt), sol.y_events[k][j])

    def event(self, tt: float, kind: int, c_from: int, c_to: int, velocity: float) -> None:
        out = self.out
        if tt < 0.0:
            return
        if out.n_events < out.events.shape[0]:
            out.events[out.n_events] = (tt, kind, c_from, c_to, velocity, 0.0)
        out.n_events += 1

    def off_cam(self, ta: float, tb: float, seated: bool) -> None:
        """Cam angle [rad] spent off the cam from ta to tb [s], per turn."""
        k = SEATED_OFF_CAM if seated else SEPARATION
        a, b = max(self.w * ta, 0.0), self.w * tb
        r = int(a / TWO_PI)
        while a < b and r < self.n_rev:
            stop = min(b, (r + 1) * TWO_PI)
            self.out.per_rev[r, k] += stop - a
            a = stop
            r += 1

    def plunger(self, t: float, z: np.ndarray, t_seg: float, z_seg: np.ndarray) -> None:
        """A carried plunger's motion from (t, z) to (t_seg, z_seg), within one turn: its
        extension at the turn's start, what it leaked down or pumped up."""
        table, p = self.out.adjuster, self.run.s.plunger
        if table is not None and p is not None and t >= 0.0:
            p.record(table[self.turn(t)], self.run.valve, z, z_seg)

    def switch(self, t: float, z: np.ndarray, hit: int, capture: float) -> None:
        """Switch contact ``hit`` (0 cam, 1 seat) at t and record it: a closing as an impact
        with its closing velocity (counted from ``capture`` [m/s]), an opening as a
        separation. A plunger's switch (``hit`` VALVE, TRAVEL or LOAD) moves it to its next
        regime, an event of velocity 0; one to an end of its travel puts it there."""
        run, out = self.run, self.out
        if hit in (VALVE, TRAVEL, LOAD):
            p = run.s.plunger
            assert p is not None
            run.valve, kind = SWITCHES[(run.valve, hit)]
            if run.valve in (BOTTOMED, TOPPED):
                z[2 * run.n] = p.low if run.valve == BOTTOMED else p.high
            if kind is not None:  # (its load through 0 is not an event of the archive's)
                here = configuration(*run.closed)
                self.event(t, kind, here, here, 0.0)
            return
        before = configuration(*run.closed)
        d = run.approaches(t, z)
        run.closed[hit] = not run.closed[hit]
        after = configuration(*run.closed)
        closing = run.closed[hit]
        kinds = ((CAM_SEPARATION, CAM_IMPACT), (SEAT_SEPARATION, SEAT_IMPACT))
        # a closing's velocity is δ̇ (a damper's re-engagement in overlap, δ̇ < 0: 0, a touch)
        velocity = max(d[2 * hit + 1], 0.0) if closing else 0.0
        self.event(t, kinds[hit][closing], before, after, velocity)
        if closing and t >= 0.0 and not is_captured(velocity, capture):
            r = self.turn(t)
            count = (CAM_IMPACTS, SEAT_IMPACTS)[hit]
            fastest = (MAX_CAM_IMPACT_VELOCITY, MAX_SEATING_VELOCITY)[hit]
            out.per_rev[r, count] += 1.0
            out.per_rev[r, fastest] = max(out.per_rev[r, fastest], velocity)
        self.peak(t, z)


class StepLimit(CampipeError, RuntimeError):
    """A case past its ``run.max_steps`` steps: it ends with status STEP_LIMIT (a stiff
    contact without damping takes steps without end); the batch's other cases go on."""


def _step_counter(budget: float) -> Any:
    """An event that never fires and counts the steps: solve_ivp (and the exact propagation)
    calls each event once at a segment's start and once a step; past ``budget`` steps it
    raises StepLimit, which stops the integration within the step, whatever its length."""
    calls = [0]

    def counter(t: float, z: np.ndarray) -> float:
        calls[0] += 1
        if calls[0] - 1 > budget:
            raise StepLimit(f"more than {budget:.6g} steps", key="run.max_steps", found=budget)
        return 1.0

    counter.terminal = False  # type: ignore[attr-defined]
    counter.direction = 0.0  # type: ignore[attr-defined]
    counter.contact = -1  # type: ignore[attr-defined]
    return counter


def _segment(run: _Run, t: float, t_stop: float, z: np.ndarray, exact: bool, atol: np.ndarray,
             budget: float = math.inf) -> tuple[Any, list[Any]]:  # fmt: skip
    """One smooth segment from (t, z) to t_stop or its first switch, in at most ``budget``
    steps (else StepLimit): (its solution, its events)."""
    from scipy.integrate import solve_ivp

    events = run.monitors(t, z) + [_step_counter(budget)]
    if exact:
        return exact_segment(run, t, t_stop, z, events, run.max_step), events
    sol = solve_ivp(
        run.rhs, (t, t_stop), z, method=METHOD, rtol=run.rtol, atol=atol,
        events=events, dense_output=True, jac=run.jac, max_step=run.max_step,
    )  # fmt: skip
    return sol, events


def _segment_end(sol: Any, events: list[Any], t_stop: float) -> tuple[float, np.ndarray, int]:
    """Where a segment ends: (t [s], z, the contact switched there, -1 for none)."""
    if sol.status != 1:
        return t_stop, sol.y[:, -1], -1
    firsts = [(te[0], k) for k, te in enumerate(sol.t_events) if events[k].terminal and len(te)]
    t_seg, k = min(firsts)
    return t_seg, sol.y_events[k][0], events[k].contact


def _next_piece(run: _Run) -> None:
    """Into the profile's next piece (the next turn's first after the last)."""
    if run.piece + 1 < run.s.lift.poly.shape[0]:
        run.piece += 1
    else:
        run.piece, run.rev = 0, run.rev + 1


def integrate(
    system: CompliantSystem,
    t0: float,
    z0: np.ndarray,
    closed: tuple[bool, bool],
    t_out: np.ndarray,
    out: CaseOutputs,
    *,
    rtol: float,
    max_step: float = math.inf,
    max_steps: float = math.inf,
    capture: float = 1e-3,
    lift_bound: float = math.inf,
    valve_ref: float = 0.0,
) -> CaseOutputs:
    """Integrate one case from t0 to t_out[-1], recording into ``out``.

    Parameters
    ----------
    system : CompliantSystem
    t0 : float
        Start time [s] (≤ t_out[0]; nothing before t = 0 is recorded).
    z0 : (2n,) array
        Start state: coordinates, then velocities [SI]; then the plunger's u where the
        system carries one.
    closed : (bool, bool)
        Cam and seat contacts closed at the start.
    t_out : (n_out,) array
        Sample times [s], from 0.
    rtol : float
        Relative tolerance; the absolute one is rtol × ``system.scale``.
    max_step : float
        Largest step [s].
    max_steps : float
        The most steps the case takes (``run.max_steps``); a case that needs more stops
        there with status STEP_LIMIT, its samples after that point left as they were.
    capture : float
        A closing slower than this [m/s] is a touch: switched and recorded as an event, but
        not counted as an impact in the per-turn counts and closing velocities.
    lift_bound : float
        |q7 − valve_ref| beyond this [m] ends the case with status UNBOUNDED.
    """
    run = _Run(system, rtol, max_step)
    run.closed = [bool(closed[0]), bool(closed[1] and system.seat is not None)]
    rec = _Recorder(run, out)
    t_end = float(t_out[-1])
    t, z = float(t0), np.asarray(z0, dtype=float).copy()
    run.piece, run.rev = system.lift.piece_at(t)
    _close_touching(run, t, z)
    run.valve = HELD
    _release_plunger(run, t, z)
    k_out = 0
    stalled = 0
    atol = rtol * system.scale
    exact = is_linear(system)

    rec.peak(t, z)
    while t < t_end:
        t_stop = min(system.lift.break_after(run.piece, run.rev), t_end)
        if t_stop - t > 1e-15 * (1.0 + abs(t)):
            try:
                sol, events = _segment(run, t, t_stop, z, exact, atol, max_steps - out.steps)
            except UnresolvedSwitch:
                out.status = NONFINITE
                return out
            except StepLimit:
                out.steps, out.status = int(max_steps), STEP_LIMIT
                return out
            out.steps += sol.t.size - 1
            if sol.status == -1 or not np.all(np.isfinite(sol.y[:, -1])):
                out.status = NONFINITE
                return out
            t_seg, z_seg, hit = _segment_end(sol, events, t_stop)
            rec.peaks(sol, events, t_seg)
            rec.plunger(t, z, t_seg, z_seg)
            while k_out < t_out.size and t_out[k_out] <= t_seg * (1.0 + 1e-14):
                zs = sol.sol(t_out[k_out])
                _sample(run, t_out[k_out], zs, out, k_out)
                if abs(zs[SEAT] - valve_ref) > lift_bound:
                    out.status = UNBOUNDED
                    return out
                k_out += 1
            if not run.closed[0]:
                rec.off_cam(t, t_seg, run.closed[1])
            rec.peak(t_seg, z_seg)
            stalled = stalled + 1 if t_seg - t < STALL_WINDOW else 0
            t, z = float(t_seg), np.array(z_seg)
        else:
            t, hit = t_stop, -1
        if hit >= 0:
            if stalled > MAX_STALLED:
                out.status = CHATTER
                return out
            rec.switch(t, z, hit, capture)
            continue
        if t >= t_end:
            break
        _next_piece(run)
        _release_plunger(run, t, z)
    while k_out < t_out.size:  # the last sample, to rounding
        _sample(run, t_out[k_out], z, out, k_out)
        k_out += 1
    if out.n_events > out.events.shape[0] and out.status == 0:
        out.status = EVENTS_TRUNCATED
    return out


def _release_plunger(run: _Run, t: float, z: np.ndarray) -> None:
    """A carried plunger held until t = 0 (``engine.plunger.HELD``: a periodic start's
    warm-up, which ends on a piece's end, the turn's) takes the regime its load gives."""
    p = run.s.plunger
    if p is not None and run.valve == HELD and t >= 0.0:
        run.valve = p.regime_at(z, run.gain(t)[0])


def _close_touching(run: _Run, t: float, z: np.ndarray) -> None:
    """Close each contact the start puts in touch though it is not held (its monitor
    positive): a rigid start's held contact, compressed (``compliant_start``), moves the other
    coordinates by its static response, and a periodic start just before the valve lands
    then has it a micron into its seat, which no crossing would close."""
    d = run.approaches(t, z)
    for i, law in enumerate((run.s.cam, run.s.seat)):
        if law is None or run.closed[i]:
            continue
        delta, rate = run.at_roller(t, d[0], d[1])[:2] if i == 0 else (d[2], d[3])
        if delta > 0.0 and law.monitor(delta, rate) > 0.0:
            run.closed[i] = True


def is_linear(system: CompliantSystem) -> bool:
    """Every contact the case can touch has a linear law (kelvin-voigt) and no lever's ratio
    or pivot's gain changes its coefficients with the cam angle: linear and time-invariant
    in each contact state, so propagated exactly (``exact_segment``)."""
    linear = system.cam.linear and (system.seat is None or system.seat.linear)
    return linear and system.ratio is None


def _sample(run: _Run, t: float, z: np.ndarray, out: CaseOutputs, k: int) -> None:
    n = run.n
    fc, fs = run.forces(t, z)
    acc = run.rhs(t, z)[n : 2 * n]
    m = min(n, out.q.shape[1])
    out.q[k, :m] = z[:m]
    out.v[k, :m] = z[n : n + m]
    out.q[k, m:] = out.v[k, m:] = np.nan  # a batch's coordinates beyond this train's
    out.force[k] = (-fc, fs)
    out.cam[k] = run.excitation(t, z)[0]
    out.cfg[k] = configuration(*run.closed)
    out.acc[k] = (acc[CAM], acc[SEAT])
    if out.extension is not None:
        out.extension[k] = out.extension_start + z[2 * n]


def compliant_system(train: ValveTrain, profile: Profile, speed: float, seat_q: float | None
                     ) -> CompliantSystem:  # fmt: skip
    """A case's equations: ``seat_q`` the q7 of its seat [m], None for no seat."""
    sm = system_matrices(train)
    lift = Lift(profile, speed)
    lift_max = float(np.abs(profile.poly[:, 0]).max() + np.abs(profile.trig).sum(axis=1).max())
    n = sm.preload.size
    scale = np.full(n, max(lift_max, 1e-6))
    rotations = [i for i, c in enumerate(coordinates(train)) if c.kind != "translation"]
    scale[rotations] /= train.rocker_pushrod_arm_length
    system = CompliantSystem(
        sm.mass, sm.damping, sm.stiffness, sm.preload,
        contact_law(train, "cam"),
        None if seat_q is None else contact_law(train, "seat"),
        math.nan if seat_q is None else seat_q,
        lift,
        np.concatenate([scale, speed * scale]),
    )  # fmt: skip
    gains = None
    if is_valve_side(profile):  # a lever's: its ratio and its pivot's gain over the turn
        ratio, gain = lever_tables(profile)
        system.ratio, gains = Lift(ratio, speed), Lift(gain, speed)
    system.plunger = plunger_state(train, system.minv, gains)
    if system.plunger is not None:
        travel = system.plunger.high - system.plunger.low
        system.scale = np.append(system.scale, max(travel, 1e-6))
    return system


def compliant_start(system: CompliantSystem, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                    cam_held: bool, seat_held: bool, t0: float = 0.0) -> np.ndarray:  # fmt: skip
    """The state z = (q, q̇) a compliant case starts from at ``t0`` [s], from the rigid
    model's (q, v, a) with the given contacts held: each held contact compressed by its static
    approach under the rigid reaction (a lever's at its roller, under the reaction times the
    ratio, r times that on the valve side), the other coordinates moved by their static
    response to it, so the start carries no spurious contact transient (the difference is
    O(1/k) and damps out)."""
    s = system
    reaction = s.mass @ a + s.damping @ v + s.stiffness @ q - s.load
    dq = np.zeros(q.size)
    moved: list[int] = []
    if cam_held:
        r = 1.0 if s.ratio is None else s.ratio.at(*s.ratio.piece_at(t0), t0)[0]
        dq[CAM] = r * s.cam.approach(-reaction[CAM] * r)
        moved.append(CAM)
    if seat_held and s.seat is not None:
        dq[SEAT] = -s.seat.approach(reaction[SEAT])
        moved.append(SEAT)
    if moved:
        held = np.array(moved)
        free = np.setdiff1d(np.arange(q.size), held)
        kff = s.stiffness[np.ix_(free, free)]
        dq[free] = -np.linalg.solve(kff, s.stiffness[np.ix_(free, held)] @ dq[held])
    return np.concatenate([q + dq, v])
