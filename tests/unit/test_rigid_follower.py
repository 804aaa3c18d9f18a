"""The one-mass lumped chain, a rigid direct-acting follower: its onset against the closed
form ω² = 2(P₀ + k·h)/(m·h), its cam force against the algebraic m·ẍ + c·ẋ + k·x + P₀, its
flight off the cam against a free damped mass on its spring, its valve the follower
(q7 = −q1), and its refusals."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from campipe.engine import Case, CaseError, RunSettings, run_batch
from campipe.engine import onset as O
from campipe.model import ModelParameterError, coordinates, placeholders, valve_train
from campipe.profiles import harmonic
from campipe.vocabulary import CAM_CONTACT, FREE, SEAT

RPM = 2.0 * math.pi / 60.0
MASS, RATE, PRELOAD, LIFT = 0.08, 40e3, 250.0, 0.01  # [kg, N/m, N, m]


def follower(zeta: float = 0.0, **changes):
    spec = {
        "layout": "lumped",
        "masses": [f"{MASS} kg"],
        "stiffnesses": [],
        "spring_rate": f"{RATE / 1e3} N/mm",
        "spring_preload": f"{PRELOAD} N",
        "damping_ratios": [zeta],
    }
    return valve_train("thesis-1971", {**spec, **changes}, key_prefix="model.")


def cam(theta: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The thesis's harmonic cam h/2·(1 − sin θ) and its first two time derivatives."""
    s, c = np.sin(theta), np.cos(theta)
    return LIFT / 2 * (1 - s), -LIFT / 2 * omega * c, LIFT / 2 * omega**2 * s


def test_the_onset_is_the_closed_form():
    """Undamped, the cam force m·ẍ + k·x + P₀ on h/2·(1 − sin θ) is least at the nose,
    P₀ + k·h − m·h·ω²/2: zero at ω² = 2(P₀ + k·h)/(m·h), 12 173.01 rpm. The engine's onset
    search (the periodic closed form's margin, proven bracket) finds it to 0.5 rpm. Fails on
    a copy whose mirror (q7) leaks its mass into the cam force (the Schur complement of the
    free coordinates not cancelling: the onset moves by thousands of rpm) or whose spring
    acts on the placeholder q7."""
    expected = math.sqrt(2 * (PRELOAD + RATE * LIFT) / (MASS * LIFT)) / RPM
    on = O.onset_speeds([Case(follower(), harmonic(LIFT), 1.0)], 8000 * RPM, 16000 * RPM)
    assert on.status[0] == "found" and on.proven[0]
    assert abs(on.speed[0] / RPM - expected) < 0.5
    assert expected == pytest.approx(12173.0124, abs=1e-3)


@pytest.mark.parametrize(
    "integrator, dt, tol, lift_tol",
    [("modal-exact", None, 1e-9, 1e-12), ("newmark-linear", 1e-6, 1e-3, 1e-7)],
)
def test_on_the_cam_the_force_is_algebraic(integrator, dt, tol, lift_tol):
    """Below the onset (6000 rpm, ζ = 0.1: c = 2ζ√(k·m)) nothing of the train is free: the
    cam force is m·ẍ + c·ẋ + k·x + P₀ of the cam's motion at every sample, to 1e-9 N in
    modal-exact (1e-3 N in newmark-linear at 1 µs), the valve lift is the cam lift (to 1e-12
    of it; newmark-linear's step error on the mirror, 1e-7) and the placeholders stay at
    rest. Fails on a copy whose damping takes the mirror's mass into the follower's ζ (c off
    by 44 %: 16 N), or whose valve q7 is a placeholder (lift 0)."""
    omega = 6000 * RPM
    settings = {"integrator": integrator} | ({"dt": dt} if dt else {})
    train = follower(0.1)
    run = run_batch(
        [Case(train, harmonic(LIFT), omega)],
        RunSettings(revolutions=2, output_every=math.radians(1), **settings),
        full_state=True,
    )
    assert run.status[0] == 0 and np.all(run.contact_state[0] == CAM_CONTACT)
    x, v, a = cam(run.cam_angle, omega)
    c = 2 * 0.1 * math.sqrt(RATE * MASS)
    assert_allclose(run.cam_force[0], MASS * a + c * v + RATE * x + PRELOAD, rtol=0, atol=tol)
    assert_allclose(run.valve_lift[0], x, rtol=0, atol=lift_tol * LIFT)
    assert_allclose(run.q[0][:, SEAT], -run.q[0][:, 0], rtol=0, atol=lift_tol * LIFT)
    assert np.abs(run.q[0][:, placeholders(train)]).max() < 1e-12 * LIFT


def test_off_the_cam_it_is_a_free_mass_on_its_spring():
    """Above the onset (14 000 rpm, ζ = 0.1) the follower leaves the cam where the algebraic
    force crosses zero (found here by a root search of m·ẍ + c·ẋ + k·x + P₀ between the
    samples) and flies as a damped mass on its spring, m·ẍ + c·ẋ + k·x = −P₀, from the cam's
    lift and velocity there: the engine's valve lift equals that closed form at every free
    sample of the first flight to 1e-9 of the lift. Fails on a copy whose mirror stiffness
    acts in the flight (a frequency off by 2 %) or whose preload pushes the valve open."""
    omega, zeta = 14000 * RPM, 0.1
    c = 2 * zeta * math.sqrt(RATE * MASS)
    run = run_batch(
        [Case(follower(zeta), harmonic(LIFT), omega)],
        RunSettings(revolutions=2, output_every=math.radians(0.5)),
    )
    state, theta = run.contact_state[0], run.cam_angle
    first = int(np.argmax(state == FREE))
    last = first + int(np.argmax(state[first:] != FREE))  # back on the cam
    assert 0 < first < last and np.all(state[first:last] == FREE)

    def force(th: float) -> float:
        x, v, a = (float(f) for f in cam(np.array(th), omega))
        return MASS * a + c * v + RATE * x + PRELOAD

    ts = brentq(force, theta[first - 1], theta[first], xtol=1e-14) / omega
    x0, v0, _ = (float(f) for f in cam(np.array(ts * omega), omega))
    wn = math.sqrt(RATE / MASS)
    wd, sigma = wn * math.sqrt(1 - zeta**2), zeta * wn
    rest = -PRELOAD / RATE
    tau = theta[first:last] / omega - ts
    amp_c, amp_s = x0 - rest, (v0 + sigma * (x0 - rest)) / wd
    flight = rest + np.exp(-sigma * tau) * (amp_c * np.cos(wd * tau) + amp_s * np.sin(wd * tau))
    assert_allclose(run.valve_lift[0][first:last], flight, rtol=0, atol=1e-9 * LIFT)
    assert np.all(flight > cam(theta[first:last], omega)[0])  # truly off the cam


def test_the_coordinates_and_the_refusals():
    """q1 the follower, q7 its mirror the valve, q2 … q6 placeholders; no masses, lash, or a
    seat on a one-mass chain refused naming the key. Fails on a copy that runs a seated
    one-mass chain (its seat and cam holding one body)."""
    train = follower()
    names = [c.name for c in coordinates(train)]
    assert names[0] == "follower" and names[SEAT] == "valve"
    assert list(placeholders(train)) == [1, 2, 3, 4, 5]
    with pytest.raises(ModelParameterError) as info:
        follower(masses=[], stiffnesses=[])
    assert info.value.key == "model.masses" and "one or more" in str(info.value)
    with pytest.raises(ModelParameterError) as info:
        follower(lash="0.2 mm")
    assert info.value.key == "model.lash"
    with pytest.raises(CaseError) as err:
        Case(train, harmonic(LIFT), 1000 * RPM, seat=0.0)
    assert err.value.key == "seat" and "without a seat" in str(err.value)
