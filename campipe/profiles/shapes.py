"""The kinds of cam profile: the thesis's harmonic cam, polydyne rises and measured tables.

Each constructor returns a :class:`~campipe.profiles.pieces.Profile` in the common piecewise
form; angles in radians, lifts in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.polynomial import Polynomial

from campipe.profiles.pieces import (
    BREAK_TOL,
    INCHES,
    N_COEFFS,
    TWO_PI,
    LengthUnit,
    Profile,
    format_angle,
    format_length,
    shift_polynomial,
)

#: Normalised polydyne rises P(u), P(0) = 0, P(1) = 1, ascending coefficients (thesis
#: Eqs. 29–34): "345" matches lift, velocity and acceleration at both ends, "4567" also jerk.
POLYDYNE_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "345": (0.0, 0.0, 0.0, 10.0, -15.0, 6.0, 0.0, 0.0),
    "4567": (0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0),
}

#: Fewest table points a periodic cubic spline is built from.
MIN_TABLE_POINTS = 4

#: Ramp shapes: "constant-velocity" climbs at its velocity from the base circle (a velocity
#: step where it starts, taken up by the lash); "smooth" reaches the same end velocity with
#: velocity 3u² − 2u³ of it (u the ramp's fraction), so lift, velocity and acceleration are
#: continuous, at twice the end velocity for the same height and duration.
RAMP_SHAPES = ("constant-velocity", "smooth")
#: Derivatives each polydyne matches at its ends (lift, velocity, acceleration, and for
#: 4567 jerk): the polynomial's conditions when a ramp sets its end velocity.
_POLYDYNE_ORDER = {"345": 3, "4567": 4}


@dataclass(frozen=True)
class Ramp:
    """Opening and closing ramps of a polydyne cam: the cam climbs ``height`` [m] over
    ``duration`` [rad] before the rise, and descends it after the fall, so the valve's lash
    is taken up (and the valve seated) at the ramp's velocity, not on the steep flank."""

    height: float
    duration: float
    shape: str = "constant-velocity"

    def velocity(self) -> float:
        """Lift rate at the ramp's end, where the rise takes over [m/rad]."""
        mean = self.height / self.duration
        return mean if self.shape == "constant-velocity" else 2.0 * mean

    def polynomial(self) -> np.ndarray:
        """Opening ramp lift as coefficients of (θ − its start)ᵏ [m/rad**k]."""
        d, v = self.duration, self.velocity()
        c = np.zeros(N_COEFFS)
        if self.shape == "constant-velocity":
            c[1] = v
        else:  # ∫ v(3u² − 2u³) dθ, u = θ/d
            c[3] = v / d**2
            c[4] = -0.5 * v / d**3
        return c


def _rise_polynomial(kind: str, slope: float) -> np.ndarray:
    """P(u) with P(0) = 0, P(1) = 1, P'(0) = ``slope``, P'(1) = 0 and the higher derivatives
    the kind matches (to jerk for 4567) zero at both ends; ``slope`` 0 gives the thesis's."""
    order = _POLYDYNE_ORDER[kind]
    n = 2 * order
    rows, rhs = [], []
    for end, values in (
        (0.0, [0.0, slope] + [0.0] * (order - 2)),
        (1.0, [1.0] + [0.0] * (order - 1)),
    ):
        for d, target in enumerate(values):
            rows.append([_derivative_at(k, d, end) for k in range(n)])
            rhs.append(target)
    c = np.zeros(N_COEFFS)
    c[:n] = np.linalg.solve(np.array(rows), np.array(rhs))
    return c


def _derivative_at(k: int, d: int, u: float) -> float:
    """The d-th derivative of uᵏ at u."""
    if d > k:
        return 0.0
    return math.perm(k, d) * u ** (k - d)


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def harmonic(lift: float, unit: LengthUnit = INCHES) -> Profile:
    """The thesis's harmonic cam: lift = h/2·(1 − sin θ).

    The thesis drives the pushrod foot with q1 = 0.5 sin ωt [in], q1 pointing down: mid-lift
    at θ = 0, base circle (lift 0) at 90°, nose (lift h) at 270°. The thesis's machining-error
    run agrees: its flat from 268° to 272°, across the nose, is 0.5·(1 − cos 2°) = 0.0003 in
    deep, the error it states.

    Parameters
    ----------
    lift : float
        Full lift h, peak to peak [m] (thesis: 1 in).
    unit : LengthUnit, optional
        The unit the label writes the lift in (``harmonic 1 in``); inches by default.
    """
    h = _finite("lift", lift)
    if h <= 0.0:
        raise ValueError(f"lift must be > 0, got {h!r} m")
    poly = np.zeros((1, N_COEFFS))
    poly[0, 0] = 0.5 * h
    label = f"harmonic {format_length(h, unit)}"
    return Profile(np.array([0.0, TWO_PI]), poly, np.array([[-0.5 * h, 0.0]]), label)


def polydyne(
    kind: str,
    lift: float,
    rise: float,
    dwell: float,
    fall: float,
    ramp: Ramp | None = None,
    unit: LengthUnit = INCHES,
) -> Profile:
    """A polydyne cam: rise, dwell at full lift, fall, dwell on the base circle.

    The rise from θ = 0 is h·P(θ/β), the fall h·P(1 − u) with u local to the fall, and the
    base-circle dwell takes the rest of the turn (thesis Eqs. 29–34, Figures 35–36). With a
    ``ramp`` the turn starts with the opening ramp (up to the ramp's height), the rise takes
    the lift from there to h starting at the ramp's velocity (P'(0) matched, the higher
    derivatives as without), and the fall and the closing ramp mirror them.

    Parameters
    ----------
    kind : {"345", "4567"}
        The normalised polynomial, see ``POLYDYNE_POLYNOMIALS``.
    lift : float
        Full lift h [m], the ramp's height included.
    rise : float
        Angle of the rise β [rad], the ramp's excluded.
    dwell : float
        Angle of the dwell at full lift [rad]; 0 for none.
    fall : float
        Angle of the fall [rad], the ramp's excluded.
    ramp : Ramp, optional
        Opening and closing ramps.
    unit : LengthUnit, optional
        The unit the label writes the lift and the ramps' height in; inches by default. The
        label reads ``polydyne-4567 1 in 90/90/90/90 deg``: the kind, the lift, then the rise,
        the dwell, the fall and the base circle's dwell.

    Raises
    ------
    ValueError
        For an unknown kind or ramp shape, lift ≤ 0, rise or fall ≤ 0, dwell < 0, a ramp not
        below the lift or of no duration, or ramps, rise, dwell and fall more than one turn.
    """
    kind = str(kind)
    if kind not in POLYDYNE_POLYNOMIALS:
        raise ValueError(f"kind must be one of {sorted(POLYDYNE_POLYNOMIALS)}, got {kind!r}")
    h = _finite("lift", lift)
    rise = _finite("rise", rise)
    dwell = _finite("dwell", dwell)
    fall = _finite("fall", fall)
    if h <= 0.0:
        raise ValueError(f"lift must be > 0, got {h!r} m")
    if rise <= 0.0:
        raise ValueError(f"rise must be > 0, got {rise!r} rad")
    if fall <= 0.0:
        raise ValueError(f"fall must be > 0, got {fall!r} rad")
    if dwell < 0.0:
        raise ValueError(f"dwell must be ≥ 0, got {dwell!r} rad")
    ramp_angle = 0.0
    if ramp is not None:
        if ramp.shape not in RAMP_SHAPES:
            raise ValueError(f"ramp shape must be one of {list(RAMP_SHAPES)}, got {ramp.shape!r}")
        if not 0.0 < _finite("ramp height", ramp.height) < h:
            raise ValueError(f"ramp height must be > 0 and below the lift, got {ramp.height!r} m")
        if not _finite("ramp duration", ramp.duration) > 0.0:
            raise ValueError(f"ramp duration must be > 0, got {ramp.duration!r} rad")
        ramp_angle = ramp.duration
    total = 2 * ramp_angle + rise + dwell + fall
    if total > TWO_PI + BREAK_TOL:
        raise ValueError(
            "ramps + rise + dwell + fall must be at most one turn (360 deg), got "
            f"{format_angle(total)} deg"
        )

    k = np.arange(N_COEFFS)
    rows, breaks = [], [0.0]
    if ramp is None:
        base_lift, main = 0.0, h
        p = np.array(POLYDYNE_POLYNOMIALS[kind])
        p_fall = p
    else:
        base_lift, main = ramp.height, h - ramp.height
        v = ramp.velocity()
        p = _rise_polynomial(kind, v * rise / main)
        p_fall = _rise_polynomial(kind, v * fall / main)
        rows.append(ramp.polynomial())
        breaks.append(ramp_angle)
    rise_row = main * p / rise**k
    rise_row[0] += base_lift
    rows.append(rise_row)
    breaks.append(breaks[-1] + rise)
    # a dwell shorter than any break spacing would be a zero-length piece: leave it out
    if dwell > BREAK_TOL:
        rows.append(np.eye(1, N_COEFFS)[0] * h)
        breaks.append(breaks[-1] + dwell)
    q = np.asarray(Polynomial(p_fall)(Polynomial([1.0, -1.0])).coef, dtype=float)
    fall_row = np.zeros(N_COEFFS)
    fall_row[: q.size] = main * q / fall ** k[: q.size]
    fall_row[0] += base_lift
    rows.append(fall_row)
    breaks.append(breaks[-1] + fall)
    if ramp is not None:
        # the closing ramp: the opening one run backwards, from its height down to 0
        back = Polynomial(ramp.polynomial())(Polynomial([ramp_angle, -1.0])).coef
        closing = np.zeros(N_COEFFS)
        closing[: back.size] = back
        rows.append(closing)
        breaks.append(breaks[-1] + ramp_angle)
    base = TWO_PI - total
    if base > BREAK_TOL:
        rows.append(np.zeros(N_COEFFS))  # the base-circle dwell
        breaks.append(TWO_PI)
    else:
        breaks[-1] = TWO_PI
    poly = np.array(rows)
    label = (
        f"polydyne-{kind} {format_length(h, unit)} {format_angle(rise)}/{format_angle(dwell)}/"
        f"{format_angle(fall)}/{format_angle(max(base, 0.0))} deg"
    )
    if ramp is not None:
        label += (
            f", {ramp.shape} ramps {format_length(ramp.height, unit)} over "
            f"{format_angle(ramp.duration)} deg"
        )
    return Profile(np.array(breaks), poly, np.zeros((poly.shape[0], 2)), label)


def table(angles: npt.ArrayLike, lifts: npt.ArrayLike) -> Profile:
    """A measured lift table over one turn, smoothed by a periodic cubic spline.

    The spline makes lift, velocity and acceleration continuous everywhere, the wrap from
    2π to 0 included; it passes through every point of the table.

    Parameters
    ----------
    angles : array_like
        (m,) cam angles [rad], strictly increasing within [0, 2π), m ≥ 4.
    lifts : array_like
        (m,) lifts at those angles [m].

    Raises
    ------
    ValueError
        For fewer than 4 points, mismatched lengths, non-finite values, angles outside
        [0, 2π) or not strictly increasing.
    """
    a = np.asarray(angles, dtype=float)
    y = np.asarray(lifts, dtype=float)
    if a.ndim != 1 or y.ndim != 1 or a.shape != y.shape:
        raise ValueError(
            f"angles and lifts must be 1-D arrays of the same length, got {a.shape} and {y.shape}"
        )
    if a.size < MIN_TABLE_POINTS:
        raise ValueError(f"a lift table needs at least {MIN_TABLE_POINTS} points, got {a.size}")
    if not (np.isfinite(a).all() and np.isfinite(y).all()):
        raise ValueError("lift table angles and lifts must be finite (found NaN or inf)")
    if a[0] < 0.0 or a[-1] >= TWO_PI:
        raise ValueError(f"lift table angles must lie within [0, 2π) rad, got {a[0]!r} … {a[-1]!r}")
    if not np.all(np.diff(a) > 0.0):
        raise ValueError("lift table angles must be strictly increasing")

    from scipy.interpolate import CubicSpline  # 0.15 s to import: only for a lift table

    spline = CubicSpline(np.append(a, a[0] + TWO_PI), np.append(y, y[0]), bc_type="periodic")
    poly = np.zeros((a.size, N_COEFFS))
    poly[:, :4] = spline.c[::-1].T  # PPoly holds descending powers of the local variable
    breaks = np.append(a, TWO_PI)
    if a[0] <= BREAK_TOL:
        # first point at (or within round-off of) 0: re-expand its piece about 0 exactly
        poly[0] = shift_polynomial(poly[0], -a[0])
        breaks[0] = 0.0
    else:
        # the last spline piece runs from a[-1] through 2π to a[0] + 2π: its part past 2π is
        # the first piece of the turn, re-expanded about 0
        head = shift_polynomial(poly[-1], TWO_PI - a[-1])
        poly = np.vstack([head, poly])
        breaks = np.concatenate([[0.0], breaks])
    label = f"table {a.size} points"
    return Profile(breaks, poly, np.zeros((poly.shape[0], 2)), label)
