"""Lever layouts (finger follower, centre-pivot rocker): their kinematics against a hand
calculation of the geometry written here, their chain against its closed forms, the engine's
valve lift at a crawl against the kinematic lift, their refusals."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import ModelParameterError, system_matrices, valve_train
from campipe.model.levers import kinematic_state, lever_of
from campipe.profiles import evaluate, harmonic
from campipe.profiles.levers import cam_kinematics, is_valve_side, valve_side

RPM = 2.0 * math.pi / 60.0
A, B, RB, RR, ALPHA0, OFFSET = 0.030, 0.045, 0.018, 0.009, math.radians(5.0), 0.004
J, MR, MV, KL, KS, RATE, PRELOAD = 40e-6, 0.010, 0.060, 15e6, 60e6, 35e3, 220.0
LIFT = 0.006  # the harmonic cam's lift [m]
FINGER = {
    "layout": "finger-follower",
    "pivot_to_roller": "30 mm",
    "pivot_to_pallet": "45 mm",
    "cam_base_radius": "18 mm",
    "cam_roller_radius": "9 mm",
    "lever_rest_angle": "5 deg",
    "cam_offset": "4 mm",
    "lever_inertia": "40 kg*mm**2",
    "roller_mass": "10 g",
    "valve_mass": "60 g",
    "lever_stiffness": "15 N/um",
    "stem_stiffness": "60 N/um",
    "spring_rate": "35 N/mm",
    "spring_preload": "220 N",
    "damping_ratios": [0.01],
}


def lever(**changes):
    return valve_train("thesis-1971", {**FINGER, **changes})


def hand_kinematics(theta: float, side: float = 1.0) -> tuple[float, float]:
    """(valve lift [m], lever ratio [-]) of the finger (side +1) or the rocker (−1) at cam
    angle ``theta``, worked out here in polar coordinates about the cam's centre: the roller's
    centre C(α) = side·a·(cos α, sin α) must sit at the pitch radius R + h(s) of the cam
    direction it lies in, s = ψ₀ + θ − (direction of C − c); solved for the lever angle α by
    Brent's method. The ratio is dv/dα over the roller's normal approach, the radial gap's
    rate times the pressure angle's cosine ρ/√(ρ² + ρ'²)."""
    R = RB + RR
    rest = side * A * np.array([math.cos(ALPHA0), math.sin(ALPHA0)])
    c = rest + np.array([OFFSET, side * math.sqrt(R * R - OFFSET * OFFSET)])
    psi0 = math.atan2(rest[1] - c[1], rest[0] - c[0])
    cam = harmonic(LIFT)

    def gap(alpha: float) -> float:
        d = side * A * np.array([math.cos(alpha), math.sin(alpha)]) - c
        s = psi0 + theta - math.atan2(d[1], d[0])
        return float(np.hypot(*d) - (R + evaluate(cam, s)[0]))

    alpha = brentq(gap, ALPHA0 - 0.6, ALPHA0 + 0.05, xtol=1e-15)
    d = side * A * np.array([math.cos(alpha), math.sin(alpha)]) - c
    s = psi0 + theta - math.atan2(d[1], d[0])
    h, dh, _ = evaluate(cam, s)
    rho = R + h
    eps = 1e-7
    dgap = (gap(alpha + eps) - gap(alpha - eps)) / (2 * eps)
    ratio = B * math.cos(alpha) / abs(dgap * rho / math.hypot(rho, dh))
    return B * (math.sin(ALPHA0) - math.sin(alpha)), ratio


@pytest.mark.parametrize("side, layout", [(1.0, "finger-follower"), (-1.0, "centre-pivot-rocker")])
def test_kinematic_lift_and_ratio_against_a_hand_calculation(side, layout):
    """At cam angles over the turn, the valve lift and the lever ratio equal the polar-
    coordinate calculation above; on the base circle (90°) the ratio is the closed form
    b·R·cos α₀/(a·|e·sin α₀ − d·cos α₀|), d = √(R² − e²). Fails on a copy that takes the
    valve lift at the roller (a·…), that turns the cam clockwise, or that takes the ratio
    along the cam's radius instead of the contact normal."""
    train = lever(layout=layout)
    angles = np.radians([0.0, 45.0, 90.0, 150.0, 200.0, 250.0, 270.0, 300.0])
    state = cam_kinematics(harmonic(LIFT), train, angles)
    expected = np.array([hand_kinematics(t, side) for t in angles])
    assert_allclose(state.valve_lift, expected[:, 0], atol=1e-12)
    assert_allclose(state.ratio, expected[:, 1], rtol=1e-6)
    R = RB + RR
    d = math.sqrt(R * R - OFFSET * OFFSET)
    normal = abs(side * OFFSET * math.sin(ALPHA0) - d * math.cos(ALPHA0))
    rest = B * R * math.cos(ALPHA0) / (A * normal)
    assert state.valve_lift[2] == pytest.approx(0.0, abs=1e-15)
    assert state.ratio[2] == pytest.approx(rest, rel=1e-12)
    assert state.valve_lift.max() > 1.4 * LIFT  # about b/a of the cam's


def _whole_grid_contact(lev, lift, theta: np.ndarray) -> np.ndarray:
    """The roller's contact angle as first written: every point of the bracketing grid
    looked at, sixty bisections."""
    from campipe.model import levers

    offsets = np.arange(-1.0, 1.0 + 0.005, 0.01)
    s = theta[:, None] + offsets[None, :]

    def f(s_, th):
        p = levers._pitch_point(lev, lift, s_, th)
        return np.einsum("...i,...i->...", p, p) - lev.roller_arm**2

    g = f(s, np.broadcast_to(theta[:, None], s.shape))
    change = np.sign(g[:, :-1]) * np.sign(g[:, 1:]) <= 0.0
    j = np.argmin(np.where(change, np.abs(offsets[:-1] + 0.005), np.inf), axis=1)
    lo = theta + offsets[j]
    hi, f_lo = lo + 0.01, f(lo, theta)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = f(mid, theta)
        left = np.sign(f_mid) == np.sign(f_lo)
        lo, f_lo, hi = np.where(left, mid, lo), np.where(left, f_mid, f_lo), np.where(left, hi, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("near", [1, 2, 5])
@pytest.mark.parametrize("layout", ["finger-follower", "centre-pivot-rocker"])
def test_the_contact_search_is_the_whole_grid_s_bit_for_bit(layout, near, monkeypatch):
    """The contact's search looks at the grid's points nearest s = θ first and bisects each
    bracket only while it moves (three times faster on a finger's turn, which a lash
    adjuster derives again every turn): the contact angles over the turn, the pivot raised
    too, are those of the whole grid and sixty bisections, bit for bit, however few points
    are looked at first (one or two on either side: the whole grid at some angles).
    Broken copies: the nearest change of the near points taken without the whole grid where
    they bracket none (refused: "cannot reach the cam"); a bracket dropped from the
    bisection while it still moves (differs from the first bits on)."""
    import dataclasses

    from campipe.model import levers

    monkeypatch.setattr(levers, "SEARCH_NEAR", near)
    cam = harmonic(LIFT)
    lift = lambda s: evaluate(cam, s)[:2]  # noqa: E731
    theta = np.linspace(0.0, 2.0 * math.pi, 2001)
    for height in (0.0, 2e-4):
        lev = dataclasses.replace(lever_of(lever(layout=layout)), pivot_height=height)
        found = levers._contact_angle(lev, lift, theta)
        assert np.array_equal(found, _whole_grid_contact(lev, lift, theta))
    assert np.abs(found - theta).max() > 0.02  # beyond two points on either side: the fallback


def test_the_lever_s_chain_is_its_reduced_mass_and_series_link():
    """The chain's masses are (J + m_r·a²)/(b·cos α₀)² and the valve's, its link the lever's
    and the stem's stiffness in series; its free frequencies are those of that two-mass chain
    on the valve spring, solved here. Fails on a copy that reduces at b instead of b·cos α₀,
    or adds the stiffnesses in parallel."""
    train = lever()
    m1 = (J + MR * A * A) / (B * math.cos(ALPHA0)) ** 2
    k = 1.0 / (1.0 / KL + 1.0 / KS)
    assert_allclose(train.masses, [m1, MV], rtol=1e-12)
    assert_allclose(train.stiffnesses, [k], rtol=1e-12)
    sm = system_matrices(train)
    a, b, cc = m1 * MV, -(m1 * (k + RATE) + MV * k), k * RATE
    roots = np.sqrt((-b + np.array([-1, 1]) * math.sqrt(b * b - 4 * a * cc)) / (2 * a))
    used = [0, 6]
    lam = np.linalg.eigvals(
        np.linalg.solve(sm.mass[np.ix_(used, used)], sm.stiffness[np.ix_(used, used)])
    )
    assert_allclose(np.sort(np.sqrt(lam.real)), roots, rtol=1e-9)


def test_at_a_crawl_the_valve_follows_the_kinematic_lift():
    """At 100 rpm the valve lift is the kinematic lift (the hand calculation's) times the
    chain's static give k/(k + ks), to 1e-6 of the lift: what remains is the damping's and
    the inertia's, 3e-7. The archive's cam lift is the kinematic valve lift. Fails on a copy
    that drives the chain with the cam's own lift, or that drops the lever's kinematics from
    a case made by dataclasses.replace (a profile derived twice)."""
    train = lever()
    case = Case(train, harmonic(LIFT), 100 * RPM)
    assert is_valve_side(case.profile)
    assert valve_side(case.profile, train) is case.profile
    run = run_batch([case], RunSettings(revolutions=2, output_every=math.radians(10)))
    assert run.status[0] == 0
    kin = np.array([hand_kinematics(t)[0] for t in run.cam_angle])
    k = 1.0 / (1.0 / KL + 1.0 / KS)
    assert_allclose(run.cam_lift[0], kin, atol=1e-11)
    assert_allclose(run.valve_lift[0], kin * k / (k + RATE), atol=1e-6 * kin.max())


def test_the_rocker_is_the_finger_turned_half_a_turn():
    """A centre-pivot rocker with the finger's numbers, its cam offset the other way (the
    offset runs towards the pallet, which the half turn puts on the other side), is the finger
    turned by 180° about the pivot (cam under the roller, the valve under the other arm, the
    cam still counter-clockwise): the same valve lift over the turn; and a rocker may have its
    cam above its roller."""
    theta = np.linspace(0.0, 2 * math.pi, 37)
    finger = cam_kinematics(harmonic(LIFT), lever(), theta)
    rocker = cam_kinematics(
        harmonic(LIFT), lever(layout="centre-pivot-rocker", cam_offset="-4 mm"), theta
    )
    assert_allclose(rocker.valve_lift, finger.valve_lift, atol=1e-12)
    long_arm = lever(layout="centre-pivot-rocker", pivot_to_roller="50 mm")
    state = kinematic_state(lever_of(long_arm), lambda s: evaluate(harmonic(LIFT), s)[:2], theta)
    assert state.ratio.max() < 1.0 and state.valve_lift.max() > 0.8 * LIFT


@pytest.mark.parametrize(
    "changes, key",
    [
        ({"lever_inertia": "none"}, "model.lever_inertia"),
        ({"pivot_to_roller": "50 mm"}, "model.pivot_to_roller"),
        ({"cam_offset": "30 mm"}, "model.cam_offset"),
        ({"lever_rest_angle": "70 deg"}, "model.lever_rest_angle"),
        ({"cam_roller_radius": "0 mm"}, "model.cam_roller_radius"),
        ({"masses": ["1 kg", "1 kg"]}, "model.masses"),
    ],
)
def test_lever_refusals_name_their_keys(changes, key):
    """Each refusal names its key: a needed key left out, a finger whose roller is beyond its
    pallet, a cam offset beyond the pitch circle, a rest angle beyond 60°, a flat follower, a
    lumped chain's key. Fails on a copy that builds the chain with a
    NaN mass."""
    with pytest.raises(ModelParameterError) as info:
        valve_train("thesis-1971", {**FINGER, **changes}, key_prefix="model.")
    assert info.value.key == key


def test_a_cam_offset_s_refusal_gives_the_offset_and_its_bound():
    """The cam's offset beyond 0.9 of the pitch radius is refused with the offset found and
    the bound, in mm: FINGER's 18 + 9 mm pitch radius bounds it at ±24.3 mm. Broken copy:
    the message without numbers (a rocker engineer's refusal gave neither)."""
    with pytest.raises(ModelParameterError, match=r"\(30 mm\).*±24\.3 mm"):
        valve_train("thesis-1971", {**FINGER, "cam_offset": "30 mm"}, key_prefix="model.")


@pytest.mark.parametrize("value", [0.1, "0.1", 10])
def test_a_rest_angle_needs_an_angle_s_units(value):
    """A bare number for ``lever_rest_angle`` is refused (pint's radian is dimensionless: it
    was read as 0.1 rad, 5.7°), and a bound is named in degrees, the key's units (it read
    "at most 1.0472 deg", radians). Broken copies: the angle parsed as any quantity; the
    range's bounds shown in SI with the degree's name."""
    with pytest.raises(ModelParameterError, match=r"found .*(0\.1|10).*deg") as info:
        valve_train("thesis-1971", {**FINGER, "lever_rest_angle": value}, key_prefix="model.")
    assert info.value.key == "model.lever_rest_angle"
    with pytest.raises(ModelParameterError, match="at least -60 deg and at most 60 deg"):
        valve_train("thesis-1971", {**FINGER, "lever_rest_angle": "70 deg"})
    train = valve_train("thesis-1971", {**FINGER, "lever_rest_angle": "0.1 rad"})
    assert train.lever_rest_angle == pytest.approx(0.1)


def test_a_lever_key_on_another_layout_is_refused():
    """``pivot_to_roller`` on the thesis's train names the key and the layouts it belongs to.
    Fails on a copy that lets it through unread."""
    with pytest.raises(ModelParameterError, match="finger-follower") as info:
        valve_train("thesis-1971", {"pivot_to_roller": "30 mm"}, key_prefix="model.")
    assert info.value.key == "model.pivot_to_roller"


def test_a_spec_s_seat_is_checked_against_the_kinematic_valve_lift():
    """A finger's seat at 7 mm, above its cam's lift (6.5 mm) yet below its valve's (about
    b/a = 1.5 times it), is a seat the valve leaves; 10 mm is refused at ``seat``, naming the
    valve's full lift. Fails on a copy that compares the seat with the cam's lift (a chain's
    ratio of 1)."""
    from pathlib import Path

    from campipe.study import SpecError, load_study

    study = Path(__file__).parents[2] / "studies" / "finger-follower.yaml"
    case = load_study(study, {"model.lash": "none", "seat": "7 mm"}).cases[0].case
    assert case.seat == pytest.approx(0.007)
    with pytest.raises(SpecError, match="full valve lift") as info:
        load_study(study, {"model.lash": "none", "seat": "10 mm"})
    assert [p.key for p in info.value.problems] == ["seat"]


def test_the_plot_s_kinematic_overlay_reads_a_chain_s_cam_lift_as_its_valve_s():
    """The histories figure's kinematic lift multiplies the archive's cam lift by the train's
    ratio: 1.5 for the thesis's rocker (1.5 in / 1.0 in), 1 for a finger (its archive's cam
    lift is already the kinematic valve lift). Fails on a copy that reads a chain's ratio off
    the thesis's rocker coordinate q4 (a placeholder: 0)."""
    from pathlib import Path

    from campipe.plot.kinematics import rocker_ratios

    text = (Path(__file__).parents[2] / "studies" / "finger-follower.yaml").read_text()
    columns = {"spring_rate": np.array([35e3, 40e3])}
    assert_allclose(rocker_ratios({"spec": text}, columns)[0], [1.0, 1.0])
    thesis = rocker_ratios({"spec": "model: {preset: thesis-1971}"}, {"lash": np.array([0.0])})[0]
    assert thesis[0] == pytest.approx(1.5, rel=1e-9)


def test_the_thesis_s_members_take_their_masses_given_directly():
    """``pushrod_mass`` given as the thesis's own ρ·A·L (0.283 lbf/in³ × π·0.3²/4 in² × 9 in,
    worked out here) leaves the matrices as they are; given at twice that, the pushrod's
    consistent mass (m/6)·[[2, 1], [1, 2]] doubles and nothing else changes; on a chain it is
    refused, naming the key. Fails on a copy that reads the given mass per member, not per
    element, once the member is divided in two."""
    from campipe.constants import INCH, LBF, STANDARD_GRAVITY
    from campipe.model import thesis_train

    rho_a_l = 0.283 * LBF / INCH**3 / STANDARD_GRAVITY * math.pi * (0.3 * INCH) ** 2 / 4 * 9 * INCH
    base = system_matrices(thesis_train())
    same = system_matrices(valve_train("thesis-1971", {"pushrod_mass": f"{rho_a_l!r} kg"}))
    assert_allclose(same.mass, base.mass, rtol=1e-12, atol=1e-15)
    double = system_matrices(valve_train("thesis-1971", {"pushrod_mass": f"{2 * rho_a_l!r} kg"}))
    added = double.mass - base.mass
    assert_allclose(added[:2, :2], rho_a_l / 6 * np.array([[2.0, -1.0], [-1.0, 2.0]]), rtol=1e-9)
    added[:2, :2] = 0.0
    assert np.abs(added).max() < 1e-15
    halves = {"pushrod_mass": f"{rho_a_l!r} kg", "pushrod_elements": 2}
    split = system_matrices(valve_train("thesis-1971", halves)).mass
    plain = system_matrices(valve_train("thesis-1971", {"pushrod_elements": 2})).mass
    assert_allclose(split, plain, rtol=1e-12, atol=1e-15)
    with pytest.raises(ModelParameterError) as info:
        valve_train("thesis-1971", {**FINGER, "pushrod_mass": "0.1 kg"}, key_prefix="model.")
    assert info.value.key == "model.pushrod_mass"


def test_the_recorded_cam_normal_force_is_the_cam_force_through_the_lever_ratio(tmp_path):
    """``run.record: [cam_normal_force]`` stores the roller's normal force on the cam: the
    engine's valve-side cam force times the lever ratio of the hand calculation at each
    sample's cam angle, which the archive's cam force now is too. Fails on a copy that
    divides by the ratio, or records the valve-side force unchanged."""
    import xarray as xr
    import yaml

    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    spec = {
        "name": "finger-normal-force",
        "model": FINGER,
        "profile": {"kind": "harmonic", "lift": "6 mm"},
        "speed": "1000 rpm",
        "run": {"revolutions": 1, "output_every": "15 deg", "record": ["cam_normal_force"]},
    }
    path = tmp_path / "finger.yaml"
    path.write_text(yaml.safe_dump(spec))
    run_study(load_study(path), tmp_path / "finger.nc", scheduler="synchronous")
    ds = xr.load_dataset(tmp_path / "finger.nc")
    theta = np.radians(ds["cam_angle"].values)
    ratio = np.array([hand_kinematics(t)[1] for t in theta])
    case = load_study(path).cases[0]
    force = run_batch([case.case], case.settings).cam_force[0]  # the valve side's
    assert force.min() > 100.0  # it follows the cam
    assert_allclose(ds["cam_normal_force"].values[0], force * ratio, rtol=1e-6)
    np.testing.assert_array_equal(ds["cam_force"].values, ds["cam_normal_force"].values)


def test_a_case_copied_with_another_train_drives_it_with_its_own_kinematics():
    """A case's excitation follows its train: copied with another finger (a longer pallet
    arm) it is that finger's kinematic lift, copied with the thesis's train the cam's own
    lift. Fails on a copy that keeps the first finger's derived lift for any train."""
    import dataclasses

    from campipe.model import thesis_train

    cam = harmonic(LIFT)
    case = Case(lever(), cam, 100 * RPM)
    longer = dataclasses.replace(case, train=lever(pivot_to_pallet="54 mm"))
    theta = np.radians([200.0, 270.0])
    lift = evaluate(longer.profile, theta)[0]
    assert_allclose(lift, 54 / 45 * evaluate(case.profile, theta)[0], rtol=1e-9)
    back = dataclasses.replace(case, train=thesis_train()).profile
    assert not is_valve_side(back) and back.label == cam.label
    assert_allclose(evaluate(back, theta)[0], evaluate(cam, theta)[0], rtol=0)


def test_a_cam_that_swings_the_lever_past_75_degrees_is_refused():
    """A 40 mm harmonic cam under a 30 mm finger arm would swing it past the vertical (its
    valve lift turning back while the cam still lifts): a case refuses it, and a spec names
    ``model.pivot_to_roller``; 25 mm (52° of swing) is a lever still. Fails on a copy that
    follows the lever past the vertical, where b·(sin α₀ − sin α) no longer grows with the
    cam."""
    from pathlib import Path

    from campipe.study import SpecError, load_study

    level = lever(cam_offset="0 mm", lever_rest_angle="0 deg")
    assert is_valve_side(Case(level, harmonic(0.025), 100 * RPM).profile)
    with pytest.raises(ModelParameterError, match="swings the lever") as info:
        Case(level, harmonic(0.040), 100 * RPM)
    assert info.value.key == "pivot_to_roller"
    study = Path(__file__).parents[2] / "studies" / "finger-follower.yaml"
    with pytest.raises(SpecError) as refused:
        load_study(study, {"profile.lift": "40 mm"})
    assert [p.key for p in refused.value.problems] == ["model.pivot_to_roller"]
