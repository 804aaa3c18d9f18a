"""Refined members and physical damping (issue 16): convergence to closed forms, the thesis's
model unchanged to the bit, Rayleigh and loss-factor damping against hand calculations."""

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from campipe.constants import STANDARD_GRAVITY
from campipe.model import (
    ELEMENTS,
    ModelParameterError,
    coordinates,
    modal_damping_ratios,
    n_coordinates,
    newmark_linear_stability_limit,
    spring_clash_margin,
    spring_element_forces,
    system_matrices,
    thesis_train,
    valve_train,
)
from campipe.model.assembly import assemble, frequency_convergence, observed_orders
from campipe.model.elements import bar_mass, bar_stiffness, elements
from campipe.vocabulary import CONFIGURATIONS, free_coordinates
from tests.references import assert_recorded, recorded_digests

THESIS_MATRICES = Path(__file__).parents[1] / "data" / "thesis-matrices.sha256"
COUNTS = (2, 4, 8, 16)


def slope(counts, errors) -> float:
    """Least-squares slope of log(error) against log(1/n): the observed order."""
    return float(np.polyfit(np.log(1.0 / np.asarray(counts)), np.log(errors), 1)[0])


def thesis_matrix_digest(name: str) -> str:
    """SHA-256 of the preset's ``name`` matrix's bytes."""
    return hashlib.sha256(getattr(system_matrices(thesis_train()), name).tobytes()).hexdigest()


def test_the_thesis_model_is_the_one_element_case_unchanged_to_the_bit():
    """M, K and C of the preset hash to the bytes they had before members could be refined
    (``tests/data/thesis-matrices.sha256``, written by commit 9a16481's ``system_matrices``).
    Fails if the refinement changes one operation of the one-element path: a mass m/n or a
    length L/n computed another way, another element order in the sums, the modes' signs, or
    damping ratios extended or converted differently. C comes from LAPACK's modes, whose last
    bits are a platform's (tests/integration/test_digest.py): one digest per platform."""
    for name in ("mass", "stiffness", "damping"):
        assert getattr(system_matrices(thesis_train()), name).shape == (7, 7)
        recorded = recorded_digests(THESIS_MATRICES, name)
        digest = thesis_matrix_digest(name)
        assert_recorded(digest, recorded, __file__, f"thesis_matrix_digest({name!r})")
    # The defaults are the thesis's: one element each, modal damping.
    train = thesis_train()
    assert [train.elements_of(m) for m in ELEMENTS] == [1] * 5
    assert train.damping_kind == "modal" and n_coordinates(train) == 7


def test_clamped_free_bar_converges_at_the_consistent_mass_rate():
    """A bar (stiffness k = EA/L, mass m) fixed at one end, free at the other, assembled from
    n of the model's bar elements (stiffness n·k, mass m/n). Its frequencies converge to the
    continuous bar's ω_j = (2j − 1)π/2·√(k/m) at order 2 in 1/n, from above, within the
    consistent-mass bound (θ²/24, θ = κ·L/n), and equal the discrete chain's dispersion
    relation ω = (n/L)·c·√(6(1 − cos θ)/(2 + cos θ)) to round-off. Fails if ``bar_mass`` is
    lumped ((m/2)·I: off the dispersion relation, converging from below) or its coupling
    changes ((m/6)·[[2, −1], [−1, 2]], (m/4)·[[2, 1], [1, 2]]: another limit), or if
    ``bar_stiffness`` loses a sign."""
    k, m = 3.0e5, 2.0e-3  # [N/m], [kg]
    j = np.arange(1, 3)
    theta_l = (2 * j - 1) * math.pi / 2  # κ·L of the clamped–free modes
    exact = theta_l * math.sqrt(k / m)
    errors = []
    for n in COUNTS:
        K = np.zeros((n + 1, n + 1))
        M = np.zeros((n + 1, n + 1))
        for i in range(n):
            K[i : i + 2, i : i + 2] += bar_stiffness(n * k)
            M[i : i + 2, i : i + 2] += bar_mass(m / n)
        omega = np.sqrt(scipy.linalg.eigh(K[1:, 1:], M[1:, 1:], eigvals_only=True))[:2]
        theta = theta_l / n
        dispersion = n * math.sqrt(k / m) * np.sqrt(6 * (1 - np.cos(theta)) / (2 + np.cos(theta)))
        assert_allclose(omega, dispersion, rtol=1e-12)
        relative = omega / exact - 1
        assert np.all(relative > 0)
        assert np.all(relative <= 1.01 * theta**2 / 24)
        errors.append(relative)
    errors = np.array(errors)
    for mode in range(2):
        assert abs(slope(COUNTS, errors[:, mode]) - 2) < 0.1
        assert abs(math.log2(errors[-2, mode] / errors[-1, mode]) - 2) < 0.01
    assert errors[-1, 0] < 4.1e-4  # n = 16, fundamental: (π/32)²/24


def _spring_with_tip_mass(train, tip_mass):
    """The model's own spring elements, on ground, with ``tip_mass`` [kg] on q4: (K, M) over
    q4 and the spring's internal coordinates."""
    n = n_coordinates(train)
    K = np.zeros((n, n))
    M = np.zeros((n, n))
    for e in elements(train):
        if e.name == "spring":
            K += e.beta.T @ e.stiffness @ e.beta
            M += e.beta.T @ e.mass @ e.beta
    used = [3, *(i for i, c in enumerate(coordinates(train)) if c.name.startswith("spring_"))]
    M[3, 3] += tip_mass
    return K[np.ix_(used, used)], M[np.ix_(used, used)]


def test_spring_with_the_valve_mass_at_its_end_converges_to_the_transcendental_roots():
    """The thesis's spring (rate k, equivalent-wire mass m_s) divided into n elements by the
    model itself (``spring_elements``, its compatibility matrices and internal coordinates),
    grounded, with the valve stem's mass m_t on its end (q4). A uniform bar fixed at one end
    with a tip mass has ω_j = β_j·√(k/m_s), β tan β = m_s/m_t. The error falls at order 2
    in 1/n, from above, within (β/n)²/24. Fails if the spring's elements get the rate k
    instead of n·k (the limit is wrong by √n), the wire's whole mass instead of m_s/n, or
    internal nodes wired to the wrong coordinates."""
    base = thesis_train()
    density = base.specific_weight / STANDARD_GRAVITY
    m_s = density * math.pi * base.spring_diameter**2 / 4 * base.spring_length
    m_t = density * math.pi * base.valve_stem_diameter**2 / 4 * base.valve_stem_length
    ratio = m_s / m_t
    beta = np.array(
        [
            brentq(
                lambda b: b * math.tan(b) - ratio, j * math.pi, j * math.pi + math.pi / 2 - 1e-12
            )
            for j in range(2)
        ]
    )
    exact = beta * math.sqrt(base.spring_rate / m_s)
    errors = []
    for n in COUNTS:
        K, M = _spring_with_tip_mass(base.replace(spring_elements=n), m_t)
        assert K.shape == (n, n)
        omega = np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True))[:2]
        relative = omega / exact - 1
        assert np.all(relative > 0)
        assert np.all(relative <= 1.01 * (beta / n) ** 2 / 24)
        errors.append(relative)
    errors = np.array(errors)
    for mode in range(2):
        assert abs(slope(COUNTS, errors[:, mode]) - 2) < 0.1
        assert abs(math.log2(errors[-2, mode] / errors[-1, mode]) - 2) < 0.03
    assert errors[-1, 0] < 1.5e-4


def test_refined_members_condense_back_to_the_thesis_matrices():
    """Every member divided into 3 elements, the internal coordinates condensed out statically
    (Guyan: q_internal = −K_bb⁻¹ K_ba q_thesis). Bars are exact for end loads (springs in
    series) and cubic beams for end forces and moments, and the static shapes (linear, cubic)
    lie in the elements' spaces, so the condensed K and M equal the one-element thesis
    matrices to round-off, with q1 … q7 still at indices 0–6. Fails on an internal node wired
    to a wrong coordinate or sign, a beam node's (v, θ) swapped, a length or mass split
    other than L/n, m/n, or the thesis's coordinates moved."""
    base = thesis_train()
    refined = base.replace(**{f"{m}_elements": 3 for m in ELEMENTS})
    assert n_coordinates(refined) == 7 + 2 * (1 + 2 + 2 + 1 + 1)  # two internal nodes each
    M, K = assemble(refined)
    a, b = np.arange(7), np.arange(7, M.shape[0])
    transform = np.vstack([np.eye(7), -np.linalg.solve(K[np.ix_(b, b)], K[np.ix_(b, a)])])
    M7, K7 = assemble(base)
    assert_allclose(transform.T @ K @ transform, K7, rtol=0, atol=1e-9 * np.abs(K7).max())
    assert_allclose(transform.T @ M @ transform, M7, rtol=0, atol=1e-12 * np.abs(M7).max())


def test_refined_train_keeps_the_thesis_coordinates_and_names_the_new_ones():
    """The thesis's seven come first with their symbols; the internal nodes follow member by
    member, a beam's as (v, θ) pairs. Fails if the order of the appended coordinates and the
    compatibility matrices disagree (the spring's nodes named but wired elsewhere)."""
    train = thesis_train().replace(rocker_valve_arm_elements=2, spring_elements=3)
    coords = coordinates(train)
    assert [c.symbol for c in coords[:7]] == [f"q{i}" for i in range(1, 8)]
    assert [c.name for c in coords[7:]] == [
        "rocker_valve_arm_1",
        "rocker_valve_arm_1_rotation",
        "spring_1",
        "spring_2",
    ]
    assert [c.kind for c in coords[7:]] == ["translation", "rotation", "translation", "translation"]
    assert [c.symbol for c in coords[7:]] == ["q8", "q9", "q10", "q11"]
    # The spring's elements run ground → spring_1 → spring_2 → q4.
    chain = [e.beta for e in elements(train) if e.name == "spring"]
    assert [tuple(np.flatnonzero(beta.any(axis=0))) for beta in chain] == [(9,), (9, 10), (3, 10)]
    # The contacts stay at 0 and 6: configuration III holds them whatever n is.
    assert free_coordinates(3, 11) == (1, 2, 3, 4, 5, 7, 8, 9, 10)
    assert free_coordinates(2, 11) == tuple(range(11))
    assert all(free_coordinates(c, 7) == CONFIGURATIONS[c].free for c in CONFIGURATIONS)


def test_spring_surge_modes_approach_the_fixed_fixed_spring():
    """A spring of 16 elements gives the train modes near the spring's own fixed–fixed surge
    frequencies jπ·√(k/m_s) (4917 and 9834 rad/s for the thesis's spring: at those
    frequencies the rest of the train barely moves q4), which the one-element spring cannot
    have. A loose check (q4 is not quite fixed, n is finite): within 3 %. Fails if the
    spring's mass is not spread along it."""
    base = thesis_train()
    density = base.specific_weight / STANDARD_GRAVITY
    m_s = density * math.pi * base.spring_diameter**2 / 4 * base.spring_length
    surge = math.pi * math.sqrt(base.spring_rate / m_s) * np.arange(1, 3)
    one = system_matrices(base).frequencies
    assert not np.any(np.abs(one / surge[0] - 1) < 0.5)
    refined = system_matrices(base.replace(spring_elements=16)).frequencies
    for w in surge:
        assert np.min(np.abs(refined / w - 1)) < 0.03


def test_stability_limits_of_a_refined_train_hold_coordinates_0_and_6():
    """newmark-linear's limit √12/ω_max in each configuration of a train with a refined
    pushrod and spring, against the eigenvalues of M and K with the held rows and columns
    deleted by hand (q1 for the cam, q7 for the seat). Fails if the configurations hold the
    last coordinates, or only the first seven are kept."""
    sm = system_matrices(thesis_train().replace(pushrod_elements=4, spring_elements=2))
    n = sm.mass.shape[0]
    assert n == 11
    held = {1: [0], 2: [], 3: [0, 6], 4: [6]}
    for c, out in held.items():
        keep = [i for i in range(n) if i not in out]
        lam = scipy.linalg.eigh(
            sm.stiffness[np.ix_(keep, keep)], sm.mass[np.ix_(keep, keep)], eigvals_only=True
        )
        limit = newmark_linear_stability_limit(sm.mass, sm.stiffness, c)
        assert_allclose(limit, math.sqrt(12 / lam.max()), rtol=1e-9)


def test_frequency_convergence_reports_order_two_for_the_spring_and_four_for_a_beam():
    """``campipe model --convergence``'s numbers: the fundamental converges at order 2 with
    the spring refined (bars) and the rocker arm's bending modes at order 4 (cubic Hermite
    beams with consistent mass). Fails if the rows are not the refined trains' frequencies."""
    freqs, roundoff = frequency_convergence(thesis_train(), "spring", n_modes=3)
    assert_allclose(
        freqs[2], system_matrices(thesis_train().replace(spring_elements=4)).frequencies[:3]
    )
    orders = observed_orders(freqs, roundoff)
    assert abs(orders[0] - 2) < 0.05 and abs(orders[1] - 2) < 0.05
    freqs, roundoff = frequency_convergence(thesis_train(), "rocker_valve_arm", n_modes=4)
    orders = observed_orders(freqs, roundoff)
    assert np.all(np.abs(orders[1:] - 4) < 0.2)


def test_rayleigh_damping_gives_each_mode_alpha_over_two_omega_plus_beta_omega_over_two():
    """C = α·M + β·K with mass-normalised Φ: Φᵀ C Φ = α·I + β·diag(ω²), so mode j's ratio is
    α/(2ωⱼ) + β·ωⱼ/2 and the modes stay uncoupled; on the thesis train and on one with a
    refined spring. Fails if α and β are swapped, either is scaled (2α, β/2), or the
    preset's modal ratios are added."""
    alpha, beta = 40.0, 2.0e-7  # [1/s], [s]
    for changes in ({}, {"spring_elements": 4}):
        train = thesis_train().replace(
            damping_kind="rayleigh", rayleigh_alpha=alpha, rayleigh_beta=beta, **changes
        )
        sm = system_matrices(train)
        w = sm.frequencies
        modal = sm.modes.T @ sm.damping @ sm.modes
        expected = alpha / (2 * w) + beta * w / 2
        assert_allclose(np.diag(modal) / (2 * w), expected, rtol=1e-8)
        assert_allclose(modal_damping_ratios(sm.damping, sm.modes, w), expected, rtol=1e-8)
        off = modal - np.diag(np.diag(modal))
        assert np.abs(off).max() < 1e-8 * np.abs(np.diag(modal)).max()
    # The spec form: quantities with units.
    t = valve_train(
        overrides={
            "damping_kind": "rayleigh",
            "rayleigh_alpha": "40 s**-1",
            "rayleigh_beta": "0.2 µs",
        }
    )
    assert (t.rayleigh_alpha, t.rayleigh_beta) == (40.0, pytest.approx(2e-7, rel=1e-12))


def test_loss_factor_damping_of_one_member_by_hand():
    """Only the pushrod has a loss factor η: its element is k·[[1, −1], [−1, 1]] on
    (u_foot, u_top) = (−q1, q2), so mode j stores ½k(φ1ⱼ + φ2ⱼ)² of its ½ωⱼ² in the pushrod
    (mass-normalised modes) and ζⱼ = ½η·k(φ1ⱼ + φ2ⱼ)²/ωⱼ², k = E·π·D²/4/L; the damping is
    modal, so C couples no modes. Fails with the viscous C = (η/ω₁)·K_e (ζ grows with ωⱼ), a
    sign of (q1, q2) lost, or the loss factor applied to the whole train."""
    eta = 0.04
    train = thesis_train().replace(damping_kind="loss-factor", pushrod_loss_factor=eta)
    sm = system_matrices(train)
    k = train.elastic_modulus * math.pi * train.pushrod_diameter**2 / 4 / train.pushrod_length
    phi, w = sm.modes, sm.frequencies
    expected = 0.5 * eta * k * (phi[0] + phi[1]) ** 2 / w**2
    modal = phi.T @ sm.damping @ phi
    assert_allclose(np.diag(modal) / (2 * w), expected, rtol=1e-9)
    assert_allclose(modal - np.diag(np.diag(modal)), 0.0, atol=1e-9 * np.abs(modal).max())
    assert expected.max() > 10 * expected.min() > 0  # the members' shares differ by mode


def test_one_loss_factor_on_every_member_damps_every_mode_by_half_of_it():
    """With the same η on every member, every mode's damping ratio is η/2 (the time-domain
    equivalent of structural damping), also for a refined spring. Fails with the viscous
    C = (η/ω₁)·K (ζ = 0.01, 0.38, … 15.8 on the thesis's seven modes for η = 0.02), or if a
    member (the spring, whose stiffness is not EA/L) is left out."""
    eta = 0.02
    for changes in ({}, {"spring_elements": 4, "rocker_pushrod_arm_elements": 2}):
        train = thesis_train().replace(
            damping_kind="loss-factor",
            **{f"{m}_loss_factor": eta for m in ELEMENTS},
            **changes,
        )
        sm = system_matrices(train)
        zeta = modal_damping_ratios(sm.damping, sm.modes, sm.frequencies)
        # to the eigensolver's round-off, about ε·(ω_max/ωⱼ)² relative in mode j: 1e-8 in a
        # refined train's first mode (seen 12 times ε·(ω_max/ω₁)² with one platform's LAPACK)
        w = sm.frequencies
        bound = 1e-12 + 100.0 * np.finfo(float).eps * (w[-1] / w) ** 2
        assert np.all(np.abs(zeta / (eta / 2) - 1.0) <= bound)


def test_a_short_list_of_damping_ratios_gives_its_last_value_to_the_modes_above():
    """``damping_ratios: [0.5, 0.1]`` is the preset's seven (bit for bit), and with a refined
    spring (10 modes) the preset's seven mean 0.5, then 0.1 for the nine above. More ratios
    than modes is refused, naming the key. Fails if the list is padded with zeros or
    truncated silently."""
    short = system_matrices(valve_train(overrides={"damping_ratios": [0.5, 0.1]}))
    assert short.damping.tobytes() == system_matrices(thesis_train()).damping.tobytes()
    sm = system_matrices(thesis_train().replace(spring_elements=4))
    zeta = modal_damping_ratios(sm.damping, sm.modes, sm.frequencies)
    assert_allclose(zeta, [0.5] + [0.1] * 9, rtol=1e-7)
    with pytest.raises(ModelParameterError) as err:
        valve_train(overrides={"damping_ratios": [0.1] * 8}, key_prefix="model.")
    assert err.value.key == "model.damping_ratios"
    assert "8 ratios for a train of 7 modes" in str(err.value)
    assert (
        len(
            valve_train(
                overrides={"damping_ratios": [0.1] * 8, "spring_elements": 2}
            ).damping_ratios
        )
        == 8
    )


def test_spring_element_forces_and_clash_margin_by_hand():
    """A spring of 4 elements (each 4·k): compressed uniformly by d (q4 = −d, internal nodes
    on the straight line) every element carries preload + k·d and the margin is travel − d;
    with the top internal node pushed down to q4's place, the top element is back at the
    preload, the one below it is shortened by d/2 (preload + 4·k·d/2) and the margin is
    travel + 4·(−d/2). With one element the force is the thesis's preload − k·q4. Fails on a
    sign (tension positive), a rate k per element instead of n·k, or a margin not scaled to
    the whole spring."""
    base = thesis_train()
    k, f0, travel = base.spring_rate, base.spring_preload, base.spring_travel_to_solid
    d = 0.004  # [m]
    train = base.replace(spring_elements=4)
    q = np.zeros((2, n_coordinates(train)))
    q[:, 3] = -d
    q[0, 7:10] = -d * np.array([1, 2, 3]) / 4  # spring_1 … spring_3 on the line
    q[1, 7:10] = -d * np.array([1, 2, 4]) / 4  # spring_3 pushed down to q4's place
    forces = spring_element_forces(train, q)
    assert_allclose(forces[0], f0 + k * d, rtol=1e-12)
    # Extensions of the second state: −d/4, −d/4, −d/2, 0.
    assert_allclose(forces[1], f0 + 4 * k * d * np.array([0.25, 0.25, 0.5, 0.0]), rtol=1e-12)
    assert_allclose(spring_clash_margin(train, q), [travel - d, travel - 4 * d / 2], rtol=1e-12)
    one = np.zeros(7)
    one[3] = -d
    assert_allclose(spring_element_forces(base, one), [f0 + k * d], rtol=1e-12)
    assert_allclose(spring_clash_margin(base, one), travel - d, rtol=1e-12)


def test_observed_orders_of_manufactured_sequences():
    """ω(n) = 100 + 5/n^p gives p exactly; a column that jumps between modes (the changes'
    order drifts) and one that changes by less than its round-off give NaN; three counts
    give the plain estimate. Fails if the ratio of the counts or the settling check is
    wrong."""
    counts = (1, 2, 4, 8, 16)
    n = np.array(counts, dtype=float)[:, None]
    freqs = np.hstack([100 + 5 / n**2, 100 + 5 / n**4, [[900], [400], [160], [150], [149]]])
    freqs = np.hstack([freqs, 100 + 1e-9 / n**2])
    roundoff = np.full_like(freqs, 1e-8)
    orders = observed_orders(freqs, roundoff, counts)
    assert_allclose(orders[:2], [2, 4], rtol=1e-9)
    assert np.isnan(orders[2]) and np.isnan(orders[3])
    assert_allclose(observed_orders(freqs[2:], roundoff[2:], counts[2:])[:2], [2, 4], rtol=1e-9)
    with pytest.raises(ValueError, match="geometric"):
        observed_orders(freqs[:3], roundoff[:3], (1, 2, 5))
