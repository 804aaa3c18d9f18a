"""``campipe model``'s reports over the cam turn: a lever layout's kinematic ratio, and the
cam's shape from its base circle (``cam_base_radius``: its radius of curvature, and where no
cam makes the lift, undercut, from :func:`campipe.profiles.curvature.cam_shape`)."""

from __future__ import annotations

import math

import click
import numpy as np

from campipe.constants import TWO_PI
from campipe.model import lash_ratio
from campipe.model.checks import PUSHROD_ROCKER
from campipe.model.levers import LEVERS, lever_of, reduced_mass_factor
from campipe.profiles import evaluate, harmonic
from campipe.profiles.curvature import cam_shape
from campipe.profiles.levers import cam_kinematics


def shape_report(train, cam, label: str) -> dict[str, object]:
    """The cam's shape (SI, JSON form) under ``train``'s follower, ``cam`` the follower's
    lift (``label`` says which); empty where the train gives no base circle."""
    if cam is None or not train.cam_base_radius > 0.0:  # NaN: not given
        return {}
    roller = float(train.cam_roller_radius)
    shape = cam_shape(cam, float(train.cam_base_radius), roller)
    least, at = shape.least
    start = shape.first_undercut
    out: dict[str, object] = {
        "cam": label,
        "base_radius": float(train.cam_base_radius),
        "roller_radius": roller,
        "least_radius_of_curvature": least,
        "least_at": at,
        "undercut_from": start,
        "constant": bool(np.ptp(shape.radius) <= 1e-9 * abs(least)),  # an eccentric disc's
    }
    units = {"base_radius": "m", "roller_radius": "m", "least_radius_of_curvature": "m",
             "least_at": "rad", "undercut_from": "rad"}  # fmt: skip
    if roller == 0.0:
        out["max_contact_offset"] = float(np.abs(shape.offset).max())
        units["max_contact_offset"] = "m"
    elif train.layout not in LEVERS:  # a lever's roller swings: its pressure angle is not this
        out["max_pressure_angle"] = float(np.abs(shape.pressure_angle).max())
        units["max_pressure_angle"] = "rad"
    return {"cam_shape": {**out, "units": units}}


def shape_text(report: dict[str, object]) -> str:
    """The human form of :func:`shape_report`."""
    if not report:
        return ""
    s = report["cam_shape"]
    assert isinstance(s, dict)
    roller = s["roller_radius"]
    follower = f"a {roller * 1e3:.4g} mm roller" if roller > 0.0 else "a flat face"
    lines = [
        "",
        "",
        f"Cam shape ({s['cam']}; base circle {s['base_radius'] * 1e3:.4g} mm, {follower}):",
        f"  least radius of curvature  {s['least_radius_of_curvature'] * 1e3:.4g} mm "
        + ("(the same all round)" if s["constant"] else f"at {math.degrees(s['least_at']):.1f}°"),
    ]
    if "max_pressure_angle" in s:
        lines.append(
            f"  largest pressure angle     {math.degrees(s['max_pressure_angle']):.1f}° (a "
            "translating roller's: its travel against the contact normal)"
        )
    elif roller == 0.0:
        lines.append(
            f"  contact off the face's axis up to {s['max_contact_offset'] * 1e3:.4g} mm (the "
            "face's radius must reach it)"
        )
    if s["undercut_from"] is not None:
        lines.append(
            f"  UNDERCUT from {math.degrees(s['undercut_from']):.1f}°: no cam makes this lift "
            "under this follower; give a larger cam_base_radius or a longer rise"
        )
    return "\n".join(lines)


def shown_cam(cam, lift: float):
    """The cam the reports over the turn draw, and its label: the spec's (``cam``), or else
    the harmonic cam of ``lift`` [m] (--cam-lift; None where it is not positive)."""
    if cam is not None:
        return cam, f"the spec's cam, {cam.label}"
    return (harmonic(lift) if lift > 0.0 else None), f"harmonic, lift {lift * 1e3:g} mm"


def ratio_table(train, sm, lift: float, step: float, cam, label: str) -> dict[str, object]:
    """The kinematic ratio over the cam turn (SI, JSON form): a lever layout's, valve lift and
    lever ratio every ``step`` [rad] under ``cam`` (:func:`shown_cam`, ``label``; None: the
    harmonic cam of a ``lift`` [m] that is not positive, refused) (:mod:`campipe.model.levers`);
    another layout's, one constant (the thesis's rocker's ``lash_ratio``, a chain's 1: its
    coordinates are the valve side's)."""
    if train.layout not in LEVERS:
        ratio = lash_ratio(sm) if train.layout == PUSHROD_ROCKER else 1.0
        return {"kinematic_ratio": {"constant": ratio}}
    if cam is None:
        raise click.UsageError(f"--cam-lift: found {lift!r} m, expected a positive lift")
    theta = np.arange(0.0, TWO_PI - 1e-12, step)
    state = cam_kinematics(cam, train, theta)
    mass = reduced_mass_factor(lever_of(train), state.angle)
    return {
        "kinematic_ratio": {
            "cam": label,
            "cam_angle": theta.tolist(),
            "cam_lift": evaluate(cam, theta)[0].tolist(),
            "valve_lift": state.valve_lift.tolist(),
            "ratio": state.ratio.tolist(),
            "reduced_mass_factor": mass.tolist(),
            "units": {
                "cam_angle": "rad", "cam_lift": "m", "valve_lift": "m", "ratio": "1",
                "reduced_mass_factor": "1",
            },
        }
    }  # fmt: skip


def ratio_text(table: dict) -> str:
    """The human form of :func:`ratio_table`."""
    k = table["kinematic_ratio"]
    if "constant" in k:
        return f"\n\nKinematic ratio (valve travel per cam travel): {k['constant']:.6g}, constant"
    lines = [
        "",
        "",
        f"Kinematic ratio over the cam turn ({k['cam']}): the lever ratio is the valve's "
        "travel per unit of the roller's along the contact normal (the cam force per valve-side "
        "force); mass: the lever's mass reduced to the valve over its rest value, cos²α₀/cos²α "
        "(held at its rest value in the dynamics)",
        f"  {'cam deg':>8} {'cam lift mm':>12} {'valve lift mm':>14} {'ratio':>9} {'mass':>7}",
    ]
    columns = ("cam_angle", "cam_lift", "valve_lift", "ratio", "reduced_mass_factor")
    for a, h, v, r, m in zip(*(k[c] for c in columns), strict=True):
        lines.append(f"  {math.degrees(a):8.1f} {h * 1e3:12.4f} {v * 1e3:14.4f} {r:9.4f} {m:7.4f}")
    return "\n".join(lines)
