"""Accuracy of the integrators: convergence orders, analytic checks, impacts, cost settings.

The reference for every comparison is modal-exact with a tight event tolerance and a small
step cap: exact between events, so its only error is the event location (≤ 1e-15 s here).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from references import steady_state_cam_force

from campipe.engine import Case, IntegrationError, RunSettings, run_batch, stability_limit
from campipe.engine.batch import train_matrices
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.vocabulary import (
    CAM_IMPACT,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    EV_VELOCITY,
    OK,
    UNBOUNDED,
)

INCH = 0.0254
TRAIN = thesis_train()
CAM = harmonic(INCH)


def rpm(r):
    return r * math.pi / 30


SEPARATING = Case(TRAIN, CAM, rpm(11000))
SEAT_BOUNCE = Case(TRAIN, CAM, rpm(13205), seat=0.1 * INCH)


def run(case, revolutions=2, **kw):
    return run_batch([case], RunSettings(revolutions=revolutions, **kw))


@pytest.fixture(scope="module")
def references():
    return {
        id(case): run(case, integrator="modal-exact", dt=0.05e-6, tolerance=1e-15)
        for case in (SEPARATING, SEAT_BOUNCE)
    }


def slope(x, y):
    """Observed order: the least-squares slope of log y against log x."""
    return np.polyfit(np.log(x), np.log(y), 1)[0]


def valve_error(res, ref):
    return np.abs(res.valve_lift - ref.valve_lift).max()


def event_angle_error(res, ref, case, first=None):
    a, b = res.events[0], ref.events[0]
    n = first or len(b)
    assert len(a) >= n and (first or len(a) == len(b)), (len(a), len(b))
    assert np.array_equal(a[:n, EV_KIND], b[:n, EV_KIND])
    return np.abs(a[:n, EV_TIME] - b[:n, EV_TIME]).max() * case.speed  # [rad]


@pytest.mark.parametrize(
    ("case", "tolerances", "first"),
    [(SEPARATING, [1e-7, 1e-8, 1e-9, 1e-10], None), (SEAT_BOUNCE, [1e-8, 1e-9, 1e-10, 1e-11], 8)],
    ids=["11000rpm", "seat-13205rpm"],
)
def test_modal_exact_error_is_first_order_in_the_event_tolerance(
    references, case, tolerances, first
):
    ref = references[id(case)]
    runs = [run(case, integrator="modal-exact", tolerance=t) for t in tolerances]
    valve = np.array([valve_error(r, ref) for r in runs])
    events = np.array([event_angle_error(r, ref, case, first) for r in runs])
    # An error at the round-off floor says nothing of the order: a thousand ulps of the
    # valve's lift (3.5e-15 m), the reference's own round-off over its thousands of steps. A
    # tolerance whose roots land on the reference's by luck (1.3e-15 m at 1e-10 on OpenBLAS's
    # Sandybridge kernels) is left out of the slope, at least three points kept.
    floor = 1000 * np.spacing(np.abs(ref.valve_lift).max())
    above = valve > floor
    assert above.sum() >= 3, valve
    assert 0.8 < slope(np.array(tolerances)[above], valve[above]) < 1.5, valve
    assert slope(tolerances, events) > 0.8, events
    # Bounds: the valve moves at most ~v_closing·tolerance off per event, which later events
    # may amplify by a bounded factor; event angles within a hundred ω·tolerance.
    v_max = max(ref.max_cam_impact_velocity[0], ref.max_seating_velocity[0])
    assert np.all(valve <= 2 * v_max * np.array(tolerances)), valve
    assert np.all(events <= 100 * case.speed * np.array(tolerances)), events


@pytest.mark.parametrize("case", [SEPARATING, SEAT_BOUNCE], ids=["11000rpm", "seat-13205rpm"])
def test_modal_exact_does_not_depend_on_its_step(references, case):
    """Exact between events: capping the step changes nothing beyond rounding."""
    ref = references[id(case)]
    for cap in (2e-6, 1e-6, 0.25e-6, None):
        res = run(case, integrator="modal-exact", dt=cap, tolerance=1e-14)
        assert valve_error(res, ref) < 1e-12 * INCH * 100
        assert len(res.events[0]) == len(ref.events[0])


def test_newmark_linear_converges_to_the_same_history_at_first_order(references):
    """Switching at step ends makes the thesis algorithm first order through contact events:
    the valve history over 2 … 0.25 µs, the event angles over 0.5 … 0.0625 µs. At 1 µs and
    above the step also opens a grazing contact near 531° (a 1° flight the exact solution
    does not have: the exact contact force dips to 26 N there), so the event list is
    compared only where it has the reference's 9 events; at the thesis's 1 µs the valve is
    still within 2e-4 in."""
    ref = references[id(SEPARATING)]
    steps = [2e-6, 1e-6, 0.5e-6, 0.25e-6]
    valve = np.array(
        [valve_error(run(SEPARATING, integrator="newmark-linear", dt=dt), ref) for dt in steps]
    )
    assert 0.8 < slope(steps, valve) < 1.3, valve
    assert valve[1] < 2e-4 * INCH  # 1 µs, the thesis's step
    fine = [0.5e-6, 0.25e-6, 0.125e-6, 0.0625e-6]
    runs = [run(SEPARATING, integrator="newmark-linear", dt=dt) for dt in fine]
    events = np.array([event_angle_error(r, ref, SEPARATING) for r in runs])
    assert 0.8 < slope(fine, events) < 1.3, events
    assert np.degrees(events[0]) < 0.05


def test_newmark_linear_converges_on_the_seat_bounce(references):
    ref = references[id(SEAT_BOUNCE)]
    steps = [1e-6, 0.5e-6, 0.25e-6, 0.125e-6]
    valve = np.array(
        [valve_error(run(SEAT_BOUNCE, integrator="newmark-linear", dt=dt), ref) for dt in steps]
    )
    assert 0.6 < slope(steps, valve) < 1.8, valve
    assert valve[-1] < 3e-4 * INCH


def test_impulse_and_closing_velocity_converge_the_thesis_impact_force_does_not(references):
    ref = references[id(SEPARATING)]
    first_ref = ref.events[0][ref.events[0][:, EV_KIND] == CAM_IMPACT][0]
    steps = [1e-6, 0.5e-6, 0.25e-6, 0.125e-6]
    velocity, impulse, peak, between = [], [], [], []
    for dt in steps:
        res = run(SEPARATING, integrator="newmark-linear", dt=dt)
        first = res.events[0][res.events[0][:, EV_KIND] == CAM_IMPACT][0]
        velocity.append(first[EV_VELOCITY])
        impulse.append(first[EV_IMPULSE])
        peak.append(res.thesis_impact_force[0])
        between.append(res.max_cam_force[0])
    v_err = np.abs(np.array(velocity) - first_ref[EV_VELOCITY])
    j_err = np.abs(np.array(impulse) - first_ref[EV_IMPULSE])
    assert v_err[-1] < 0.003 * first_ref[EV_VELOCITY] and v_err[-1] < v_err[0]
    assert j_err[-1] < 0.003 * first_ref[EV_IMPULSE] and j_err[-1] < j_err[0]
    # The impulse itself is checked against a momentum balance M Δq̇ in
    # tests/integration/test_trust.py.
    # The thesis's peak "impact force" is Δv·m/Δt: it doubles each time the step halves.
    ratios = np.array(peak[1:]) / np.array(peak[:-1])
    assert np.all((ratios > 1.8) & (ratios < 2.2)), ratios
    # The largest force between impacts converges, to modal-exact's.
    assert_allclose(between[-1], ref.max_cam_force[0], rtol=2e-4)
    assert abs(between[-1] - ref.max_cam_force[0]) < abs(between[0] - ref.max_cam_force[0])
    # modal-exact applies impulses at an instant: nothing in it measures a step.
    assert ref.thesis_impact_force[0] == ref.max_cam_force[0]


def test_default_reaches_a_micro_inch_on_the_separation_case(references):
    """The accuracy half of 'accuracy for cost' (the cost half is in `campipe bench`)."""
    res = run(SEPARATING)  # integrator: default, its own steps
    assert valve_error(res, references[id(SEPARATING)]) < 1e-6 * INCH


@pytest.mark.parametrize("method", ["modal-exact", "newmark-linear"])
def test_steady_state_contact_force_matches_the_frequency_response(method):
    speed = rpm(3000)
    res = run(Case(TRAIN, CAM, speed), revolutions=6, integrator=method)
    last = slice(-361, None)
    expected = -steady_state_cam_force(TRAIN, speed, INCH, res.cam_angle[last])
    tol = 1e-7 if method == "modal-exact" else 2e-3
    assert_allclose(res.cam_force[0, last], expected, rtol=0, atol=tol * np.abs(expected).max())


def free_flight(train, q0, v0, t):
    """Configuration II from (q0, v0): classical modal damping, each mode a damped
    oscillator about the static deflection under the preload (the full train's real modes)."""
    sm = train_matrices(train)
    qs = np.linalg.solve(sm.stiffness, sm.preload)
    phi, w = sm.modes, sm.frequencies
    zeta = np.asarray(train.damping_ratios)
    eta0 = phi.T @ sm.mass @ (q0 - qs)
    deta0 = phi.T @ sm.mass @ v0
    wd = w * np.sqrt(1 - zeta**2)
    decay = np.exp(-zeta * w * t)
    eta = decay * (eta0 * np.cos(wd * t) + (deta0 + zeta * w * eta0) / wd * np.sin(wd * t))
    return qs + phi @ eta


@pytest.mark.parametrize("method", ["modal-exact", "newmark-linear"])
def test_free_decay_in_configuration_II_matches_the_modal_solution(method):
    res = run(Case(TRAIN, CAM, rpm(20000)), revolutions=2, integrator=method)
    # The longest stretch in flight.
    free = np.flatnonzero(res.contact_state[0] == 2)
    stretches = np.split(free, np.flatnonzero(np.diff(free) > 1) + 1)
    longest = max(stretches, key=len)
    start, stop = longest[0], longest[-1]
    assert stop - start > 200  # degrees in flight
    k0, k1 = start + 1, stop - 1
    t = res.time[0, k1] - res.time[0, k0]
    expected = free_flight(TRAIN, res.q[0, k0], res.v[0, k0], t)
    translations = [0, 1, 3, 6]
    err = np.abs(res.q[0, k1, translations] - expected[translations]).max()
    # modal-exact: rounding and the modes dropped below 1e-13 m (MODE_FLOOR).
    tol = 1e-9 if method == "modal-exact" else 1e-5
    assert err < tol * np.abs(expected[translations]).max()


def test_energy_balance_of_an_undamped_impact_free_run():
    """Undamped and always on the cam: the train's energy changes by the cam's work,
    E(t) − E(0) = ∫ F1·q̇1 dt, with E = ½ q̇ᵀMq̇ + ½ qᵀKq − fᵀq."""
    undamped = TRAIN.replace(damping_ratios=(0.0,) * 7)
    res = run(
        Case(undamped, CAM, rpm(3000)),
        revolutions=1,
        integrator="modal-exact",
        output_every=math.radians(0.25),
    )
    sm = train_matrices(undamped)
    q, v = res.q[0], res.v[0]
    energy = (
        0.5 * np.einsum("ki,ij,kj->k", v, sm.mass, v)
        + 0.5 * np.einsum("ki,ij,kj->k", q, sm.stiffness, q)
        - q @ sm.preload
    )
    power = -res.cam_force[0] * v[:, 0]  # F1 = −(compressive cam force) acts on q1
    t = res.time[0]
    # Simpson's rule on the uniform samples (an even number of intervals).
    work = np.concatenate(
        [
            [0.0],
            np.cumsum((t[2::2] - t[:-2:2]) / 6 * (power[:-2:2] + 4 * power[1::2] + power[2::2])),
        ]
    )
    swing = np.ptp(energy)
    assert swing > 1.0  # joules: the cam does real work on the spring
    assert np.abs(energy[::2] - energy[0] - work).max() < 1e-6 * swing
    assert res.cam_impacts[0] == 0 and np.all(res.contact_state[0] == 1)


def test_newmark_stability_limit_reproduced_by_runs_just_under_and_over():
    """Just under the limit the run stays within the train's travel; just over, the highest
    mode grows ×1.1 a step in contact and ×1.15 in flight (spectral radius of the
    amplification matrix) and the run is stopped with an error, never stored. A limit computed
    for the wrong configuration or a missing bound check fails one side."""
    case = Case(TRAIN, CAM, rpm(11000))  # no seat: configurations I and II
    limit = stability_limit(case)
    under = run(case, revolutions=1, integrator="newmark-linear", dt=0.99 * limit)
    assert np.isfinite(under.q).all() and np.abs(under.valve_lift).max() < 2 * INCH
    with pytest.raises(IntegrationError, match="physical bounds|non-finite"):
        run_batch(
            [case],
            RunSettings(revolutions=4, integrator="newmark-linear", dt=1.02 * limit),
            check_stability_limit=False,
        )
    assert math.isinf(stability_limit(case, "modal-exact"))


@pytest.mark.parametrize("fraction", [0.99, 0.999])
def test_newmark_near_its_limit_undamped_with_a_seat_never_stores_a_runaway(fraction):
    """Issue 18's case: zero damping, seat at 0.1 in, 11000 rpm, a step at 0.99 and 0.999 of
    the stated limit. The limit is linear Newmark's; switching between configurations and
    impacts near it pump energy into the highest mode (campipe 0.1 stored 1030 m/s, then
    3.4e37 m/s; 4.7e6 m/s at 0.999 here before the bounds). Over 20 turns both runs leave
    the physical bounds: each is stopped, recorded UNBOUNDED with NaN results, and raises
    naming the integrator and step; none stores a speed beyond the bound. Without the bound
    check the run returns status OK with the runaway speeds."""
    train = TRAIN.replace(damping_ratios=(0.0,) * 7)
    case = Case(train, CAM, rpm(11000), seat=0.1 * INCH)
    settings = RunSettings(
        revolutions=20, integrator="newmark-linear", dt=fraction * stability_limit(case)
    )
    res = run_batch([case], settings, on_failure="record")
    assert res.status.tolist() == [UNBOUNDED]
    assert np.isnan(res.valve_velocity).all() and np.isnan(res.max_cam_force[0])
    with pytest.raises(IntegrationError, match=r"physical bounds \(newmark-linear, step 3\.2"):
        run_batch([case], settings)
    exact = run(case, revolutions=20, integrator="modal-exact")
    assert exact.status.tolist() == [OK]  # the same case, integrated exactly, stays bounded


def test_contact_states_only_gives_the_same_contacts():
    """full_state=False computes only q1, q7 (and velocities) at the samples."""
    full = run(SEAT_BOUNCE, integrator="modal-exact")
    lean = run_batch(
        [SEAT_BOUNCE], RunSettings(revolutions=2, integrator="modal-exact"), full_state=False
    )
    assert np.array_equal(full.valve_lift, lean.valve_lift)
    assert np.array_equal(full.follower_lift, lean.follower_lift)
    assert np.array_equal(full.cam_force, lean.cam_force)
    assert np.isnan(lean.q[0, :, 1:6]).any() and not np.isnan(lean.q[0, :, [0, 6]]).any()


@pytest.mark.parametrize("speed, revolutions", [(6979.591836734694, 2), (9000, 1.37)])
def test_contact_states_only_to_the_end_of_any_run(speed, revolutions):
    """A contacts-only run that ends between profile breaks (a speed whose last break falls
    just after the end by rounding, or a part turn) finishes with its contacts exact: the
    coordinates it does not compute are NaN in the samples only, never in the state."""
    case = Case(TRAIN, CAM, rpm(speed))
    settings = RunSettings(revolutions=revolutions, integrator="modal-exact")
    full = run_batch([case], settings)
    lean = run_batch([case], settings, full_state=False)
    assert np.array_equal(full.valve_lift, lean.valve_lift)
    assert np.isnan(lean.q[0, :, 1:6]).all() and np.isfinite(lean.q[0, :, [0, 6]]).all()


def test_overdamped_modes_against_an_independent_integrator():
    """Modes with real eigenvalues (overdamped: summed once, where modal-exact sums one mode of
    each conjugate pair doubled) give the same separation run as SciPy's DOP853 through the
    same events (``campipe.bench.ivp``, written from the matrices, not the modal forms)."""
    import dataclasses

    from campipe.bench.ivp import solve_case
    from campipe.engine.batch import train_modal

    train = dataclasses.replace(TRAIN, damping_ratios=(1.8, 0.1, 1.5, 0.1, 0.1, 0.1, 0.1))
    data = train_modal(train)
    ns = 2 * data.n_free[1]
    # configuration II: two overdamped modes
    assert np.sum(data.eigenvalues[1, :ns].imag == 0.0) == 4
    case = Case(train, CAM, rpm(11000))
    ours = run_batch([case], RunSettings(revolutions=2))
    peer = solve_case(case, 2, method="DOP853", rtol=1e-10)
    assert ours.cam_impacts[0] >= 2 and len(ours.events[0]) == len(peer.events)
    assert np.max(np.abs(ours.valve_lift[0] - peer.valve_lift)) < 1e-9 * INCH


def _event_angles(case, revolutions=4):
    res = run(case, revolutions=revolutions)
    ev = res.events[0]
    return ev[:, EV_KIND], np.degrees(ev[:, EV_TIME] * case.speed)


@pytest.mark.parametrize("seat", [None, 0.1 * INCH])
def test_critical_damping_is_propagated_exactly(seat):
    """ζ1 = 1 makes configuration II's first mode a defective pair (one eigenvector: a modal
    basis is singular there); the block form propagates it exactly. ζ1 = 1 and 1 ± 1e-9 give
    the same events to 1e-6°; 1 − 1e-6 and 1 − 1e-5 move them by amounts in the ratio 1 : 10
    (to 2 %): the response is smooth and linear in ζ1 through critical damping, as the exact
    solution is. Broken copy: with the eigenvector basis the preset with ζ1 = 1 logged 133
    zero-time impacts, and 1 − 1e-9 stopped with a chatter error."""

    def angles(zeta):
        train = TRAIN.replace(damping_ratios=(zeta,) + TRAIN.damping_ratios[1:])
        kw = {} if seat is None else {"seat": seat}
        return _event_angles(Case(train, CAM, rpm(13205 if seat else 11000), **kw))

    kinds, at_one = angles(1.0)
    assert at_one.size >= 12
    for zeta in (1.0 - 1e-9, 1.0 + 1e-9):
        k, a = angles(zeta)
        assert_array_equal(k, kinds)
        assert_allclose(a, at_one, rtol=0, atol=1e-6)
    k6, a6 = angles(1.0 - 1e-6)
    k5, a5 = angles(1.0 - 1e-5)
    assert_array_equal(k6, kinds) and assert_array_equal(k5, kinds)
    d6, d5 = a6 - at_one, a5 - at_one
    big = np.abs(d5) > 1e-5  # events that move measurably
    assert big.sum() >= 10
    assert_allclose(d6[big] / d5[big], 0.1, atol=0.002)


def test_a_millionth_off_critical_damping_moves_the_events_in_an_independent_integrator_too():
    """ζ1 = 1 − 1e-6 moves the events of the 11000 rpm run by about 6e-5° from ζ1 = 1, not by
    less than 1e-6°: the solve_ivp peer (``campipe.bench.ivp``: DOP853 on the matrices, which
    never forms the block form) moves them by the same amounts to 1e-8°. The sensitivity to
    ζ1 is the model's, not the propagation's. Broken copy (run): a block form that takes a
    nearly critical block as critical (δ² rounded to 0 below 1e-5·λ̄²) moves the events by up
    to 3e-4°, the other way, and fails."""
    from campipe.bench.ivp import solve_case

    def angles(zeta):
        train = TRAIN.replace(damping_ratios=(zeta,) + TRAIN.damping_ratios[1:])
        case = Case(train, CAM, rpm(11000))
        ours = run(case, revolutions=2, tolerance=1e-14).events[0]
        peer = solve_case(case, 2, method="DOP853", rtol=1e-13).events
        assert_array_equal(ours[:, EV_KIND], peer[:, EV_KIND])
        return (np.degrees(ev[:, EV_TIME] * case.speed) for ev in (ours, peer))

    ours_1, peer_1 = angles(1.0)
    ours_6, peer_6 = angles(1.0 - 1e-6)
    shift = ours_6 - ours_1
    assert len(shift) >= 12 and np.all((np.abs(shift) > 4e-5) & (np.abs(shift) < 1e-4))
    assert_allclose(shift, peer_6 - peer_1, rtol=0, atol=1e-8)
