"""The engine on refined members: trains of more than the thesis's seven coordinates."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from campipe.engine import (
    Case,
    RunSettings,
    RunSettingsError,
    member_loads,
    per_turn,
    periodic,
    run_batch,
    spring_histories,
)
from campipe.engine import onset as onset_search
from campipe.engine.batch import initial_state, train_matrices, valve_reference
from campipe.model import spring_clash_margin, spring_element_forces, thesis_train
from campipe.profiles import harmonic, polydyne
from campipe.vocabulary import CAM_IMPACT, EV_KIND, SEAT_IMPACT

INCH = 0.0254
TRAIN = thesis_train()
CAM = harmonic(1.0 * INCH)


def rpm(r):
    return r * 2 * math.pi / 60


def test_valve_lift_converges_at_order_two_as_the_spring_is_refined():
    """At 9000 rpm (below the no-follow onset, 9383 rpm) the valve lift of a spring in n
    elements converges at the consistent-mass bar's order 2 in 1/n: the largest change
    between n and 2n falls by 4 each doubling (observed orders 1.92, 1.98, 1.99, 2.00 from
    n = 2 … 64), and n = 16 is within 3 nm of n = 64 (observed 1.8 nm). Fails if the refined
    spring's mass or stiffness is misplaced in the engine's matrices, or its coordinates are
    dropped."""
    ns = [2, 4, 8, 16, 32, 64]
    cases = [Case(TRAIN.replace(spring_elements=n), CAM, rpm(9000)) for n in ns]
    res = run_batch(cases, RunSettings(revolutions=1, output_every=math.radians(1)))
    assert np.all(res.separation == 0.0)
    lift = res.valve_lift
    change = np.array([np.abs(lift[k + 1] - lift[k]).max() for k in range(len(ns) - 1)])
    orders = np.log2(change[:-1] / change[1:])
    assert_allclose(orders[1:], 2.0, atol=0.05)  # from n = 4 on
    assert np.abs(lift[3] - lift[-1]).max() < 3e-9


def test_a_refined_train_starts_on_its_periodic_steady_state():
    """The periodic start (run.start: periodic) with 22 coordinates (a 16-element spring):
    turn 1 repeats in turn 2 to rounding. Fails if the steady state's turn map ignores the
    internal coordinates."""
    train = TRAIN.replace(spring_elements=16)
    res = run_batch([Case(train, CAM, rpm(8000))], RunSettings(revolutions=2))
    q = res.q[0]
    assert q.shape[1] == 22 and np.isfinite(q).all()
    assert_allclose(q[360:], q[:361], atol=1e-12)


def _compare(alone, mixed, i):
    for name in ("q", "v", "acc", "cam_force", "seat_force", "contact_state", "cam_lift"):
        a = getattr(alone, name)[0]
        b = getattr(mixed, name)[i][..., : a.shape[-1]] if name in ("q", "v") else None
        b = getattr(mixed, name)[i] if b is None else b
        assert_array_equal(a, b, err_msg=name)
    for name in ("separation_per_rev", "cam_impacts_per_rev", "seat_impacts_per_rev",
                 "max_seating_velocity_per_rev", "max_cam_force_per_rev"):  # fmt: skip
        assert_array_equal(getattr(alone, name)[0], getattr(mixed, name)[i], err_msg=name)
    assert_array_equal(alone.events[0], mixed.events[i])
    assert_array_equal(alone.steps[0], mixed.steps[i])


def test_a_batch_mixing_seven_and_more_coordinates_gives_each_case_its_own_result():
    """The thesis's train (7 coordinates) with a seat at 11000 rpm (seat and cam impacts),
    a refined spring (10), and pushrod, rocker arm and stem refined together (12), run in
    one batch and each alone: bit for bit the same histories, metrics and events; the
    7-coordinate case's padding is NaN. Fails if a train's numbers depend on its batch's
    padding."""
    cases = [
        Case(TRAIN, CAM, rpm(11000), seat=0.1 * INCH),
        Case(TRAIN.replace(spring_elements=4), CAM, rpm(11000), seat=0.1 * INCH),
        Case(
            TRAIN.replace(pushrod_elements=2, rocker_valve_arm_elements=2, valve_stem_elements=3),
            CAM,
            rpm(9800),
        ),
        Case(TRAIN, CAM, rpm(9000)),
    ]
    settings = RunSettings(revolutions=2)
    mixed = run_batch(cases, settings)
    assert mixed.q.shape[2] == 12
    kinds = mixed.events[0][:, EV_KIND]
    assert np.any(kinds == SEAT_IMPACT) and np.any(kinds == CAM_IMPACT)
    assert np.any(mixed.events[1][:, EV_KIND] == SEAT_IMPACT)
    for i, case in enumerate(cases):
        _compare(run_batch([case], settings), mixed, i)
    assert np.isnan(mixed.q[0, :, 7:]).all() and np.isnan(mixed.q[1, :, 10:]).all()


def test_one_element_per_member_is_the_thesis_run_to_the_bit():
    """spring_elements = 1 is the thesis's model: its run, batched with 4- and 16-element
    springs, equals the preset's run alone (the mixed study's digest,
    tests/integration/test_digest.py, holds the rest)."""
    base = Case(TRAIN, polydyne("345", INCH, *np.radians([90, 90, 90])), rpm(9000), closure="form")
    refined = [Case(TRAIN.replace(spring_elements=n), base.profile, base.speed, closure="form")
               for n in (1, 4, 16)]  # fmt: skip
    settings = RunSettings(revolutions=2)
    _compare(run_batch([base], settings), run_batch(refined, settings), 0)


def test_newmark_linear_refuses_a_refined_train_naming_modal_exact():
    case = Case(TRAIN.replace(spring_elements=4), CAM, rpm(9000))
    with pytest.raises(RunSettingsError) as err:
        run_batch([case], RunSettings(revolutions=1, dt=1e-6, integrator="newmark-linear"))
    assert err.value.key == "run.integrator" and "modal-exact" in str(err.value)
    assert err.value.found == [10]


def test_member_loads_of_refined_members_at_static_equilibrium():
    """Quasi-static, the member loads do not depend on how the members are divided: a train
    with every member refined gives the thesis train's pushrod, stem and spring forces and the
    rocker's moment at the pivot (from the valve arm's first element: its last would give the
    moment at the valve end, about zero). Fails if a load is read from the wrong element."""
    refined = TRAIN.replace(
        pushrod_elements=3,
        rocker_pushrod_arm_elements=2,
        rocker_valve_arm_elements=3,
        spring_elements=4,
        valve_stem_elements=2,
    )
    loads = []
    for train in (TRAIN, refined):
        sm = train_matrices(train)
        q, _, _, _ = initial_state(Case(train, CAM, rpm(1)), sm, valve_reference(sm))
        loads.append(member_loads(train, q))
    for name in loads[0]:
        assert_allclose(loads[1][name], loads[0][name], rtol=1e-9, atol=1e-6, err_msg=name)
    assert abs(loads[0]["rocker_moment"]) > 50.0


def test_spring_histories_and_their_per_turn_extremes():
    """The spring's largest element force and clash margin are the model's functions of the
    run's coordinates; with one element the largest element force is the spring force on the
    rocker; per_turn takes each turn's samples, the turn's start included, the run's end in
    its last turn."""
    cases = [Case(TRAIN.replace(spring_elements=n), CAM, rpm(9000)) for n in (1, 4)]
    res = run_batch(cases, RunSettings(revolutions=2))
    h = [spring_histories(c.train, res.q[i]) for i, c in enumerate(cases)]
    four = cases[1].train
    assert_array_equal(h[1]["spring_clash_margin"], spring_clash_margin(four, res.q[1]))
    assert_array_equal(
        h[1]["max_spring_element_force"], spring_element_forces(four, res.q[1]).max(axis=1)
    )
    assert_array_equal(
        h[0]["max_spring_element_force"], member_loads(TRAIN, res.q[0])["spring_force"]
    )
    margin = h[0]["spring_clash_margin"]
    assert_allclose(margin, TRAIN.spring_travel_to_solid + res.q[0, :, 3], rtol=1e-12)
    turns = per_turn(margin, res.cam_angle, 2, "min")
    assert_array_equal(turns, [margin[:360].min(), margin[360:].min()])
    # The full lift leaves 0.1 in, a little more as the members give (0.105 in).
    assert np.all((turns > 0.1 * INCH) & (turns < 0.11 * INCH))


def test_the_steady_state_path_runs_refined_trains():
    """The closed-form steady state of a 15-coordinate train (spring in 8, pushrod in 2) is
    the engine's turn from its periodic start, to rounding; the no-follow onset converges
    at order 2 as the spring is refined (9382.9 rpm with one element, 9371.1 with 16; the
    change from n to 2n falls about fourfold: observed 3.2, 3.8, 3.9)."""
    cases = [
        Case(TRAIN, CAM, rpm(8000)),
        Case(TRAIN.replace(spring_elements=8, pushrod_elements=2), CAM, rpm(8000)),
    ]
    steady = periodic.steady_state(cases)
    res = run_batch(cases, RunSettings(revolutions=1))
    assert steady.q.shape == res.q.shape == (2, 361, 15)
    assert_allclose(steady.q, res.q, atol=1e-12)
    designs = [Case(TRAIN.replace(spring_elements=n), CAM, rpm(9000)) for n in (1, 2, 4, 8, 16)]
    onset = onset_search.onset_speeds(designs, rpm(8000), rpm(11000)).speed / rpm(1)
    assert_allclose(onset[[0, -1]], [9382.9, 9371.1], atol=0.2)
    change = -np.diff(onset)
    assert np.all(change > 0)
    assert np.all((change[:-1] / change[1:] > 3.0) & (change[:-1] / change[1:] < 4.5))


def test_harmonic_responses_solve_their_equation_for_trains_of_several_sizes():
    """``modal.harmonic_responses`` stacks the cases by train, each train's state padded to
    the largest: every case's ζ solves (iωI − A)ζ = −b_q − iω b_v + ω² b_a of its own train
    and configuration (I and III, the cam held) to rounding, the padding and the
    configurations that leave the cam free stay zero, and cases given in any order get the
    answers they get alone. Checked by the residual, computed here from the matrices."""
    from campipe.engine.batch import train_modal
    from campipe.engine.modal import harmonic_responses, pad_stack

    data = [train_modal(TRAIN), train_modal(TRAIN.replace(spring_elements=4))]
    a_mat = pad_stack([d.a_mat for d in data])
    b_in = pad_stack([d.b_in for d in data])
    n_free = np.stack([d.n_free for d in data])
    train = np.array([1, 0, 1, 0, 0])
    omega = rpm(np.array([6000.0, 9000.0, 9524.0, 14000.0, 300.0]))
    zeta = harmonic_responses(train, n_free, a_mat, b_in, omega)
    assert zeta.shape == (5, 4, a_mat.shape[2])
    for c, (t, w) in enumerate(zip(train, omega, strict=True)):
        for ci in range(4):
            ns = 2 * n_free[t, ci]
            if ci in (1, 3):
                assert not zeta[c, ci].any()
                continue
            a = a_mat[t, ci, :ns, :ns]
            b = b_in[t, ci, :ns, :, 0]
            rhs = -b[:, 0] - 1j * w * b[:, 1] + w * w * b[:, 2]
            residual = (1j * w * np.eye(ns) - a) @ zeta[c, ci, :ns] - rhs
            scale = np.abs(a).max() * np.abs(zeta[c, ci]).max() + np.abs(rhs).max()
            assert np.abs(residual).max() < 1e-13 * scale
            assert not zeta[c, ci, ns:].any()
        alone = harmonic_responses(train[c : c + 1], n_free, a_mat, b_in, omega[c : c + 1])
        assert_array_equal(alone[0], zeta[c])


def test_the_kernels_harmonic_responses_are_numpy_s_solve():
    """modal-exact computes each case's ζ at its start (``closed_form.harmonic_response``,
    elimination with partial pivoting): for trains of two sizes, seated or not, at five
    speeds, configuration I's and (seated) III's agree with numpy's LAPACK solve
    (``modal.harmonic_responses``) to 1e-13 of ζ (the block form X (iωI − B)⁻¹ X⁻¹ is 5e-12
    off). Fails with a sign of ω's term flipped, III left out, or the block form."""
    from campipe.engine import batch as B
    from campipe.engine import exact, integrators
    from campipe.engine.integrators.modal_exact import arguments
    from campipe.engine.modal import harmonic_responses, pad_stack

    trains = [TRAIN, TRAIN.replace(spring_elements=4)]
    speeds = rpm(np.array([300.0, 6000.0, 9000.0, 9524.0, 14000.0]))
    cases = [
        Case(trains[k % 2], CAM, w, seat=0.0 if k % 3 == 0 else math.nan)
        for k, w in enumerate(speeds)
    ]
    settings = RunSettings(revolutions=1)
    batch = B._prepare_batch(cases, settings, True)
    start = B._starts(cases, settings, batch, in_run=True)
    run = batch.cases._replace(**start._asdict())
    method = integrators.get("modal-exact")
    exact.modal_exact_batch(
        *arguments(method.prepare(batch, settings), run, B._outputs(batch, settings))
    )
    data = [B.train_modal(t) for t in batch.trains]
    expected = harmonic_responses(
        batch.which,
        np.stack([d.n_free for d in data]),
        pad_stack([d.a_mat for d in data]),
        pad_stack([d.b_in for d in data]),
        speeds,
    )
    got = batch.runs.zeta
    for c, case in enumerate(cases):
        for ci in (0, 2) if case.has_seat else (0,):
            scale = np.abs(expected[c, ci]).max()
            assert scale > 0 and np.abs(got[c, ci] - expected[c, ci]).max() < 1e-13 * scale
