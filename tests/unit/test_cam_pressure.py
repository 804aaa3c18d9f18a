"""The Hertz pressure at the cam over its turn: where the cam's shape is known (its base circle
``cam_base_radius`` and a line contact ``cam_contact_width``), ``max_cam_pressure`` takes the
cam's radius of curvature at every angle, where one ``cam_curvature_radius`` (the nose's)
overstated a flank's pressure two times over at speed.

Checked against the eccentric disc's closed form, and against a dense second evaluation
written here: the same train run with samples 50 times closer, its pressure at each sample
from a radius of curvature this file computes on its own (a flat face's from the lift's
finite differences; a roller's pitch curve's in Cartesian form, by finite differences along
it; a finger's roller placed on its pitch curve by Brent's method).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from campipe.constants import INCH
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.levers import at_the_cam
from campipe.model import ModelParameterError, thesis_train, valve_train
from campipe.model.contact import contact_law
from campipe.model.contact.base import pair_modulus
from campipe.profiles import evaluate, harmonic, polydyne
from tests.unit.test_levers import FINGER

RPM = 2.0 * math.pi / 60.0
BASE, WIDTH = 0.75 * INCH, 0.5 * INCH
#: A polydyne whose radius of curvature ranges from 7.4 mm at the nose to far more on the
#: flanks under a flat face on the 0.75 in base circle.
CAM = polydyne("4567", 0.4 * INCH, math.radians(110), 0.0, math.radians(110))
#: Output spacings [deg]: the study's, and the dense second evaluation's.
COARSE, DENSE = 1.0, 0.02


def _run(case: Case, every: float, turns: int = 2):
    settings = RunSettings(revolutions=turns, output_every=math.radians(every))
    result = at_the_cam(run_batch([case], settings), [case])
    assert result.status[0] == 0
    return result


def _dense_pressure(result, train, radius: np.ndarray) -> np.ndarray:
    """Each turn's largest √(F·E*/(π·w·R')) over ``result``'s samples, R' = ``radius``."""
    e_star = pair_modulus(train.contact_modulus, train.contact_poisson)
    p = np.sqrt(result.cam_force[0] / train.cam_contact_width * e_star / (math.pi * radius))
    turn = np.minimum((result.cam_angle / (2 * math.pi) + 1e-9).astype(int), result.n_turns - 1)
    return np.array([p[turn == k].max() for k in range(result.n_turns)])


def _flat_face_radius(theta: np.ndarray) -> np.ndarray:
    """r_b + h + h″ with h″ by central differences of the lift (step 1e-4 rad)."""
    d = 1e-4

    def h(t):
        return evaluate(CAM, np.mod(t, 2 * math.pi))[0]

    return BASE + h(theta) + (h(theta + d) - 2 * h(theta) + h(theta - d)) / d**2


def _pitch_curvature_radius(pitch: float, s: np.ndarray) -> np.ndarray:
    """The radius of curvature of the pitch curve (pitch + h(s))·(cos s, sin s), taken in
    Cartesian form by central differences along s (step 1e-4 rad)."""
    d = 1e-4

    def point(t):
        r = pitch + evaluate(CAM, np.mod(t, 2 * math.pi))[0]
        return r * np.cos(t), r * np.sin(t)

    (x0, y0), (x1, y1), (x2, y2) = point(s - d), point(s), point(s + d)
    dx, dy = (x2 - x0) / (2 * d), (y2 - y0) / (2 * d)
    ddx, ddy = (x2 - 2 * x1 + x0) / d**2, (y2 - 2 * y1 + y0) / d**2
    return (dx * dx + dy * dy) ** 1.5 / (dx * ddy - dy * ddx)


def test_an_eccentric_disc_gives_its_one_radius():
    """The thesis's harmonic cam is an eccentric disc under a flat face: its radius is
    r_b + h/2 all round, so the pressure over the turn is the one-radius rule's with that
    radius, to rounding. Fails on a copy that takes r_b + h (no h″) or the base radius."""
    lift = 1.0 * INCH
    train = thesis_train().replace(cam_base_radius=BASE, cam_contact_width=WIDTH)
    result = _run(Case(train, harmonic(lift), 6000 * RPM), COARSE)
    disc = thesis_train().replace(cam_curvature_radius=BASE + lift / 2, cam_contact_width=WIDTH)
    expected = contact_law(disc, "cam").pressure(result.max_cam_force_per_rev[0])
    assert_allclose(result.max_cam_pressure_per_rev[0], expected, rtol=1e-12)
    assert np.all(expected > 3e8)


@pytest.mark.parametrize("rpm", [3000.0, 6000.0, 12000.0])
def test_a_flat_face_s_pressure_over_the_turn_against_dense_samples(rpm):
    """A flat face on a polydyne: at 1° samples the pressure is the dense evaluation's to
    0.2 % in every turn (measured: 0.07 % at 6000 rpm). The nose's radius with the turn's
    largest force, the rule this replaces, reads 2.3 times too much at 6000 rpm (the largest
    force falls on a flank); at 3000 rpm the spring's force peaks at the nose and the two
    agree within 10 %. Fails on a copy that keeps the nose's radius."""
    train = thesis_train().replace(cam_base_radius=BASE, cam_contact_width=WIDTH)
    case = Case(train, CAM, rpm * RPM)
    coarse, dense = _run(case, COARSE), _run(case, DENSE)
    truth = _dense_pressure(dense, train, _flat_face_radius(dense.cam_angle))
    assert_allclose(coarse.max_cam_pressure_per_rev[0], truth, rtol=2e-3)
    nose = _flat_face_radius(np.radians(np.arange(0.0, 360.0, 0.01))).min()
    one_radius = contact_law(train.replace(cam_base_radius=math.nan, cam_curvature_radius=nose),
                             "cam").pressure(coarse.max_cam_force_per_rev[0])  # fmt: skip
    if rpm >= 6000.0:
        assert np.all(one_radius > 1.5 * truth)
    else:
        assert_allclose(one_radius, truth, rtol=0.1)


def test_a_roller_s_pressure_against_its_pitch_curve():
    """A translating roller (0.5 in) on the polydyne: R' = ρ·r/(ρ + r), ρ the cam surface's
    radius, its pitch curve's less r; the dense evaluation takes the pitch curve's curvature
    in Cartesian form. Agrees to 0.2 %."""
    roller = 0.5 * INCH
    train = thesis_train().replace(
        cam_base_radius=BASE, cam_contact_width=WIDTH, cam_roller_radius=roller
    )
    case = Case(train, CAM, 9000 * RPM)
    coarse, dense = _run(case, COARSE), _run(case, DENSE)
    rho = _pitch_curvature_radius(BASE + roller, dense.cam_angle) - roller
    truth = _dense_pressure(dense, train, rho * roller / (rho + roller))
    assert_allclose(coarse.max_cam_pressure_per_rev[0], truth, rtol=2e-3)


def _finger_contact(train, theta: float, raised: float = 0.0) -> float:
    """The profile angle s of a finger's roller's centre at cam angle ``theta``, placed here:
    the centre a from the pivot (at rest, or ``raised`` [m] above it) at lever angle α,
    s = ψ₀ + θ − (its direction from the cam's centre, which stays where it is at rest), and
    α where its distance from the cam's centre is the pitch radius R + h(s) (Brent's method
    about the rest angle)."""
    a, alpha0, offset = train.pivot_to_roller, train.lever_rest_angle, train.cam_offset
    pitch = train.cam_base_radius + train.cam_roller_radius
    rest = a * np.array([math.cos(alpha0), math.sin(alpha0)])
    c = rest + np.array([offset, math.sqrt(pitch * pitch - offset * offset)])
    psi0 = math.atan2(rest[1] - c[1], rest[0] - c[0])

    def place(alpha: float) -> tuple[float, float]:
        d = np.array([a * math.cos(alpha), raised + a * math.sin(alpha)]) - c
        s = psi0 + theta - math.atan2(d[1], d[0])
        return float(np.hypot(*d) - pitch - evaluate(CAM, np.array([s % (2 * math.pi)]))[0][0]), s

    alpha = brentq(lambda x: place(x)[0], alpha0 - 0.6, alpha0 + 0.05, xtol=1e-14)
    return place(alpha)[1]


def test_a_finger_s_pressure_where_its_roller_touches():
    """A finger follower's swinging roller touches its cam where a radial roller would at
    another angle s(θ) (the pitch curve's point its centre sits on): the pressure takes the
    cam's radius there, with the roller's normal force. The dense evaluation places the
    roller by Brent's method and takes the pitch curve's curvature in Cartesian form: 0.2 %.
    The radius at each sample is the one placed here to 1e-6. Fails on a copy that takes
    the radius at θ itself (s is up to 1.4° from θ here: the radius is then up to 1.5 %
    off, the pressure 0.26 % at 1000 rpm)."""
    train = valve_train("thesis-1971", {**FINGER, "cam_contact_width": "10 mm"})
    roller, pitch = train.cam_roller_radius, train.cam_base_radius + train.cam_roller_radius

    def radius(theta):
        s = np.array([_finger_contact(train, t) for t in theta])
        rho = _pitch_curvature_radius(pitch, s) - roller
        return rho * roller / (rho + roller)

    case = Case(train, CAM, 3000 * RPM)
    coarse, dense = _run(case, COARSE, turns=1), _run(case, 0.1, turns=1)
    assert_allclose(coarse.cam_contact_radius[0], radius(coarse.cam_angle), rtol=1e-6)
    truth = _dense_pressure(dense, train, radius(dense.cam_angle))
    assert_allclose(coarse.max_cam_pressure_per_rev[0], truth, rtol=2e-3)


def test_a_finger_s_contact_radius_on_each_turn_s_raised_pivot():
    """A finger whose pivot's lash adjuster starts 0.3 mm out (and moves) runs each turn on
    its pivot raised by the turn's starting extension (``engine.lash_adjuster``): its roller
    touches the cam where the raised pivot places it, and the radius at each sample is the
    one placed here with the pivot raised by its turn's extension, to 1e-6. Fails on a copy
    that places the roller with the pivot at rest (1.2e-3 off here)."""
    from campipe.engine.plunger import EXTENSION

    hla = {
        "hla_stiffness": "20000 N/mm", "hla_leak_down": "2000 N*s/mm", "hla_check_force": "25 N",
        "hla_pump_up": "20 N*s/mm", "hla_travel": "1 mm", "hla_extension": "0.3 mm",
        "lash": "0.15 mm",
    }  # fmt: skip
    train = valve_train("thesis-1971", {**FINGER, "cam_contact_width": "10 mm", **hla})
    roller, pitch = train.cam_roller_radius, train.cam_base_radius + train.cam_roller_radius
    result = _run(Case(train, CAM, 1000 * RPM), 5.0, turns=3)
    extension = result.lash_adjuster[0, :, EXTENSION]
    assert extension[0] == pytest.approx(3e-4) and np.all(np.abs(np.diff(extension)) > 1e-6)
    theta = np.asarray(result.cam_angle)
    for k in range(3):
        turn = (theta >= 2 * math.pi * k) & (theta < 2 * math.pi * (k + 1))
        s = np.array([_finger_contact(train, t, extension[k]) for t in theta[turn]])
        rho = _pitch_curvature_radius(pitch, s) - roller
        assert_allclose(result.cam_contact_radius[0, turn], rho * roller / (rho + roller), 1e-6)


def test_an_undercut_cam_has_no_pressure():
    """Where no cam makes the lift (a radius of curvature below 0 under a flat face) the
    pressure is not a number: the run's notes say why (``campipe.study.spec.notes``)."""
    steep = polydyne("4567", 0.5 * INCH, math.radians(70), math.radians(20), math.radians(70))
    train = thesis_train().replace(cam_base_radius=BASE, cam_contact_width=WIDTH)
    result = _run(Case(train, steep, 3000 * RPM), COARSE)
    assert np.all(np.isnan(result.max_cam_pressure_per_rev[0]))
    assert np.all(result.max_cam_force_per_rev[0] > 0.0)


def test_one_radius_with_the_cam_s_shape_is_refused():
    """``cam_curvature_radius`` with ``cam_base_radius`` and a line contact would be unused:
    refused, naming it and the fix."""
    with pytest.raises(ModelParameterError, match="cam_curvature_radius.*leave") as info:
        valve_train(
            "thesis-1971",
            {"cam_base_radius": "19 mm", "cam_contact_width": "12 mm",
             "cam_curvature_radius": "8 mm"},
        )  # fmt: skip
    assert info.value.key == "cam_curvature_radius"


def test_a_study_s_archive_takes_the_pressure_over_the_turn(tmp_path):
    """A study that records the pressure (``record: [contact_pressure]``) archives the same
    turn's pressure as the engine's result read at the cam: the study asks for the cam's
    radii only where the pressure is recorded (a finger's cost 23 ms a batch). Broken copy:
    the study not asking (the one-radius rule: NaN without ``cam_curvature_radius``)."""
    import xarray as xr

    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    spec = tmp_path / "p.yaml"
    spec.write_text(
        "name: p\nmodel: {preset: thesis-1971, cam_base_radius: 0.75 in, "
        "cam_contact_width: 0.5 in}\n"
        "profile: {kind: polydyne-4567, lift: 0.4 in, rise: 110 deg, dwell: 0 deg, "
        "fall: 110 deg}\nspeed: 6000 rpm\n"
        "run: {revolutions: 2, output_every: 1 deg, record: [contact_pressure]}\n"
    )
    study = load_study(spec)
    run_study(study, tmp_path / "p.nc", scheduler="synchronous")
    case = study.cases[0].case
    direct = _run(case, COARSE).max_cam_pressure_per_rev[0]
    with xr.open_dataset(tmp_path / "p.nc") as ds:
        assert_allclose(ds.max_cam_pressure_by_rev.values[0], direct, rtol=1e-12)
