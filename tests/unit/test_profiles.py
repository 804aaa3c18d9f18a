"""Cam profiles against closed forms: the harmonic cam, polydyne rises, tables and defects."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as npoly
from numpy.testing import assert_allclose, assert_array_equal
from scipy.interpolate import CubicSpline

from campipe.profiles import (
    bump,
    evaluate,
    evaluate_packed,
    flat,
    harmonic,
    max_lift,
    min_lift,
    pack,
    polydyne,
    shift_polynomial,
    split,
    table,
)
from campipe.profiles.pieces import piece_index, wrap

INCH = 0.0254
H = 1.0 * INCH  # the thesis's lift, 1 in peak to peak
TWO_PI = 2.0 * math.pi
deg = np.radians


def harmonic_reference(theta, h=H):
    """lift = h/2·(1 − sin θ) and its derivatives, closed form."""
    return 0.5 * h * (1 - np.sin(theta)), -0.5 * h * np.cos(theta), 0.5 * h * np.sin(theta)


def third_derivative(profile, theta, side="right"):
    """d³lift/dθ³ from the piece coefficients (polynomial part plus −a·cos θ + b·sin θ)."""
    t = wrap(theta, side)
    i = piece_index(profile, t, side)
    x = t - profile.breaks[i]
    poly = npoly.polyval(x, npoly.polyder(profile.poly[i], 3))
    a, b = profile.trig[i]
    return poly - a * np.cos(t) + b * np.sin(t)


#: Round-off of a re-expanded degree-7 piece in lift, velocity and acceleration [m, m/rad, m/rad²]:
#: eps × Σ k!/(k − j)!·|pₖ| for the 4567 polynomial is ≈ 5e-14, 3e-13, 1e-12 times h/βʲ (β ≥ 45°).
REEXPANSION_ATOL = (1e-13 * H, 1e-12 * H, 1e-11 * H)


def assert_same_profile(got, want):
    """Lift, velocity and acceleration agree to the round-off of re-expanded pieces."""
    for g, w, atol in zip(got, want, REEXPANSION_ATOL, strict=True):
        assert_allclose(g, w, rtol=0, atol=atol)


def assert_continuous(profile, theta, scales, rtol=1e-12):
    """Left and right limits of lift, velocity and acceleration agree at ``theta``."""
    left = evaluate(profile, theta, side="left")
    right = evaluate(profile, theta)
    for order, (lv, rv, scale) in enumerate(zip(left, right, scales, strict=True)):
        assert abs(lv - rv) <= rtol * scale, f"derivative {order} jumps at {theta} rad"


# --------------------------------------------------------------------------- harmonic


def test_harmonic_representation():
    p = harmonic(H)
    assert_array_equal(p.breaks, [0.0, TWO_PI])
    assert p.poly[0, 0] == 0.5 * H
    assert_array_equal(p.poly[0, 1:], 0.0)
    assert_array_equal(p.trig[0], [-0.5 * H, 0.0])
    assert p.label == "harmonic 1 in"


def test_harmonic_lift_at_base_nose_and_mid():
    lift, _, _ = evaluate(harmonic(H), deg([0.0, 90.0, 270.0, 360.0, -90.0, 450.0]))
    assert_allclose(lift, [H / 2, 0.0, H, H / 2, H, 0.0], rtol=0, atol=1e-17)


def test_harmonic_derivatives_closed_form():
    theta = np.linspace(-7.0, 14.0, 301)
    for got, want in zip(evaluate(harmonic(H), theta), harmonic_reference(theta), strict=True):
        assert_allclose(got, want, rtol=0, atol=1e-15 * H)


def test_evaluate_keeps_the_input_shape():
    p = harmonic(H)
    scalar = evaluate(p, 1.0)
    assert all(np.shape(v) == () for v in scalar)
    grid = np.linspace(0, 6, 12).reshape(3, 4)
    lift, velocity, acceleration = evaluate(p, grid)
    assert lift.shape == velocity.shape == acceleration.shape == (3, 4)
    assert_allclose(lift, harmonic_reference(grid)[0], atol=1e-17)
    assert_allclose(float(scalar[0]), harmonic_reference(1.0)[0], atol=1e-17)


@pytest.mark.parametrize("bad", [0.0, -0.01, math.nan, math.inf])
def test_harmonic_refuses_bad_lift(bad):
    with pytest.raises(ValueError, match="lift"):
        harmonic(bad)


# --------------------------------------------------------------------------- polydyne

SCHEDULES = {"90/90/90/90": deg([90.0, 90.0, 90.0]), "45/45/225/45": deg([45.0, 45.0, 225.0])}


@pytest.mark.parametrize("kind", ["345", "4567"])
@pytest.mark.parametrize("schedule", list(SCHEDULES))
def test_polydyne_continuous_to_acceleration_at_every_break(kind, schedule):
    rise, dwell, fall = SCHEDULES[schedule]
    p = polydyne(kind, H, rise, dwell, fall)
    assert p.n_pieces == 4
    assert_allclose(p.breaks, np.cumsum([0.0, rise, dwell, fall, TWO_PI - rise - dwell - fall]))
    beta = min(rise, fall)
    for b in p.breaks:
        assert_continuous(p, b, (H, H / beta, H / beta**2))


@pytest.mark.parametrize("schedule", list(SCHEDULES))
def test_polydyne_4567_is_jerk_continuous_and_345_is_not(schedule):
    rise, dwell, fall = SCHEDULES[schedule]
    ends = [0.0, rise, rise + dwell, rise + dwell + fall]
    p7 = polydyne("4567", H, rise, dwell, fall)
    p5 = polydyne("345", H, rise, dwell, fall)
    for b in ends:
        assert abs(third_derivative(p7, b, "left")) <= 1e-12 * H / rise**3
        assert abs(third_derivative(p7, b)) <= 1e-12 * H / rise**3
    # the 345 rise starts with jerk P'''(0)·h/β³ = 60·h/β³ against 0 on the base circle
    assert_allclose(third_derivative(p5, 0.0), 60.0 * H / rise**3, rtol=1e-12)
    assert third_derivative(p5, 0.0, "left") == 0.0


@pytest.mark.parametrize("kind", ["345", "4567"])
def test_polydyne_dwells_and_end_values(kind):
    rise, dwell, fall = SCHEDULES["90/90/90/90"]
    p = polydyne(kind, H, rise, dwell, fall)
    lift, velocity, acceleration = evaluate(p, np.linspace(rise, rise + dwell, 50))
    assert_allclose(lift, H, rtol=1e-14)
    assert_allclose(velocity, 0.0, atol=1e-14 * H)
    assert_allclose(acceleration, 0.0, atol=1e-12 * H)
    lift, velocity, _ = evaluate(p, np.linspace(rise + dwell + fall, TWO_PI, 50))
    assert_array_equal(lift, 0.0)
    assert_array_equal(velocity, 0.0)
    # mid-rise is half lift for both polynomials (P(1/2) = 1/2 by symmetry)
    assert_allclose(evaluate(p, rise / 2)[0], H / 2, rtol=1e-14)


def test_polydyne_345_peak_acceleration_closed_form():
    rise, dwell, fall = SCHEDULES["90/90/90/90"]
    p = polydyne("345", H, rise, dwell, fall)
    peak = 10.0 * math.sqrt(3.0) / 3.0 * H / rise**2  # P'' = 60u − 180u² + 120u³ at its max
    assert_allclose(peak, 5.7735 * H / rise**2, rtol=1e-5)
    u_star = 0.5 - math.sqrt(3.0) / 6.0
    assert_allclose(evaluate(p, u_star * rise)[2], peak, rtol=1e-12)
    acceleration = evaluate(p, np.linspace(0.0, rise, 20001))[2]
    assert_allclose(acceleration.max(), peak, rtol=1e-7)
    assert acceleration.max() <= peak * (1 + 1e-12)
    assert_allclose(acceleration.min(), -peak, rtol=1e-7)


@pytest.mark.parametrize("kind", ["345", "4567"])
@pytest.mark.parametrize("schedule", list(SCHEDULES))
def test_polydyne_fall_mirrors_the_rise(kind, schedule):
    rise, dwell, fall = SCHEDULES[schedule]
    p = polydyne(kind, H, rise, dwell, fall)
    u = np.linspace(0.0, 1.0, 41)
    up = evaluate(p, (1.0 - u) * rise)
    down = evaluate(p, rise + dwell + u * fall)
    assert_allclose(down[0], up[0], rtol=0, atol=1e-14 * H)
    # lift(rise + dwell + u·γ) = lift((1 − u)·β): velocity scales by −β/γ, acceleration (β/γ)²
    assert_allclose(down[1], -up[1] * rise / fall, rtol=0, atol=1e-13 * H / rise)
    assert_allclose(down[2], up[2] * (rise / fall) ** 2, rtol=0, atol=1e-12 * H / rise**2)


def test_polydyne_full_turn_has_no_base_dwell_and_zero_dwell_no_dwell_piece():
    p = polydyne("4567", H, deg(90.0), deg(180.0), deg(90.0))
    assert p.n_pieces == 3
    assert p.breaks[-1] == TWO_PI
    assert_continuous(p, 0.0, (H, H, H))
    q = polydyne("345", H, deg(90.0), 0.0, deg(90.0))
    assert q.n_pieces == 3
    assert_allclose(q.breaks, deg([0.0, 90.0, 180.0, 360.0]))
    assert_allclose(evaluate(q, deg(90.0))[0], H, rtol=1e-14)
    assert q.label == "polydyne-345 1 in 90/0/90/180 deg"


@pytest.mark.parametrize(
    ("args", "name"),
    [
        (("345", H, 0.0, 1.0, 1.0), "rise"),
        (("345", H, -1.0, 1.0, 1.0), "rise"),
        (("345", H, 1.0, 1.0, 0.0), "fall"),
        (("345", H, 1.0, -0.1, 1.0), "dwell"),
        (("345", H, 3.0, 1.0, 3.0), "rise \\+ dwell \\+ fall"),
        (("345", 0.0, 1.0, 1.0, 1.0), "lift"),
        (("345", -H, 1.0, 1.0, 1.0), "lift"),
        (("345", H, math.nan, 1.0, 1.0), "rise"),
        (("3456", H, 1.0, 1.0, 1.0), "kind"),
    ],
)
def test_polydyne_refuses_bad_arguments(args, name):
    with pytest.raises(ValueError, match=name):
        polydyne(*args)


# --------------------------------------------------------------------------- table


def harmonic_table(start_deg=0.0, step_deg=5.0):
    angles = deg(np.arange(start_deg, 360.0, step_deg))
    return angles, harmonic_reference(angles)[0]


@pytest.mark.parametrize("start_deg", [0.0, 2.5])
def test_table_of_the_harmonic_cam_reproduces_it(start_deg):
    angles, lifts = harmonic_table(start_deg)
    p = table(angles, lifts)
    assert p.breaks[0] == 0.0 and p.breaks[-1] == TWO_PI
    assert_allclose(evaluate(p, angles)[0], lifts, rtol=0, atol=1e-15 * H)
    theta = np.linspace(0.0, TWO_PI, 3601)
    lift, _, acceleration = evaluate(p, theta)
    ref_lift, _, ref_acceleration = harmonic_reference(theta)
    assert np.abs(lift - ref_lift).max() <= 1e-5 * H
    between = deg(np.arange(start_deg, 360.0, 5.0) + 2.5)
    error = np.abs(evaluate(p, between)[2] - harmonic_reference(between)[2])
    assert error.max() <= 0.02 * H / 2


@pytest.mark.parametrize("start_deg", [0.0, 2.5, 17.0])
def test_table_is_continuous_through_the_wrap_and_matches_the_spline(start_deg):
    angles, lifts = harmonic_table(start_deg, step_deg=10.0)
    p = table(angles, lifts)
    for b in p.breaks:
        assert_continuous(p, b, (H, H, H))
    spline = CubicSpline(
        np.append(angles, angles[0] + TWO_PI), np.append(lifts, lifts[0]), bc_type="periodic"
    )
    theta = np.random.default_rng(1).uniform(-TWO_PI, 2 * TWO_PI, 500)
    t = np.mod(theta, TWO_PI)
    t = np.where(t < angles[0], t + TWO_PI, t)
    for order, got in enumerate(evaluate(p, theta)):
        assert_allclose(got, spline(t, order), rtol=0, atol=1e-14 * H)


def test_table_with_nonzero_start_adds_a_break_at_zero():
    angles, lifts = harmonic_table(2.5)
    p = table(angles, lifts)
    assert p.n_pieces == angles.size + 1
    assert_allclose(p.breaks[1:-1], angles, rtol=0, atol=0)
    assert p.label == "table 72 points"


@pytest.mark.parametrize(
    ("angles", "lifts", "message"),
    [
        ([0.0, 1.0, 2.0], [0.0, 1.0, 0.0], "at least 4"),
        ([0.0, 2.0, 1.0, 3.0], [0.0, 1.0, 1.0, 0.0], "increasing"),
        ([0.0, 1.0, 1.0, 3.0], [0.0, 1.0, 1.0, 0.0], "increasing"),
        ([-0.1, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 0.0], r"\[0, 2π\)"),
        ([0.0, 1.0, 2.0, TWO_PI], [0.0, 1.0, 1.0, 0.0], r"\[0, 2π\)"),
        ([0.0, 1.0, 2.0, 3.0], [0.0, math.nan, 1.0, 0.0], "finite"),
        ([0.0, 1.0, math.inf, 3.0], [0.0, 1.0, 1.0, 0.0], "finite"),
        ([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0], "same length"),
    ],
)
def test_table_refuses_bad_tables(angles, lifts, message):
    with pytest.raises(ValueError, match=message):
        table(angles, lifts)


# --------------------------------------------------------------------------- flat

THESIS_FLAT = deg(268.0), deg(272.0)


def test_thesis_flat_on_the_harmonic_nose():
    base = harmonic(H)
    p = flat(base, *THESIS_FLAT)
    assert p.label == "harmonic 1 in + flat 268–272 deg"
    assert_allclose(p.breaks, [0.0, *THESIS_FLAT, TWO_PI], rtol=0, atol=0)
    inside = np.linspace(*THESIS_FLAT, 41)[:-1]
    lift, velocity, acceleration = evaluate(p, inside)
    assert_array_equal(lift, evaluate(base, THESIS_FLAT[0])[0])
    assert_array_equal(velocity, 0.0)
    assert_array_equal(acceleration, 0.0)
    depth = H - evaluate(p, deg(270.0))[0]
    assert abs(depth - 0.5 * (1 - math.cos(deg(2.0))) * INCH) <= 1e-12
    assert round(depth / INCH, 4) == 0.0003


def test_flat_velocity_jumps_exactly_at_its_edges():
    p = flat(harmonic(H), *THESIS_FLAT)
    enter, leave = THESIS_FLAT
    # entering: the cam's velocity on the left, the flat's zero on the right; leaving: reversed
    assert_allclose(evaluate(p, enter, side="left")[1], harmonic_reference(enter)[1], rtol=1e-12)
    assert evaluate(p, enter)[1] == 0.0
    assert evaluate(p, leave, side="left")[1] == 0.0
    assert_allclose(evaluate(p, leave)[1], harmonic_reference(leave)[1], rtol=1e-12)
    # each jump is |h/2·cos 268°| = 0.0349·h/2, while the lift stays continuous (lift(268°) =
    # lift(272°) on the harmonic nose)
    for edge in THESIS_FLAT:
        left, right = evaluate(p, edge, side="left"), evaluate(p, edge)
        assert_allclose(abs(left[1] - right[1]), 0.5 * H * math.sin(deg(2.0)), rtol=1e-12)
        assert abs(left[0] - right[0]) <= 1e-15 * H


def test_flat_leaves_the_rest_unchanged():
    base = harmonic(H)
    p = flat(base, *THESIS_FLAT)
    theta = np.linspace(-TWO_PI, 2 * TWO_PI, 2001)
    outside = ~(
        (np.mod(theta, TWO_PI) >= THESIS_FLAT[0]) & (np.mod(theta, TWO_PI) < THESIS_FLAT[1])
    )
    for got, want in zip(
        evaluate(p, theta[outside]), harmonic_reference(theta[outside]), strict=True
    ):
        assert_allclose(got, want, rtol=0, atol=1e-15 * H)


def test_wrapping_flat_through_zero():
    base = harmonic(H)
    p = flat(base, deg(350.0), deg(10.0))
    assert_allclose(p.breaks, deg([0.0, 10.0, 350.0, 360.0]), rtol=1e-15)
    hold = harmonic_reference(deg(350.0))[0]
    lift, velocity, acceleration = evaluate(p, deg([350.0, 355.0, 0.0, 5.0, 9.99, -5.0, 365.0]))
    assert_allclose(lift, hold, rtol=1e-15)
    assert_array_equal(velocity, 0.0)
    assert_array_equal(acceleration, 0.0)
    outside = deg([10.0, 20.0, 180.0, 349.0])
    assert_allclose(evaluate(p, outside)[0], harmonic_reference(outside)[0], atol=1e-15 * H)
    # the lift jumps at the exit (hold at lift(350°) ≠ lift(10°))
    assert_allclose(evaluate(p, deg(10.0), side="left")[0], hold, rtol=1e-15)
    assert_allclose(evaluate(p, deg(10.0))[0], harmonic_reference(deg(10.0))[0], rtol=1e-14)
    assert p.label == "harmonic 1 in + flat 350–10 deg"


def test_flat_refuses_coinciding_edges():
    with pytest.raises(ValueError, match="coincide"):
        flat(harmonic(H), deg(100.0), deg(460.0))


# --------------------------------------------------------------------------- bump


def bump_reference(theta, center, height, width):
    y = np.mod(theta - center + math.pi, TWO_PI) - math.pi
    u = 2 * y / width
    return np.where(np.abs(u) <= 1.0, height * (1 - u**2) ** 3, 0.0)


@pytest.mark.parametrize("center_deg", [100.0, 2.0, 357.0])
@pytest.mark.parametrize("height", [1e-4, -2e-5])
def test_bump_adds_the_closed_form_and_stays_c2(center_deg, height):
    base = polydyne("4567", H, *SCHEDULES["90/90/90/90"])
    center, width = deg(center_deg), deg(12.0)
    p = bump(base, center, height, width)
    theta = np.linspace(-1.0, 7.5, 3001)
    added = evaluate(p, theta)[0] - evaluate(base, theta)[0]
    assert_allclose(added, bump_reference(theta, center, height, width), rtol=0, atol=1e-13 * H)
    assert_allclose(evaluate(p, center)[0] - evaluate(base, center)[0], height, rtol=1e-12)
    far = np.mod(center + math.pi + np.linspace(-2.0, 2.0, 50), TWO_PI)
    assert_same_profile(evaluate(p, far), evaluate(base, far))
    for edge in (center - width / 2, center + width / 2):
        assert np.any(np.isclose(p.breaks, np.mod(edge, TWO_PI), rtol=0, atol=1e-14))
        assert_continuous(p, edge, (H, H, H))
    for b in p.breaks:
        assert_continuous(p, b, (H, H, H))


def test_defects_apply_in_order():
    base = harmonic(H)
    height, width = 1e-4, deg(10.0)
    bump_then_flat = flat(bump(base, deg(270.0), height, width), *THESIS_FLAT)
    flat_then_bump = bump(flat(base, *THESIS_FLAT), deg(270.0), height, width)
    nose = deg(270.0)
    held = harmonic_reference(THESIS_FLAT[0])[0]
    # the flat holds the bumped lift at 268°: u = 2·(−2°)/10° = −0.4
    assert_allclose(
        evaluate(bump_then_flat, nose)[0], held + height * (1 - 0.4**2) ** 3, rtol=1e-14
    )
    assert_allclose(evaluate(flat_then_bump, nose)[0], held + height, rtol=1e-14)
    assert evaluate(bump_then_flat, nose)[1] == 0.0
    # on the flat only the bump moves: d/dθ h·(1 − u²)³ = −6u(1 − u²)²·h·2/w, u = −0.2 at 269°
    u = -0.2
    want = -6 * u * (1 - u**2) ** 2 * height * 2 / width
    assert_allclose(evaluate(flat_then_bump, deg(269.0))[1], want, rtol=1e-12)


@pytest.mark.parametrize("width", [0.0, -0.1, TWO_PI, 7.0, math.nan])
def test_bump_refuses_bad_width(width):
    with pytest.raises(ValueError, match="width"):
        bump(harmonic(H), 1.0, 1e-4, width)


# --------------------------------------------------------------------------- extremes


def test_max_and_min_lift():
    assert_allclose(max_lift(harmonic(H)), H, rtol=1e-15)
    assert abs(min_lift(harmonic(H))) <= 1e-18
    p = polydyne("345", H, *SCHEDULES["45/45/225/45"])
    assert min_lift(p) == 0.0
    assert_allclose(max_lift(p), H, rtol=1e-15)
    flattened = flat(harmonic(H), *THESIS_FLAT)
    assert_allclose(max_lift(flattened), 0.5 * H * (1 + math.cos(deg(2.0))), rtol=1e-15)
    bumped = bump(harmonic(H), deg(270.0), 1e-4, deg(10.0))
    assert_allclose(max_lift(bumped), H + 1e-4, rtol=1e-14)
    dented = bump(harmonic(H), deg(90.0), -1e-5, deg(10.0))
    assert_allclose(min_lift(dented), -1e-5, rtol=1e-12)


# --------------------------------------------------------------------------- split, shift

coefficient = st.floats(-10.0, 10.0, allow_nan=False)
shift = st.floats(-7.0, 7.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.lists(coefficient, min_size=8, max_size=8), shift, shift)
def test_shift_polynomial_is_a_taylor_shift(coeffs, dx, x):
    shifted = shift_polynomial(coeffs, dx)
    scale = sum(abs(c) * (abs(x) + abs(dx)) ** k for k, c in enumerate(coeffs)) + 1.0
    assert abs(npoly.polyval(x, shifted) - npoly.polyval(x + dx, coeffs)) <= 1e-12 * scale


def test_shift_polynomial_broadcasts_over_pieces():
    coeffs = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 1.0]])
    assert_allclose(shift_polynomial(coeffs, [1.0, -2.0]), [[6.0, 8.0, 3.0], [4.0, -4.0, 1.0]])


PROFILES = [
    harmonic(H),
    polydyne("4567", H, *SCHEDULES["90/90/90/90"]),
    polydyne("345", H, *SCHEDULES["45/45/225/45"]),
    table(*harmonic_table(2.5, 15.0)),
]


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(range(len(PROFILES))), st.floats(-10.0, 20.0, allow_nan=False))
def test_split_leaves_the_profile_unchanged(which, theta):
    p = PROFILES[which]
    q = split(p, theta)
    assert q.n_pieces in (p.n_pieces, p.n_pieces + 1)
    grid = np.concatenate([np.linspace(-1.0, 7.0, 97), [theta, theta - 1e-9, theta + 1e-9]])
    assert_same_profile(evaluate(q, grid), evaluate(p, grid))


def test_split_at_an_existing_break_is_a_no_op():
    p = PROFILES[1]
    assert split(p, math.pi / 2) is p
    assert split(p, TWO_PI) is p
    assert split(p, -TWO_PI + 1e-14) is p
    q = split(p, deg(30.0))
    assert q.n_pieces == 5
    assert_allclose(q.breaks[1], deg(30.0), rtol=1e-15)


# --------------------------------------------------------------------------- pack


def test_pack_and_evaluate_packed_match_evaluate():
    profiles = [
        harmonic(H),
        flat(harmonic(H), *THESIS_FLAT),
        bump(
            flat(polydyne("4567", H, *SCHEDULES["90/90/90/90"]), deg(350.0), deg(5.0)),
            1.0,
            1e-4,
            0.2,
        ),
        table(*harmonic_table(2.5, 10.0)),
        flat(polydyne("345", 2 * H, *SCHEDULES["45/45/225/45"]), deg(20.0), deg(22.0)),
    ]
    packed = pack(profiles)
    n = [p.n_pieces for p in profiles]
    assert_array_equal(packed.n_pieces, n)
    assert packed.n_pieces.dtype == np.int64
    assert packed.breaks.shape == (5, max(n) + 1)
    assert packed.poly.shape == (5, max(n), 8) and packed.trig.shape == (5, max(n), 2)
    for c, p in enumerate(profiles):
        assert_array_equal(packed.breaks[c, : n[c] + 1], p.breaks)
        assert np.all(np.isinf(packed.breaks[c, n[c] + 1 :]))
        assert_array_equal(packed.poly[c, n[c] :], 0.0)

    rng = np.random.default_rng(7)
    for c, p in enumerate(profiles):
        theta = np.concatenate([rng.uniform(-15.0, 20.0, 300), p.breaks, [-1e-300, -TWO_PI]])
        want = np.array(evaluate(p, theta))
        got = np.array([evaluate_packed(packed, c, t) for t in theta]).T
        assert_allclose(got, want, rtol=1e-14, atol=1e-15 * H)
