"""The valve train as a 2-D sketch: pure functions from the coordinates q to line strips.

Layout (x to the right, y up, metres, the rocker pivot at the origin; the reference geometry
is q = 0, the follower on the cam's base circle):

- rocker: from the pushrod end (x = −a) through the pivot (0, 0) to the valve end (x = +b),
  a and b the two arm lengths; each arm is drawn as its Euler–Bernoulli element deflects
  (the cubic Hermite shape functions of thesis Eq. 8 between its nodal deflections and
  slopes), so bending shows. Slopes are dv/dx: positive from the pushrod end towards the
  valve end, as q3, q5, q6 are (see :data:`campipe.model.COORDINATES`).
- pushrod: vertical at x = −a, from its foot (y = −L1 − q1; q1 positive down) to its top
  (y = q2).
- cam: centre (−a, −L1 − R), R the base-circle radius (a drawing choice: the model has no
  cam radius); the polar outline r(φ) = R + lift(φ) turned clockwise by the cam angle θ, so
  that the lift straight above the centre, under the follower, is lift(θ).
- valve: stem from the rocker valve end (b, q4) down to the valve (b, −L5 − q7; q7 positive
  down, opening), the head a plate hanging under it; the seat two blocks above the head's
  rim, touching it when q7 reaches the seat.
- spring: a zig-zag from a fixed plate to a retainer on the stem, moving with q4 (element 4
  joins ground and q4).

Magnification (:func:`displayed_coordinates`): the sketch draws the rigid train the cam (and
the seat) would carry, at true scale, plus ``magnification`` × the computed deviation from it.
The deviation holds everything the dynamics adds: the gap at the cam while the follower is
off it, the valve's bounce off its seat, and the members' elastic deflections. A coordinate
held by a contact is drawn where it truly is, so the follower never enters the cam and the
valve never passes its seat.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from campipe.constants import TWO_PI
from campipe.model import ValveTrain
from campipe.vocabulary import CONFIGURATIONS

#: Base-circle radius of the drawn cam [m]: the thesis's model needs none.
BASE_RADIUS = 0.02
#: Deviations from the rigid-body motion are drawn this many times larger, unless told.
DEFAULT_MAGNIFICATION = 10.0
#: Points along each rocker arm's deflected shape.
ARM_POINTS = 17
#: Zig-zag corners of the spring.
SPRING_CORNERS = 14
#: Contact configurations (thesis Table I) with the follower on the cam / the valve seated.
CAM_CONTACT = tuple(n for n, c in CONFIGURATIONS.items() if c.cam)
SEAT_CONTACT = tuple(n for n, c in CONFIGURATIONS.items() if c.seat)


@dataclass(frozen=True)
class Geometry:
    """Lengths of the drawn train [m]: the model's own, plus drawing choices."""

    pushrod_arm: float  # a: rocker arm from the pushrod end to the pivot
    valve_arm: float  # b: rocker arm from the pivot to the valve end
    pushrod_length: float  # L1
    valve_stem_length: float  # L5
    pushrod_radius: float  # half the pushrod diameter
    rocker_radius: float  # half the rocker diameter (the larger arm's)
    stem_radius: float  # half the valve stem diameter
    base_radius: float = BASE_RADIUS  # cam base circle (drawing only)

    @classmethod
    def from_train(cls, train: ValveTrain, base_radius: float = BASE_RADIUS) -> Geometry:
        return cls(
            pushrod_arm=train.rocker_pushrod_arm_length,
            valve_arm=train.rocker_valve_arm_length,
            pushrod_length=train.pushrod_length,
            valve_stem_length=train.valve_stem_length,
            pushrod_radius=train.pushrod_diameter / 2,
            rocker_radius=max(train.rocker_pushrod_arm_diameter, train.rocker_valve_arm_diameter)
            / 2,
            stem_radius=train.valve_stem_diameter / 2,
            base_radius=base_radius,
        )

    @property
    def ratio(self) -> float:
        """Rocker ratio b/a: valve lift per follower lift of the rigid train [-]."""
        return self.valve_arm / self.pushrod_arm

    @property
    def head_half_width(self) -> float:
        """Half the drawn valve head [m]."""
        return 0.2 * self.valve_stem_length

    @property
    def cam_centre(self) -> np.ndarray:
        return np.array([-self.pushrod_arm, -self.pushrod_length - self.base_radius])

    @property
    def spring_plate(self) -> float:
        """Height of the fixed spring plate [m]."""
        return -0.85 * self.valve_stem_length


def rigid_coordinates(follower_lift: np.ndarray, geometry: Geometry) -> np.ndarray:
    """q of the rigid train with its follower at ``follower_lift`` [m]: (n,) → (n, 7).

    The rigid train turns about the pivot: q2 = p, slopes −p/a, q4 = −(b/a)·p, q7 = (b/a)·p.
    """
    p = np.asarray(follower_lift, dtype=float)
    a, b = geometry.pushrod_arm, geometry.valve_arm
    slope = -p / a
    return np.stack([-p, p, slope, b * slope, slope, slope, -b * slope], axis=-1)


def rigid_follower_lift(
    cam_lift: np.ndarray, geometry: Geometry, seat_q7: float = np.nan
) -> np.ndarray:
    """Follower lift [m] of the rigid train on the cam, resting on the seat where the cam
    falls below it (``seat_q7``: q7 of the valve on its seat [m]; NaN: no seat)."""
    cam_lift = np.asarray(cam_lift, dtype=float)
    if np.isnan(seat_q7):
        return cam_lift
    return np.maximum(cam_lift, seat_q7 / geometry.ratio)


def displayed_coordinates(
    q: np.ndarray,
    cam_lift: np.ndarray,
    contact_state: np.ndarray,
    geometry: Geometry,
    magnification: float = DEFAULT_MAGNIFICATION,
    seat_q7: float = np.nan,
) -> np.ndarray:
    """The coordinates the sketch draws: rigid-body motion + magnification × deviation.

    Parameters
    ----------
    q : np.ndarray
        (n, 7) computed coordinates [m, rad].
    cam_lift : np.ndarray
        (n,) cam lift under the follower [m].
    contact_state : np.ndarray
        (n,) contact configuration 1–4 (thesis Table I).
    geometry : Geometry
    magnification : float
        Factor on the deviation from the rigid-body motion [-]; 1 draws q as computed.
    seat_q7 : float
        q7 with the valve on its seat [m]; NaN for no seat.

    Returns
    -------
    np.ndarray
        (n, 7) [m, rad]. The follower is drawn on the cam where it touches it and never
        inside it; the valve on its seat where it sits on it and never beyond it.
    """
    q = np.asarray(q, dtype=float)
    cam_lift = np.asarray(cam_lift, dtype=float)
    state = np.asarray(contact_state)
    rigid = rigid_coordinates(rigid_follower_lift(cam_lift, geometry, seat_q7), geometry)
    out = rigid + magnification * (q - rigid)
    on_cam = np.isin(state, CAM_CONTACT)
    out[:, 0] = np.where(on_cam, q[:, 0], np.minimum(out[:, 0], -cam_lift))
    if not np.isnan(seat_q7):
        seated = np.isin(state, SEAT_CONTACT)
        out[:, 6] = np.where(seated, q[:, 6], np.maximum(out[:, 6], seat_q7))
    return out


def hermite(v1, theta1, v2, theta2, length: float, points: int = ARM_POINTS) -> np.ndarray:
    """Deflection of a beam element at ``points`` equally spaced stations (thesis Eq. 8
    shape functions): nodal deflections v [m] and slopes θ [rad], (n,) each → (n, points)."""
    xi = np.linspace(0.0, 1.0, points)
    n1 = 1 - 3 * xi**2 + 2 * xi**3
    n2 = xi - 2 * xi**2 + xi**3
    n3 = 3 * xi**2 - 2 * xi**3
    n4 = -(xi**2) + xi**3
    col = [np.asarray(x, dtype=float)[:, None] for x in (v1, theta1, v2, theta2)]
    return col[0] * n1 + col[1] * length * n2 + col[2] * n3 + col[3] * length * n4


def rocker(qd: np.ndarray, geometry: Geometry, points: int = ARM_POINTS) -> np.ndarray:
    """(n, 2·points − 1, 2): the rocker's deflected centre line, pushrod end to valve end."""
    a, b = geometry.pushrod_arm, geometry.valve_arm
    zero = np.zeros(qd.shape[0])
    left = hermite(qd[:, 1], qd[:, 2], zero, qd[:, 5], a, points)
    right = hermite(zero, qd[:, 5], qd[:, 3], qd[:, 4], b, points)
    x = np.concatenate([np.linspace(-a, 0.0, points), np.linspace(0.0, b, points)[1:]])
    y = np.concatenate([left, right[:, 1:]], axis=1)
    return np.stack([np.broadcast_to(x, y.shape), y], axis=-1)


def pushrod(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2, 2): foot, top."""
    x = np.full(qd.shape[0], -geometry.pushrod_arm)
    foot = np.stack([x, -geometry.pushrod_length - qd[:, 0]], axis=-1)
    top = np.stack([x, qd[:, 1]], axis=-1)
    return np.stack([foot, top], axis=1)


def valve_position(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2): the valve (stem foot, top face of the head)."""
    return np.stack(
        [np.full(qd.shape[0], geometry.valve_arm), -geometry.valve_stem_length - qd[:, 6]], axis=-1
    )


def stem(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2, 2): rocker valve end, valve."""
    top = np.stack([np.full(qd.shape[0], geometry.valve_arm), qd[:, 3]], axis=-1)
    return np.stack([top, valve_position(qd, geometry)], axis=1)


def valve_head(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 5, 2): closed outline of the head hanging under the valve position."""
    w = geometry.head_half_width
    h = 0.25 * w
    corners = np.array([[-w, 0.0], [w, 0.0], [w, -h], [-w, -h], [-w, 0.0]])
    return valve_position(qd, geometry)[:, None, :] + corners


def spring(qd: np.ndarray, geometry: Geometry, corners: int = SPRING_CORNERS) -> np.ndarray:
    """(n, corners + 2, 2): zig-zag from the fixed plate up to the retainer under the rocker
    valve end (the retainer follows q4)."""
    b = geometry.valve_arm
    width = 0.6 * geometry.head_half_width
    bottom = geometry.spring_plate
    top = qd[:, 3] - 0.05 * geometry.valve_stem_length
    s = np.linspace(0.0, 1.0, corners + 2)
    side = np.zeros(corners + 2)
    side[1:-1] = np.where(np.arange(corners) % 2 == 0, -width, width)
    y = bottom + (top[:, None] - bottom) * s
    return np.stack([np.broadcast_to(b + side, y.shape), y], axis=-1)


def retainer(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2, 2): the spring retainer on the stem."""
    w = 0.8 * geometry.head_half_width
    y = qd[:, 3] - 0.05 * geometry.valve_stem_length
    b = geometry.valve_arm
    return np.stack(
        [np.stack([np.full_like(y, b - w), y], -1), np.stack([np.full_like(y, b + w), y], -1)],
        axis=1,
    )


def cam_outline(
    turn_angle: np.ndarray, turn_lift: np.ndarray, cam_angle: np.ndarray, geometry: Geometry
) -> np.ndarray:
    """The cam's polar outline turned by each cam angle.

    Parameters
    ----------
    turn_angle : np.ndarray
        (m,) increasing angles of one turn, in [0, 2π) [rad].
    turn_lift : np.ndarray
        (m,) cam lift at those angles [m].
    cam_angle : np.ndarray
        (n,) cam angles to draw [rad].

    Returns
    -------
    np.ndarray
        (n, m + 1, 2) [m], closed on its first point, when the angles span a whole turn;
        else (n, m, 2), open.
    """
    phi = np.asarray(turn_angle, dtype=float)
    r = geometry.base_radius + np.asarray(turn_lift, dtype=float)
    alpha = np.pi / 2 + phi[None, :] - np.asarray(cam_angle, dtype=float)[:, None]
    c = geometry.cam_centre
    out = np.stack([c[0] + r * np.cos(alpha), c[1] + r * np.sin(alpha)], axis=-1)
    # a whole turn (no gap wider than twice the spacing) is closed on its first point
    if phi.size > 1 and phi[0] - phi[-1] + TWO_PI <= 2 * np.max(np.diff(phi)) + 1e-12:
        out = np.concatenate([out, out[:, :1]], axis=1)
    return out


def cam_mark(cam_angle: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2, 2): a radius from the cam centre along body angle 0, so the turning shows on
    the base circle too."""
    alpha = np.pi / 2 - np.asarray(cam_angle, dtype=float)
    c = geometry.cam_centre
    r = 0.8 * geometry.base_radius
    tip = np.stack([c[0] + r * np.cos(alpha), c[1] + r * np.sin(alpha)], axis=-1)
    return np.stack([np.broadcast_to(c, tip.shape), tip], axis=1)


def moving_parts(qd: np.ndarray, geometry: Geometry) -> dict[str, np.ndarray]:
    """The parts that move with q, each (n, k, 2) [m]: one line strip per sample."""
    return {
        "pushrod": pushrod(qd, geometry),
        "rocker": rocker(qd, geometry),
        "stem": stem(qd, geometry),
        "head": valve_head(qd, geometry),
        "spring": spring(qd, geometry),
        "retainer": retainer(qd, geometry),
    }


def follower_position(qd: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(n, 2): the follower (pushrod foot), where it meets the cam."""
    return pushrod(qd, geometry)[:, 0]


def fixed_parts(geometry: Geometry, seat_q7: float = np.nan) -> dict[str, np.ndarray]:
    """Ground: the pivot support and the spring plate as line strips (k, 2), and the seat
    blocks as boxes (2, 2, 2): [min corner, size] each; no seat blocks for NaN."""
    a, b = geometry.pushrod_arm, geometry.valve_arm
    w = geometry.head_half_width
    h = 0.3 * a
    out = {
        "pivot": np.array([[0.0, 0.0], [-0.5 * h, h], [0.5 * h, h], [0.0, 0.0]]),
        "ground": np.array([[-h, h], [h, h]]),
        "spring_plate": np.array(
            [
                [b - 1.3 * w, geometry.spring_plate],
                [b - 0.2 * w, geometry.spring_plate],
                [b - 0.2 * w, geometry.spring_plate - 0.05 * w],
                [b + 0.2 * w, geometry.spring_plate - 0.05 * w],
                [b + 0.2 * w, geometry.spring_plate],
                [b + 1.3 * w, geometry.spring_plate],
            ]
        ),
    }
    if not np.isnan(seat_q7):
        y = -geometry.valve_stem_length - seat_q7
        block = np.array([0.8 * w, 0.3 * w])
        out["seat"] = np.array([[[b - 1.3 * w, y], block], [[b + 0.5 * w, y], block]])
    return out
