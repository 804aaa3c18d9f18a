"""Impacts with a coefficient of restitution (``cam_restitution``, ``seat_restitution``): a
bouncing series against its closed form, resolved to the capture instant; the full train
against the independent solve_ivp peer; the refusals. Each test says how a broken copy of what
it checks fails it."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from campipe.bench.ivp import solve_case
from campipe.engine import Case, RunSettings, RunSettingsError, run_batch
from campipe.engine import batch as engine_batch
from campipe.engine.common import GAP_LEVEL, MICRO_FLIGHT, make_outputs
from campipe.engine.exact import modal_exact_batch
from campipe.engine.kernel_call import plain
from campipe.model import ModelParameterError, thesis_train, valve_train
from campipe.model.assembly import SystemMatrices
from campipe.profiles import harmonic
from campipe.vocabulary import (
    CAM_AND_SEAT,
    CAM_CONTACT,
    EV_FROM,
    EV_IMPULSE,
    EV_KIND,
    EV_TIME,
    EV_TO,
    EV_VELOCITY,
    SEAT,
    SEAT_IMPACT,
)

INCH = 0.0254
CAM = harmonic(INCH)


def rpm(r):
    return r * math.pi / 30


# --------------------------------------------------------------------------- a closed form

#: The valve alone: a mass m on a spring k to ground, pressed up (−q7) by a preload F0, every
#: other coordinate on a spring of its own (no coupling): between impacts q7 is a harmonic
#: oscillator about q_eq = −F0/k, exactly what modal-exact propagates.
MASS, STIFFNESS, PRELOAD = 0.05, 5e4, 40.0  # [kg], [N/m], [N]
OMEGA = math.sqrt(STIFFNESS / MASS)  # 1000 rad/s
PRESS = 1e-3  # the seat sits this far below q_eq (a seat force k·PRESS = 50 N at rest) [m]
DROP = 2e-3  # the valve starts at rest this far below the seat [m]


def _valve_alone() -> SystemMatrices:
    n = 7
    stiffness = np.diag([1.1, 1.7, 2.3, 2.9, 3.7, 4.3, 1.0]) * STIFFNESS  # distinct modes
    mass = np.eye(n) * MASS
    omega = np.sqrt(np.diag(stiffness) / MASS)
    order = np.argsort(omega)
    preload = np.zeros(n)
    preload[SEAT] = -PRELOAD
    return SystemMatrices(
        mass, stiffness, np.zeros((n, n)), omega[order], np.eye(n)[:, order] / math.sqrt(MASS),
        preload,
    )  # fmt: skip


def _flight(u: float) -> tuple[float, float]:
    """The flight [s] of a valve leaving its seat at u [m/s] until it is back, and its closing
    velocity then [m/s]. Its height y = (u/ω)·sin ωτ − d·(1 − cos ωτ) (d = PRESS); a contact
    switch is decided at GAP_LEVEL of penetration, so back is y = −GAP_LEVEL: with
    R·sin(ωτ + α) = d − GAP_LEVEL, R = √((u/ω)² + d²), α = atan2(d, u/ω), the second root.
    Energy gives the closing velocity: u² + ω²d² = v² + ω²(d − GAP_LEVEL)²."""
    a, d = u / OMEGA, PRESS
    radius, alpha = math.hypot(a, d), math.atan2(d, a)
    tau = (math.pi - math.asin((d - GAP_LEVEL) / radius) - alpha) / OMEGA
    return tau, math.sqrt(u * u + OMEGA**2 * (d * d - (d - GAP_LEVEL) ** 2))


def _series(e: float, capture: float) -> tuple[np.ndarray, np.ndarray]:
    """The impacts' times [s] and closing velocities [m/s], by hand: the valve swings from
    rest at x = DROP + PRESS from its free equilibrium to the seat (x = PRESS − GAP_LEVEL),
    each bounce leaves at e times the closing velocity (``_flight``), up to the capture: the
    first impact slower than ``capture`` or whose flight since the last bounce (closing ×
    duration) is below MICRO_FLIGHT."""
    amplitude, level = DROP + PRESS, PRESS - GAP_LEVEL
    t = math.acos(level / amplitude) / OMEGA
    v = OMEGA * math.sqrt(amplitude**2 - level**2)
    times, speeds = [t], [v]
    while v >= capture:
        flight, v = _flight(e * v)
        t += flight
        times.append(t)
        speeds.append(v)
        if v * flight < MICRO_FLIGHT:
            break
    return np.array(times), np.array(speeds)


@pytest.fixture
def valve_alone(monkeypatch):
    """The thesis's train replaced by ``_valve_alone`` wherever the engine asks for its
    matrices (and the per-train caches cleared before and after)."""
    engine_batch.prepare.cache_clear()
    engine_batch.train_modal.cache_clear()
    monkeypatch.setattr(engine_batch, "train_matrices", lambda train: _valve_alone())
    yield
    monkeypatch.undo()
    engine_batch.prepare.cache_clear()
    engine_batch.train_modal.cache_clear()


def _bounce(e: float, capture: float):
    """modal-exact on the valve alone, started at rest DROP below its seat (the cam held by
    form closure and decoupled): its events."""
    train = thesis_train().replace(seat_restitution=e)
    case = Case(train, CAM, rpm(3000), seat=PRESS, closure="form")
    settings = RunSettings(
        revolutions=1, capture_velocity=capture, integrator="modal-exact", tolerance=1e-15
    )
    b = engine_batch._prepare_batch([case], settings, True)
    q0 = np.zeros((1, b.cases.q0.shape[1]))
    q0[0, SEAT] = b.cases.seat_q[0] + DROP
    q0[0, 0] = -engine_batch.cam_at(b.packed, 0.0)[0, 0]
    cases = b.cases._replace(
        q0=q0, cfg0=np.array([CAM_CONTACT]), lift_bound=np.array([np.inf]),
        speed_bound=np.array([np.inf]),
    )  # fmt: skip
    n_q = q0.shape[1]
    out = make_outputs(1, 2, 1, 256, n_q)
    ws = engine_batch.make_workspace(n_q)
    modal_exact_batch(
        *plain(cases, b.modal_trains, b.packed, b.runs, out, ws),
        np.zeros(1, engine_batch.STATE),
        None,  # no carried plunger
    )
    assert out.status[0] == 0
    return out.events[0, : out.n_events[0]]


@pytest.mark.parametrize(("e", "capture"), [(0.5, 5e-3), (0.5, 0.0), (0.8, 1e-3)])
def test_a_bouncing_valve_is_its_geometric_series_to_the_capture(valve_alone, e, capture):
    """The valve alone dropped on its seat: the impacts form the closed form's geometric
    series (closing velocities v0·eᵏ, flights 2·atan(u/(ω·d))/ω), every bounce leaving the seat
    open (configuration I), and the series ends at the capture instant: the last impact is
    plastic and leaves the valve resting on its seat (III), with nothing after it. The
    capture velocity ends the first series (10 bounces), the converged flights (MICRO_FLIGHT)
    the second, where the capture velocity is 0 (12); the recorded impulse is the momentum
    balance m·(1 + e)·v of a bounce, m·v of the capture.

    Broken copies: a bounce leaving at v instead of e·v fails the velocities; a series that
    never captures (the converged-flight test in ``exact._impact`` made to fail) runs on in
    micro-bounces past the 256 kept events with capture 0 (status EVENTS_TRUNCATED, run)."""
    times, speeds = _series(e, capture)
    ev = _bounce(e, capture)
    assert np.all(ev[:, EV_KIND] == SEAT_IMPACT)
    assert len(ev) == len(times)
    assert_allclose(ev[:, EV_TIME], times, rtol=0, atol=1e-13)
    assert_allclose(ev[:, EV_VELOCITY], speeds, rtol=1e-9)
    assert np.all(ev[:-1, EV_FROM] == CAM_CONTACT) and np.all(ev[:-1, EV_TO] == CAM_CONTACT)
    assert ev[-1, EV_TO] == CAM_AND_SEAT
    gain = np.r_[np.full(len(ev) - 1, 1.0 + e), 1.0]
    assert_allclose(ev[:, EV_IMPULSE], MASS * gain * speeds, rtol=1e-9)


# --------------------------------------------------------------------------- the full train


@pytest.mark.parametrize(("e", "speed"), [(0.5, 1000), (0.5, 9000), (0.3, 13205)])
def test_bounces_of_the_thesis_train_agree_with_the_solve_ivp_peer(e, speed):
    """The thesis's train with restitution at both contacts, seat at 0.1 in: modal-exact and
    the solve_ivp peer (``campipe.bench.ivp``: DOP853 on the matrices, its impacts written
    again) give the same events, kinds, counts and times to 1e-6°, closing velocities to
    1e-4; the valve bounces (several seat impacts a turn, the seat left open after each but
    the last of a series). Broken copy: the free coordinates' share of a bounce's impulse not
    scaled by 1 + e in ``exact._impact`` gives 36, 91 and 38 events against the peer's 38, 76
    and 37 (run)."""
    train = thesis_train().replace(seat_restitution=e, cam_restitution=e)
    case = Case(train, CAM, rpm(speed), seat=0.1 * INCH)
    res = run_batch([case], RunSettings(revolutions=1, tolerance=1e-14))
    peer = solve_case(case, 1, method="DOP853", rtol=1e-12)
    ours, theirs = res.events[0], peer.events
    assert len(ours) == len(theirs)
    assert_allclose(ours[:, EV_KIND], theirs[:, EV_KIND])
    assert_allclose(ours[:, EV_TO], theirs[:, EV_TO])
    assert_allclose(ours[:, EV_TIME] * case.speed, theirs[:, EV_TIME] * case.speed,
                    atol=math.radians(1e-6))  # fmt: skip
    assert_allclose(ours[:, EV_VELOCITY], theirs[:, EV_VELOCITY], rtol=1e-4, atol=1e-9)
    seated = ours[ours[:, EV_KIND] == SEAT_IMPACT]
    assert res.seat_impacts_per_rev[0, 0] >= 5
    assert np.sum(seated[:, EV_TO] != seated[:, EV_FROM]) < len(seated)  # bounces stay open


def test_plastic_is_the_default_and_restitution_changes_the_run():
    """Restitution 0 (the default) is the thesis's plastic impact: its events are those of the
    preset train bit for bit; 0.5 makes the seat bounce (more seat impacts, at the same first
    closing velocity). Broken copy: a restitution read from the wrong contact (the cam's for
    the seat) leaves the seat plastic and fails the second half."""
    base = Case(thesis_train(), CAM, rpm(1000), seat=0.1 * INCH)
    zero = Case(thesis_train().replace(seat_restitution=0.0), CAM, rpm(1000), seat=0.1 * INCH)
    bouncy = Case(thesis_train().replace(seat_restitution=0.5), CAM, rpm(1000), seat=0.1 * INCH)
    res = run_batch([base, zero, bouncy], RunSettings(revolutions=2))
    assert np.array_equal(res.events[0], res.events[1])
    assert res.seat_impacts_per_rev[2, 1] > res.seat_impacts_per_rev[0, 1] + 3
    first = [ev[ev[:, EV_KIND] == SEAT_IMPACT][0, EV_VELOCITY] for ev in res.events]
    assert first[2] == pytest.approx(first[0], rel=1e-9)


# --------------------------------------------------------------------------- refusals


def test_newmark_linear_refuses_restitution():
    """newmark-linear applies the thesis's plastic impacts only: a train with restitution is
    refused at run.integrator, naming modal-exact. Broken copy: without the check the run
    silently applies plastic impacts."""
    case = Case(thesis_train().replace(seat_restitution=0.4), CAM, rpm(1000), seat=0.1 * INCH)
    with pytest.raises(RunSettingsError, match="modal-exact") as info:
        run_batch([case], RunSettings(revolutions=1, integrator="newmark-linear"))
    assert info.value.key == "run.integrator" and "seat_restitution" in str(info.value)


def test_a_compliant_contact_refuses_a_restitution():
    """A compliant contact's restitution comes from its damping: seat_restitution beside
    seat_contact hertz is refused, naming the key and the damping constant to set. Broken
    copy: dropping "rigid" from CONTACT_CONSTANTS lets it through."""
    with pytest.raises(ModelParameterError, match="seat_hunt_crossley") as info:
        valve_train(
            overrides={
                "seat_contact": "hertz",
                "seat_hertz_constant": "1e7 lbf/in**1.5",
                "seat_restitution": 0.5,
            }
        )
    assert info.value.key == "seat_restitution"


def test_restitution_is_a_model_parameter_between_0_and_1():
    """The spec takes seat_restitution as a number in [0, 1]; 1.2 is refused naming the key.
    Broken copy: no maximum lets an impact gain energy."""
    assert valve_train(overrides={"seat_restitution": 0.6}).seat_restitution == 0.6
    with pytest.raises(ModelParameterError) as info:
        valve_train(overrides={"seat_restitution": 1.2})
    assert info.value.key == "seat_restitution"
