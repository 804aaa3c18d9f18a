"""A run of automatic length (``run.revolutions: auto``) with a hydraulic lash adjuster: the
plunger's extension settles as part of the run's convergence (campipe.engine.lash_adjuster's
Plunger through campipe.engine.settle.run_settled)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from campipe.engine import Case, RunSettings, run_batch
from campipe.model import valve_train
from campipe.profiles import Ramp, polydyne

RPM = 2.0 * math.pi / 60.0
LINK, HLA_K, CHECK, DRY = 20000e3, 20000e3, 25.0, 0.2e-3
K = 1.0 / (1.0 / LINK + 1.0 / HLA_K)
POLYDYNE = polydyne("4567", 9e-3, *np.radians([110, 20, 110]), ramp=Ramp(0.3e-3, 0.5))
CHAIN = {
    "layout": "lumped",
    "masses": ["0.05 kg", "0.06 kg"],
    "stiffnesses": ["20000 N/mm"],
    "spring_rate": "40 N/mm",
    "spring_preload": "250 N",
    "damping_ratios": [0.05],
    "lash": "0.2 mm",
    "hla_stiffness": "20000 N/mm",
    "hla_leak_down": "2000 N*s/mm",
    "hla_check_force": "25 N",
    "hla_pump_up": "0.01 N*s/mm",
    "hla_travel": "1 mm",
}


def test_a_chain_s_plunger_settles_with_the_run():
    """With a free-flowing feed the plunger takes the whole gap up on each base circle, so
    from the second turn each turn starts at ℓ + F_c/k (the closed form of
    test_lash_adjuster): a run of automatic length settles with period 1,
    its settled window's extensions that closed form to 1e-2 of a leak; its turns are those
    of a run of fixed length, turn for turn (to 1e-9); its histories have the train's
    coordinates only. Fails on a copy that leaves the plunger at its start (the extension
    0 throughout) or keeps the ledger's column in the histories."""
    case = Case(valve_train("thesis-1971", CHAIN), POLYDYNE, 1000 * RPM)
    auto = run_batch([case], RunSettings(revolutions=None, output_every=math.radians(0.5)))
    assert auto.status[0] == 0 and auto.period_turns[0] == 1
    done = int(auto.turns_run[0])
    table = auto.lash_adjuster[0, :done]
    leak = table[:, 1]
    window = np.flatnonzero(auto.measured[0])
    assert window.size >= 1 and window[0] >= 1
    settled = DRY + CHECK / K
    assert np.all(np.abs(table[window, 0] - settled) < 1e-2 * leak.min())
    fixed = run_batch([case], RunSettings(revolutions=done, output_every=math.radians(0.5)))
    assert_allclose(table, fixed.lash_adjuster[0], rtol=1e-9, atol=1e-15)
    assert auto.q.shape[2] == fixed.q.shape[2]
    assert auto.metric("hla_lash")[0] == pytest.approx(DRY - table[window, 0].max(), rel=1e-12)


def test_a_finger_settles_only_once_its_plunger_has_pumped_up():
    """The bundled finger at 4000 rpm engine speed, its adjuster started leaked down: the
    follower stands off its cam at each turn's start while the plunger pumps the lash up, so
    the train's own state repeats from the first turn; the run settles only once the plunger
    has (at least 12 turns, and its extension repeating turn to turn over the window to 1e-5
    of its travel, the run's settle_tolerance), the effective lash then the hand's: the
    plunger holding F_c on the base circle, raised F_c/k past the roller's touch (k the
    pivot's load per unit of its rise through the adjuster, the finger and the stem, g₀²
    times the pallet's path, g₀ = (b − a)/a for this level finger), which the valve sees as
    −g₀·F_c/k, to 5 % (found 3 %: the turn's pump-up approaches it as 1 − exp(−k·t/c_P)).
    At 9000 rpm it pumps up into the flights every turn, never repeating within the cap
    (period 0). Fails on a copy whose plunger is not part of the state compared (it
    settles after one turn, 0.15 mm of lash still there) or whose pump-up stops at the
    turn's gap without what the turn leaked down (the lash −0.9 µm, a sixth of the hand's)."""
    from pathlib import Path

    from campipe.study import load_study

    path = Path(__file__).parents[2] / "studies" / "finger-follower-hla.yaml"
    study = load_study(
        path, {"sweep.engine_speed": ["4000 rpm", "9000 rpm"], "run.revolutions": "auto"}
    )
    run = run_batch([c.case for c in study.cases], study.cases[0].settings)
    assert list(run.status) == [0, 0]
    assert run.period_turns[0] == 1 and run.settled_turn[0] >= 12
    window = run.measured[0]
    lash = run.metric_per_rev("hla_lash")[0]
    assert lash[0] == pytest.approx(0.15e-3, rel=1e-12)
    g0 = (36.0 - 22.0) / 22.0  # the pivot's gain: (pivot to pallet − to roller) / to roller
    k = 1.0 / (1.0 / 20000e3 + (1.0 / 10000e3 + 1.0 / 50000e3) / g0**2)  # hla, finger, stem
    assert lash[window] == pytest.approx(np.full(window.sum(), -g0 * 25.0 / k), rel=0.05)
    assert np.all(np.abs(np.diff(run.lash_adjuster[0, window, 0])) < 1e-5 * 1e-3)
    assert run.period_turns[1] == 0 and run.turns_run[1] == 48
    assert np.all(np.diff(run.lash_adjuster[1, :, 0]) > 0)
