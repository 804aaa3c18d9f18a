"""A chain's lash-adjuster plunger in the form modal-exact integrates: one more coordinate.

The plunger (:mod:`campipe.engine.plunger`) is first order: with the force through the link
F = k·(d·q + u) it moves as

    u̇ = −(F − F_c)/c,   c = c_L (check valve closed) or c_P (open),

a spring in series with a dashpot, and modal-exact integrates second-order trains
M q̈ + C q̇ + K q = f (``campipe.engine.modal``: their state [x; ẋ], a coordinate's velocity
beside it). Differentiating the plunger's law once makes u a coordinate like the others, its
velocity w = u̇ the other half of its state:

    ẇ = −(k/c)·(d·q̇ + w) − β·I,     I = w + (F − F_c)/c.

I is the law's residual. Along any solution İ = −β·I, so a state that obeys the law
(I = 0: w set from the state where a regime begins, ``PlungerState.rate``) obeys it for
ever, exactly, and the term −β·I changes nothing on such a solution; without it (β = 0) I
would be conserved, not zero, an eigenvalue 0 that the particular solutions' A⁻¹
(``modal``) cannot take. With it the regime's state matrix has the Maxwell element's own
eigenvalue −k/c (the link relaxing through the dashpot) and −β besides, a mode that no
consistent state excites. β is set well above the train's fastest natural frequency
(BAUMGARTE_FACTOR), so that it never coincides with a mode of the train.

In one row, with the chain's n coordinates first and u last (index n):

    ü + (k/c + β)·u̇ + (k/c)·d·q̇ + (β·k/c)·(d·q + u) = β·F_c/c,

and the link's rows gain k·d·u (the extension lengthens the link). The particular solutions
of the polynomial and harmonic forcing obey the law too (I is a polynomial, or a harmonic,
with İ = −β·I: zero), so the exact propagation keeps I at rounding.

**Off the cam the follower floats.** In a chain the cam's mass hangs on the rest only
through the link, so with the follower off the cam (configurations II and IV) and the
plunger free the link's spring and dashpot in series leave it no static stiffness: the state
matrix has an eigenvalue 0 (a drift, which the first-order law has too, and F_c drives:
pumping up, the plunger pushes the follower back to the cam at a steady rate). modal-exact's
particular solutions, Z_k = A⁻¹(…), then need their drift form: a term in the null vector
one degree higher (the forcing there is constant: the cam's lift enters only where the
follower is held). On the cam (I, III), and with the plunger held anywhere, A is regular.
The link relaxing through the dashpot is slow too (k/c of a few per second, against the
cam's hundreds): the drift and that relaxation are ``modal``'s slow blocks, whose particular
solutions are a series (``closed_form._slow_series``).

A plunger at an end of its travel (or held until t = 0, ``plunger.HELD``) does not move: its
row is ü + 2β·u̇ + β²·u = β²·u_end, decoupled from the chain, which from u = u_end, u̇ = 0
stays there exactly (a double eigenvalue −β: one 2×2 block, ``modal``'s critically damped
case); the link's rows still take k·d·u_end.

Unloaded (the link pulling on it, ``plunger.UNLOADED``) it rises at F_c/c_P whatever the
chain does: ü + β·u̇ = β·F_c/c_P, decoupled from the chain (an eigenvalue 0, a drift, and
−β), the link's rows still taking k·d·u.

**In modal-exact.** A case runs the train :class:`Embedded` in the regime ``HELD`` (its
periodic start the train's with the plunger fixed at its start) and the batch's stack holds
its other regimes' rows (:func:`regime_rows`); its run carries the plunger's rows
(:func:`plunger_runs`): at t = 0 it takes the regime its load gives, and its check valve
(with ``plunger.HYSTERESIS``), its travel and its load through 0 are three more monitors,
each switch changes the row (``exact.kernel._plunger_event``), the first two's an event.
``lash_adjuster.in_kernel`` runs it and reads each turn's leak-down and pump-up from u.

Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.engine.closed_form import no_plungers
from campipe.engine.plunger import (
    BOTTOMED,
    CLOSED,
    HELD,
    OPEN,
    TOPPED,
    UNLOADED,
    PlungerState,
    plunger_state,
)
from campipe.model import ValveTrain, system_matrices
from campipe.model.assembly import SystemMatrices

#: β over the train's fastest undamped natural frequency: far enough above it that −β
#: coincides with none of the train's eigenvalues (an irrational factor, so no multiple of a
#: mode's either).
BAUMGARTE_FACTOR = 4.0 * math.sqrt(2.0)


def baumgarte_rate(sm: SystemMatrices) -> float:
    """β [1/s] for the train of ``sm`` (see the module)."""
    return BAUMGARTE_FACTOR * float(np.max(sm.frequencies))


def end_of(p: PlungerState, regime: int) -> float:
    """u [m] where ``regime`` holds the plunger (an end of its travel, or its start)."""
    return {BOTTOMED: p.low, TOPPED: p.high, HELD: 0.0}[regime]


def embedded(sm: SystemMatrices, p: PlungerState, regime: int, beta: float) -> SystemMatrices:
    """The train of ``sm`` with its adjuster's plunger ``p`` as a coordinate n (see the
    module) in ``regime`` (``plunger.CLOSED``, ``OPEN``, ``BOTTOMED``, ``TOPPED``, ``HELD``,
    ``UNLOADED``),
    β = ``beta`` [1/s]. Its matrices are not symmetric; ``frequencies`` and ``modes`` are the
    chain's own (for reports), the plunger's row having none."""
    if p.gains is not None:
        raise ValueError("a pivot's plunger is not a link's: it has no embedded form")
    n = sm.mass.shape[0]
    m = np.zeros((n + 1, n + 1))
    c = np.zeros((n + 1, n + 1))
    k = np.zeros((n + 1, n + 1))
    f = np.zeros(n + 1)
    m[:n, :n], c[:n, :n], k[:n, :n], f[:n] = sm.mass, sm.damping, sm.stiffness, sm.preload
    m[n, n] = 1.0
    k[:n, n] = p.k * p.d  # the link's force k·(d·q + u) on the chain
    if regime == UNLOADED:  # u̇ = F_c/c_P, whatever the link does: ü = −β·(u̇ − F_c/c_P)
        c[n, n] = beta
        f[n] = beta * p.check_force / p.damper(regime)
    elif regime in (CLOSED, OPEN):
        rate = p.k / p.damper(regime)  # the Maxwell element's, k/c [1/s]
        c[n, :n] = rate * p.d
        c[n, n] = rate + beta
        k[n, :n] = beta * rate * p.d
        k[n, n] = beta * rate
        f[n] = beta * p.check_force / p.damper(regime)
    else:
        c[n, n] = 2.0 * beta
        k[n, n] = beta * beta
        f[n] = beta * beta * end_of(p, regime)
    return SystemMatrices(m, k, c, sm.frequencies, sm.modes, f)


#: The regimes a carried plunger's run needs a train row for, in ``plunger``'s order.
REGIMES = (CLOSED, OPEN, BOTTOMED, TOPPED, HELD, UNLOADED)


@dataclass(frozen=True)
class Embedded:
    """A chain's train with its lash adjuster's plunger as coordinate n in ``regime`` (see
    the module): what modal-exact runs for a case whose plunger it carries. Reads as its
    ``train`` for everything else (the case's contacts, restitution, lash)."""

    train: ValveTrain
    regime: int = HELD

    def __getattr__(self, name: str):
        if name.startswith("__") or name == "train":  # (copy and pickle look for dunders)
            raise AttributeError(name)
        return getattr(self.train, name)

    def matrices(self) -> SystemMatrices:
        """The embedded system matrices (``embedded``), β from the chain's own."""
        sm = system_matrices(self.train)
        p = self.plunger()
        return embedded(sm, p, self.regime, baumgarte_rate(sm))

    def plunger(self) -> PlungerState:
        sm = system_matrices(self.train)
        p = plunger_state(self.train, np.linalg.inv(sm.mass))
        if p is None or p.gains is not None:
            raise ValueError("an embedded plunger needs a lash adjuster in a chain's link")
        return p

    def in_regime(self, regime: int) -> Embedded:
        return Embedded(self.train, regime)


def regime_rows(trains, data: list, preps, modal, matrices) -> tuple[np.ndarray, list, list]:
    """A batch's stack of ``trains``' closed-form ``data`` (``batch.train_modal`` per train)
    with each carried plunger's other regimes appended (by ``modal`` and ``matrices``:
    ``batch.train_modal`` and ``batch.train_matrices``): ((n_trains, 6) each train's row per
    regime (``REGIMES``), −1 for any other train; the data; the preloads; ``preps`` the
    trains' ``batch.Prepared``)."""
    data = list(data)
    loads = [p.matrices.preload for p in preps]
    rows = np.full((len(trains), len(REGIMES)), -1, np.int64)
    for i, t in enumerate(trains):
        if isinstance(t, Embedded):
            for r in REGIMES:
                rows[i, r] = i if r == t.regime else len(data)
                if r != t.regime:
                    data.append(modal(t.in_regime(r)))
                    loads.append(matrices(t.in_regime(r)).preload)
    return rows, data, loads


def plunger_runs(trains, which: np.ndarray, regimes: np.ndarray, n_q: int) -> dict[str, np.ndarray]:
    """``closed_form.ExactRuns``' plunger fields of a batch whose case c runs ``trains[which[c]]``
    (``regimes``: ``regime_rows``'), for at most ``n_q`` coordinates."""
    out = no_plungers(which.size, n_q)
    for i, t in enumerate(trains):
        if isinstance(t, Embedded):
            rows = plunger_rows(t, n_q)
            for c in np.flatnonzero(which == i):
                for name, value in rows.items():
                    out[name][c] = value
                out["plunger_train"][c] = regimes[i]
    return out


def plunger_rows(train: Embedded, n_q: int) -> dict[str, Any]:
    """One case's ``closed_form.ExactRuns`` plunger fields (but its train rows) for
    ``train`` in a batch of at most ``n_q`` coordinates: u's coordinate n, the force
    through the adjuster F = k·(d·q + u) as a row, its check force, damper and ends per
    regime (u measured from the start's extension e₀: from −e₀ to travel − e₀)."""
    p = train.plunger()
    n = p.d.size
    force = np.zeros(n_q)
    force[:n] = p.k * p.d
    force[n] = p.k
    return {
        "plunger_coord": np.int64(n),
        "plunger_force": force,
        "plunger_check": p.check_force,
        "plunger_damper": np.array([p.damper(r) for r in REGIMES]),
        "plunger_end": np.array(
            [end_of(p, r) if r in (BOTTOMED, TOPPED, HELD) else np.nan for r in REGIMES]
        ),
    }
