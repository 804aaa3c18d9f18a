"""modal-exact carrying a chain's lash-adjuster plunger (campipe.engine.plunger_modes: the
plunger as a coordinate, its regimes as train rows, its check valve, travel and load through
0 as monitors)
against a second method written apart: the bench's solve_ivp peer (campipe.bench.ivp), the
same model stated afresh in each contact configuration and regime, its switches events of
solve_ivp (DOP853 at rtol 1e-11)."""

import math

import numpy as np
import pytest

from campipe.bench.ivp import solve_case
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.lash_adjuster import extended
from campipe.model import valve_train
from campipe.profiles import Ramp, polydyne
from campipe.vocabulary import ADJUSTER_EVENTS, PLUNGER_BOTTOMS

RPM = 2.0 * math.pi / 60.0
#: The bundled lash-adjuster study's bucket tappet (studies/lash-adjuster.yaml).
BUCKET = {
    "layout": "direct-acting",
    "tappet_mass": "0.045 kg",
    "valve_mass": "0.065 kg",
    "stem_stiffness": "30000 N/mm",
    "tappet_contact_stiffness": "60000 N/mm",
    "spring_rate": "35 N/mm",
    "spring_preload": "220 N",
    "damping_ratios": [0.05],
    "lash": "0.2 mm",
    "hla_stiffness": "20000 N/mm",
    "hla_leak_down": "2000 N*s/mm",
    "hla_check_force": "25 N",
    "hla_pump_up": "20 N*s/mm",
    "hla_travel": "1 mm",
}
CAM = polydyne("4567", 9e-3, *np.radians([110, 20, 110]), ramp=Ramp(0.3e-3, 30 / 110))


def _both(rpm: float, turns: int, extension: str = "0 mm"):
    case = Case(valve_train("thesis-1971", {**BUCKET, "hla_extension": extension}), CAM,
                rpm * RPM)  # fmt: skip
    engine = run_batch([case], RunSettings(revolutions=turns))
    assert engine.status[0] == 0
    peer = solve_case(
        extended(case, case.train.hla_extension), revolutions=turns, method="DOP853", rtol=1e-11
    )
    return engine, peer


@pytest.mark.parametrize("extension", ["0 mm", "0.1 mm"])
def test_below_the_onset_every_switch_is_the_peer_s(extension):
    """At 2000 rpm, 3 turns, started leaked down (the plunger bottomed: it pumps the lash up
    on the base circle, leaks down through the event, bottoms out mid-lift in the first
    turn) and 0.1 mm out: each turn's leak-down and pump-up agree with the peer's to 1e-8 of
    the largest (found 1e-10), the valve's lift to 1e-9 m (4e-11), every event (contacts,
    the check valve, the plunger's travel) in kind and to 1e-9 s. Fails on a copy whose
    monitors' roots ignore the slow block's series beyond degree 7 (the bottoming 6 µs
    early), or that keeps the plunger's rate across a switch (leak-down off by 1e-4)."""
    engine, peer = _both(2000.0, 3, extension)
    ledger = engine.lash_adjuster[0][:, 1:]
    scale = np.abs(peer.plunger_ledger).max()
    assert np.abs(ledger - peer.plunger_ledger).max() < 1e-8 * scale
    assert np.abs(engine.q[0, :, 6] - peer.q[:, 6]).max() < 1e-9
    ours, theirs = engine.events[0], peer.events
    assert len(ours) == len(theirs) and np.isin(ours[:, 1], ADJUSTER_EVENTS).sum() >= 9
    np.testing.assert_array_equal(ours[:, 1:4], theirs[:, 1:4])
    assert np.abs(ours[:, 0] - theirs[:, 0]).max() < 1e-9
    if extension == "0 mm":
        assert PLUNGER_BOTTOMS in ours[:, 1]


def test_past_the_onset_the_pump_up_into_the_flights_is_the_peer_s():
    """At 6000 rpm (past the bucket's onset: it leaves the cam every turn, the link rings to
    1400 N of pull in flight and the plunger, unloaded there, pumps up 3.7 to 3.9 µm a turn),
    3 turns: each turn's leak-down and pump-up agree with the peer's to 1e-6 (found 4e-7),
    the valve's lift to 1e-8 m (4e-10), the contacts' events in kind and to 1e-8 s. (The
    check valve's switches may differ by a grazing pair, a dip of the load through F_c within
    one of solve_ivp's steps, which its event search does not see.)"""
    engine, peer = _both(6000.0, 3)
    ledger = engine.lash_adjuster[0][:, 1:]
    assert ledger[:, 1].min() > 3e-6  # pumping up
    scale = np.abs(peer.plunger_ledger).max()
    assert np.abs(ledger - peer.plunger_ledger).max() < 1e-6 * scale
    assert np.abs(engine.q[0, :, 6] - peer.q[:, 6]).max() < 1e-8
    ours = engine.events[0][~np.isin(engine.events[0][:, 1], ADJUSTER_EVENTS)]
    theirs = peer.events[~np.isin(peer.events[:, 1], ADJUSTER_EVENTS)]
    assert len(ours) == len(theirs) > 6
    np.testing.assert_array_equal(ours[:, 1:4], theirs[:, 1:4])
    assert np.abs(ours[:, 0] - theirs[:, 0]).max() < 1e-8


@pytest.mark.parametrize("rpm", [2000.0, 6000.0])
def test_the_plunger_only_pushes(rpm):
    """The bucket's link rings in tension after each landing (to −144 N at 2000 rpm, −1427 N
    in flight at 6000), which the hardware's plunger cannot carry: unloaded, it rises at
    F_c/c_P, its fastest (``plunger.UNLOADED``). Between any two samples 0.25° apart its
    rise is at most F_c/c_P times their interval, to 1e-9, and reaches it (to 1e-6) where the
    link pulls. Fails on a copy that takes the pull as the plunger's load (it rose at up to
    6.7 times that at 2000 rpm, and the per-turn model's pump-up, which does not, was half
    the carried plunger's)."""
    case = Case(valve_train("thesis-1971", BUCKET), CAM, rpm * RPM)
    run = run_batch([case], RunSettings(revolutions=3, output_every=math.radians(0.25)))
    assert run.status[0] == 0
    assert np.nanmin(run.member_loads()["pushrod_force"]) < -100.0  # the link pulls
    fastest = float(BUCKET["hla_check_force"].split()[0]) / 20e3  # F_c/c_P [m/s]
    rate = np.diff(run.extension[0]) / np.diff(run.time[0])
    assert rate.max() <= fastest * (1 + 1e-9)
    assert rate.max() >= fastest * (1 - 1e-6)


def test_a_batch_with_a_plunger_runs_its_other_cases_bit_for_bit():
    """A batch that carries a plunger runs the kernel compiled with the plunger's code (its
    last argument the cases' plunger coordinates); one that carries none, the kernel without
    it (None: numba prunes every plunger branch, a quarter less to compile). A thesis case in
    the first kind of batch, beside a bucket with its adjuster, gives its own batch's
    histories, metrics and events to the bit. Fails on a copy whose two kernels differ in
    the contacts' monitors (a plunger's monitor count or branch leaking into the other)."""
    from campipe.engine import batch as batch_module
    from campipe.engine.integrators.modal_exact import arguments
    from campipe.engine.plunger_modes import Embedded

    bucket = Case(Embedded(valve_train("thesis-1971", BUCKET)), CAM, 3000 * RPM)
    thesis = Case(valve_train("thesis-1971"), CAM, 3000 * RPM)
    settings = RunSettings(revolutions=2)
    for cases, marker in (([bucket, thesis], [7, -1]), ([thesis], None)):
        b = batch_module._prepare_batch(cases, settings, True)
        args = arguments((b.modal_trains, b.packed, b.runs), b.cases,
                         batch_module._outputs(b, settings))  # fmt: skip
        assert (args[-1] is None) if marker is None else list(args[-1]) == marker
    run = batch_module._run_carried
    mixed = run([bucket, thesis], settings, check_stability_limit=True, on_failure="raise")
    alone = run([thesis], settings, check_stability_limit=True, on_failure="raise")
    assert list(mixed.status) == [0, 0] and len(alone.events[0]) >= 2
    assert np.array_equal(mixed.q[1, :, :7], alone.q[0])
    assert np.array_equal(mixed.per_rev[1], alone.per_rev[0])
    assert np.array_equal(mixed.events[1], alone.events[0])
