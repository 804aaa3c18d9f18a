"""A hydraulic lash adjuster's plunger as a state of the compliant integrator, its check
valve's switch an event located on the solution (:mod:`campipe.engine.compliant`).

The adjuster (:mod:`campipe.model.hla`) sits in series with a chain's link next to the cam
(under a finger follower's pivot: below). Its plunger's extension e lengthens that link, so
the force through it is

    F = k·(d·q + u),     u = e − e₀,

k the link's stiffness with the adjuster's in series, d·q the link's compression (the
chain's placement: x₁ − x₂), e₀ the extension the run's frame is raised by (the case runs
on its cam lifted by e₀, as :mod:`campipe.engine.lash_adjuster`'s turns do, so a start the
settings compute is the train's with that extension). The plunger is a massless piston on
its oil: the spring k in series with a one-way dashpot,

    u̇ = −(F − F_c)/c,   c = c_L (check valve closed, F > F_c: leak-down),
                           c = c_P (open, F < F_c: pump-up),

and held at its ends: bottomed out (e = 0) while F > F_c, fully out (e = travel) while
F < F_c. The plunger only pushes (so do the pushrod's cup, the stem's tip, the finger's
socket on it): where the model's two-sided joints would pull it (F < 0, a link ringing
after a landing, a follower in flight past the onset) it is *unloaded*, u̇ = F_c/c_P, its
fastest pump-up. Each regime is linear, so a kelvin–voigt case keeps exact propagation
(one more row in its augmented system), and every switch between regimes is a terminal
event on the solution, as a contact's is: the check valve opening or closing where F − F_c
crosses zero (recorded as ``vocabulary.CHECK_VALVE_OPENS`` / ``CHECK_VALVE_CLOSES``
events, their velocity 0), the plunger reaching an end of its travel (``PLUNGER_BOTTOMS`` /
``PLUNGER_TOPS``), with a dead band (HYSTERESIS) about F_c; and, not recorded, its load
falling through 0 (unloaded) and rising through it again, with the same band about 0.
Nothing is applied at a turn's end: the leak-down and pump-up of each turn are what the
plunger moved in each regime (``BatchResult.lash_adjuster``: the extension at each turn's
start, the turn's leak-down and pump-up).

**Under a finger follower's pivot** the plunger raises the pivot: the lever turns about
its roller and its pallet moves by g(θ)·u, g the pivot's gain
(:func:`campipe.profiles.levers.pivot_gains`, which changes with the cam angle). The valve
side's excitation is then the kinematic lift with the pivot at e₀ plus g·u (its linear part:
the rest is 1e-5 of u for a micron of it), the coordinates stay the lever's and the valve's
own, and the load through the adjuster is the pivot's, g·F, F the link's force k·d·q (by
virtual work, as the per-turn model takes it); u̇ = −(g·F − F_c)/c. With g changing with the
angle the equations are not time-invariant, so such a case goes through solve_ivp, not the
exact propagation; and its run starts each turn in a new frame, the kinematic lift with the
pivot at the extension reached (``lash_adjuster.Carried``), so that what is linearised is
one turn's motion.

What the per-turn model approximates (the plunger fixed within a turn, its motion applied at
the turn's end, the switch on the samples' interpolant, :func:`interpolated_switches`; left
to newmark-linear and to a finger's pivot with rigid contacts) this carries exactly; the two
are compared in the tests (the error of the per-turn model stated there). With rigid
contacts modal-exact carries a chain's plunger the same way, as a coordinate of its train
(:mod:`campipe.engine.plunger_modes`).

Pure numerics on floats and arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.model.elements import chain_elements
from campipe.model.hla import adjuster, on_pivot
from campipe.model.layouts import chain_placement
from campipe.vocabulary import (
    CAM_IMPACT,
    CAM_SEPARATION,
    CHECK_VALVE_CLOSES,
    CHECK_VALVE_OPENS,
    EV_KIND,
    EV_TIME,
    EV_TO,
    N_EVENT_FIELDS,
    PLUNGER_BOTTOMS,
    PLUNGER_TOPS,
    SEAT_IMPACT,
    SEAT_SEPARATION,
)

#: The events that change the contacts' configuration.
CONTACT_EVENTS = (CAM_SEPARATION, CAM_IMPACT, SEAT_SEPARATION, SEAT_IMPACT)

#: The plunger's regimes: check valve closed (leaking down), open (pumping up), bottomed
#: out, fully out; held where the settings' start puts it until t = 0 (a periodic start
#: begins before the run's first turn: ``hla_extension`` is the extension at t = 0); and
#: unloaded (open, the model's joints pulling on it: it pumps up at F_c/c_P).
CLOSED, OPEN, BOTTOMED, TOPPED, HELD, UNLOADED = 0, 1, 2, 3, 4, 5
#: Monitor tags (``_Run.monitors``' ``contact``), beyond the contacts' 0–3: the check valve,
#: the travel's end, the load through 0.
VALVE, TRAVEL, LOAD = 4, 5, 6
#: The columns of ``BatchResult.lash_adjuster``: the plunger's extension at each turn's
#: start, the turn's leak-down and its pump-up [m].
EXTENSION, LEAK_DOWN, PUMP_UP = 0, 1, 2
#: The check valve's dead band, relative to its check force: it opens where F falls to
#: F_c·(1 − HYSTERESIS) and closes where F rises to F_c·(1 + HYSTERESIS). Open on a base
#: circle, the plunger takes its load up to F_c exponentially, never reaching it: without a
#: band, rounding would switch it back and forth there. 1e-6 of F_c moves the plunger by
#: 1e-6·F_c/c at most, far below any leak-down.
HYSTERESIS = 1e-6
#: The regime a switch leads to: (regime, tag) → (regime after, event kind).
SWITCHES = {
    (CLOSED, VALVE): (OPEN, CHECK_VALVE_OPENS),
    (CLOSED, TRAVEL): (BOTTOMED, PLUNGER_BOTTOMS),
    (OPEN, VALVE): (CLOSED, CHECK_VALVE_CLOSES),
    (OPEN, TRAVEL): (TOPPED, PLUNGER_TOPS),
    (BOTTOMED, VALVE): (OPEN, CHECK_VALVE_OPENS),
    (TOPPED, VALVE): (CLOSED, CHECK_VALVE_CLOSES),
    (OPEN, LOAD): (UNLOADED, None),
    (UNLOADED, LOAD): (OPEN, None),
    (UNLOADED, TRAVEL): (TOPPED, PLUNGER_TOPS),
}


@dataclass(frozen=True)
class PlungerState:
    """One case's adjuster as the compliant integrator carries it (see the module): a chain's
    in its link (``gains`` None), a finger follower's under its pivot (``gains`` its g(θ))."""

    d: np.ndarray  # (n,) the link's compression d·q [m] per coordinate
    k: float  # [N/m] the link with the adjuster in series
    check_force: float  # F_c [N]
    leak_down: float  # c_L [N·s/m]
    pump_up: float  # c_P [N·s/m]
    low: float  # u at the bottom, −e₀ [m]
    high: float  # u fully out, travel − e₀ [m]
    offset: float  # e₀ [m]
    push: np.ndarray  # (n,) M⁻¹·k·d: the accelerations a unit of u gives [1/s²] (0: a pivot's)
    #: a pivot's gain g(θ) [-] over the turn (``profiles.levers.lever_tables``, a ``Lift``
    #: on the excitation's pieces): the valve side's excitation rises by g·u, the load
    #: through the adjuster is g·F; None: in the chain's link (g = 1, F = k·(d·q + u))
    gains: Any = None

    def force(self, z: np.ndarray) -> float:
        """The link's force [N] in state z = (q, q̇, u): k·(d·q + u) with the adjuster in the
        link, k·d·q under a pivot."""
        n = self.d.size
        return self.k * (float(self.d @ z[:n]) + (z[2 * n] if self.gains is None else 0.0))

    def damper(self, regime: int) -> float:
        """The dashpot's coefficient [N·s/m] in ``regime`` (inf: held at an end)."""
        return (self.leak_down, self.pump_up, math.inf, math.inf, math.inf, self.pump_up)[regime]

    def rate(self, z: np.ndarray, regime: int, gain: float = 1.0) -> float:
        """u̇ [m/s] in ``regime``, the gain g at the instant (1 in a link): −(g·F − F_c)/c,
        F_c/c_P unloaded, 0 held."""
        c = self.damper(regime)
        if math.isinf(c):
            return 0.0
        load = 0.0 if regime == UNLOADED else gain * self.force(z)
        return -(load - self.check_force) / c

    def row(self, regime: int, gain: float = 1.0) -> tuple[np.ndarray, float, float]:
        """u̇ = a·q + b·u + f: (a (n,), b, f) in ``regime``, the gain g at the instant."""
        c = self.damper(regime)
        if math.isinf(c):
            return np.zeros(self.d.size), 0.0, 0.0
        if regime == UNLOADED:
            return np.zeros(self.d.size), 0.0, self.check_force / c
        b = -self.k / c if self.gains is None else 0.0
        return -gain * self.k / c * self.d, b, self.check_force / c

    def record(self, turn: np.ndarray, regime: int, z: np.ndarray, z_end: np.ndarray) -> None:
        """Its motion from state z to z_end in ``regime`` into its turn's row of the table
        (the extension at the turn's start where not yet set, the leak-down, the pump-up)."""
        u = 2 * self.d.size
        if math.isnan(turn[EXTENSION]):
            turn[EXTENSION] = self.offset + z[u]
        moved = z_end[u] - z[u]
        if regime == CLOSED:
            turn[LEAK_DOWN] -= moved
        elif regime in (OPEN, UNLOADED):
            turn[PUMP_UP] += moved

    def regime_at(self, z: np.ndarray, gain: float = 1.0) -> int:
        """The regime a run starts in from state z, the gain g there."""
        n = self.d.size
        u = z[2 * n]
        load = gain * self.force(z)
        if load > self.check_force:
            return BOTTOMED if u <= self.low else CLOSED
        if u >= self.high:
            return TOPPED
        return UNLOADED if load < 0.0 else OPEN

    def monitors(
        self, regime: int, gain: Callable[[float], float]
    ) -> list[tuple[int, float, Callable[[float, np.ndarray], float]]]:
        """(tag, direction, g(t, z)) of the switches out of ``regime``; ``gain`` gives g at
        an instant [s] (1 in a link)."""
        if regime == HELD:
            return []
        n = self.d.size
        band = HYSTERESIS * self.check_force

        def load(level: float) -> Callable[[float, np.ndarray], float]:
            return lambda t, z: gain(t) * self.force(z) - level

        def top(t: float, z: np.ndarray) -> float:
            return z[2 * n] - self.high

        if regime == UNLOADED:  # loaded again (open), or fully out
            return [(LOAD, 1.0, load(band)), (TRAVEL, 1.0, top)]
        closed = regime in (CLOSED, BOTTOMED)
        level = self.check_force + (-band if closed else band)
        out: list[tuple[int, float, Callable[[float, np.ndarray], float]]] = [
            (VALVE, -1.0 if closed else 1.0, load(level))
        ]
        if regime == CLOSED:
            out.append((TRAVEL, -1.0, lambda t, z: z[2 * n] - self.low))
        elif regime == OPEN:
            out += [(TRAVEL, 1.0, top), (LOAD, -1.0, load(-band))]
        return out


def interpolated_switches(
    time: np.ndarray,
    force: np.ndarray,
    check_force: float,
    cfg: np.ndarray,
    closed: bool | None = None,
    events: np.ndarray | None = None,
) -> np.ndarray:
    """(m, N_EVENT_FIELDS) the check valve's switches of a turn the per-turn model runs
    (``lash_adjuster.Plunger``): where the force through the adjuster at the samples
    (``time`` [s], ``force`` [N]) crosses F_c on their linear interpolant, with the dead band
    HYSTERESIS (the check valve opening where it falls to F_c·(1 − HYSTERESIS), closing where
    it rises to F_c·(1 + HYSTERESIS)); each in the configuration the turn's contact
    ``events`` before it leave (none before it: the configuration ``cfg`` of the first
    sample; ``events`` None: of the sample before it), velocity 0. The valve starts
    ``closed`` as the last turn left it (None: closed where the first sample's force is above
    F_c), so a turn's switches go on from the last's."""
    low, high = check_force * (1.0 - HYSTERESIS), check_force * (1.0 + HYSTERESIS)
    f = np.asarray(force, float)
    down = np.flatnonzero((f[:-1] > low) & (f[1:] <= low))
    up = np.flatnonzero((f[:-1] < high) & (f[1:] >= high))
    found = sorted([(i, CHECK_VALVE_OPENS, low) for i in down.tolist()]
                   + [(i, CHECK_VALVE_CLOSES, high) for i in up.tolist()])  # fmt: skip
    rows = []
    if closed is None:
        closed = bool(f[0] > check_force)
    for i, kind, level in found:
        if (kind == CHECK_VALVE_OPENS) != closed:  # a second crossing of the same level
            continue
        share = (f[i] - level) / (f[i] - f[i + 1])
        t = time[i] + share * (time[i + 1] - time[i])
        here = cfg[i] if events is None else _configuration_at(t, events, cfg[0])
        rows.append((t, kind, here, here, 0.0, 0.0))
        closed = not closed
    return np.array(rows, float).reshape(len(rows), N_EVENT_FIELDS)


def _configuration_at(t: float, events: np.ndarray, first: float) -> float:
    """The configuration at time ``t`` [s]: the one the last contact event (separation or
    impact) of ``events`` at or before it leaves, ``first`` before any."""
    contact = np.isin(events[:, EV_KIND], CONTACT_EVENTS) & (events[:, EV_TIME] <= t)
    return float(events[np.flatnonzero(contact)[-1], EV_TO]) if contact.any() else float(first)


def plunger_state(train, mass_inverse: np.ndarray, gains: Any = None) -> PlungerState | None:
    """The compliant integrator's state of ``train``'s adjuster (None: none): in a chain's
    link, or under a finger follower's pivot with ``gains`` its g(θ) (a ``Lift``, see
    :class:`PlungerState`)."""
    hla = adjuster(train)
    if hla is None:
        return None
    pivot = on_pivot(train)
    if pivot and gains is None:
        raise TypeError("a pivot's plunger needs its gains over the turn (lever_tables)")
    n = mass_inverse.shape[0]
    index, sign = chain_placement(len(train.masses))
    d = np.zeros(n)
    d[index[0]] += sign[0]
    d[index[1]] -= sign[1]
    link = next(e for e in chain_elements(train) if e.name == "link")
    k = float(link.stiffness[0, 0])
    e0 = float(train.hla_extension)
    push = np.zeros(n) if pivot else mass_inverse @ d * k
    return PlungerState(
        d, k, hla.check_force, hla.leak_down, hla.pump_up, -e0, hla.travel - e0, e0, push,
        gains if pivot else None,
    )  # fmt: skip


def carried(case, integrator: str) -> bool:
    """``case``'s adjuster is a state of its run, not moved turn by turn: with compliant
    contacts the compliant integrator's (under ``integrator`` default or compliant); with
    rigid ones modal-exact's, in a chain's link (``plunger_modes``, under default or
    modal-exact)."""
    if adjuster(case.train) is None:
        return False
    if case.compliant:
        return integrator in ("default", "compliant")
    return integrator in ("default", "modal-exact") and not on_pivot(case.train)
