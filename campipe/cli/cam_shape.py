"""``campipe model``'s cam shape: the cam's radius of curvature over the turn from its base
circle (``cam_base_radius``), and where no cam makes the lift (undercut), from
:func:`campipe.profiles.curvature.cam_shape`."""

from __future__ import annotations

import math

import numpy as np

from campipe.model.levers import LEVERS
from campipe.profiles.curvature import cam_shape


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
    }
    units = {"base_radius": "m", "roller_radius": "m", "least_radius_of_curvature": "m",
             "least_at": "rad", "undercut_from": "rad"}  # fmt: skip
    if roller > 0.0 and train.layout in LEVERS:
        pass  # a lever's roller swings: its pressure angle is the lever's, not atan(r′/r)
    elif roller > 0.0:
        out["max_pressure_angle"] = float(np.abs(shape.pressure_angle).max())
        units["max_pressure_angle"] = "rad"
    else:
        out["max_contact_offset"] = float(np.abs(shape.offset).max())
        units["max_contact_offset"] = "m"
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
        f"  least radius of curvature  {s['least_radius_of_curvature'] * 1e3:.4g} mm at "
        f"{math.degrees(s['least_at']):.1f}°",
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
