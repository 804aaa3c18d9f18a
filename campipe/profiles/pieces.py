"""The one piecewise form every cam profile takes, its evaluation and its re-expansion.

On piece i, ``breaks[i] ≤ θ mod 2π < breaks[i+1]``, the lift is

    lift(θ) = Σₖ poly[i, k]·(θ − breaks[i])ᵏ + trig[i, 0]·sin θ + trig[i, 1]·cos θ,  k = 0…7.

A polynomial of degree ≤ 7 covers the polydyne rises (thesis Eqs. 29–34), the cubic spline of
a measured table and the smooth defects; the two trig terms cover the harmonic cam exactly.
The trig terms use the absolute angle, so re-expanding a piece about a new break only touches
its polynomial.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

# TWO_PI: one turn of the cam [rad], every profile's period; INCH: labels give lengths in the
# thesis's inches [m/in] unless told another unit.
from campipe.constants import INCH, TWO_PI

#: Polynomial coefficients per piece (degree ≤ 7).
N_COEFFS = 8

#: Two angles closer than this [rad] are the same break: no piece is ever shorter.
BREAK_TOL = 1e-12

#: Angles [rad], any shape; any real value (the profile wraps modulo 2π).
Angles = npt.ArrayLike


# eq=False: the fields are arrays, so the generated __eq__ would raise on comparison.
@dataclass(frozen=True, eq=False)
class Profile:
    """A cam lift profile over one turn in the piecewise form above, SI units.

    The arrays are copied to float64 and made read-only on construction, so a profile can be
    shared between runs without any one of them changing it.
    """

    breaks: np.ndarray  # (n+1,) piece boundaries [rad], 0 = breaks[0] < … < breaks[n] = 2π
    poly: np.ndarray  # (n, 8) coefficients of (θ − breaks[i])**k, k = 0…7 [m/rad**k]
    trig: np.ndarray  # (n, 2) coefficients of sin θ and cos θ, absolute θ [m]
    label: str  # readable label, e.g. "harmonic 1 in + flat 268–272 deg"

    def __post_init__(self) -> None:
        breaks = _frozen(self.breaks)
        poly = _frozen(self.poly)
        trig = _frozen(self.trig)
        if breaks.ndim != 1 or breaks.size < 2:
            raise ValueError(f"breaks must be a 1-D array of ≥ 2 angles, got {breaks.shape}")
        n = breaks.size - 1
        if poly.shape != (n, N_COEFFS):
            raise ValueError(f"poly must have shape ({n}, {N_COEFFS}), got {poly.shape}")
        if trig.shape != (n, 2):
            raise ValueError(f"trig must have shape ({n}, 2), got {trig.shape}")
        if breaks[0] != 0.0 or breaks[-1] != TWO_PI:
            raise ValueError(f"breaks must run from 0 to 2π, got {breaks[0]!r} … {breaks[-1]!r}")
        if not np.all(np.diff(breaks) > 0.0):
            raise ValueError("breaks must be strictly increasing")
        if not (np.isfinite(poly).all() and np.isfinite(trig).all()):
            raise ValueError("profile coefficients must be finite")
        object.__setattr__(self, "breaks", breaks)
        object.__setattr__(self, "poly", poly)
        object.__setattr__(self, "trig", trig)

    @property
    def n_pieces(self) -> int:
        """Number of pieces n."""
        return self.poly.shape[0]

    @property
    def content_key(self) -> tuple[bytes, bytes, bytes]:
        """The pieces as a hashable key (their arrays' bytes; not the label): equal for
        profiles that lift alike, for caches keyed by a profile."""
        return self.breaks.tobytes(), self.poly.tobytes(), self.trig.tobytes()


def _frozen(a) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


def wrap(theta: Angles, side: str = "right") -> np.ndarray:
    """Angles reduced to one turn: [0, 2π) for ``side="right"``, (0, 2π] for ``"left"``."""
    t = np.mod(np.asarray(theta, dtype=float), TWO_PI)
    if side == "right":
        # mod of a tiny negative angle rounds up to exactly 2π, which is 0 on the next turn
        return np.where(t >= TWO_PI, 0.0, t)
    if side == "left":
        return np.where(t <= 0.0, TWO_PI, t)
    raise ValueError(f"side must be 'right' or 'left', got {side!r}")


def piece_index(profile: Profile, theta: Angles, side: str = "right") -> np.ndarray:
    """Index of the piece holding each angle; at a break, the piece on ``side`` of it."""
    t = wrap(theta, side)
    i = np.searchsorted(profile.breaks, t, side="right" if side == "right" else "left") - 1
    return np.clip(i, 0, profile.n_pieces - 1)


def evaluate_pieces(
    profile: Profile, index: npt.ArrayLike, theta: Angles
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lift and its first two derivatives using the given piece at each angle.

    The piece's expression is evaluated as is, even outside the piece (used for one-sided
    limits at breaks and for refining extrema).

    Parameters
    ----------
    profile : Profile
        The profile.
    index : array_like of int
        Piece index for each angle, broadcast against ``theta``.
    theta : array_like
        Angles [rad], not wrapped: the caller chooses the turn.

    Returns
    -------
    lift : np.ndarray
        Lift [m].
    velocity : np.ndarray
        dlift/dθ [m/rad].
    acceleration : np.ndarray
        d²lift/dθ² [m/rad²].
    """
    theta = np.asarray(theta, dtype=float)
    index = np.asarray(index)
    x = theta - profile.breaks[index]
    c = profile.poly[index]
    # Horner's scheme for the value and both derivatives at once
    p = c[..., N_COEFFS - 1]
    dp = np.zeros_like(p)
    ddp = np.zeros_like(p)
    for k in range(N_COEFFS - 2, -1, -1):
        ddp = ddp * x + 2.0 * dp
        dp = dp * x + p
        p = p * x + c[..., k]
    a = profile.trig[index, 0]
    b = profile.trig[index, 1]
    s = np.sin(theta)
    co = np.cos(theta)
    return p + a * s + b * co, dp + a * co - b * s, ddp - a * s - b * co


def evaluate(
    profile: Profile, theta: Angles, side: str = "right"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cam lift and its derivatives with respect to cam angle.

    Parameters
    ----------
    profile : Profile
        The profile.
    theta : array_like
        Cam angles [rad], any real values: they wrap modulo 2π.
    side : {"right", "left"}
        At a break, use the piece to the right (the default) or the left-hand limit.

    Returns
    -------
    lift : np.ndarray
        Lift [m], shaped like ``theta``.
    velocity : np.ndarray
        dlift/dθ [m/rad].
    acceleration : np.ndarray
        d²lift/dθ² [m/rad²].
    """
    t = wrap(theta, side)
    return evaluate_pieces(profile, piece_index(profile, t, side), t)


def shift_polynomial(coeffs: npt.ArrayLike, dx: npt.ArrayLike) -> np.ndarray:
    """Taylor shift: the coefficients of p(x + dx) in x.

    Parameters
    ----------
    coeffs : array_like
        (..., m) coefficients of p in ascending powers of x.
    dx : array_like
        Shift, broadcast against ``coeffs[..., 0]`` [units of x].

    Returns
    -------
    np.ndarray
        (..., m) coefficients of p(x + dx) in ascending powers of x.
    """
    c = np.asarray(coeffs, dtype=float)
    dx = np.asarray(dx, dtype=float)
    shape = np.broadcast_shapes(c.shape[:-1], dx.shape) + c.shape[-1:]
    c = np.broadcast_to(c, shape).copy()
    m = c.shape[-1]
    # repeated synthetic division by (x − (−dx)): only additions of like-scaled terms
    for i in range(m - 1):
        for j in range(m - 2, i - 1, -1):
            c[..., j] += dx * c[..., j + 1]
    return c


def split_at(profile: Profile, theta: float) -> tuple[Profile, float]:
    """Insert a break at ``theta`` and return the profile and the break's angle in [0, 2π).

    An angle within ``BREAK_TOL`` of an existing break snaps to it (no piece is created), so
    the returned angle is always exactly one of ``breaks``.
    """
    t = float(wrap(theta))
    b = profile.breaks
    i = int(piece_index(profile, t))
    if t - b[i] <= BREAK_TOL:
        return profile, float(b[i])
    if b[i + 1] - t <= BREAK_TOL:
        return profile, float(b[i + 1]) if i + 1 < profile.n_pieces else 0.0
    breaks = np.insert(b, i + 1, t)
    poly = np.insert(profile.poly, i + 1, shift_polynomial(profile.poly[i], t - b[i]), axis=0)
    trig = np.insert(profile.trig, i + 1, profile.trig[i], axis=0)
    return Profile(breaks, poly, trig, profile.label), t


def split(profile: Profile, theta: float) -> Profile:
    """The same profile with a break at ``theta`` [rad] (wrapped; no-op if one is there).

    The piece holding ``theta`` is re-expanded about the new break by a Taylor shift of its
    polynomial; its trig terms use the absolute angle and carry over unchanged.
    """
    return split_at(profile, theta)[0]


def lift_range(profile: Profile, samples: int = 32) -> tuple[float, float]:
    """Smallest and largest lift over the turn [m].

    Each piece is sampled at ``samples`` intervals (ends included, each piece using its own
    expression so one-sided limits count); wherever the velocity changes sign between samples,
    the extremum is refined by bisection to round-off.
    """
    n = profile.n_pieces
    s = np.linspace(0.0, 1.0, samples + 1)
    lo = profile.breaks[:-1, None]
    theta = lo + s * (profile.breaks[1:, None] - lo)
    index = np.broadcast_to(np.arange(n)[:, None], theta.shape)
    lift, velocity, _ = evaluate_pieces(profile, index, theta)
    candidates = [lift.ravel()]
    change = velocity[:, :-1] * velocity[:, 1:] < 0.0
    if change.any():
        idx = index[:, :-1][change]
        a = theta[:, :-1][change]
        b = theta[:, 1:][change]
        va = velocity[:, :-1][change]
        for _ in range(60):
            m = 0.5 * (a + b)
            vm = evaluate_pieces(profile, idx, m)[1]
            left = np.sign(vm) == np.sign(va)
            a = np.where(left, m, a)
            va = np.where(left, vm, va)
            b = np.where(left, b, m)
        candidates.append(evaluate_pieces(profile, idx, 0.5 * (a + b))[0])
    values = np.concatenate(candidates)
    return float(values.min()), float(values.max())


def max_lift(profile: Profile) -> float:
    """Largest lift over the turn [m] (full lift; a seat above it can never open)."""
    return lift_range(profile)[1]


def min_lift(profile: Profile) -> float:
    """Smallest lift over the turn [m] (negative lift means the cam dips below its base)."""
    return lift_range(profile)[0]


class LengthUnit(NamedTuple):
    """The unit a label writes a length in: its symbol and its size [m]."""

    symbol: str
    metres: float


#: The thesis's inches, every label's unit unless a caller (a spec written in mm) says another.
INCHES = LengthUnit("in", INCH)


def format_length(value: float, unit: LengthUnit = INCHES) -> str:
    """A length [m] in ``unit`` (the thesis's inches by default), for labels."""
    return f"{value / unit.metres:.4g} {unit.symbol}"


def format_angle(value: float) -> str:
    """An angle [rad] in degrees, for labels."""
    return f"{math.degrees(value):.6g}"


class Lift:
    """A profile's lift at one speed as a scalar function of time, piece by piece (Horner's
    scheme): what a Python integrator calls at every right-hand side, where the vectorised
    :func:`evaluate_pieces` costs more than the arithmetic."""

    def __init__(self, profile: Profile, speed: float) -> None:
        self.breaks = profile.breaks
        self.poly = profile.poly
        self.trig = profile.trig
        self.w = speed
        # Python floats: a NumPy scalar read costs several times a list's in this loop
        self._starts = profile.breaks.tolist()
        self._rows = profile.poly.tolist()
        self._trigs = profile.trig.tolist()
        self._last: tuple = (None, None)  # ((piece, rev, t), its value): asked again at once

    def piece_at(self, t: float) -> tuple[int, int]:
        """(piece, turn) holding time t, by its position on the turn."""
        theta = self.w * t
        rev = math.floor(theta / TWO_PI)
        phi = theta - rev * TWO_PI
        piece = int(np.searchsorted(self.breaks, phi, side="right") - 1)
        return min(max(piece, 0), self.poly.shape[0] - 1), rev

    def break_after(self, piece: int, rev: int) -> float:
        """The time the piece ends [s]."""
        return (rev * TWO_PI + self.breaks[piece + 1]) / self.w

    def at(self, piece: int, rev: int, t: float) -> tuple[float, float, float]:
        """Lift [m], its rate [m/s] and acceleration [m/s²] on ``piece`` of turn ``rev``."""
        key = (piece, rev, t)
        if self._last[0] == key:  # an integrator's right-hand side and its events ask twice
            return self._last[1]
        theta = self.w * t
        x = theta - rev * TWO_PI - self._starts[piece]
        c = self._rows[piece]
        p0 = p1 = p2 = 0.0
        for k in range(len(c) - 1, -1, -1):
            p2 = p2 * x + 2.0 * p1
            p1 = p1 * x + p0
            p0 = p0 * x + c[k]
        s, co = math.sin(theta), math.cos(theta)
        ta, tb = self._trigs[piece]
        w = self.w
        out = (p0 + ta * s + tb * co, w * (p1 + ta * co - tb * s), w * w * (p2 - ta * s - tb * co))
        self._last = (key, out)
        return out
