"""Lever layouts: an overhead cam on a roller lever, built from named geometry and masses.

``finger-follower``
    a finger pivoted at one end (on a post or a lash adjuster), its roller between the pivot
    and the pallet, the cam above the roller, the valve under the pallet;
``centre-pivot-rocker``
    a rocker pivoted between its arms, the roller on one arm with the cam under it, the
    valve under the pallet of the other.

**Geometry** (a plane, the valve's axis vertical, the valve opening downwards; the pivot at
the origin). The lever is straight: the roller's centre and the pallet's centre of curvature
lie on one line through the pivot, at ``pivot_to_roller`` (a) and ``pivot_to_pallet`` (b), on
the same side of the pivot for the finger, on opposite sides for the rocker. The lever's
pallet arm makes ``lever_rest_angle`` (α₀) with the horizontal at rest (valve closed, roller
on the base circle), positive when the pallet sits above the pivot. The cam's centre is
``cam_base_radius`` + ``cam_roller_radius`` (R) from the roller's centre at rest, above it
(finger) or below it (rocker), ``cam_offset`` horizontally towards the pallet. The cam turns
counter-clockwise, x pointing from the pivot towards the pallet and y up.

**Kinematics** (exact). The cam's profile is the lift h(θ) a radial roller follower of the
same roller would see, so the roller's centre runs on the cam's pitch curve: at cam angle θ,
its point of profile angle s sits at c + (R + h(s))·u(ψ₀ + θ − s) (ψ₀ the direction from the
cam's centre to the roller's rest centre, u(φ) = (cos φ, sin φ)). The roller's centre is the
point of that curve at a from the pivot nearest s = θ (:func:`kinematic_state`: a bracketed
bisection on s); the lever's angle α follows, and the valve lift is the pallet centre's fall,
b·(sin α₀ − sin α), whatever the pallet's radius (a round pallet on a flat stem tip).

**The lever ratio** (:func:`kinematic_state`) is the valve's travel per unit of the roller
centre's travel along the contact normal: b·cos α / (a·|t·n|), t the lever's direction of
motion at the roller, n the pitch curve's normal. It changes with lift; by virtual work the
roller's normal force on the cam is the valve-side force at the pallet times it.

**Dynamics** (linear about the kinematic motion). The train is built as a two-mass chain in
valve-side coordinates (:func:`lever_chain`): the lever (``lever_inertia`` about the pivot and
``roller_mass`` at a) reduced to the pallet at the rest ratio, (J + m_r·a²)/(b·cos α₀)²,
rides the kinematic valve lift; the valve (``valve_mass``) hangs on the lever's stiffness at
the pallet (``lever_stiffness``) and the stem's (``stem_stiffness``) in series. What is
linearised: the reduced mass is held at its rest value (the lever's angle changes it by
cos²α₀/cos²α, :func:`reduced_mass_factor`: a few per cent over a lift for a lever near
level, more for a tilted one), and a deflection adds to the kinematic motion
without changing the ratio. The engine drives the chain's cam mass with the kinematic lift
(:func:`campipe.profiles.levers.valve_side`), so the archive's cam lift, cam force and cam
contact are the valve side's: the cam force at the pallet, along the valve.

**A compliant cam contact** (``cam_contact`` kelvin-voigt or hertz) acts at the roller: its
approach there is the valve side's over the ratio r(θ) at the instant, and its force r times
the valve side's (virtual work), so the lever's contact stiffness seen at the
valve is k/r² as the lever turns (``campipe.engine.compliant``). With r changing with the
cam angle such a case is integrated by solve_ivp, not propagated exactly.

Pure Python and numpy; the cam's lift comes in as a function (this layer has no profiles).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from campipe.model.declared import ModelParameterError, Parameter

FINGER_FOLLOWER, CENTRE_PIVOT_ROCKER = "finger-follower", "centre-pivot-rocker"
#: The lever layouts.
LEVERS = (FINGER_FOLLOWER, CENTRE_PIVOT_ROCKER)
#: Keys a lever layout needs (none given: refused), and those it may leave at their default.
LEVER_NEEDS = (
    "pivot_to_roller",
    "pivot_to_pallet",
    "cam_base_radius",
    "cam_roller_radius",
    "lever_inertia",
    "valve_mass",
    "lever_stiffness",
    "stem_stiffness",
)
LEVER_KEYS = (  # cam_base_radius is needed here and read by any layout (the cam's shape)
    "pivot_to_roller",
    "pivot_to_pallet",
    "lever_rest_angle",
    "cam_offset",
    "lever_inertia",
    "roller_mass",
    "lever_stiffness",
)
#: Largest rest angle [rad] of the lever's pallet arm from the horizontal.
MAX_REST_ANGLE = math.radians(60.0)
#: How far [rad] from s = θ the roller's contact on the pitch curve is looked for, and the
#: bracketing grid's spacing.
SEARCH_HALF_WIDTH, SEARCH_STEP = 1.0, 0.01
#: The grid's points looked at first on either side of s = θ (the contact lies within a few
#: hundredths of a radian of θ on the bundled levers); the rest only where these bracket none.
SEARCH_NEAR = 5

Lift = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # θ [rad] → (h [m], dh/dθ [m/rad])


def _key(name: str, what: str, units: str, shown: str, **kw: Any) -> Parameter:
    kw.setdefault("default", "none")
    kw.setdefault("allow_none", kw["default"] == "none")
    minimum = kw.pop("minimum", 0.0)
    return Parameter(name, f"{what} (layouts {', '.join(LEVERS)})", units, shown, minimum, **kw)


def lever_parameters() -> list[Parameter]:
    """The lever layouts' own keys (``cam_roller_radius``, ``valve_mass`` and
    ``stem_stiffness`` are shared with other layouts)."""
    return [
        _key("pivot_to_roller", "pivot's centre to the roller's centre", "m", "mm"),
        _key("pivot_to_pallet", "pivot's centre to the pallet's centre of curvature", "m", "mm"),
        Parameter(
            "cam_base_radius",
            "cam's base-circle radius (layouts finger-follower and centre-pivot-rocker need "
            "it; on any layout it gives the cam's shape: campipe model's radius of curvature, "
            "and a note where no cam makes the lift, undercut)",
            "m",
            "in",
            0.0,
            default="none",
            allow_none=True,
        ),
        _key(
            "lever_rest_angle",
            "pallet arm's angle above the horizontal at rest (valve closed)",
            "rad",
            "deg",
            default="0 deg",
            minimum=-MAX_REST_ANGLE,
            exclusive_minimum=False,
            maximum=MAX_REST_ANGLE,
        ),
        _key(
            "cam_offset",
            "cam centre's horizontal offset from the roller's rest centre, towards the pallet",
            "m",
            "mm",
            default="0 mm",
            minimum=-math.inf,
        ),
        _key("lever_inertia", "lever's moment of inertia about its pivot", "kg*m**2", "kg*mm**2"),
        _key(
            "roller_mass",
            "roller's mass with its axle (at pivot_to_roller)",
            "kg",
            "g",
            default="0 kg",
            exclusive_minimum=False,
        ),
        _key("lever_stiffness", "lever's stiffness at the pallet, along the valve", "N/m", "N/mm"),
    ]


@dataclass(frozen=True)
class Lever:
    """A lever layout's geometry, SI."""

    kind: str  # FINGER_FOLLOWER or CENTRE_PIVOT_ROCKER
    roller_arm: float  # [m] a, pivot to roller centre
    pallet_arm: float  # [m] b, pivot to pallet centre
    pitch_radius: float  # [m] R, base circle plus roller
    rest_angle: float  # [rad] α₀, pallet arm above the horizontal at rest
    offset: float  # [m] cam centre's horizontal offset from the roller's rest centre
    pivot_height: float = 0.0  # [m] the pivot raised from its rest (a lash adjuster's e)

    @property
    def side(self) -> float:
        """+1: the roller on the pallet's arm (finger), −1: on the other (rocker)."""
        return 1.0 if self.kind == FINGER_FOLLOWER else -1.0

    @property
    def pivot(self) -> np.ndarray:
        """(2,) the pivot's centre [m]: the origin raised by ``pivot_height``."""
        return np.array([0.0, self.pivot_height])

    def roller_at(self, alpha: np.ndarray) -> np.ndarray:
        """(…, 2) the roller's centre [m] at pallet-arm angle ``alpha`` [rad]."""
        arm = self.side * self.roller_arm * np.stack([np.cos(alpha), np.sin(alpha)], -1)
        return arm + self.pivot

    @property
    def rest_roller(self) -> np.ndarray:
        """(2,) the roller's centre at rest [m], the pivot at the origin (the cam's place)."""
        return self.side * self.roller_arm * np.array(_unit(self.rest_angle))

    @property
    def cam_centre(self) -> np.ndarray:
        """(2,) the cam's centre [m]: above the roller (finger), below it (rocker); fixed
        whatever the pivot's height."""
        rise = math.sqrt(self.pitch_radius**2 - self.offset**2)
        return self.rest_roller + np.array([self.offset, self.side * rise])

    def valve_lift(self, alpha: np.ndarray) -> np.ndarray:
        """The valve lift [m] at pallet-arm angle ``alpha`` [rad]: the pallet centre's fall
        from its rest (the pivot at the origin, the arm at α₀)."""
        return self.pallet_arm * (math.sin(self.rest_angle) - np.sin(alpha)) - self.pivot_height


def _unit(angle: float) -> tuple[float, float]:
    return math.cos(angle), math.sin(angle)


def lever_of(train: Any) -> Lever:
    """``train``'s lever geometry (a lever layout's, checked by :func:`check_lever`)."""
    return Lever(
        train.layout,
        train.pivot_to_roller,
        train.pivot_to_pallet,
        train.cam_base_radius + train.cam_roller_radius,
        train.lever_rest_angle,
        train.cam_offset,
    )


def _pitch_point(lever: Lever, lift: Lift, s: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The pitch curve's point of profile angle ``s`` at cam angle ``theta``, from the pivot."""
    c = lever.cam_centre
    psi0 = math.atan2(*(lever.rest_roller - c)[::-1])
    rho = lever.pitch_radius + lift(s)[0]
    phi = psi0 + theta - s
    return c - lever.pivot + rho[..., None] * np.stack([np.cos(phi), np.sin(phi)], -1)


def _contact_angle(lever: Lever, lift: Lift, theta: np.ndarray) -> np.ndarray:
    """The profile angle s [rad] of the roller's contact at each cam angle: the root of
    |pitch point|² − a² nearest s = θ, bracketed on a grid, then bisected to round-off.

    The grid's nearest :data:`SEARCH_NEAR` points on either side are searched first and the
    whole grid only for the angles they bracket no root at: the nearest sign change of the
    whole grid is then among them (every other interval lies farther from θ), so the bracket,
    and the root, are the whole grid's. The bisection leaves a bracket at the first step that
    does not move it (every later step would not either)."""

    def f(s_: np.ndarray, th: np.ndarray) -> np.ndarray:
        p = _pitch_point(lever, lift, s_, th)
        return np.einsum("...i,...i->...", p, p) - lever.roller_arm**2

    def nearest_change(offsets: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = th[:, None] + offsets[None, :]
        g = f(s, np.broadcast_to(th[:, None], s.shape))
        change = np.sign(g[:, :-1]) * np.sign(g[:, 1:]) <= 0.0
        distance = np.where(change, np.abs(offsets[:-1] + SEARCH_STEP / 2), np.inf)
        j = np.argmin(distance, axis=1)
        return offsets[j], np.isfinite(distance[np.arange(th.size), j])

    offsets = np.arange(-SEARCH_HALF_WIDTH, SEARCH_HALF_WIDTH + SEARCH_STEP / 2, SEARCH_STEP)
    middle = offsets.size // 2
    near = offsets[middle - SEARCH_NEAR : middle + SEARCH_NEAR + 1]
    start, found = nearest_change(near, theta)
    if not found.all():
        start[~found], found[~found] = nearest_change(offsets, theta[~found])
    if not found.all():
        raise ModelParameterError.at(
            "pivot_to_roller",
            "the roller cannot reach the cam at some cam angle: the lever's geometry and the "
            "cam's lift do not meet",
            found=lever.roller_arm,
            expected="a lever whose roller stays on the cam over the turn",
        )
    lo = theta + start
    hi = lo + SEARCH_STEP
    f_lo = f(lo, theta)
    moving = np.arange(theta.size)  # brackets the last step moved: a bracket a step left
    for _ in range(60):  # as it was would stay so at every later step, and is done
        a, b, f_a = lo[moving], hi[moving], f_lo[moving]
        mid = 0.5 * (a + b)
        f_mid = f(mid, theta[moving])
        left = np.sign(f_mid) == np.sign(f_a)
        new_a, new_b = np.where(left, mid, a), np.where(left, b, mid)
        lo[moving], hi[moving], f_lo[moving] = new_a, new_b, np.where(left, f_mid, f_a)
        moving = moving[(new_a != a) | (new_b != b)]
        if not moving.size:
            break
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class KinematicState:
    """A lever's kinematic motion at a set of cam angles."""

    theta: np.ndarray  # [rad] cam angles
    angle: np.ndarray  # [rad] the pallet arm's angle α
    valve_lift: np.ndarray  # [m] b·(sin α₀ − sin α)
    ratio: np.ndarray  # [-] valve travel per roller travel along the contact normal
    gain: np.ndarray  # [-] ∂(valve lift)/∂(pivot height), the roller held on the cam
    #: [rad] the profile angle s of the roller's centre on the pitch curve: the cam touches
    #: the roller where a radial roller would touch it at cam angle s
    contact: np.ndarray


def kinematic_state(lever: Lever, lift: Lift, theta: np.ndarray) -> KinematicState:
    """The lever's angle, the valve lift and the lever ratio at cam angles ``theta`` [rad] for
    a cam of lift ``lift`` (see the module)."""
    theta = np.asarray(theta, float).ravel()
    s = _contact_angle(lever, lift, theta)
    centre = _pitch_point(lever, lift, s, theta)
    alpha = np.arctan2(lever.side * centre[:, 1], lever.side * centre[:, 0])
    # the pitch curve's tangent along s, and the lever's direction of motion at the roller
    c = lever.cam_centre
    psi0 = math.atan2(*(lever.rest_roller - c)[::-1])
    phi = psi0 + theta - s
    h, dh = lift(s)
    u = np.stack([np.cos(phi), np.sin(phi)], -1)
    n_u = np.stack([-np.sin(phi), np.cos(phi)], -1)
    tangent = dh[:, None] * u - (lever.pitch_radius + h)[:, None] * n_u
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], -1)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    motion = np.stack([-np.sin(alpha), np.cos(alpha)], -1)
    along = np.einsum("ij,ij->i", motion, normal)
    ratio = _ratio(lever, alpha, along)
    gain = _gain(lever, alpha, normal[:, 1], along)
    return KinematicState(theta, alpha, lever.valve_lift(alpha), ratio, gain, s)


def _ratio(lever: Lever, alpha: np.ndarray, along: np.ndarray) -> np.ndarray:
    """The lever ratio b·cos α/(a·|n·t|): the valve's travel per unit of the roller's along
    the contact normal n (``along`` = n·t, t the lever's direction of motion)."""
    return lever.pallet_arm * np.cos(alpha) / (lever.roller_arm * np.abs(along))


def _gain(lever: Lever, alpha: np.ndarray, normal_up: np.ndarray, along: np.ndarray):
    """∂v/∂e, the valve lift's change per unit rise of the pivot with the roller held on the
    pitch curve (see :func:`pivot_gain`): the roller's centre moves by e·ŷ + side·a·t·dα, t
    the lever's direction of motion, and keeps on the curve, n·(e·ŷ + side·a·t·dα) = 0 (n its
    normal, either orientation); v = b·sin α₀ − e − b·sin α, so
    ∂v/∂e = b·cos α·n_y / (side·a·n·t) − 1."""
    arm = lever.side * lever.roller_arm
    return lever.pallet_arm * np.cos(alpha) * normal_up / (arm * along) - 1.0


def _rest_normal(lever: Lever) -> tuple[np.ndarray, np.ndarray]:
    """At rest, the contact's normal at the roller (the radius from the cam's centre: the
    roller on the base circle) and its component along the lever's motion, each (1,)."""
    normal = (lever.rest_roller - lever.cam_centre) / lever.pitch_radius
    motion = np.array([-math.sin(lever.rest_angle), math.cos(lever.rest_angle)])
    return normal[1:], np.array([float(normal @ motion)])


def rest_ratio(train: Any) -> float:
    """The lever ratio [-] at rest, the roller on the base circle: b·cos α₀/(a·|n·t|), as
    :func:`kinematic_state` gives on the base circle; b/a for a level finger under its cam."""
    lever = lever_of(train)
    return float(_ratio(lever, np.array([lever.rest_angle]), _rest_normal(lever)[1])[0])


def pivot_gain(train: Any) -> float:
    """The valve lift's change per unit rise of a lever's pivot [-] at rest (the roller on the
    base circle, whose normal at the roller is the radius from the cam's centre):
    b·cos α₀·n_y/(side·a·n·t) − 1; (b − a)/a for a level finger under its cam. By virtual
    work it is also the pivot's load per unit of the pallet's force, the lever's own momentum
    left out (``campipe.engine.lash_adjuster``)."""
    lever = lever_of(train)
    normal_up, along = _rest_normal(lever)
    return float(_gain(lever, np.array([lever.rest_angle]), normal_up, along)[0])


def base_take_up(lever: Lever, height: float) -> float:
    """The valve lift [m] on the base circle with the pivot raised by ``height`` [m] (a lash
    adjuster's extension e): the lash it takes up at the valve, exactly. The roller's centre
    X = P + side·a·u(α) sits on the pitch circle |X − c| = R, so with D = c − P (d = |D|, of
    direction φ) side·a·d·cos(α − φ) = (a² + d² − R²)/2, the root nearest α₀; about
    e·(b − a)/a for a level finger and a small e (:func:`pivot_gain`)."""
    lifted = dataclasses.replace(lever, pivot_height=height)
    D = lifted.cam_centre - lifted.pivot
    d, phi = float(np.hypot(*D)), math.atan2(D[1], D[0])
    a, R = lever.roller_arm, lever.pitch_radius
    cosine = lever.side * (a * a + d * d - R * R) / (2.0 * a * d)
    if not abs(cosine) <= 1.0:
        raise ModelParameterError.at(
            "hla_travel",
            "the lash adjuster raises the pivot so far that the roller cannot reach the cam",
            found=height,
            expected="a plunger travel the lever's geometry takes",
        )
    roots = phi + np.array([1.0, -1.0]) * math.acos(cosine)
    roots = np.angle(np.exp(1j * (roots - lever.rest_angle))) + lever.rest_angle
    alpha = roots[np.argmin(np.abs(roots - lever.rest_angle))]
    return float(lifted.valve_lift(np.asarray(alpha)))


def reduced_mass_factor(lever: Lever, angle: np.ndarray) -> np.ndarray:
    """cos²α₀/cos²α: how the lever's pallet-arm angle ``angle`` α [rad] changes its mass
    reduced to the pallet, (J + m_r·a²)/(b·cos α)², from its rest value (:func:`reduced_mass`,
    at α₀), which the dynamics hold (see the module)."""
    return (math.cos(lever.rest_angle) / np.cos(np.asarray(angle, float))) ** 2


def reduced_mass(train: Any) -> float:
    """The lever and its roller reduced to the pallet at the rest ratio [kg]:
    (J + m_r·a²)/(b·cos α₀)²."""
    arm = train.pivot_to_pallet * math.cos(train.lever_rest_angle)
    return (train.lever_inertia + train.roller_mass * train.pivot_to_roller**2) / arm**2


def check_lever(train: Any, key_prefix: str = "") -> None:
    """Refuse a lever layout's geometry that does not go together, naming the key: a needed
    key not given, a finger whose roller is not between its pivot and its pallet, a cam
    offset beyond the pitch circle."""
    for name in LEVER_NEEDS:
        if not getattr(train, name) > 0.0:  # NaN: not given; 0: a flat follower
            raise ModelParameterError.at(
                key_prefix + name,
                f"layout {train.layout} needs a positive {name} (" + ", ".join(LEVER_NEEDS) + ")",
                found=getattr(train, name),
                expected=f"a positive {name}",
            )
    if train.layout == FINGER_FOLLOWER and not train.pivot_to_roller < train.pivot_to_pallet:
        raise ModelParameterError.at(
            key_prefix + "pivot_to_roller",
            "a finger follower's roller sits between its pivot and its pallet: give "
            "pivot_to_roller less than pivot_to_pallet",
            found=train.pivot_to_roller,
            expected=f"less than pivot_to_pallet {train.pivot_to_pallet:g} m",
        )
    pitch = train.cam_base_radius + train.cam_roller_radius
    if not abs(train.cam_offset) < 0.9 * pitch:
        raise ModelParameterError.at(
            key_prefix + "cam_offset",
            f"the cam's centre is cam_base_radius + cam_roller_radius ({pitch * 1e3:g} mm) from "
            f"the roller's centre: its horizontal offset ({train.cam_offset * 1e3:g} mm) must "
            f"stay within 0.9 of that, ±{0.9 * pitch * 1e3:g} mm",
            found=train.cam_offset,
            expected=f"an offset within ±{0.9 * pitch:g} m",
        )


def lever_chain(train: Any, key_prefix: str = "") -> dict[str, tuple[float, ...]]:
    """A lever layout as its two-mass chain in valve-side coordinates: the lever with its
    roller reduced to the pallet (:func:`reduced_mass`), the valve; between them the lever's
    stiffness at the pallet and the stem's in series."""
    check_lever(train, key_prefix)
    link = 1.0 / (1.0 / train.lever_stiffness + 1.0 / train.stem_stiffness)
    return {"masses": (reduced_mass(train), train.valve_mass), "stiffnesses": (link,)}
