"""The compliant integrator's exact propagation of a kelvin–voigt case
(:mod:`campipe.engine.compliant`): with the cam's polynomial and harmonic made states of one
homogeneous linear system, e^{A·τ} (balanced, on a grid of STEPS_PER_PERIOD steps a period of
its fastest oscillation) propagates it to rounding, whatever the tolerance, and its events are
located on that exact state by a bracketed root search, as solve_ivp's are on its dense output.

A segment reads the run (``compliant._Run``: its system, contact state, piece, a carried
plunger's regime) and returns what ``compliant.integrate`` reads of solve_ivp's solution.

Pure numerics: arrays in, arrays out. SciPy is imported where it is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.constants import TWO_PI
from campipe.errors import CampipeError
from campipe.vocabulary import CAM, SEAT


class UnresolvedSwitch(CampipeError, RuntimeError):
    """A contact switch whose instant the root search cannot locate: the monitor's sign
    change lost to rounding or to non-finite states (a stiff undamped contact). It ends its
    case with status NONFINITE, as a failed step does; the batch's other cases go on."""


#: Polynomial states of the augmented system: x^j, j = 0 … 7 (x the angle into the piece).
N_POLY = 8
#: Grid steps per period of the fastest oscillation of a contact state's modes.
STEPS_PER_PERIOD = 8
#: Bracketed root search tolerance [s], as solve_ivp's (4 ulp).
EVENT_XTOL = 4 * np.finfo(float).eps


@dataclass
class _ExactResult:
    """What ``integrate`` reads of a segment (solve_ivp's names)."""

    status: int  # 0: reached the end; 1: a terminal event
    t: np.ndarray  # grid times [s]
    y: np.ndarray  # (2n, n_t) states on the grid
    t_events: list[np.ndarray]
    y_events: list[np.ndarray]
    sol: Any  # t → state


def _augmented(run: Any) -> np.ndarray:
    """The kelvin-voigt system in the current contact state and piece as one homogeneous
    linear system ẇ = A w, w = (q, q̇, x⁰ … x⁷, sin ωt, cos ωt): the cam's lift on the piece is
    a polynomial in x = θ − the piece's start plus a harmonic, and each of those is itself
    the solution of a linear system, so e^{A·τ} propagates the state exactly."""
    s, n, p = run.s, run.n, run.s.plunger
    w = s.lift.w
    n2 = 2 * n + (p is not None)  # (q, q̇) and a carried plunger's u
    m = n2 + N_POLY + 2
    a = np.zeros((m, m))
    k_eff = s.stiffness.copy()
    c_eff = s.damping.copy()
    force = s.load.copy()  # on the constant state x⁰
    cam = np.zeros(N_POLY + 2)  # k·L + c·L' per forcing state
    poly = s.lift.poly[run.piece]
    ta, tb = s.lift.trig[run.piece]
    if run.closed[0]:
        k, c = s.cam.stiffness, s.cam.damping
        k_eff[CAM, CAM] += k
        c_eff[CAM, CAM] += c
        cam[:N_POLY] = k * poly
        cam[: N_POLY - 1] += c * w * np.arange(1, N_POLY) * poly[1:]
        cam[N_POLY:] = (k * ta - c * w * tb, k * tb + c * w * ta)
    if run.closed[1] and s.seat is not None:
        k_eff[SEAT, SEAT] += s.seat.stiffness
        c_eff[SEAT, SEAT] += s.seat.damping
        force[SEAT] += s.seat.stiffness * s.seat_q
    a[:n, n : 2 * n] = np.eye(n)
    a[n : 2 * n, :n] = -s.minv @ k_eff
    a[n : 2 * n, n : 2 * n] = -s.minv @ c_eff
    a[n : 2 * n, n2:] = -np.outer(s.minv[:, CAM], cam)
    a[n : 2 * n, n2] += s.minv @ force
    if p is not None:
        a[n : 2 * n, 2 * n] = -p.push
        a[2 * n, :n], a[2 * n, 2 * n], a[2 * n, n2] = p.row(run.valve)
    for j in range(1, N_POLY):
        a[n2 + j, n2 + j - 1] = j * w
    a[m - 2, m - 1] = w
    a[m - 1, m - 2] = -w
    return a


class _Propagator:
    """e^{A·τ} for 0 ≤ τ ≤ h, applied to a state: e^{A·h} once, and e^{A·h·2^−j} − I for
    j = 1 … levels (each from the next by E ← 2E + E², the smallest by its Taylor series), so
    τ = h·Σ b_j 2^−j costs a matrix–vector product per set bit, not a Padé approximant. The
    matrix is balanced first: the state mixes metres, metres per second and the forcing's
    powers of the angle, and the contact force is a small difference of positions, so an
    unbalanced exponential loses digits it needs."""

    def __init__(self, a: np.ndarray, h: float) -> None:
        from scipy.linalg import matrix_balance

        b, (d, _) = matrix_balance(a * h, permute=False, separate=True)
        norm = float(np.abs(b).sum(axis=1).max())
        self.levels = int(max(48, math.ceil(math.log2(max(norm, 1.0))) + 24))
        x = b / 2.0**self.levels
        e = x.copy()
        term = x.copy()
        for k in range(2, 8):
            term = term @ x / k
            e = e + term
        steps = [e]
        for _ in range(self.levels):
            e = 2.0 * e + e @ e
            steps.append(e)
        self.minus_one = steps[::-1]  # [j]: e^{b·2^−j} − I
        self.d = d
        self.h = h
        self.phi = (np.eye(b.shape[0]) + self.minus_one[0]) * d[:, None] / d[None, :]

    def advance(self, w: np.ndarray, tau: float) -> np.ndarray:
        """e^{A·τ}·w, 0 ≤ τ ≤ h."""
        f = tau / self.h
        if f >= 1.0:
            return self.phi @ w
        wb = w / self.d
        for j in range(1, self.levels + 1):
            part = 2.0**-j
            if f >= part:
                wb = wb + self.minus_one[j] @ wb
                f -= part
            if f <= 0.0:
                break
        return wb * self.d


def _forcing_state(run: Any, t: float) -> np.ndarray:
    lift = run.s.lift
    x = lift.w * t - run.rev * TWO_PI - lift.breaks[run.piece]
    theta = lift.w * t
    return np.concatenate([x ** np.arange(N_POLY), [math.sin(theta), math.cos(theta)]])


def exact_segment(run: Any, t_a: float, t_b: float, z_a: np.ndarray, events: list[Any],
                  max_step: float) -> _ExactResult:  # fmt: skip
    """Propagate a kelvin-voigt case exactly from t_a to t_b (or its first terminal event):
    e^{A·h} on a grid fine enough to see each monitor's sign change (STEPS_PER_PERIOD a
    period of the fastest oscillation), each crossing found by brentq on the exact state, as
    solve_ivp's events are on its dense output."""
    from scipy.optimize import brentq

    n2 = z_a.size
    key = (tuple(run.closed), run.valve, run.piece)
    cache = run.exact_cache
    if key not in cache:
        a = _augmented(run)
        top = np.abs(np.linalg.eigvals(a[:n2, :n2]).imag).max()
        h = min(TWO_PI / (STEPS_PER_PERIOD * top) if top > 0 else math.inf, max_step)
        h = min(h, TWO_PI / (STEPS_PER_PERIOD * run.s.lift.w))
        cache[key] = (h, _Propagator(a, h))
    h, prop = cache[key]
    phi = prop.phi

    def state(t0: float, w0: np.ndarray, t: float) -> np.ndarray:
        return prop.advance(w0, t - t0)

    ts, ws = [t_a], [np.concatenate([z_a, _forcing_state(run, t_a)])]
    g_old = [ev(t_a, z_a) for ev in events]
    t_events: list[list[float]] = [[] for _ in events]
    y_events: list[list[np.ndarray]] = [[] for _ in events]
    status = 0
    while ts[-1] < t_b:
        t, w = ts[-1], ws[-1]
        if t + h >= t_b * (1.0 - 1e-15):
            t_new, w_new = t_b, state(t, w, t_b)
        else:
            t_new, w_new = t + h, phi @ w
        g_new = [ev(t_new, w_new[:n2]) for ev in events]
        found = []
        for k, ev in enumerate(events):
            up = g_old[k] <= 0.0 <= g_new[k]
            down = g_old[k] >= 0.0 >= g_new[k]
            if (up and ev.direction > 0) or (down and ev.direction < 0):
                try:
                    root = brentq(
                        lambda tt, ev=ev, t=t, w=w: ev(tt, state(t, w, tt)[:n2]),
                        t, t_new, xtol=EVENT_XTOL, rtol=EVENT_XTOL,
                    )  # fmt: skip
                except (ValueError, RuntimeError) as exc:  # no bracket, or no convergence
                    if not ev.terminal:  # a force's maximum where its rate is rounding:
                        continue  # (a static force) no maximum to locate, nothing switches
                    raise UnresolvedSwitch(
                        f"a switch in [{t}, {t_new}] s: {exc}", key="compliant", found=(t, t_new)
                    ) from None
                found.append((root, k))
        terminal = [(tt, k) for tt, k in found if events[k].terminal]
        if terminal:
            t_stop, _ = min(terminal)
            t_new, w_new = t_stop, state(t, w, t_stop)
            status = 1
        for tt, k in found:
            if tt <= t_new:
                t_events[k].append(tt)
                y_events[k].append(state(t, w, tt)[:n2])
        ts.append(t_new)
        ws.append(w_new)
        g_old = g_new
        if status:
            break
    grid = np.array(ts)
    states = np.array(ws)

    def sol(tt: float) -> np.ndarray:
        i = min(max(int(np.searchsorted(grid, tt, side="right")) - 1, 0), grid.size - 1)
        return state(grid[i], states[i], tt)[:n2]

    return _ExactResult(
        status, grid, states[:, :n2].T,
        [np.array(te) for te in t_events], [np.array(ye) for ye in y_events], sol,
    )  # fmt: skip
