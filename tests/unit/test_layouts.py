"""model.layout: a lumped chain of masses against the closed forms of a two-mass chain, its
placeholders at rest, its refusals; the thesis's layout unchanged."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.batch import valve_ratio, valve_reference
from campipe.model import (
    ModelParameterError,
    coordinates,
    modal_damping_ratios,
    placeholders,
    system_matrices,
    thesis_train,
    train_lash_seat,
    used_coordinates,
    valve_train,
)
from campipe.model.assembly import configuration_frequencies, normal_modes
from campipe.profiles import harmonic
from campipe.vocabulary import CAM_AND_SEAT, CAM_CONTACT, FREE, SEAT, SEATED

RPM = 2.0 * math.pi / 60.0
#: The issue's chain, in SI.
M1, M2, LINK, RATE, PRELOAD, ZETA = 0.05, 0.06, 20000e3, 40e3, 250.0, 0.05
LUMPED = {
    "layout": "lumped",
    "masses": ["0.05 kg", "0.06 kg"],
    "stiffnesses": ["20000 N/mm"],
    "spring_rate": "40 N/mm",
    "spring_preload": "250 N",
    "damping_ratios": [0.05, 0.05],
}
LIFT = 0.01  # the harmonic cam's lift [m]


def chain(**changes):
    return valve_train("thesis-1971", {**LUMPED, **changes})


def two_mass_free() -> np.ndarray:
    """The roots ω² of m1·m2·ω⁴ − (m1·(k + ks) + m2·k)·ω² + k·ks = 0: the chain on its spring,
    both masses free."""
    a, b, c = M1 * M2, -(M1 * (LINK + RATE) + M2 * LINK), LINK * RATE
    disc = math.sqrt(b * b - 4 * a * c)
    return np.sqrt(np.array([(-b - disc) / (2 * a), (-b + disc) / (2 * a)]))


def test_the_chain_s_frequencies_are_the_two_mass_closed_forms():
    """Every mass free: the quadratic's roots; the cam mass prescribed: the valve on its link
    and spring, √((k + ks)/m2); the valve seated: the cam mass on its link, √(k/m1); both
    held: nothing free but the placeholders, all below the chain's lowest. Fails on a copy
    that puts the valve spring on the cam's mass, or leaves the link out of the valve's row."""
    sm = system_matrices(chain())
    free = two_mass_free()
    expected = {
        FREE: free,
        CAM_CONTACT: [math.sqrt((LINK + RATE) / M2)],
        SEATED: [math.sqrt(LINK / M1)],
        CAM_AND_SEAT: [],
    }
    spare = placeholders(chain())
    assert list(spare) == [1, 2, 3, 4, 5]
    for cfg, omegas in expected.items():
        found = configuration_frequencies(sm.mass, sm.stiffness, cfg)
        chain_modes = found[found > 0.9 * free[0]]
        assert_allclose(chain_modes, omegas, rtol=1e-9)
        assert found.size - chain_modes.size == spare.size  # the placeholders, below
    # the chain's own modes (the placeholders left out) carry damping_ratios exactly
    used = used_coordinates(chain())
    sub = np.ix_(used, used)
    omega, phi = normal_modes(sm.mass[sub], sm.stiffness[sub], np.ones(2, bool))
    assert_allclose(omega, free, rtol=1e-12)
    assert_allclose(modal_damping_ratios(sm.damping[sub], phi, omega), [ZETA, ZETA], rtol=1e-9)


def test_the_chain_s_coordinates_and_signs():
    """q1 the cam's mass (positive away from the lift), q7 the valve (opening), mass 3 of a
    three-mass chain q2; an eight-mass chain puts its seventh mass after q7. The cam's mass
    enters K12 with a + (its coordinate points the other way), as the thesis's pushrod foot.
    Fails on a copy that numbers the valve as the chain's last index."""
    names = [c.name for c in coordinates(chain())]
    assert names == ["cam_mass", "unused", "unused", "unused", "unused", "unused", "valve"]
    sm = system_matrices(chain())
    assert sm.stiffness[0, SEAT] == pytest.approx(LINK)  # +k: q1 = −x1
    assert sm.mass[0, 0] == M1 and sm.mass[SEAT, SEAT] == M2
    eight = chain(masses=[f"{0.01 * (i + 1)} kg" for i in range(8)], stiffnesses=["1e4 N/mm"] * 7)
    assert eight.n_coordinates == 8
    e = system_matrices(eight)
    assert e.mass[SEAT, SEAT] == pytest.approx(0.08) and e.mass[7, 7] == pytest.approx(0.07)
    assert e.stiffness[7, SEAT] == pytest.approx(-1e7)  # mass 7 linked to the valve
    assert placeholders(eight).size == 0
    assert [c.name for c in coordinates(eight)][6:] == ["valve", "mass_7"]


def test_static_preload_and_deflection():
    """Cam on its base circle: the preload compresses the link, the valve stands at
    −P/(k + ks); a unit of cam lift lifts the valve k/(k + ks); the cam force at 10 rpm is the
    static k·(P + ks·x1)/(k + ks) at the base circle and the nose. Fails on a copy whose
    preload pushes the valve open (+q7), or that drops the link's give."""
    sm = system_matrices(chain())
    assert valve_reference(sm) == pytest.approx(-PRELOAD / (LINK + RATE), rel=1e-12)
    assert valve_ratio(sm) == pytest.approx(LINK / (LINK + RATE), rel=1e-9)
    run = run_batch(
        [Case(chain(), harmonic(LIFT), 10 * RPM)],
        RunSettings(revolutions=1, output_every=math.radians(1)),
    )
    # at the base circle (90°) and the nose (270°) the train stands still: no damping force,
    # and its inertia m·ω²·h/2 is 6e-4 N (2.4e-6 of the preload)
    at = [int(np.argmin(np.abs(run.cam_angle - math.radians(d)))) for d in (90, 270)]
    assert_allclose(run.cam_lift[0, at], [0.0, LIFT], atol=1e-15)
    static = LINK * (PRELOAD + RATE * np.array([0.0, LIFT])) / (LINK + RATE)
    assert_allclose(run.cam_force[0, at], static, rtol=4e-6)
    assert_allclose(run.valve_lift[0, at], [0.0, LIFT * LINK / (LINK + RATE)], atol=1e-10)


def harmonic_steady(theta: np.ndarray, omega: float, zetas) -> tuple[np.ndarray, np.ndarray]:
    """The two-mass chain's steady response to the harmonic cam with the cam mass following
    it, written here from the chain's equations: (valve lift [m], cam force [N]) at cam
    angles ``theta``. x = displacements along the lift; modal damping ``zetas`` on the free
    modes, the lower first."""
    M = np.diag([M1, M2])
    K = np.array([[LINK, -LINK], [-LINK, LINK + RATE]])
    s = np.diag(1.0 / np.sqrt([M1, M2]))
    lam, v = np.linalg.eigh(s @ K @ s)
    phi = s @ v  # mass-normalised
    C = M @ phi @ np.diag(2.0 * np.asarray(zetas) * np.sqrt(lam)) @ phi.T @ M
    x1_mean, x1_amp = LIFT / 2.0, -LIFT / 2.0  # x1 = h/2 + Im(X1·e^{iθ}), h/2·(1 − sin θ)
    a2 = (-PRELOAD - K[1, 0] * x1_mean) / K[1, 1]
    X2 = (
        -(1j * omega * C[1, 0] + K[1, 0])
        * x1_amp
        / (-M2 * omega**2 + 1j * omega * C[1, 1] + K[1, 1])
    )
    e = np.exp(1j * theta)
    x1 = x1_mean + np.imag(x1_amp * e)
    v1, a1 = np.imag(1j * omega * x1_amp * e), np.imag(-(omega**2) * x1_amp * e)
    x2, v2 = a2 + np.imag(X2 * e), np.imag(1j * omega * X2 * e)
    valve_lift = x2 - (-PRELOAD / K[1, 1])
    force = M1 * a1 + C[0, 0] * v1 + C[0, 1] * v2 + K[0, 0] * x1 + K[0, 1] * x2
    return valve_lift, force


@pytest.mark.parametrize("speed_rpm", [3000.0, 7000.0])
def test_steady_response_below_the_onset_is_the_harmonic_closed_form(speed_rpm):
    """The periodic start and modal-exact against the closed-form harmonic response of the
    two-mass chain (the follower on the cam throughout: below the onset, about 10 400 rpm),
    and newmark-linear at 0.2 µs close to it. Fails on a copy whose damping ratios apply to
    the placeholders' modes instead of the chain's, or whose cam force misses the cam mass's
    inertia."""
    omega, zetas = speed_rpm * RPM, (0.05, 0.02)
    case = Case(chain(damping_ratios=list(zetas)), harmonic(LIFT), omega)
    run = run_batch([case], RunSettings(revolutions=2, output_every=math.radians(2)))
    assert run.status[0] == 0 and not np.any(run.contact_state[0] != CAM_CONTACT)
    theta = run.cam_angle
    assert_allclose(run.cam_lift[0], LIFT / 2 * (1 - np.sin(theta)), atol=1e-15)
    lift, force = harmonic_steady(theta, omega, zetas)
    assert_allclose(run.valve_lift[0], lift, atol=1e-10 * LIFT)
    assert_allclose(run.cam_force[0], force, rtol=1e-7, atol=1e-6)
    nm = run_batch(
        [case],
        RunSettings(
            revolutions=2, output_every=math.radians(2), integrator="newmark-linear", dt=2e-7
        ),
    )
    half = theta >= np.pi * 2  # the second turn: the quasi-static start's transient gone
    assert_allclose(nm.valve_lift[0][half], lift[half], atol=2e-4 * LIFT)


def test_placeholders_stay_at_rest_through_separation_and_seat_impacts():
    """Above the onset with a seat: the follower leaves the cam and the valve strikes its
    seat, and the placeholders stay at rest (to round-off) in both rigid integrators. Fails
    on a copy that couples a placeholder to the chain (a stiffness or damping off its
    diagonal)."""
    case = Case(chain(), harmonic(LIFT), 16000 * RPM, seat=0.0)
    for settings in (
        RunSettings(revolutions=3),
        RunSettings(revolutions=3, integrator="newmark-linear", dt=5e-7),
    ):
        run = run_batch([case], settings, full_state=True)
        assert run.status[0] == 0
        assert run.separation_per_rev.sum() > 0  # off the cam part of each turn
        assert np.any(run.contact_state[0] == FREE)
        # at rest to round-off (modal-exact's block basis mixes at 1e-14 m, 1e-12 of the lift)
        assert np.abs(run.q[0][:, placeholders(case.train)]).max() < 1e-10 * LIFT
        assert np.all(np.isfinite(run.q[0][:, [0, SEAT]]))


def test_lumped_refusals_name_their_keys():
    """No mass, stiffnesses not one fewer, the thesis's members on a chain, a chain's masses
    on the thesis's train, damping ratios for more modes than masses or none of its own (the
    preset's): each refused naming its key. Fails on a copy that pads missing stiffnesses or
    runs an empty chain."""
    cases = [
        ({"masses": [], "stiffnesses": []}, "model.masses", "one or more"),
        ({"stiffnesses": ["1 N/mm", "2 N/mm"]}, "model.stiffnesses", "one fewer"),
        ({"pushrod_length": "9 in"}, "model.pushrod_length", "layout pushrod-rocker"),
        ({"damping_ratios": [0.1, 0.1, 0.1]}, "model.damping_ratios", "2 modes"),
        ({"masses": ["0.05", "0.06 kg"]}, "model.masses[0]", "units"),
    ]
    for changes, key, words in cases:
        with pytest.raises(ModelParameterError) as info:
            valve_train("thesis-1971", {**LUMPED, **changes}, key_prefix="model.")
        assert info.value.key == key, (changes, info.value)
        assert words in str(info.value)
    with pytest.raises(ModelParameterError) as info:
        valve_train("thesis-1971", {"masses": ["1 kg"]}, key_prefix="model.")
    assert info.value.key == "model.masses" and "layout lumped" in str(info.value)
    # the preset's seven ratios are the thesis's train's, not the chain's
    own = {k: v for k, v in LUMPED.items() if k != "damping_ratios"}
    with pytest.raises(ModelParameterError) as info:
        valve_train("thesis-1971", own, key_prefix="model.")
    assert info.value.key == "model.damping_ratios" and "needs its own" in str(info.value)


def test_the_thesis_train_is_unchanged_by_the_layout_key():
    """The default layout is the thesis's: the same train as naming it, seven coordinates,
    no placeholders. Fails on a copy whose default layout is lumped or adds coordinates."""
    train = thesis_train()
    assert train.layout == "pushrod-rocker" and train.masses == ()
    assert valve_train("thesis-1971", {"layout": "pushrod-rocker"}) == train
    assert train.n_coordinates == 7 and placeholders(train).size == 0


DIRECT = {
    "layout": "direct-acting",
    "tappet_mass": "0.05 kg",
    "valve_mass": "0.06 kg",
    "stem_stiffness": "30000 N/mm",
    "tappet_contact_stiffness": "60000 N/mm",
    "spring_rate": "40 N/mm",
    "spring_preload": "250 N",
    "damping_ratios": [0.05],
}


def test_direct_acting_is_the_two_mass_chain_of_its_named_keys():
    """A bucket tappet on its valve: the tappet's and the valve's masses, the stem and the
    tappet's contact in series (1/(1/30000 + 1/60000) = 20000 N/mm): the issue's chain, its
    matrices to the bit. Fails on a copy that adds the two stiffnesses (in parallel) or puts
    the valve's mass on the cam."""
    train = valve_train("thesis-1971", DIRECT)
    assert train.masses == (M1, M2)
    assert train.stiffnesses == pytest.approx((LINK,), rel=1e-15)
    a, b = system_matrices(train), system_matrices(chain())
    assert_allclose(a.mass, b.mass, rtol=0)
    assert_allclose(a.stiffness, b.stiffness, rtol=1e-15)
    assert_allclose(a.damping, b.damping, rtol=1e-12)
    assert [c.name for c in coordinates(train)][::6] == ["cam_mass", "valve"]


def test_a_chain_with_rayleigh_damping_needs_no_ratios():
    """Rayleigh damping on a chain takes α and β alone: a bucket tappet's without
    damping_ratios builds (it was refused until ratios were given, which it then left
    unused), holds no ratios (not the preset's seven), and damps mode j by α/(2ωⱼ) + β·ωⱼ/2
    of its two-mass closed-form frequencies. Broken copy: the refusal of a chain without its
    own ratios whatever its damping."""
    alpha, beta = 40.0, 2e-6
    own = {k: v for k, v in DIRECT.items() if k != "damping_ratios"}
    rayleigh = {"damping_kind": "rayleigh", "rayleigh_alpha": "40 s**-1", "rayleigh_beta": "2 us"}
    train = valve_train("thesis-1971", {**own, **rayleigh}, key_prefix="model.")
    assert train.damping_ratios == ()
    sm = system_matrices(train)
    k, m1, m2 = LINK, M1, M2  # free-free chain with the spring on the valve
    kv = 40e3
    a, b, c = m1 * m2, -(m1 * (k + kv) + m2 * k), k * kv
    w = np.sqrt((-b + np.array([-1.0, 1.0]) * np.sqrt(b * b - 4 * a * c)) / (2 * a))
    chain_modes = [int(np.argmin(np.abs(sm.frequencies - x))) for x in w]  # (placeholders)
    assert_allclose(sm.frequencies[chain_modes], w, rtol=1e-10)
    phi = sm.modes[:, chain_modes]
    ratios = np.diag(phi.T @ sm.damping @ phi) / (2 * w)
    assert_allclose(ratios, alpha / (2 * w) + beta * w / 2, rtol=1e-8)


def test_direct_acting_refusals_name_their_keys():
    """A direct-acting key left out, a lumped chain's masses on it, its keys on the thesis's
    train: each refused naming the key. Fails on a copy that defaults a missing mass."""
    for changes, key, words in [
        ({"stem_stiffness": "none"}, "model.stem_stiffness", "needs stem_stiffness"),
        ({"masses": ["1 kg", "1 kg"]}, "model.masses", "layout lumped"),
        ({"layout": "pushrod-rocker"}, "model.tappet_mass", "layout direct-acting"),
    ]:
        with pytest.raises(ModelParameterError) as info:
            valve_train("thesis-1971", {**DIRECT, **changes}, key_prefix="model.")
        assert info.value.key == key, (changes, info.value)
        assert words in str(info.value)


@pytest.mark.parametrize("side", ["valve", "cam"])
def test_a_chain_s_lash_places_the_seat_at_the_lash_plus_the_preload_s_give(side):
    """Seated and off its cam, the chain sheds the preload that compressed its link: the
    seat is the lash plus P/(k + ks), on either side (a chain takes the gap up as a rigid
    body), P the spring's force at the unstressed reference, the installed force less ks
    times the lash (seated, the spring pushes with the installed force); the valve then
    reads 0 on its seat and the follower stands off the cam on the base circle
    (configuration IV). Fails on a copy that measures a chain's valve-side lash at the
    thesis's rocker end (q4, a placeholder)."""
    train = chain(lash="0.2 mm", lash_side=side)
    seat = train_lash_seat(train)
    reference = PRELOAD - RATE * 0.2e-3
    assert seat == pytest.approx(0.2e-3 + reference / (LINK + RATE), rel=1e-12)
    run = run_batch([Case(train, harmonic(LIFT), 3000 * RPM)], RunSettings(revolutions=2))
    assert run.status[0] == 0 and run.valve_lift[0].min() == 0.0
    assert np.any(run.contact_state[0] == SEATED)
