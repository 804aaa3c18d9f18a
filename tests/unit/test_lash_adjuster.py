"""The hydraulic lash adjuster (campipe.model.hla, campipe.engine.lash_adjuster): its
leak-down over a closed-valve interval and its pump-up against closed forms, the switch's
integral against a smooth load, the turn-to-turn extension, its refusals."""

import math

import numpy as np
import pytest

from campipe.engine import Case, RunSettings, RunSettingsError, run_batch
from campipe.model import ModelParameterError, system_matrices, valve_train
from campipe.model.hla import LashAdjuster, excess_integral
from campipe.profiles import Ramp, harmonic, polydyne

RPM = 2.0 * math.pi / 60.0
M1, M2, LINK, RATE, PRELOAD = 0.05, 0.06, 20000e3, 40e3, 250.0
HLA_K, LEAK, CHECK, PUMP, TRAVEL, DRY = 20000e3, 2e6, 25.0, 2e6, 1e-3, 0.2e-3
K = 1.0 / (1.0 / LINK + 1.0 / HLA_K)  # the link with the adjuster in series
LIFT = 0.01
#: A cam whose turn starts on its base circle, at its opening ramp (the turn's end, where the
#: plunger's extension moves, falls there).
POLYDYNE = polydyne("4567", 9e-3, *np.radians([110, 20, 110]), ramp=Ramp(0.3e-3, 0.5))


def _spec() -> dict:
    return {
        "layout": "lumped",
        "masses": [f"{M1} kg", f"{M2} kg"],
        "stiffnesses": [f"{LINK / 1e3} N/mm"],
        "spring_rate": f"{RATE / 1e3} N/mm",
        "spring_preload": f"{PRELOAD} N",
        "damping_ratios": [0.05],
        "lash": f"{DRY * 1e3} mm",
        "hla_stiffness": f"{HLA_K / 1e3} N/mm",
        "hla_leak_down": f"{LEAK / 1e3} N*s/mm",
        "hla_check_force": f"{CHECK} N",
        "hla_pump_up": f"{PUMP / 1e3} N*s/mm",
        "hla_travel": f"{TRAVEL * 1e3} mm",
    }


def train(**changes):
    return valve_train("thesis-1971", {**_spec(), **changes}, key_prefix="model.")


def test_the_switch_s_integral_against_a_smooth_load():
    """∫ (F − F_c)⁺ dt of F = A + B·sin(ωt) over a turn is 2·(A − F_c)·φ/ω + 2·B·cos(…)…
    in closed form, (A − F_c)·(π + 2·asin a)/ω + 2·B·√(1 − a²)/ω with a = (A − F_c)/B: the
    samples' piecewise-linear integral (the switches located on each interval) converges to
    it at order 2, and is exact for a load linear between samples (a triangle's area). Fails
    on a copy that drops the crossing intervals (order 1) or integrates them whole."""
    A, B, w = 100.0, 200.0, 300.0
    a = (A - CHECK) / B
    exact = ((A - CHECK) * (math.pi + 2 * math.asin(a)) + 2 * B * math.sqrt(1 - a * a)) / w
    errors = []
    for n in (360, 720, 1440):
        t = np.linspace(0.0, 2 * math.pi / w, n + 1) + 0.123 / w  # switches between samples
        errors.append(abs(excess_integral(t, A + B * np.sin(w * t), CHECK) - exact))
    order = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(order - 2.0) < 0.1) and errors[-1] < 1e-5 * exact
    # a triangle 0 → 10 → 0 N over 2 s, level 4 N: the part above is a triangle of base 1.2 s
    assert excess_integral(np.array([0.0, 1.0, 2.0]), np.array([0.0, 10.0, 0.0]), 4.0) == (
        pytest.approx(0.5 * 1.2 * 6.0, rel=1e-14)
    )


def _excess_above(level: float, h: float) -> float:
    """∫ (L(θ) − level)⁺ dθ over a turn of the harmonic cam L = h/2·(1 − sin θ): with
    u = θ − 3π/2, L = h/2·(1 + cos u) ≥ level on |u| ≤ φ = acos(2·level/h − 1)."""
    phi = math.acos(min(max(2 * level / h - 1, -1.0), 1.0))
    return 2 * phi * (h / 2 - level) + h * math.sin(phi)


def _own_motion(extension: float, omega: float, slow: float) -> tuple[float, float]:
    """The plunger's own motion within the turn, to first order: the quasi-static force
    through the adjuster (as the test below states it) changes by b·(e − e₀) as the
    extension moves from the turn's start (b = k while the valve is seated on the cam, k_v
    while it is open, 0 off the cam), which changes the turn's leak-down and pump-up by
    ∓∫ b·(e − e₀) dt / c, e − e₀ the frozen rates' running integral; by the trapezoid rule on
    4·10⁵ points of the turn. (The second order is (b·T/c)², 1e-8 here.)"""
    theta = np.linspace(0.0, 2.0 * math.pi, 400001)
    lift = LIFT / 2 * (1 - np.sin(theta))
    lash = DRY - extension
    lift_off = lash + PRELOAD / K
    k_v = K * RATE / (K + RATE)
    force = np.where(lift < lash, 0.0, K * (np.minimum(lift, lift_off) - lash))
    force = force + np.where(lift > lift_off, k_v * (lift - lift_off), 0.0)
    b = np.where(lift < lash, 0.0, np.where(lift < lift_off, K, k_v))
    closed = force > CHECK
    dt = (theta[1] - theta[0]) / omega
    rate = -(force - CHECK) / slow  # de/dt, the extension frozen
    moved = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)])
    change = -b * moved / slow  # the rate's change by the plunger's own motion
    return (
        -float(np.trapezoid(np.where(closed, change, 0.0), dx=dt)),
        float(np.trapezoid(np.where(closed, 0.0, change), dx=dt)),
    )


def test_leak_down_over_a_closed_valve_interval_is_the_closed_form():
    """At 10 rpm (the train quasi-static: inertia and damping forces under 1e-3 N) the force
    through the adjuster is the static one: 0 off the cam, k·(L − ℓ) once the cam takes the
    lash ℓ up (valve seated), from the lift-off load P₀ on (the installed force: seated, the
    spring pushes with it), at the lift L_lo = ℓ + P₀/k, P₀ + k_v·(L − L_lo) (valve open; k
    the link in series with the adjuster, k_v = k·k_s/(k + k_s)). Over the turn the check valve
    is closed where it exceeds F_c, and the plunger leaks down ∫ (F − F_c)⁺ dt / c_L, which
    is k·I(L_c) − (k − k_v)·I(L_lo) over ω·c_L with I(a) = ∫ (L − a)⁺ dθ in closed form; the
    check valve is open elsewhere and the plunger pumps up (2π·F_c − k·(I(ℓ) − I(L_c)))/(ω·c_P)
    (here less than the lash it could take up). These take the extension frozen over the
    turn; the engine carries the plunger (``plunger_modes``), whose own motion changes the
    force through it by b·Δe: with that first-order term added (``_own_motion``, 8e-5 of
    the leak-down, 1e-3 of the pump-up), the engine's turn 0 and turn 1 (its extension
    advanced by both) agree to 1e-5 (the pump-up to 1e-4). Fails on a copy that leaves the
    adjuster's stiffness out of the link (k doubled), or moves the next turn's frame the wrong
    way (turn 1 off by the extension)."""
    omega, slow, start = 10 * RPM, 2e9, 0.1e-3  # a turn of 6 s: a micron of leak-down
    hla = {"hla_leak_down": "2e6 N*s/mm", "hla_pump_up": "2e6 N*s/mm", "hla_extension": "0.1 mm"}
    run = run_batch(
        [Case(train(**hla), harmonic(LIFT), omega)],
        RunSettings(revolutions=2, output_every=math.radians(0.05)),
    )
    assert run.status[0] == 0
    k_v = K * RATE / (K + RATE)
    extension = start
    for turn in range(2):
        lash = DRY - extension
        l_c = lash + CHECK / K  # the check valve closes
        l_lo = lash + PRELOAD / K  # the valve lifts off its seat
        leak = (K * _excess_above(l_c, LIFT) - (K - k_v) * _excess_above(l_lo, LIFT)) / (
            omega * slow
        )
        below = 2 * math.pi * CHECK - K * (_excess_above(lash, LIFT) - _excess_above(l_c, LIFT))
        pump = below / (omega * slow)
        assert pump < lash + CHECK / K  # the capacity, not the lash, limits it
        leak_own, pump_own = _own_motion(extension, omega, slow)
        assert abs(leak_own) > 5e-5 * leak  # the plunger's own motion counts here
        leak, pump = leak + leak_own, pump + pump_own
        found = run.lash_adjuster[0, turn]
        assert found[0] == pytest.approx(extension, rel=1e-9)
        assert found[1] == pytest.approx(leak, rel=1e-5)
        assert found[2] == pytest.approx(pump, rel=1e-4)
        extension = extension - leak + pump
    # the archive's effective lash: the dry lash less the extension
    assert run.hla_lash_per_rev[0, 1] == pytest.approx(DRY - run.lash_adjuster[0, 1, 0])


def test_the_plunger_pumps_up_to_the_check_force_and_no_further():
    """With a free-flowing feed (c_P small) the plunger takes up on each base circle the whole
    gap and the check force's give, so every turn (starting on the base circle, at the
    opening ramp) starts at the extension that holds F_c there, ℓ + F_c/k (to 1e-2 of a leak
    of 10 µm, from the second turn: the first starts from the periodic start, its base
    circle not yet settled), and pumps up what it leaked down; the valve keeps seating.
    Fails on a copy whose pump-up ignores the need (it would extend to its travel, holding
    the valve open)."""
    run = run_batch(
        [Case(train(hla_pump_up="0.01 N*s/mm"), POLYDYNE, 1000 * RPM)],
        RunSettings(revolutions=6, output_every=math.radians(0.5)),
    )
    settled = DRY + CHECK / K  # the extension that holds F_c on the base circle
    table = run.lash_adjuster[0]
    leak, pump = table[:, 1], table[:, 2]
    assert np.all(leak > 1e-6)
    assert np.all(np.abs(table[1:, 0] - settled) < 1e-2 * leak[1:])
    assert np.all(np.abs(pump[1:] - leak[1:]) < 1e-2 * leak[1:])  # steady
    assert np.all(run.valve_lift[0] >= -1e-9)  # the valve seats, not held open
    assert run.seat_impacts_per_rev[0, 1:].min() >= 1


def test_refusals_name_their_keys():
    """An adjuster on the thesis's train or a one-mass chain, a key of it left out, no dry
    lash, an extension beyond the travel, and a run of a fractional length: each refused
    naming its key. Fails on a copy that runs an adjuster without its leak-down."""
    with pytest.raises(ModelParameterError) as info:
        valve_train("thesis-1971", {"hla_stiffness": "1 N/mm"}, key_prefix="model.")
    assert info.value.key == "model.hla_stiffness" and "chain" in str(info.value)
    for changes, key in [
        ({"hla_leak_down": "none"}, "model.hla_leak_down"),
        ({"lash": "none"}, "model.lash"),
        ({"hla_extension": "2 mm"}, "model.hla_extension"),
        ({"masses": ["1 kg"], "stiffnesses": [], "lash": "none"}, "model.hla_stiffness"),
    ]:
        with pytest.raises(ModelParameterError) as info:
            train(**changes)
        assert info.value.key == key, (changes, info.value)
    case = Case(train(), harmonic(LIFT), 1000 * RPM)
    with pytest.raises(RunSettingsError) as err:  # automatic length runs: test_lash_auto
        run_batch([case], RunSettings(revolutions=2.5))
    assert err.value.key == "run.revolutions"
    # a part of a turn (the estimate's warm-up) runs, its plunger where it starts
    part = run_batch([case], RunSettings(revolutions=0.01))
    assert part.status[0] == 0 and np.all(np.isnan(part.lash_adjuster))
    # the adjuster is in series with the link next to the cam
    assert system_matrices(train()).stiffness[0, 6] == pytest.approx(K, rel=1e-12)
    hla = LashAdjuster(HLA_K, LEAK, CHECK, PUMP, TRAVEL, K)
    assert hla.series(LINK) == pytest.approx(K)
    # the plunger stays within its travel: a pump-up past it stops there, a leak-down at 0
    t, gap = np.linspace(0.0, 1.0, 11), np.full(11, 1.0)
    free = LashAdjuster(HLA_K, LEAK, CHECK, 1.0, TRAVEL, K)  # a free feed: 25 m a second
    assert free.advance(0.9e-3, t, np.zeros(11), gap)[0] == TRAVEL
    assert hla.advance(1e-6, t, np.full(11, 1e4), gap)[0] == 0.0


def test_the_steady_level_runs_an_adjuster_turn_by_turn():
    """``run.fidelity: steady`` takes a plain case that follows from one turn's closed form,
    never a case with an adjuster (its plunger moves turn by turn): the merged result keeps
    the adjuster's table, NaN for the plain case, and the same values as a full run. Fails
    on a copy whose steady level takes the adjuster's case (no table) or whose merge drops
    it."""
    from campipe.engine import run_at_fidelity
    from campipe.engine.periodic import steady_cases

    own = {k: v for k, v in _spec().items() if "hla" not in k and k != "lash"}
    plain = Case(valve_train("thesis-1971", own), harmonic(LIFT), 1000 * RPM)
    hla = Case(train(), POLYDYNE, 1000 * RPM)
    settings = RunSettings(revolutions=3, output_every=math.radians(1), fidelity="steady")
    assert list(steady_cases([plain, hla], settings)) == [True, False]
    res = run_at_fidelity([plain, hla], settings)
    full = run_batch([hla], RunSettings(revolutions=3, output_every=math.radians(1)))
    assert np.all(np.isnan(res.lash_adjuster[0]))
    np.testing.assert_array_equal(res.lash_adjuster[1], full.lash_adjuster[0])
