"""The cam's shape from its lift (``campipe.profiles.curvature``), against closed forms (an
eccentric disc) and against the cam's surface built point by point as the follower's envelope,
its curvature taken by finite differences; the undercut note and ``campipe model``'s report.

Broken copies: the flat face's radius without the lift's second derivative (r_b + h) fails
the disc and the envelope; the pitch curve's radius with r″ of the wrong sign fails the
roller's disc; the pitch curve's radius taken as the cam's (no − r_r) fails both roller tests.
"""

import json
import math

import numpy as np
from click.testing import CliRunner
from numpy.testing import assert_allclose
from study_helpers import write_spec

from campipe.cli import main
from campipe.profiles import evaluate, harmonic, polydyne, table
from campipe.profiles.curvature import cam_shape, flat_face_radius, pitch_radius

MM = 1e-3


def envelope_curvature_radius(points: np.ndarray, step: float) -> np.ndarray:
    """The radius of curvature of a closed planar curve sampled at equal parameter steps,
    by central differences (periodic), positive where it turns clockwise (a cam's surface
    runs so as θ grows: the follower's point turned back by θ): |r′|³ / (y′x″ − x′y″)."""
    d1 = (np.roll(points, -1, 0) - np.roll(points, 1, 0)) / (2 * step)
    d2 = (np.roll(points, -1, 0) - 2 * points + np.roll(points, 1, 0)) / step**2
    cross = d1[:, 1] * d2[:, 0] - d1[:, 0] * d2[:, 1]
    return np.linalg.norm(d1, axis=1) ** 3 / cross


def rotate(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1]], 1)


def test_the_harmonic_cam_under_a_flat_face_is_an_eccentric_disc():
    """h/2·(1 − sin θ) is an eccentric disc's lift under a flat face: its radius of
    curvature is the disc's, r_b + h/2, at every angle; the contact runs h/2 off the axis."""
    h, base = 6 * MM, 15 * MM
    shape = cam_shape(harmonic(h), base, 0.0)
    assert_allclose(shape.radius, base + h / 2, rtol=1e-12)
    assert_allclose(np.abs(shape.offset).max(), h / 2, rtol=1e-6)
    assert shape.first_undercut is None


def test_a_roller_on_an_eccentric_disc_sees_the_disc_s_radius():
    """A radial roller of radius r on a disc of radius R set e off the cam's centre: its
    centre stays R + r from the disc's centre, at e·cos θ + √((R + r)² − e² sin² θ) from the
    cam's (the lift, less the pitch circle r_b + r, r_b = R − e); the pitch curve's radius
    is R + r and the cam's R at every angle. The lift goes in as a measured table (a periodic
    spline of 0.25° samples)."""
    R, e, r = 20 * MM, 3 * MM, 8 * MM
    theta = np.arange(1440) * (2 * math.pi / 1440)
    centre = e * np.cos(theta) + np.sqrt((R + r) ** 2 - (e * np.sin(theta)) ** 2)
    cam = table(theta, centre - (R - e + r))
    shape = cam_shape(cam, R - e, r)
    assert_allclose(shape.radius, R, rtol=2e-6)
    assert shape.first_undercut is None
    lift, velocity, _ = evaluate(cam, theta)
    assert_allclose(shape.least[0], R, rtol=2e-6)
    # a translating roller's pressure angle: tan φ = r′/r, at most asin(e/(R + r)) here
    assert_allclose(np.abs(shape.pressure_angle).max(), math.asin(e / (R + r)), rtol=1e-4)


def test_a_polydyne_s_radius_is_its_envelope_s_under_a_flat_face_and_a_roller():
    """A polydyne (7 mm over 90°) on a 20 mm base circle. The flat face's contact point in
    the cam's frame is the follower's (h′, r_b + h) turned back by θ; the roller's is its
    centre (on the pitch curve, r_b + r + h along the follower) moved r towards the cam along
    the pitch curve's normal. Each curve's radius of curvature by finite differences over
    0.01° agrees with the formulas to 1e-5 of the radius."""
    cam = polydyne("4567", 7 * MM, math.radians(90), 0.0, math.radians(90))
    base, roller = 20 * MM, 8 * MM
    n = 36000
    theta = np.arange(n) * (2 * math.pi / n)
    h, dh, ddh = evaluate(cam, theta)
    face = rotate(np.stack([dh, base + h], 1), -theta)
    assert_allclose(
        envelope_curvature_radius(face, 2 * math.pi / n),
        flat_face_radius(base, h, ddh),
        rtol=1e-5,
    )
    pitch = rotate(np.stack([np.zeros(n), base + roller + h], 1), -theta)
    tangent = (np.roll(pitch, -1, 0) - np.roll(pitch, 1, 0)) / 2
    inward = np.stack([tangent[:, 1], -tangent[:, 0]], 1)  # the curve runs clockwise
    inward /= np.linalg.norm(inward, axis=1)[:, None]
    surface = pitch + roller * inward
    assert np.all(np.einsum("ij,ij->i", inward, pitch) < 0)  # towards the cam's centre
    assert_allclose(
        envelope_curvature_radius(surface, 2 * math.pi / n),
        pitch_radius(base, roller, h, dh, ddh) - roller,
        rtol=1e-5,
    )


def test_undercut_where_a_flat_face_s_radius_goes_negative():
    """The same polydyne squeezed into 70° on a 15 mm base circle: r_b + h + h″ goes negative
    on the flanks (the least, −13.9 mm, where h″ is least); on a 40 mm base circle it stays
    positive. The first undercut angle is where the formula first goes negative."""
    cam = polydyne("4567", 7 * MM, math.radians(70), math.radians(10), math.radians(70))
    shape = cam_shape(cam, 15 * MM, 0.0)
    theta = np.linspace(0, math.radians(70), 70001)
    h, _, ddh = evaluate(cam, theta)
    rho = 15 * MM + h + ddh
    first = theta[np.argmax(rho < 0)]
    assert abs(shape.first_undercut - first) < math.radians(0.06)
    assert_allclose(shape.least[0], rho.min(), rtol=1e-4)
    assert cam_shape(cam, 40 * MM, 0.0).first_undercut is None


SPEC = """
name: shape
model: {preset: thesis-1971, cam_base_radius: %s}
profile: {kind: polydyne-4567, lift: 7 mm, rise: 70 deg, dwell: 10 deg, fall: 70 deg}
seat: none
run: {revolutions: 1, output_every: 2 deg}
sweep:
  speed: [1000 rpm, 2000 rpm]
"""


def test_validate_notes_an_undercut_cam_and_model_reports_its_shape(tmp_path):
    """A spec whose cam is undercut on its base circle gets a note from campipe validate
    naming cam_base_radius, where and how much; on a 40 mm base circle none. ``campipe model
    --spec --json`` gives the least radius and the undercut's start as the module does.
    Broken copy: cam_base_radius still refused outside the lever layouts."""
    path = write_spec(tmp_path, SPEC % "15 mm", "undercut.yaml")
    out = CliRunner().invoke(main, ["validate", str(path)])
    assert out.exit_code == 0, out.output
    assert "cam: the cam polydyne-4567 7 mm 70/10/70/210 deg is undercut on a 15 mm base" in (
        out.output
    )
    assert "least -13.9" in out.output and "(cam_base_radius)" in out.output
    report = CliRunner().invoke(main, ["model", "--spec", str(path), "--json"])
    assert report.exit_code == 0, report.output
    shape = json.loads(report.output)["cam_shape"]
    cam = polydyne("4567", 7 * MM, math.radians(70), math.radians(10), math.radians(70))
    expected = cam_shape(cam, 15 * MM, 0.0)
    assert_allclose(shape["least_radius_of_curvature"], expected.least[0], rtol=1e-12)
    assert_allclose(shape["undercut_from"], expected.first_undercut, rtol=1e-12)
    assert shape["units"]["least_radius_of_curvature"] == "m"
    fine = write_spec(tmp_path, SPEC % "40 mm", "fine.yaml")
    out = CliRunner().invoke(main, ["validate", str(fine)])
    assert out.exit_code == 0 and "cam:" not in out.output, out.output


def test_no_bundled_study_s_cam_is_undercut():
    """The bundled lever studies give their cam's base circle; none is undercut (a copy that
    notes every cam with a base circle fails)."""
    from study_helpers import STUDIES

    from campipe.study import load_study
    from campipe.study.spec.notes import cam_note

    given = 0
    for spec in sorted(STUDIES.glob("*.yaml")):
        study = load_study(spec)
        given += any(c.case.train.cam_base_radius > 0 for c in study.cases)
        assert cam_note(study.cases) is None, spec.name
    assert given >= 2
