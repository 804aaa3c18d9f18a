"""The physical bounds that stop a runaway (status UNBOUNDED): a valve lift beyond three times
the larger of the full lift and the height a valve thrown off at the cam's fastest valve speed
rises against its spring. Far past its onset a train is truly thrown beyond its lift: such a
run goes on, and agrees with the other integrator and with one mass's energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from campipe.engine import Case, RunSettings, run_batch
from campipe.engine import batch as batch_module
from campipe.engine.failures import failure_texts
from campipe.engine.integrators import get
from campipe.model import thesis_train, valve_train
from campipe.profiles import harmonic, polydyne
from campipe.profiles.packed import keyed
from campipe.vocabulary import UNBOUNDED

INCH = 0.0254


def _polydyne(lift: float):
    return polydyne("345", lift, math.radians(80), math.radians(20), math.radians(80))


def _one_mass(mass: float, rate: float, preload: float):
    """A one-mass chain [kg, N/m, N], undamped."""
    model = {
        "layout": "lumped",
        "masses": [f"{mass} kg"],
        "stiffnesses": [],
        "spring_rate": f"{rate} N/m",
        "spring_preload": f"{preload} N",
        "damping_ratios": [0.0],
    }
    return valve_train("thesis-1971", model)


def test_a_one_mass_chains_flight_is_its_mass_on_its_spring():
    """A one-mass chain moves as its mass alone: √(m/k) of its mass and spring rate (closed
    form). Fails on a copy that takes the struck mass of another coordinate or the preload."""
    for mass, rate in ((0.5, 1e3), (0.05, 4e4)):
        train = _one_mass(mass, rate, 20.0)
        flight = batch_module.train_stack((train,), 0.0).flight[0]
        assert flight == pytest.approx(math.sqrt(mass / rate), rel=1e-9)


def test_the_lift_bound_is_three_full_lifts_until_the_throw_outgrows_them():
    """Below ω = L/(L'·√(m/k)) (L the lift, L' its steepest rate per radian) the bound is the
    thesis's three full lifts, bit for bit as before (``LIFT_BOUND * lift * ratio``); above,
    three throws, growing with the speed."""
    train = thesis_train()
    stack = batch_module.train_stack((train,), 0.0)
    flight, ratio = float(stack.flight[0]), float(stack.ratio[0])
    cam = harmonic(INCH)
    lift, rate = batch_module._peaks(keyed(cam))
    crossover = lift / (rate * flight)
    settings = RunSettings(revolutions=1)
    for omega in (0.5 * crossover, 0.99 * crossover):
        bound = batch_module._prepare_batch([Case(train, cam, omega)], settings, True)
        assert bound.cases.lift_bound[0] == 3.0 * lift * ratio
    for omega in (1.5 * crossover, 2.0 * crossover):
        bound = batch_module._prepare_batch([Case(train, cam, omega)], settings, True)
        assert bound.cases.lift_bound[0] == pytest.approx(3.0 * omega * rate * flight * ratio)


def test_a_valve_on_a_soft_link_near_its_resonance_is_not_out_of_bounds():
    """A chain whose valve (60 g) hangs on a link as soft as half its spring (20 against
    40 N/mm: a static valve ratio of a third) follows an 8 mm harmonic cam at 8939 rpm,
    below its onset (8984 rpm), near the valve's resonance: its valve lifts 10.24 mm, beyond
    three static lifts (8 mm). It runs (status ok) and its largest valve lift is the steady
    closed form's (configuration I's periodic state, a second method) to 1e-9 m, alone and
    in a batch. Broken copies: the bound at the static ratio in a batch's or in one case's
    preparation (status unbounded, a helper's finding)."""
    from campipe.engine import run_at_fidelity
    from campipe.vocabulary import OK

    train = valve_train(
        "thesis-1971",
        {"layout": "lumped", "masses": ["1 g", "1 g", "1 g", "60 g"],
         "stiffnesses": ["1000000 N/mm", "1000000 N/mm", "20 N/mm"], "spring_rate": "40 N/mm",
         "spring_preload": "250 N", "damping_ratios": [0.05]},
    )  # fmt: skip
    case = Case(train, harmonic(8e-3), 8939.3 * math.pi / 30)
    stack = batch_module.train_stack((train,), 0.0)
    assert float(stack.ratio[0]) == pytest.approx(1 / 3, rel=1e-3)
    full = run_batch([case], RunSettings(revolutions=3), on_failure="record")
    steady = run_at_fidelity([case], RunSettings(revolutions=3, fidelity="steady"))
    assert full.status[0] == OK and np.all(steady.steps == 0)
    pair = run_batch([case, case], RunSettings(revolutions=3), on_failure="record")
    assert pair.status.tolist() == [OK, OK]  # (a batch's bounds, and one case's)
    assert full.separation_per_rev[0].max() == 0.0
    lift = full.valve_lift[0].max()
    assert lift > 3 * 8e-3 / 3 and lift == pytest.approx(steady.valve_lift[0].max(), abs=1e-9)


def test_the_thesis_train_thrown_past_three_lifts_runs_and_agrees_with_newmark():
    """The thesis's train on a 0.4 in polydyne at 2000 rad/s (19100 rpm): its valve is thrown
    to 3.1 times its full lift, which the fixed bound stopped as a defect; it now runs, and
    modal-exact's valve lift agrees with newmark-linear's at 0.05 µs (another integrator)
    to 1e-5 m over two turns, their highest lifts to 1e-5 of it."""
    case = Case(thesis_train(), _polydyne(0.4 * INCH), 2000.0)
    exact = run_batch([case], RunSettings(revolutions=2))
    newmark = run_batch([case], RunSettings(revolutions=2, integrator="newmark-linear", dt=5e-8))
    full = 0.4 * INCH * float(batch_module.train_stack((case.train,), 0.0).ratio[0])
    assert exact.valve_lift.max() > 3.0 * full
    assert np.abs(exact.valve_lift - newmark.valve_lift).max() < 1e-5
    assert exact.valve_lift.max() == pytest.approx(newmark.valve_lift.max(), rel=1e-5)


def test_a_heavy_follower_on_a_weak_spring_rises_as_its_energy_allows():
    """A 0.5 kg follower on a 20 N spring at 200 rad/s leaves its 5 mm polydyne at no more
    than the cam's fastest speed v and rises at most h = (√(P² + k·m·v²) − P)/k above the
    full lift (one mass's energy against the preload P and rate k): thrown beyond three lifts,
    and within that. Fails on the fixed bound (stopped at three lifts)."""
    mass, rate, preload, lift, omega = 0.5, 1e3, 20.0, 0.005, 200.0
    train = _one_mass(mass, rate, preload)
    cam = _polydyne(lift)
    result = run_batch([Case(train, cam, omega)], RunSettings(revolutions=1))
    v = omega * batch_module._peaks(keyed(cam))[1]
    rise = (math.sqrt(preload**2 + rate * mass * v**2) - preload) / rate
    highest = result.valve_lift.max()
    assert 3.0 * lift < highest <= lift + rise


def test_a_run_out_of_bounds_says_what_it_may_be():
    text = failure_texts(RunSettings(), True, get("modal-exact"))[UNBOUNDED]
    assert "the height the cam's fastest valve speed throws it against its spring" in text
    assert "can truly be thrown that far" in text and "otherwise this is a defect" in text
