"""A chain of masses (a lumped, direct-acting or lever layout: :mod:`campipe.model.layouts`)
as a 2-D sketch: boxes joined by springs, standing on the cam. Pure functions from the
coordinates q to line strips, as :mod:`campipe.replay.sketch` draws the thesis's train.

Layout (x to the right, y up, metres): the cam at the bottom, its centre at
(0, −``BASE`` − R), R its drawn base-circle radius; above it the chain's masses from the
cam's (mass 1, its bottom face on the cam) to the valve, each a box ``BOX`` tall, each link a
zig-zag ``LINK`` long; the valve spring a zig-zag from the valve's top face to a ground plate
``LINK`` above it. Mass j's box moves up by its displacement along the lift, xⱼ (q1 = −x1,
every other q = x, :func:`campipe.model.layouts.chain_placement`). A lever layout's chain is
in valve-side coordinates (its cam lift is the kinematic valve lift), so it is drawn so too.

Magnification (:func:`displayed_displacements`): the rigid chain the cam (and the seat) would
carry, at true scale, plus ``magnification`` × the computed deviation from it; a mass held by
a contact is drawn where it truly is.
"""

from __future__ import annotations

import numpy as np

from campipe.model import ValveTrain
from campipe.model.layouts import chain_placement
from campipe.replay.sketch import CAM_CONTACT, SEAT_CONTACT, SPRING_CORNERS, Geometry

#: Drawn sizes [m]: a mass's box (height, half width), a link's length, the cam's base radius
#: and the cam's top (the chain's foot at rest) below the origin.
BOX, HALF_WIDTH, LINK, BASE_RADIUS, BASE = 0.008, 0.008, 0.012, 0.015, 0.0


def n_masses(train: ValveTrain) -> int:
    return len(train.masses)


def cam_geometry() -> Geometry:
    """The thesis sketch's geometry placing the cam under the chain (only its cam is read:
    the centre at (0, −BASE − R))."""
    return Geometry(0.0, 0.0, -BASE, 0.0, 0.0, 0.0, 0.0, BASE_RADIUS)


def displacements(q: np.ndarray, train: ValveTrain) -> np.ndarray:
    """(n, N) each mass's displacement along the lift [m] from q (n, coordinates)."""
    index, sign = chain_placement(n_masses(train))
    return np.asarray(q, float)[:, index] * sign


def displayed_displacements(
    q: np.ndarray,
    cam_lift: np.ndarray,
    contact_state: np.ndarray,
    train: ValveTrain,
    magnification: float,
    seat_q7: float = np.nan,
) -> np.ndarray:
    """(n, N) the displacements drawn: the rigid chain's (every mass at the follower's lift,
    the cam's lift or the seat's where the seat holds the chain off the cam) plus
    ``magnification`` × the deviation; the cam's mass on the cam and the valve on its seat
    drawn where they are, never inside them."""
    x = displacements(q, train)
    lift = np.asarray(cam_lift, float)
    rigid = lift if np.isnan(seat_q7) else np.maximum(lift, seat_q7)
    out = rigid[:, None] + magnification * (x - rigid[:, None])
    state = np.asarray(contact_state)
    out[:, 0] = np.where(np.isin(state, CAM_CONTACT), x[:, 0], np.maximum(out[:, 0], lift))
    if not np.isnan(seat_q7):
        seated = np.isin(state, SEAT_CONTACT)
        out[:, -1] = np.where(seated, x[:, -1], np.maximum(out[:, -1], seat_q7))
    return out


def rest_bottoms(count: int) -> np.ndarray:
    """(N,) each box's bottom face at rest [m]."""
    return BASE + np.arange(count) * (BOX + LINK)


def _zigzag(bottom: np.ndarray, top: np.ndarray, corners: int = SPRING_CORNERS) -> np.ndarray:
    """(n, corners + 2, 2): a spring from ``bottom`` to ``top`` (n,) on x = 0."""
    s = np.linspace(0.0, 1.0, corners + 2)
    side = np.zeros(corners + 2)
    side[1:-1] = np.where(np.arange(corners) % 2 == 0, -0.5, 0.5) * HALF_WIDTH
    y = bottom[:, None] + (top - bottom)[:, None] * s
    return np.stack([np.broadcast_to(side, y.shape), y], axis=-1)


def moving_parts(xd: np.ndarray) -> dict[str, np.ndarray]:
    """The parts that move, each (n, k, 2) [m]: ``mass_j`` boxes (closed outlines), ``link_j``
    springs between them, ``spring`` the valve spring up to its plate."""
    count = xd.shape[1]
    bottom = rest_bottoms(count)[None, :] + xd
    corners = np.array(
        [[-HALF_WIDTH, 0.0], [HALF_WIDTH, 0.0], [HALF_WIDTH, BOX], [-HALF_WIDTH, BOX]]
    )
    corners = np.vstack([corners, corners[:1]])
    out: dict[str, np.ndarray] = {}
    for j in range(count):
        y = bottom[:, j, None] + corners[None, :, 1]
        out[f"mass_{j + 1}"] = np.stack([np.broadcast_to(corners[:, 0], y.shape), y], -1)
        if j + 1 < count:
            out[f"link_{j + 1}"] = _zigzag(bottom[:, j] + BOX, bottom[:, j + 1])
    out["spring"] = _zigzag(bottom[:, -1] + BOX, np.full(xd.shape[0], spring_plate(count)))
    return out


def spring_plate(count: int) -> float:
    """The valve spring's ground plate [m]."""
    return float(rest_bottoms(count)[-1] + BOX + LINK)


def follower_position(xd: np.ndarray) -> np.ndarray:
    """(n, 2): the cam's mass's foot, where it meets the cam."""
    return np.stack([np.zeros(xd.shape[0]), BASE + xd[:, 0]], -1)


def valve_position(xd: np.ndarray) -> np.ndarray:
    """(n, 2): the valve's bottom face, where it meets the seat."""
    return np.stack([np.zeros(xd.shape[0]), rest_bottoms(xd.shape[1])[-1] + xd[:, -1]], -1)


def fixed_parts(count: int, seat_q7: float = np.nan) -> dict[str, np.ndarray]:
    """Ground: the spring plate as a line strip (k, 2), and the seat blocks under the valve's
    box's edges (clear of the link) as boxes (2, 2, 2): [min corner, size] each, their tops
    at the valve's bottom face on the seat; none for NaN."""
    top = spring_plate(count)
    out = {"spring_plate": np.array([[-1.5 * HALF_WIDTH, top], [1.5 * HALF_WIDTH, top]])}
    if not np.isnan(seat_q7):
        y = rest_bottoms(count)[-1] + seat_q7
        size = np.array([0.4 * HALF_WIDTH, 0.4 * BOX])
        out["seat"] = np.array(
            [[[-HALF_WIDTH, y - size[1]], size], [[0.6 * HALF_WIDTH, y - size[1]], size]]
        )
    return out
