"""The cam's own shape from its lift: its radius of curvature over the turn, and whether a
cam can make the lift at all (undercut).

A lift h(θ) is the follower's (:mod:`campipe.profiles`): for a flat-faced follower the
translation of its face, for a roller the radial travel of its centre (a lever layout's cam
is given so too, :mod:`campipe.model.levers`), from a base circle of radius r_b.

- **Flat-faced follower** (its face square to its travel): the face touches the cam where
  the cam's radius of curvature is ρ = r_b + h + h″ (h″ = d²h/dθ² per radian²), and the
  contact lies h′ from the follower's axis (so the face must reach max |h′|). Where
  ρ < 0 no cam makes the lift (the face would have to touch a cusp): *undercut*.
- **Roller** of radius r_r: its centre runs on the pitch curve, in polar form
  r = r_b + r_r + h(θ), whose radius of curvature is
  ρ_p = (r² + r′²)^(3/2) / (r² + 2r′² − r·r″) (negative where the curve is concave); the
  cam's surface is the pitch curve moved in by r_r along its normal, of radius ρ_p − r_r.
  Where the pitch curve is convex and sharper than the roller (0 < ρ_p < r_r) the surface
  would loop back on itself: *undercut*. A translating roller's pressure angle, between its
  travel and the contact normal, is atan(r′/r).

The contact's relative radius of curvature R' (the Hertz pressure's, :func:`contact_radius`)
is ρ under a flat face and ρ·r_r/(ρ + r_r) under a roller (ρ negative on a concave flank).

Pure numpy, in SI (m, rad); :func:`cam_shape` samples a profile's turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from campipe.profiles.pieces import Profile, evaluate

#: Samples of a turn :func:`cam_shape` looks at (each break's both sides as well).
SAMPLES = 7200


def flat_face_radius(base_radius: float, lift, acceleration) -> np.ndarray:
    """The cam's radius of curvature [m] under a flat-faced follower: r_b + h + h″."""
    return base_radius + np.asarray(lift) + np.asarray(acceleration)


def pitch_radius(base_radius: float, roller_radius: float, lift, velocity, acceleration):
    """The radius of curvature [m] of a roller's pitch curve r = r_b + r_r + h(θ) (negative
    where it is concave; infinite where it is straight)."""
    r = base_radius + roller_radius + np.asarray(lift)
    dr, ddr = np.asarray(velocity), np.asarray(acceleration)
    bend = r * r + 2.0 * dr * dr - r * ddr
    with np.errstate(divide="ignore"):
        return np.where(bend != 0.0, (r * r + dr * dr) ** 1.5 / bend, np.inf)


def is_undercut(radius, roller_radius: float) -> np.ndarray:
    """Where no cam makes the lift: a flat face's radius of curvature ``radius`` below 0, or
    a roller's pitch curve (``radius`` its radius) convex and sharper than the roller."""
    radius = np.asarray(radius)
    if roller_radius > 0.0:
        return (radius > 0.0) & (radius < roller_radius)
    return radius < 0.0


@dataclass(frozen=True)
class CamShape:
    """A cam's shape over a turn (SI)."""

    theta: np.ndarray  # [rad] the cam angles looked at
    radius: np.ndarray  # [m] the cam surface's radius of curvature (negative: concave)
    roller_radius: float  # [m] 0: a flat-faced follower
    #: [m] a flat face's contact offset from its axis (h′); a roller's: NaN
    offset: np.ndarray
    #: [rad] a translating roller's pressure angle, atan(r′/r); a flat face's: 0
    pressure_angle: np.ndarray
    undercut: np.ndarray  # bool: no cam makes the lift there

    @property
    def least(self) -> tuple[float, float]:
        """(the least convex radius of curvature [m], where [rad]); a flat face's least
        radius, negative where undercut."""
        convex = self.radius if self.roller_radius == 0.0 else np.where(
            self.radius + self.roller_radius > 0.0, self.radius, np.inf)  # fmt: skip
        k = int(np.argmin(convex))
        return float(convex[k]), float(self.theta[k])

    @property
    def first_undercut(self) -> float | None:
        """The first cam angle [rad] that is undercut, or None."""
        k = np.flatnonzero(self.undercut)
        return float(self.theta[k[0]]) if k.size else None


def cam_shape(
    profile: Profile, base_radius: float, roller_radius: float, samples: int = SAMPLES
) -> CamShape:
    """The cam's shape under ``profile`` (the follower's lift) over a turn: ``samples``
    angles and each break's two sides (where an acceleration steps)."""
    grid = np.arange(samples) * (2.0 * math.pi / samples)
    breaks = np.asarray(profile.breaks[:-1], float)
    theta = np.concatenate([grid, breaks, breaks])
    side = np.array(["right"] * (grid.size + breaks.size) + ["left"] * breaks.size)
    lift, velocity, acceleration = (np.empty(theta.size) for _ in range(3))
    for s in ("right", "left"):
        pick = side == s
        lift[pick], velocity[pick], acceleration[pick] = evaluate(profile, theta[pick], s)
    order = np.argsort(theta, kind="stable")
    theta, lift, velocity, acceleration = (a[order] for a in (theta, lift, velocity, acceleration))
    if roller_radius > 0.0:
        pitch = pitch_radius(base_radius, roller_radius, lift, velocity, acceleration)
        r = base_radius + roller_radius + lift
        return CamShape(
            theta,
            pitch - roller_radius,
            roller_radius,
            np.full(theta.size, np.nan),
            np.arctan2(velocity, r),
            is_undercut(pitch, roller_radius),
        )
    radius = flat_face_radius(base_radius, lift, acceleration)
    return CamShape(theta, radius, 0.0, velocity, np.zeros(theta.size), is_undercut(radius, 0.0))


def contact_radius(
    profile: Profile, base_radius: float, roller_radius: float, theta: np.ndarray
) -> np.ndarray:
    """The relative radius of curvature R' [m] of the cam and its follower at the contact, at
    cam angles ``theta`` [rad] (any turn) under ``profile`` (the follower's lift): the cam's
    radius of curvature ρ under a flat face, ρ·r_r/(ρ + r_r) under a roller of radius r_r;
    NaN where the cam is undercut there (:class:`CamShape`)."""
    angle = np.mod(np.asarray(theta, float), 2.0 * math.pi)
    lift, velocity, acceleration = evaluate(profile, angle)
    if roller_radius > 0.0:
        pitch = pitch_radius(base_radius, roller_radius, lift, velocity, acceleration)
        cut = is_undercut(pitch, roller_radius)
        # r_r·ρ/(ρ + r_r) with ρ = ρ_p − r_r: r_r·(1 − r_r/ρ_p), r_r where the curve is straight
        radius = roller_radius * (1.0 - roller_radius / pitch)
    else:
        radius = flat_face_radius(base_radius, lift, acceleration)
        cut = is_undercut(radius, 0.0)
    return np.where(cut, np.nan, radius)
