"""The no-follow onset: the lowest speed of a speed range at which a design's steady state
leaves the cam (with a seat, for at least a level a turn), found by a search that misses no
window of no-follow inside the range, and checked in the time domain.

The steady state at a speed comes from ``campipe.engine.periodic``: configuration I's closed
form (its margin, the least cam compression over the turn) where the train follows the cam
with the valve off its seat, else the seated steady state (``seated_no_follow``). Between
the speeds it looks at, the search certifies each interval free of no-follow: by a proven
bound on how fast configuration I's steady state changes with the speed
(``campipe.engine.slope_bound``) where both ends are configuration I's and the profile has
no lift or velocity step, else by an estimate from the chords (``onset_speeds``).

Pure numerics: arrays in, arrays out; no files, no printing.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe.constants import (  # noqa: F401  (the defaults, re-exported)
    DEFAULT_ONSET_LEVEL_DEG,
    DEFAULT_ONSET_TOLERANCE_RPM,
    RPM,
    TWO_PI,
)
from campipe.engine import slope_bound, steady
from campipe.engine.batch import Case, CaseError, RunSettings, check_run, run_batch, train_matrices
from campipe.engine.periodic import leave_speeds, prepare_steady
from campipe.errors import CampipeError
from campipe.model import ValveTrain
from campipe.model.hla import adjuster
from campipe.vocabulary import EV_TIME, EV_TO, FREE

#: Turns the engine integrates for a steady state with the valve seated on part of the turn
#: (from the periodic start of configuration I); the last is the steady state when it agrees
#: with the one before to SEATED_AGREEMENT [rad] of no-follow, else more turns follow, up to
#: MAX_SEATED_TURNS.
SEATED_TURNS = 3
MAX_SEATED_TURNS = 24
SEATED_AGREEMENT = 1e-9
#: Speeds at which the onset search first looks across a speed range; the intervals between
#: them are then certified free of no-follow or halved (``onset_speeds``).
SCAN_SPEEDS = 17
#: The certificate's safety factor: between two speeds where the design follows, the slope
#: of its margin is taken to be at most ONSET_SLOPE_FACTOR times the steepest of the chord
#: between them and the chords either side (``onset_speeds``).
ONSET_SLOPE_FACTOR = 2.0
#: The onset's default level [rad of no-follow a turn, with a seat] (``onset_speeds``: why
#: 0.5°); its tolerance's and the level's defaults in campipe.constants (read without numba).
DEFAULT_ONSET_LEVEL = math.radians(DEFAULT_ONSET_LEVEL_DEG)  # [rad]
#: The time-domain check: its offset either side of the onset, its turns from the periodic
#: start and the first of them left out (``confirm_onsets``).
CONFIRM_OFFSET = 0.005
CONFIRM_TURNS = 10
CONFIRM_WARMUP = 2
#: The nearer offsets above the onset the check tries in turn where the engine's no-follow
#: at onset·(1 + CONFIRM_OFFSET) does not reach the level: a window of no-follow narrower
#: than that (a helper's two-mass chain on a polydyne: a proven onset at 4328.35 rpm whose
#: window ends before 4350) is still seen (``confirm_onsets``).
CONFIRM_NEARER = (0.0025, 0.00125, 0.000625)


# --------------------------------------------------------------------------- the onset


class OnsetUnfinished(CampipeError, RuntimeError):
    """A search still open after more steps than its range and tolerance can need: never
    reported as "none" or "proven"."""


def seated_no_follow(cases: Sequence[Case]) -> tuple[np.ndarray, np.ndarray]:
    """No-follow per turn in the steady state of cases whose valve seats on part of the turn:
    the fixed point of the turn map over the exact piece propagators, by ``modal-exact`` from
    configuration I's periodic start, SEATED_TURNS turns and more until the last two turns'
    no-follow agree to SEATED_AGREEMENT.

    Returns
    -------
    separation : (n,) configuration II in the last turn [rad] (NaN: the run failed)
    converged : (n,) bool, the last two turns agreed
    """
    n = len(cases)
    sep = np.full(n, np.nan)
    converged = np.zeros(n, np.bool_)
    todo = np.arange(n)
    turns = SEATED_TURNS
    while todo.size and turns <= MAX_SEATED_TURNS:
        settings = RunSettings(revolutions=turns, output_every=math.radians(5.0))
        res = run_batch([cases[int(i)] for i in todo], settings, full_state=False,
                        on_failure="record")  # fmt: skip
        last = res.separation_per_rev[:, -1]
        ok = np.abs(last - res.separation_per_rev[:, -2]) <= SEATED_AGREEMENT
        sep[todo] = last
        converged[todo] = ok
        todo = todo[~ok & np.isfinite(last)]
        turns *= 2
    return sep, converged


@dataclass(frozen=True)
class Onset:
    """The no-follow onset of each design over a speed range (``onset_speeds``)."""

    speed: np.ndarray  # (n,) the onset [rad/s], within ± tolerance/2; NaN where none is found
    #: (n,) str: "found"; "below" (no-follow already at the range's lowest speed); "none" (the
    #: follower follows across the range)
    status: np.ndarray
    scan_speed: np.ndarray  # (n_scan,) the speeds looked at first [rad/s]
    #: (n, n_scan) the margin there, the least cam compression over the steady turn [N]; NaN
    #: where the valve seats on part of the turn (then the sign comes from ``seated_no_follow``)
    scan_margin: np.ndarray
    scan_no_follow: np.ndarray  # (n, n_scan) bool: no-follow in the steady state (at the level)
    seated: np.ndarray  # (n,) bool: the onset's bracket needed the seated steady state
    tolerance: float  # [rad/s]
    evaluations: np.ndarray  # (n,) steady states computed (closed form and seated)
    #: (n,) the level [rad of no-follow a turn] each design's onset reaches: 0 (first
    #: separation) without a seat
    level: np.ndarray | None = None
    #: (n,) bool: every interval the search passed (below the onset, or across the range)
    #: was certified by the proven bound or is no wider than the tolerance; False where an
    #: interval was certified by the chords' estimate (``onset_speeds``)
    proven: np.ndarray | None = None


#: The kinds of a point of the search: its value is the closed form's margin [N], or the
#: level less the seated steady state's no-follow per turn [rad] (``_Points``).
_CLOSED, _TURN = 0, 1


def _evaluate(designs, batch, speeds, todo, level, leave):
    """The steady state of the designs ``todo`` at speeds[i]: (value, kind, no-follow,
    margin, height). The value is positive where the design follows: the closed form's margin [N]
    where configuration I holds, or leaves the cam without a seat or at level 0; else (the
    valve seats on part of the turn, the follower leaves the cam at a break, above ``leave``
    [rad/s]: ``periodic.leave_speeds``, or it leaves the cam and a level is asked for) the
    level less the seated steady state's no-follow per turn [rad]. The margin is the closed
    form's, NaN where the valve seats or the follower leaves at a break; the height the
    closed form's least valve height above the seat [m] (+inf without a seat) where the
    value is the closed form's, else NaN."""
    n = len(designs)
    value = np.full(n, np.nan)
    kind = np.zeros(n, np.int8)
    no_follow = np.zeros(n, np.bool_)
    out = batch.extremes(np.where(todo, speeds, 1.0), with_max=False, active=todo)
    force = out[:, steady.MIN_FORCE]
    seats = todo & (out[:, steady.MIN_HEIGHT] < 0.0)
    off = seats | (todo & (speeds > leave))  # configuration I is not the steady state
    turn = off | (todo & (force < 0.0) & (level > 0.0))
    closed = todo & ~turn
    value[closed] = force[closed]
    no_follow[closed] = force[closed] < 0.0
    if turn.any():
        idx = np.flatnonzero(turn)
        sep, _ = seated_no_follow([dataclasses.replace(designs[i], speed=speeds[i]) for i in idx])
        kind[idx] = _TURN
        value[idx] = level[idx] - sep
        no_follow[idx] = np.where(level[idx] > 0.0, sep >= level[idx], sep > 0.0)
    margin = np.where(todo & ~off, force, np.nan)
    height = np.where(closed, out[:, steady.MIN_HEIGHT], np.nan)
    return value, kind, no_follow, margin, height


@functools.lru_cache(maxsize=4096)
def _transfer(train: ValveTrain) -> slope_bound.Transfer | None:
    """The train's transfer (``slope_bound.transfer``), None where it fails its check."""
    sm = train_matrices(train)
    tr = slope_bound.transfer(sm)
    return tr if slope_bound.checked(tr, sm) else None


class _Proof:
    """The proven bound of the designs' configuration I (``slope_bound``), per train and
    profile computed once, for designs whose profile is ``provable`` (no step in lift) and
    whose train's transfer passes its check, at speeds above ``held`` (where every velocity
    step strikes the held follower, as the series' impulse: ``slope_bound.held_from`` at
    the capture velocity ``capture`` [m/s])."""

    def __init__(self, designs: Sequence[Case], capture: float) -> None:
        self.designs = designs
        profiles: dict[int, int] = {}
        self.profile = np.array([profiles.setdefault(id(d.profile), len(profiles))
                                 for d in designs])  # fmt: skip
        firsts = {k: i for i, k in reversed(list(enumerate(self.profile.tolist())))}
        self._first = [firsts[k] for k in range(len(profiles))]
        ok = [slope_bound.provable(designs[i].profile) for i in self._first]
        self.provable = np.array(ok)[self.profile]
        for i in np.flatnonzero(self.provable):
            self.provable[i] = _transfer(designs[int(i)].train) is not None
        held = [slope_bound.held_from(designs[i].profile, capture) for i in self._first]
        self.held = np.array(held)[self.profile]
        self._spectra: dict[int, slope_bound.Spectrum] = {}

    def bounds(self, rows: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
        """The slope bounds of the cam force and the valve's height of the designs ``rows``
        over [a[i], b[i]], a profile and a size of train at a time."""
        force = np.empty(rows.size)
        height = np.empty(rows.size)
        transfers = [_transfer(self.designs[int(i)].train) for i in rows]
        size = np.array([t.poles.size if t is not None else 0 for t in transfers])
        for p, n in {(int(p), int(n)) for p, n in zip(self.profile[rows], size, strict=True)}:
            pick = np.flatnonzero((self.profile[rows] == p) & (size == n))
            if p not in self._spectra:
                self._spectra[p] = slope_bound.spectrum(self.designs[self._first[p]].profile)
            trs = slope_bound.stack([t for j in pick if (t := transfers[j]) is not None])
            force[pick], height[pick] = slope_bound.slope_bounds_many(
                trs, self._spectra[p], a[pick], b[pick]
            )
        return force, height


@dataclass
class _Points:
    """The search's state per design: ``a`` the highest speed up to which no-follow is
    excluded (its value, kind and height), and a stack of speeds above it still to pass (the
    top the nearest), each with its value, kind, height and whether it is no-follow."""

    a: np.ndarray
    a_value: np.ndarray
    a_kind: np.ndarray
    a_height: np.ndarray
    slope: np.ndarray  # the last certified chord's slope (NaN: none of a's kind)
    speed: np.ndarray  # (n, capacity) the stack
    value: np.ndarray
    kind: np.ndarray
    height: np.ndarray
    no_follow: np.ndarray
    depth: np.ndarray  # (n,) the stack's height
    active: np.ndarray  # (n,) bool: still searching
    scale: np.ndarray  # (n, 2) Illinois's factors on a's and the top's values
    side: np.ndarray  # (n,) the end the last split replaced: −1 a, +1 the top, 0 none
    proven: np.ndarray  # (n,) bool: no interval passed on the chords' estimate yet

    def top(self, k: int = 1) -> tuple[np.ndarray, ...]:
        """The k-th point from the top (k = 1: the top): speed, value, kind, no-follow,
        height; the bottom's where the stack is shallower."""
        rows = np.arange(self.depth.size)
        j = np.maximum(self.depth - k, 0)
        return (self.speed[rows, j], self.value[rows, j], self.kind[rows, j],
                self.no_follow[rows, j], self.height[rows, j])  # fmt: skip

    def _estimated(self, width: np.ndarray, chord: np.ndarray) -> np.ndarray:
        """Intervals [a, top] free on the chords' estimate: v_a + v_b ≥ L·(b − a), L =
        ONSET_SLOPE_FACTOR × the steepest of the chord over [a, top] (``chord``), the chord
        certified before it and the chord after it (of one kind)."""
        _, vb, kb, _, _ = self.top(1)
        c, vc, kc, _, _ = self.top(2)
        b = self.a + width
        with np.errstate(invalid="ignore", divide="ignore"):
            after = np.where(vc == vb, 0.0, (vc - vb) / (c - b))
            after = np.where((self.depth > 1) & (kc == kb), after, np.nan)
            steep = np.fmax(np.fmax(np.abs(chord), np.abs(after)), np.abs(self.slope))
            return self.a_value + vb >= ONSET_SLOPE_FACTOR * steep * width

    def certify(self, tolerance: float, proof: _Proof) -> None:
        """Move ``a`` up through every interval to the top that is certified free of
        no-follow: both ends follow, of one kind, and, where both are configuration I's and
        the design ``provable``, the margin and the valve's height stay positive on the
        proven bound (v_a + v_b ≥ L·(b − a) for each); else on the chords' estimate
        (``_estimated``); or the interval is no wider than the tolerance."""
        while True:
            live = self.active & (self.depth > 0)
            b, vb, kb, nb, hb = self.top(1)
            width = b - self.a
            same = self.a_kind == kb
            exact = same & (kb == _CLOSED) & proof.provable & (self.a > proof.held)
            wide = live & ~nb & (width > tolerance)
            free = np.zeros(width.size, np.bool_)
            rows = np.flatnonzero(wide & exact)
            if rows.size:
                lf, lh = proof.bounds(rows, self.a[rows], b[rows])
                w = width[rows]
                with np.errstate(invalid="ignore"):  # +inf + +inf: form closure, no seat
                    free[rows] = (self.a_value[rows] + vb[rows] >= lf * w) & (
                        self.a_height[rows] + hb[rows] >= lh * w
                    )
            with np.errstate(invalid="ignore", divide="ignore"):
                # Equal values (form closure's +inf among them) make a flat chord.
                chord = np.where(vb == self.a_value, 0.0, (vb - self.a_value) / width)
            guess = wide & same & ~exact & self._estimated(width, chord)
            ok = live & ~nb & (free | guess | (width <= tolerance))
            if not ok.any():
                return
            self.proven &= ~guess
            self.slope = np.where(ok, np.where(same, chord, np.nan), self.slope)
            self.a = np.where(ok, b, self.a)
            self.a_value = np.where(ok, vb, self.a_value)
            self.a_kind = np.where(ok, kb, self.a_kind)
            self.a_height = np.where(ok, hb, self.a_height)
            self.depth = self.depth - ok
            self.scale[ok, 0] = 1.0

    def split(self, tolerance: float) -> np.ndarray:
        """Where each live design looks next: the middle of a and the top, or, when the top
        is no-follow and both are the closed form's margins, the Illinois point (the chord's
        root, the end kept twice in a row weighted by ½) kept tolerance/4 inside."""
        b, vb, kb, nb, _ = self.top(1)
        x = 0.5 * (self.a + b)
        secant = nb & (self.a_kind == _CLOSED) & (kb == _CLOSED)
        fa = self.a_value * self.scale[:, 0]
        fb = vb * self.scale[:, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            root = b - fb * (b - self.a) / (fb - fa)
        root = np.clip(root, self.a + 0.25 * tolerance, b - 0.25 * tolerance)
        return np.where(secant & np.isfinite(root), root, x)

    def push(self, todo, x, value, kind, no_follow, height) -> None:
        """Put the points just looked at on the stacks of the designs ``todo``; a point with
        no-follow replaces the whole stack (nothing above it matters any more), so the stack
        holds the scan and at most the halvings down to the tolerance."""
        rows = np.flatnonzero(todo)
        j = np.where(no_follow[rows], 0, self.depth[rows])
        nb = self.top(1)[3][rows]
        self.speed[rows, j] = x[rows]
        self.value[rows, j] = value[rows]
        self.kind[rows, j] = kind[rows]
        self.no_follow[rows, j] = no_follow[rows]
        self.height[rows, j] = height[rows]
        self.depth[rows] = j + 1
        # Illinois: the end replaced twice in a row halves the other end's weight.
        replaced = np.where(no_follow[rows], 1, -1)
        again = replaced == self.side[rows]
        bracket = nb  # only while the top was no-follow is the split a chord's root
        self.scale[rows, 0] = np.where(
            bracket & again & (replaced > 0), 0.5 * self.scale[rows, 0], self.scale[rows, 0]
        )
        self.scale[rows, 1] = np.where(
            bracket & again & (replaced < 0), 0.5 * self.scale[rows, 1],
            np.where(replaced > 0, 1.0, self.scale[rows, 1]),
        )  # fmt: skip
        self.side[rows] = np.where(bracket, replaced, 0)


def _start(grid, value, kind, no_follow, height) -> _Points:
    """The search's state after the scan: ``a`` its lowest speed, the others on the stack."""
    n, m = value.shape
    cap = m + 128  # the scan's speeds, and halvings down to any tolerance (~60 at most)
    stack = np.full((n, cap), np.nan)
    speeds = stack.copy()
    heights = stack.copy()
    heights[:, : m - 1] = height[:, :0:-1]
    kinds = np.zeros((n, cap), np.int8)
    flags = np.zeros((n, cap), np.bool_)
    speeds[:, : m - 1] = grid[:0:-1]
    stack[:, : m - 1] = value[:, :0:-1]
    kinds[:, : m - 1] = kind[:, :0:-1]
    flags[:, : m - 1] = no_follow[:, :0:-1]
    return _Points(
        a=np.full(n, grid[0]), a_value=value[:, 0].copy(), a_kind=kind[:, 0].copy(),
        a_height=height[:, 0].copy(), slope=np.full(n, np.nan), speed=speeds, value=stack,
        kind=kinds, height=heights, no_follow=flags, depth=np.full(n, m - 1),
        active=~no_follow[:, 0], scale=np.ones((n, 2)), side=np.zeros(n, np.int64),
        proven=np.ones(n, np.bool_),
    )  # fmt: skip


def onset_speeds(
    designs: Sequence[Case],
    low: float,
    high: float,
    tolerance: float = DEFAULT_ONSET_TOLERANCE_RPM * RPM,
    scan: int = SCAN_SPEEDS,
    level: float = DEFAULT_ONSET_LEVEL,
) -> Onset:
    """The no-follow onset of each design: the lowest speed in [low, high] at which its steady
    state leaves the cam with the valve off its seat (configuration II) — with a seat, for
    at least ``level`` of each turn.

    **Missing no window.** The steady state is looked at on ``scan`` speeds across the
    range; then, from the lowest speed up, each interval [a, b] between speeds where the
    design follows is *certified* free of no-follow, or halved and its halves looked at in
    turn. The value v of a speed is positive where it follows: the closed form's margin
    (the least cam compression over the turn) [N]; with a seat where the valve seats (or the
    train leaves the cam), the level less the seated steady state's no-follow per turn.
    |v'| ≤ L on [a, b] gives v ≥ (v_a + v_b − L·(b − a))/2 there, so the interval is
    certified when v_a + v_b ≥ L·(b − a), or when b − a is no wider than the tolerance.
    Where both ends are configuration I's and the profile's lift has no step, L is
    *proven* (``slope_bound.slope_bounds``: the Fourier series of the steady state and the
    train's poles, over every angle and every speed of [a, b]; a velocity step's impulse is
    the series' as the closed form's, above ``slope_bound.held_from``), and the valve's
    height above a seat must pass the same test, so configuration I holds across the
    interval. Elsewhere (a seated steady state, whose no-follow has impacts and is not
    Lipschitz in the speed; a profile whose lift steps, with no Fourier tail bound) L is an
    *estimate*: ONSET_SLOPE_FACTOR × the steepest of the chord over [a, b], the chord
    certified before it and the chord after it (of the same kind of value); ``Onset.proven``
    says which a design's search needed. The first speed found with no-follow closes a
    bracket [a, b] with everything below a certified; it is refined by the same rule (a
    point that follows moves a only once [a, point] is certified), split at the Illinois
    point of the margin's chord where both ends are the closed form's and halved otherwise,
    until b − a ≤ tolerance. So with a proven search no window of no-follow wider than the
    tolerance lies below the onset, and a range enclosing another gives the same onset to
    the tolerance. With the estimate a window is missed only if the value falls to zero
    across it more than twice as steeply as on the chords either side; with a seat at level
    0 (first separation) a follow point's value is 0, so only intervals flat on every chord
    certify: the estimate says nothing there (the scan's and the refinement's speeds
    alone).

    **The level.** With a seat, the seat's and the ramp's impacts throw the follower off the
    cam for thousandths to tenths of a degree a turn over a wide band of speeds below the
    train's loss of control, where no-follow jumps to degrees a turn (a polydyne with ramps
    and 0.2 mm lash: under 0.12° a turn up to 5420 rpm, 3.3° at 5430 rpm, where the closed
    form's margin falls through zero). The default level, 0.5° a turn, sits between the two:
    the onset a designer means, the loss of control, not the first bounce; 0 gives the first
    separation. Without a seat the level is not used: the onset is the margin's root.

    Parameters
    ----------
    designs : sequence of Case
        Each design's train, profile, seat and closure (their ``speed`` is ignored).
    low, high : float
        The speed range [rad/s].
    tolerance : float
        Width of the final bracket [rad/s]; the onset is its middle.
    scan : int
        Speeds looked at first, at least 2.
    level : float
        With a seat, the no-follow a turn [rad] the onset reaches (≥ 0; 0: the first).
    """
    if not (0 < low < high and math.isfinite(high)):
        raise CaseError.at(
            "speed",
            f"found the range {low!r} … {high!r} rad/s, expected 0 < low < high",
            found=(low, high),
            expected="0 < low < high",
        )
    if not tolerance > 0:
        raise CaseError.at(
            "tolerance", f"found {tolerance!r} rad/s, expected > 0", found=tolerance,
            expected="> 0",
        )  # fmt: skip
    if not (level >= 0 and math.isfinite(level)):
        raise CaseError.at(
            "level", f"found {level!r} rad, expected ≥ 0", found=level, expected="≥ 0"
        )
    designs = [dataclasses.replace(d, speed=low) for d in designs]
    check_run(designs, RunSettings(), check_stability_limit=False)
    n = len(designs)
    batch = prepare_steady(designs)
    levels = np.where(batch.cases.has_seat, float(level), 0.0)
    capture = RunSettings().capture_velocity  # prepare_steady's, the runs'
    leave = leave_speeds(designs, capture)
    grid = np.linspace(low, high, max(2, int(scan)))
    value = np.full((n, grid.size), np.nan)
    kind = np.zeros((n, grid.size), np.int8)
    no_follow = np.zeros((n, grid.size), np.bool_)
    margin = np.full((n, grid.size), np.nan)
    every = np.ones(n, np.bool_)
    height = np.full((n, grid.size), np.nan)
    for k, s in enumerate(grid):
        value[:, k], kind[:, k], no_follow[:, k], margin[:, k], height[:, k] = _evaluate(
            designs, batch, np.full(n, s), every, levels, leave
        )
    evaluations = np.full(n, grid.size)
    pts = _start(grid, value, kind, no_follow, height)
    proof = _Proof(designs, capture)
    status = np.where(no_follow[:, 0], "below", "none").astype(object)
    # Every step splits an interval wider than the tolerance or certifies one, so a search
    # that walks the range at the tolerance (no bound certifies wider) ends within this.
    for _ in range(4 * math.ceil((high - low) / tolerance) + 64 * grid.size):
        pts.certify(tolerance, proof)
        pts.active &= pts.depth > 0  # nothing left above a: follows across the range
        b, _, _, nb, _ = pts.top(1)
        done = pts.active & nb & (b - pts.a <= tolerance)
        status[done] = "found"
        pts.active &= ~done
        if not pts.active.any():
            break
        x = pts.split(tolerance)
        vx, kx, nx, _, hx = _evaluate(designs, batch, x, pts.active, levels, leave)
        evaluations += pts.active
        pts.push(pts.active, x, vx, kx, nx, hx)
    else:
        raise OnsetUnfinished(
            f"the onset search of designs {np.flatnonzero(pts.active).tolist()} did not end "
            f"within {int(evaluations.max())} steady states: a defect, please report it"
        )
    b, _, kb, _, _ = pts.top(1)
    found = status == "found"
    speed = np.where(found, 0.5 * (pts.a + b), np.nan)
    seated = found & ((pts.a_kind == _TURN) | (kb == _TURN))
    return Onset(speed, status.astype(str), grid, margin, no_follow, seated, float(tolerance),
                 evaluations, levels, pts.proven)  # fmt: skip


#: The key an onset search with a lash adjuster is refused at (``adjuster_refusal``).
ADJUSTER_KEY = "model.hla_leak_down"


def adjuster_refusal(designs: Sequence[Case], noun: str = "design") -> str | None:
    """Why the onset of ``designs`` (each a ``noun``: campipe onset's combinations, campipe
    design's designs) is not searched, or None: a hydraulic lash adjuster's plunger moves
    turn by turn, so a design with one has no one-turn steady state for the search to read
    (it would read the train with its plunger held where ``hla_extension`` puts it, and the
    time-domain check run another, its plunger pumping up)."""
    n = sum(adjuster(c.train) is not None for c in designs)
    if not n:
        return None
    return (
        f"found a hydraulic lash adjuster (model.hla_*) in {n} of {len(designs)} {noun}"
        f"{'s' if len(designs) != 1 else ''}: the onset is searched on the steady state of a "
        "train that repeats every turn, and an adjuster's plunger moves turn by turn; run the "
        "speeds with campipe study (run.revolutions: auto) and read the onset in campipe "
        "query --summary, or search the train the adjuster holds without it (its hla_* keys "
        "and model.lash left out)"
    )


def confirm_settings(revolutions: float = CONFIRM_TURNS) -> RunSettings:
    """The settings of :func:`confirm_onsets`'s runs (for a caller that compiles their kernels
    first)."""
    return RunSettings(revolutions=revolutions, warmup=min(CONFIRM_WARMUP, int(revolutions) - 1))


def confirm_onsets(
    designs: Sequence[Case], onset: np.ndarray, offset: float = CONFIRM_OFFSET,
    revolutions: float = CONFIRM_TURNS, level: np.ndarray | float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The time-domain engine just below and just above each onset: no-follow per turn, the
    mean over the measured turns (``revolutions`` from the periodic start, the first
    CONFIRM_WARMUP left out: the study archive's ``separation_deg_per_rev``) at
    onset·(1 − offset) and onset·(1 + offset), and where the train leaves the cam just above
    it. Where the no-follow above does not reach ``level`` (at level 0: some), the check
    above runs nearer, at each of CONFIRM_NEARER in turn, and keeps the first that does (a
    window narrower than ``offset``); where none does, the first. :func:`confirmed` says
    whether they agree with the onset.

    Returns
    -------
    below, above : (n,) [rad]; NaN where there is no onset
    where : (n,) [rad] the cam angle (0 … 2π) of the first separation from the cam in the
        measured turns of the check above; NaN where there is none (or no onset)
    above_speed : (n,) [rad/s] the speed the check above ran at; NaN where there is no onset
    """
    n = len(designs)
    below, above, where, above_speed = (np.full(n, np.nan) for _ in range(4))
    level = np.broadcast_to(np.asarray(level, float), (n,))
    settings = confirm_settings(revolutions)
    idx = np.flatnonzero(np.isfinite(onset))
    for k, f in enumerate((offset, *CONFIRM_NEARER) if idx.size else ()):
        sides = (-offset, f) if k == 0 else (f,)
        cases = [dataclasses.replace(designs[int(i)], speed=onset[i] * (1 + s))
                 for s in sides for i in idx]  # fmt: skip
        res = run_batch(cases, settings, full_state=False, on_failure="record")
        if k == 0:
            below[idx] = res.separation[: idx.size]
        first = len(cases) - idx.size  # the runs above the onset, last
        run = res.separation[first:]
        take = np.isnan(above[idx]) | _reaches(run, level[idx])
        for j in np.flatnonzero(take):
            i, case = idx[j], cases[first + j]
            above[i], above_speed[i] = run[j], case.speed
            where[i] = first_separation(res.events[first + j], case.speed, settings.warmup or 0)
        idx = idx[~_reaches(above[idx], level[idx])]
        if not idx.size:
            break
    return below, above, where, above_speed


def _reaches(above: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Does the no-follow above the onset reach the level (at level 0: is there some)?"""
    with np.errstate(invalid="ignore"):
        return np.where(level > 0.0, above >= level, above > 0.0)


def first_separation(events: np.ndarray, speed: float, warmup: int = 0) -> float:
    """The cam angle [rad] (0 … 2π) of the first of a case's ``events`` (rows as
    ``BatchResult.events``') from turn ``warmup`` on, at cam speed ``speed`` [rad/s], that
    starts no-follow: the train enters configuration II (follower off the cam, valve off its
    seat), the follower leaving the cam or the valve bouncing off its seat while the follower
    is off the cam; NaN if none does. Not the follower leaving the cam onto the lash with the
    valve seated (III to IV), which a train with lash does every turn."""
    if not len(events):
        return np.nan
    angle = speed * events[:, EV_TIME]
    leaves = (events[:, EV_TO] == FREE) & (angle >= TWO_PI * warmup * (1 - 1e-12))
    if not leaves.any():
        return np.nan
    return float(np.mod(angle[leaves][0], TWO_PI))


def confirmed(below: np.ndarray, above: np.ndarray, level: np.ndarray | float = 0.0) -> np.ndarray:
    """(n,) bool: the time-domain check agrees with the onset — below it the engine's
    no-follow a turn stays under the level (at level 0: none), above it reaches the level
    (at level 0: some). False where unchecked (NaN)."""
    level = np.broadcast_to(np.asarray(level, float), np.shape(below))
    with np.errstate(invalid="ignore"):
        under = np.where(level > 0.0, below < level, below == 0.0)
    over = _reaches(above, level)
    return np.isfinite(below) & np.isfinite(above) & under & over
