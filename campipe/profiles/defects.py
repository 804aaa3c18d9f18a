"""Manufacturing defects applied to a profile: a flat and a smooth bump (or dent).

Each defect returns a new profile in the common piecewise form, with breaks at the defect's
edges so that an integrator stepping break to break meets any jump in velocity exactly there.
Defects compose: the caller applies them in order, and the order matters.
"""

from __future__ import annotations

import math

import numpy as np

from campipe.profiles.pieces import (
    INCHES,
    N_COEFFS,
    TWO_PI,
    LengthUnit,
    Profile,
    evaluate,
    format_angle,
    format_length,
    shift_polynomial,
    split_at,
    wrap,
)


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def _pieces_between(profile: Profile, start: float, end: float) -> np.ndarray:
    """Mask of the pieces within [start, end), both breaks of ``profile``; wraps if end ≤ start."""
    lo = profile.breaks[:-1]
    if start < end:
        return (lo >= start) & (lo < end)
    return (lo >= start) | (lo < end)


def flat_step(profile: Profile, start: float, end: float) -> float:
    """The step in the lift :func:`flat` makes at ``end`` [m]: the lift there less the lift
    at ``start``, which the flat holds (0 for a flat whose ends are at equal lift: across a
    symmetric nose, or on a dwell)."""
    return float(evaluate(profile, end)[0]) - float(evaluate(profile, start)[0])


def level_again(profile: Profile, start: float, tolerance: float = 1e-12) -> float | None:
    """Where a flat from ``start`` [rad] can end: the first angle after it (start < θ <
    start + 2π) where the lift, having risen more than ``tolerance`` [m] above its value at
    ``start``, comes back down to it. None where the lift falls below that value first (a
    flat from there would add metal) or never comes back."""
    value = float(evaluate(profile, start)[0])
    theta = start + np.linspace(0.0, TWO_PI, 36001)[1:-1]
    off = evaluate(profile, theta)[0] - value
    left = np.flatnonzero(np.abs(off) > tolerance)
    if not left.size or off[left[0]] < 0.0:
        return None
    back = np.flatnonzero(off[left[0] :] <= 0.0)
    if not back.size:
        return None
    j = left[0] + back[0]
    if off[j] == 0.0:
        return float(theta[j])
    from scipy.optimize import brentq

    def f(t: float) -> float:
        return float(evaluate(profile, t)[0]) - value

    return float(brentq(f, theta[j - 1], theta[j], xtol=1e-13, rtol=4 * np.finfo(float).eps))


def flat_dip(profile: Profile, start: float, end: float) -> float:
    """How far the lift falls below its value at ``start`` between ``start`` and ``end``
    [m, ≥ 0], on samples 0.01° apart: where a flat holding that value would add metal."""
    span = float(np.mod(end - start, TWO_PI)) or TWO_PI
    theta = start + np.linspace(0.0, span, max(int(span / np.radians(0.01)), 2) + 1)
    return max(0.0, float(evaluate(profile, start)[0] - evaluate(profile, theta)[0].min()))


def flat(profile: Profile, start: float, end: float) -> Profile:
    """A flat ground on the cam: lift held at its value at ``start`` until ``end``.

    Velocity and acceleration are zero on the flat, so the velocity jumps at both edges. The
    thesis's machining error is a flat from 268° to 272° on the harmonic cam, 0.5·(1 − cos 2°)
    = 0.0003 in deep at the nose. Where the lift at ``end`` is not the lift at ``start``
    (:func:`flat_step`) the lift steps there, and where it falls below it in between
    (:func:`flat_dip`) the flat adds metal, which no grinding can: a study refuses either and
    names where the lift returns to its start's (:func:`level_again`).

    Parameters
    ----------
    profile : Profile
        The profile to modify.
    start, end : float
        Edges of the flat [rad], wrapped to one turn; ``end`` before ``start`` makes the flat
        run through θ = 0.

    Raises
    ------
    ValueError
        For non-finite edges or edges that coincide (modulo 2π).
    """
    start = _finite("start", start)
    end = _finite("end", end)
    value = float(evaluate(profile, start)[0])
    out, a = split_at(profile, start)
    out, b = split_at(out, end)
    if a == b:
        raise ValueError(
            f"flat: start and end coincide modulo one turn ({format_angle(start)} and "
            f"{format_angle(end)} deg)"
        )
    inside = _pieces_between(out, a, b)
    poly = out.poly.copy()
    trig = out.trig.copy()
    poly[inside] = 0.0
    poly[inside, 0] = value
    trig[inside] = 0.0
    label = f"{profile.label} + flat {format_angle(a)}–{format_angle(b)} deg"
    return Profile(out.breaks, poly, trig, label)


def bump_coefficients(height: float, width: float) -> np.ndarray:
    """Coefficients of height·(1 − u²)³, u = 2y/width, in ascending powers of y [m/rad**k]."""
    a = 4.0 / width**2
    c = np.zeros(N_COEFFS)
    c[0] = 1.0
    c[2] = -3.0 * a
    c[4] = 3.0 * a**2
    c[6] = -(a**3)
    return height * c


def bump(
    profile: Profile, center: float, height: float, width: float, unit: LengthUnit = INCHES
) -> Profile:
    """A smooth local bump (or dent) added to the profile.

    Adds height·(1 − u²)³ with u = 2(θ − center)/width for |u| ≤ 1, zero outside: lift,
    velocity and acceleration stay continuous at its edges.

    Parameters
    ----------
    profile : Profile
        The profile to modify.
    center : float
        Angle of the bump's peak [rad], wrapped to one turn.
    height : float
        Height added at ``center`` [m]; negative for a dent.
    width : float
        Full width of the bump [rad], 0 < width < 2π; it may run through θ = 0.
    unit : LengthUnit, optional
        The unit the label writes the height in; inches by default.

    Raises
    ------
    ValueError
        For non-finite arguments or a width outside (0, 2π).
    """
    center = float(wrap(_finite("center", center)))
    height = _finite("height", height)
    width = _finite("width", width)
    if not 0.0 < width < TWO_PI:
        raise ValueError(f"width must be > 0 and < 2π rad, got {width!r} rad")
    lo = center - 0.5 * width
    hi = center + 0.5 * width
    out, a = split_at(profile, lo)
    out, b = split_at(out, hi)
    if a == b:
        raise ValueError(f"width is too small to resolve: {width!r} rad")
    inside = _pieces_between(out, a, b)
    start = out.breaks[:-1][inside]
    # on the turn where the piece lies inside (lo, hi), unwrapped, the bump's variable is
    # y = θ − center = x + (start − center) with x local to the piece
    mid = 0.5 * (start + out.breaks[1:][inside])
    turn = np.where(mid < lo, TWO_PI, np.where(mid > hi, -TWO_PI, 0.0))
    poly = out.poly.copy()
    poly[inside] += shift_polynomial(bump_coefficients(height, width), start + turn - center)
    label = (
        f"{profile.label} + bump {format_length(height, unit)} at {format_angle(center)} deg "
        f"over {format_angle(width)} deg"
    )
    return Profile(out.breaks, poly, out.trig, label)
