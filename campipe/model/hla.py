"""A hydraulic lash adjuster (HLA): plunger, high-pressure chamber, check valve, leak-down.

The adjuster is a plunger in a body over a high-pressure chamber (HPC). A light plunger
spring and the engine's oil supply push the plunger out; together they hold the *check
force* F_c (plunger spring plus supply pressure × plunger area). The load F through the
adjuster decides its check valve:

- F > F_c, **check valve closed**: the HPC is sealed and the adjuster is stiff (the oil
  column and the body, ``hla_stiffness``, in series with the member it sits in); oil leaks
  out through the plunger's clearance at a rate proportional to the excess pressure, so
  the plunger sinks (*leaks down*) at ``(F − F_c) / c_L``, c_L the leak-down coefficient
  ``hla_leak_down`` [N·s/m] (a laminar annular leak: c_L = A²/G, A the plunger's area and G
  the clearance's conductance; a leak-down test's load over its sinking speed);
- F < F_c, **check valve open**: oil refills the HPC and the plunger extends (*pumps up*)
  at ``(F_c − F) / c_P``, c_P the pump-up coefficient ``hla_pump_up`` [N·s/m] (the feed's
  and the check valve's resistance), until the load it takes up reaches F_c and the valve
  closes: it takes up lash (on the base circle, and into a gap the follower opens when it
  leaves the cam: *pump-up*, holding the valve off its seat);
- the plunger's extension e stays within its travel, 0 (bottomed: the dry lash) to
  ``hla_travel``.

**How the engine carries it.** The plunger's extension is a *slow state*: it moves microns
a valve event while the train's dynamics take milliseconds. The switch between the two
regimes is located on the force the turn gives (the roots of F − F_c on its piecewise-linear
interpolant between the output samples) and the extension advanced once a turn by the
leak-down and pump-up over that turn (:meth:`LashAdjuster.advance`). Between two turn
boundaries the train runs with the extension fixed, exactly (the adjuster is then a linear
spring in the chain, and an extension e a change of that member's rest length, which in a
chain is exactly the cam's lift raised by e: ``campipe.engine.lash_adjuster``). What is
approximated: the plunger's motion within a turn is applied to the train at the turn's end
(the train's load is the fixed extension's, an error of k·Δe, the stiffness times one turn's
leak-down or pump-up; the pump-up itself takes the load its own motion within the turn
makes, with the seated stiffness, :func:`seated_stiffness`), and the integrals over the turn
take the force as linear between samples (an error of order (Δθ)²·F″ a sample).

Pure Python and numpy on floats and arrays; a layout places the adjuster (which member's
force passes through it, how its extension moves the train): a chain's in series with its
link next to the cam (:mod:`campipe.model.elements`); a finger follower's under its pivot, its
extension raising the pivot (the valve's kinematic lift changes by
:func:`~campipe.model.levers.base_take_up`, about e·(b − a)/a) and its load the pivot's
(:attr:`~campipe.model.levers.KinematicState.gain` times the pallet's force).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.model.levers import FINGER_FOLLOWER, base_take_up, lever_of, pivot_gain

#: The adjuster's model keys: (name, long name, SI units, display units, default), in the
#: order ``campipe.model.parameters`` declares them (``none``: no adjuster).
HLA_KEYS = (
    ("hla_stiffness", "hydraulic lash adjuster's stiffness with its check valve closed (oil "
     "column and body), in series with the chain's link next to the cam or under a finger "
     "follower's pivot", "N/m", "N/mm"),
    ("hla_leak_down", "hydraulic lash adjuster's leak-down coefficient: the load above the "
     "check force per unit of the plunger's sinking speed", "N*s/m", "N*s/mm"),
    ("hla_check_force", "hydraulic lash adjuster's check force (plunger spring plus supply "
     "pressure times plunger area): below it the check valve opens", "N", "N"),
    ("hla_pump_up", "hydraulic lash adjuster's pump-up coefficient: the load below the check "
     "force per unit of the plunger's extending speed, check valve open", "N*s/m", "N*s/mm"),
    ("hla_travel", "hydraulic lash adjuster's plunger travel from bottomed out", "m", "mm"),
    ("hla_extension", "hydraulic lash adjuster's plunger extension at the run's start, from "
     "bottomed out (0: leaked down, the dry lash)", "m", "mm"),
)  # fmt: skip
#: The keys an adjuster needs (``hla_extension`` defaults to 0).
NEEDED = tuple(k[0] for k in HLA_KEYS[:-1])


@dataclass(frozen=True)
class LashAdjuster:
    """One hydraulic lash adjuster (see the module)."""

    stiffness: float  # [N/m] check valve closed, in series with its member
    leak_down: float  # [N·s/m] c_L
    check_force: float  # [N] F_c
    pump_up: float  # [N·s/m] c_P
    travel: float  # [m] the plunger's extension from bottomed out, at most
    seated: float  # [N/m] its load per unit of its extension, on the base circle (seated_stiffness)

    def series(self, stiffness: float) -> float:
        """The stiffness [N/m] of a member of ``stiffness`` with the adjuster in series."""
        return 1.0 / (1.0 / stiffness + 1.0 / self.stiffness)

    def advance(
        self, extension: float, time: np.ndarray, force: np.ndarray, gap: np.ndarray
    ) -> tuple[float, float, float]:
        """(the extension after the turn [m], its leak-down [m], its pump-up [m]) from the
        extension at its start and the turn's samples (``force`` [N] through the adjuster,
        ``gap`` [m] between cam and follower, of a run with the plunger held where it
        started), interval by interval in the turn's order, held within 0 … ``travel`` at
        each (a plunger bottomed out does not leak down, one fully out does not pump up): the
        leak-down and pump-up are what it moved.

        The check valve closed where F > F_c, it sinks ∫ (F − F_c)⁺ dt / c_L. Open, it rises
        at (F_c − F')/c_P, F' its load with the plunger where it is: the run's load F and gap
        g moved by what it rose or sank since the run's extension e₀ (:meth:`_rise`, k the
        :attr:`seated` stiffness), until it reaches e₀ + g + (F_c − F)/k, where the check
        valve closes (F and g each interval's mean over its open part). What it leaked down
        earlier in the turn is pumped back on the base circle after it, as the carried
        plunger does (a cap of the turn's gap alone left a finger's roller standing off its
        base circle every turn by a turn's leak-down less F_c/k).

        The load is never below 0 (:meth:`_rise`): the plunger and what sits on it (a
        pushrod's cup, a stem's tip, a finger's socket) only push."""
        sinks = excess_parts(time, force, self.check_force) / self.leak_down
        lacking = excess_parts(time, -force, -self.check_force)  # ∫ (F_c − F)⁺ dt [N·s]
        open_time = open_parts(time, force, self.check_force)
        is_open = np.asarray(force) < self.check_force
        g = np.where(is_open, np.asarray(gap, float), 0.0)
        ends = is_open[:-1].astype(float) + is_open[1:]
        with np.errstate(divide="ignore", invalid="ignore"):
            gaps = np.where(ends > 0, (g[:-1] + g[1:]) / ends, 0.0)
        start = float(extension)
        e, leak, pump = start, 0.0, 0.0
        rows = zip(sinks.tolist(), lacking.tolist(), open_time.tolist(), gaps.tolist(), strict=True)
        for sink, short, dt, g_j in rows:
            if sink:
                moved = min(sink, e)
                e, leak = e - moved, leak + moved
            if short > 0.0 and dt > 0.0:
                moved = self._rise(e - start, short / dt, dt, g_j)
                moved = max(min(moved, self.travel - e), 0.0)
                e, pump = e + moved, pump + moved
        return e, leak, pump

    def _rise(self, raised: float, lacking: float, dt: float, gap: float) -> float:
        """What the plunger rises [m] over ``dt`` [s] with its check valve open, ``raised``
        [m] above the run's extension (below it after a leak-down), the run's load F short of
        F_c by ``lacking`` [N] and its gap ``gap`` [m] (:meth:`advance`). Off the cam in the
        run (g > 0) the plunger's load stays the link's own F until it has risen by g, then
        gains k·(raised − g); on the cam (g = 0) it is F + k·raised, and where that is below
        0 the follower stands off and the load is 0. Below that boundary it rises at
        (F_c − load)/c_P, the load never below 0 (the plunger only pushes: where the run's
        link pulls, off the cam, it is unloaded and rises at F_c/c_P); past it it approaches
        g + (F_c − F)/k as 1 − exp(−k·t/c_P)."""
        k, force = self.seated, self.check_force - lacking
        boundary, load = (gap, max(force, 0.0)) if gap > 0.0 else (-force / k, 0.0)
        moved = 0.0
        if raised < boundary:
            rate = (self.check_force - load) / self.pump_up
            if rate <= 0.0:
                return 0.0
            if rate * dt <= boundary - raised:
                return rate * dt
            moved = boundary - raised
            dt -= moved / rate
        target = gap + lacking / k - raised - moved
        return moved + max(target, 0.0) * -math.expm1(-k * dt / self.pump_up)


def excess_integral(time: np.ndarray, force: np.ndarray, level: float) -> float:
    """∫ (F − level)⁺ dt over the piecewise-linear interpolant of the samples [N·s]: exact
    for it, each crossing of the level located on its sample interval (the check valve's
    switch, by the interpolant's root)."""
    return float(excess_parts(time, force, level).sum())


def open_parts(time: np.ndarray, force: np.ndarray, level: float) -> np.ndarray:
    """The time [s] of each sample interval the piecewise-linear interpolant of ``force``
    spends below ``level`` (one fewer than the samples)."""
    d = np.asarray(force, float) - level
    a, b, dt = d[:-1], d[1:], np.diff(np.asarray(time, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where((a < 0) != (b < 0), -np.minimum(a, b) / np.abs(b - a), 0.0)
    return np.where((a < 0) & (b < 0), dt, share * dt)


def excess_parts(time: np.ndarray, force: np.ndarray, level: float) -> np.ndarray:
    """:func:`excess_integral` over each sample interval [N·s] (one fewer than the samples)."""
    t = np.asarray(time, float)
    d = np.asarray(force, float) - level
    a, b, dt = d[:-1], d[1:], np.diff(t)
    both = (a >= 0) & (b >= 0)
    parts = np.where(both, 0.5 * (a + b) * dt, 0.0)
    cross = (a > 0) != (b > 0)
    cross &= ~both
    with np.errstate(divide="ignore", invalid="ignore"):
        # the positive part's triangle: base = its share of the interval, height = its end
        top = np.maximum(a, b)
        share = top / np.abs(b - a)
        parts += np.where(cross & (top > 0), 0.5 * top * share * dt, 0.0)
    return parts


def adjuster(train) -> LashAdjuster | None:
    """``train``'s lash adjuster, None if it has none (``hla_leak_down`` none)."""
    if math.isnan(getattr(train, "hla_leak_down", math.nan)):
        return None
    return LashAdjuster(
        train.hla_stiffness,
        train.hla_leak_down,
        train.hla_check_force,
        train.hla_pump_up,
        train.hla_travel,
        seated_stiffness(train),
    )


def seated_stiffness(train) -> float:
    """The load [N] through ``train``'s adjuster per unit of its extension [m] with the
    follower on the base circle and the valve on its seat: the adjuster in series with every
    link down to the valve (the spring, beside the seated valve, takes nothing of it); under
    a finger's pivot that path at the pallet (the adjuster in it as :func:`hla_series`) seen
    at the pivot, g₀² times it (the pivot's rise e moves the pallet by g₀·e, and its load is
    g₀ times the pallet's)."""
    flex = seated_flexibility(train)
    return pivot_gain(train) ** 2 / flex if on_pivot(train) else 1.0 / flex


def seated_flexibility(train) -> float:
    """The give [m/N] at the valve of the path from ``train``'s adjuster to the seat, the
    follower on the base circle and the valve seated: the adjuster (:func:`hla_series`) in
    series with every link down to the valve."""
    return 1.0 / hla_series(train) + sum(1.0 / float(k) for k in train.stiffnesses)


def on_pivot(train) -> bool:
    """A finger follower whose lash adjuster is under its pivot (``engine.lash_adjuster``)."""
    return getattr(train, "layout", None) == FINGER_FOLLOWER and has_adjuster(train)


def hla_series(train) -> float:
    """The adjuster's stiffness [N/m] in series with the chain's link next to the cam (NaN:
    none): its own in a chain's link; under a finger's pivot, seen at the pallet, k/g₀² (the
    pivot's give R/k under the load R = g₀·F moves the pallet by g₀ times it, g₀ the rest
    :func:`~campipe.model.levers.pivot_gain`; held at rest as the lever's reduced mass is)."""
    k = float(getattr(train, "hla_stiffness", math.nan))
    return k / pivot_gain(train) ** 2 if on_pivot(train) else k


def taken_up(train, extension: np.ndarray) -> np.ndarray:
    """The lash [m] the plunger's ``extension`` [m] takes up where ``lash`` is measured: the
    extension itself in a chain's link; under a finger's pivot its take-up at the valve on the
    base circle (:func:`~campipe.model.levers.base_take_up`, exact)."""
    extension = np.asarray(extension, float)
    if not on_pivot(train):
        return extension
    lever = lever_of(train)
    flat = [base_take_up(lever, float(e)) if e == e else math.nan for e in extension.ravel()]
    return np.reshape(flat, extension.shape)


def has_adjuster(train) -> bool:
    """A train with a hydraulic lash adjuster (its ``hla_stiffness`` given): the chain's link
    next to the cam has it in series."""
    return not math.isnan(getattr(train, "hla_stiffness", math.nan))
