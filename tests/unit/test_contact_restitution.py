"""A kelvin-voigt contact's damping given as the coefficient of restitution of a landing on
it (``model.cam_restitution`` / ``seat_restitution`` with a kelvin-voigt contact): the
inverse of e(ζ), the damping c = 2·ζ·r·√(k·m) of the struck mass m against a lumped chain's
masses, the compliant integrator's own landings, the refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.batch import train_stack
from campipe.model import ModelParameterError, system_matrices, valve_train
from campipe.model.contact import contact_law
from campipe.model.contact_keys import impact_restitution
from campipe.model.contact_modes import contact_modes
from campipe.model.landing import released_restitution, restitution_damping_ratio
from campipe.profiles import polydyne
from campipe.vocabulary import CAM_IMPACT, EV_KIND, EV_TIME, EV_VELOCITY

M1, M2 = 0.05, 0.06  # [kg]
K = 2e8  # the contacts' stiffness [N/m]


def chain(masses: list[str], **changes):
    model = {
        "layout": "lumped",
        "masses": masses,
        "stiffnesses": ["20000 N/mm"] * (len(masses) - 1),
        "spring_rate": "40 N/mm",
        "spring_preload": "250 N",
        "damping_ratios": [0.05] * len(masses),
        **changes,
    }
    return valve_train("thesis-1971", model)


@pytest.mark.parametrize("zeta", [0.0, 0.01, 0.1, 0.5, 0.9, 0.999, 1.0, 1.5, 4.0, 20.0])
def test_the_damping_ratio_of_a_restitution_inverts_the_restitution_of_a_damping_ratio(zeta):
    """ζ(e(ζ)) = ζ across under-, critically and over-damped contacts (e from 1 to 6e-4).
    Fails on a bracket that never grows past ζ = 1, or the classic exp(−πζ/√(1 − ζ²))."""
    e = released_restitution(zeta)
    assert restitution_damping_ratio(e) == pytest.approx(zeta, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("e", [0.0, -0.1, 1.2, math.nan])
def test_a_restitution_outside_its_range_is_refused(e):
    with pytest.raises(ValueError, match="restitution"):
        restitution_damping_ratio(e)


def test_the_derived_damping_is_the_chains_struck_masses_closed_form():
    """A lumped chain's mass matrix is diagonal: an impulse at its cam's mass meets m1 alone,
    at its valve m2 (and a one-mass chain's seat, its follower, m1). Against those masses,
    c = 2·ζ(e)·√(k·m) with ζ(e) solved here from e(ζ) = e by bisection of the closed form.
    Fails on a copy that takes the whole chain's mass, or forgets the factor 2."""

    def zeta_of(e: float) -> float:
        lo, hi = 0.0, 50.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if released_restitution(mid) > e else (lo, mid)
        return 0.5 * (lo + hi)

    laws = {"cam_contact": "kelvin-voigt", "cam_contact_stiffness": f"{K} N/m"}
    seats = {"seat_contact": "kelvin-voigt", "seat_contact_stiffness": f"{K} N/m"}
    two = chain(["0.05 kg", "0.06 kg"], **laws, **seats, cam_restitution=0.7, seat_restitution=0.3)
    one = chain(["0.05 kg"], **seats, seat_restitution=0.5)
    for train, contact, mass, e in (
        (two, "cam", M1, 0.7),
        (two, "seat", M2, 0.3),
        (one, "seat", M1, 0.5),
    ):
        law = contact_law(train, contact)
        assert law.stiffness == pytest.approx(K, rel=1e-12)
        assert law.damping == pytest.approx(2 * zeta_of(e) * math.sqrt(K * mass), rel=1e-9)
        # `campipe model` shows the same contact's restitution back
        shown = {m.contact: m for m in contact_modes(train, system_matrices(train))}[contact]
        assert shown.restitution == pytest.approx(e, rel=1e-9)
        assert impact_restitution(train, contact) == 0.0  # no rigid impact's e
    assert (train_stack((two,), 0.0).restitution == 0.0).all()


def test_the_compliant_integrators_landings_rebound_with_that_restitution():
    """A one-mass chain (0.5 kg on a 2e9 N/m contact) thrown off a polydyne's rise lands on
    the base circle again and again; the compliant integrator's closing velocity at each
    landing is e times the last's (the flight between on the spring alone, undamped, gives
    back the speed it left with), within what the spring's force F (20 N) changes over a
    contact: at most 2·F/√(k·m) of velocity (the force offsets the approach by F/k, whose
    velocity scale is ω·F/k; measured 0.6·F/√(k·m)). Fails when the damping comes from the
    classic exp(−πζ/√(1 − ζ²)) (e 0.6 then rebounds at 0.632), or from another mass."""
    e, mass, stiffness, force = 0.6, 0.5, 2e9, 20.0
    train = chain(
        ["0.5 kg"],
        cam_contact="kelvin-voigt",
        cam_contact_stiffness=f"{stiffness} N/m",
        cam_restitution=e,
        spring_rate="1 N/mm",  # (its force over the landings' flights: below 0.1 N)
        spring_preload=f"{force} N",
        damping_ratios=[0.0],
    )
    profile = polydyne("345", 0.005, math.radians(80), math.radians(20), math.radians(80))
    speed = 80.0  # [rad/s]: the rise's deceleration throws it off, past the dwell
    events = run_batch([Case(train, profile, speed)], RunSettings(revolutions=1)).events[0]
    theta = speed * events[:, EV_TIME]
    landings = events[(events[:, EV_KIND] == CAM_IMPACT) & (theta > math.radians(185)), :]
    v = landings[:, EV_VELOCITY]
    fast = v[:-1] > 0.05  # each landing of these, and the next
    assert fast.sum() >= 2
    ratios = (v[1:] / v[:-1])[fast]
    tolerance = 2.0 * force / math.sqrt(stiffness * mass) / v[:-1][fast]
    assert np.all(np.abs(ratios - e) <= tolerance), (ratios, tolerance)
    assert np.all(tolerance < 0.02)  # sharp enough to tell 0.632 from 0.6


def test_a_kelvin_voigt_contact_given_both_damping_and_restitution_is_refused():
    laws = {"seat_contact": "kelvin-voigt", "seat_contact_stiffness": f"{K} N/m"}
    with pytest.raises(ModelParameterError) as info:
        chain(["0.05 kg"], **laws, seat_contact_damping="50 N*s/m", seat_restitution=0.5)
    assert info.value.key == "seat_restitution"
    assert "seat_contact_damping" in str(info.value) and "leave one out" in str(info.value)
    hertz = {"cam_contact": "hertz", "cam_hertz_constant": "1e10 N/m**1.5"}
    with pytest.raises(ModelParameterError) as info:
        chain(["0.05 kg", "0.06 kg"], **hertz, cam_restitution=0.5)
    assert info.value.key == "cam_restitution" and "hunt_crossley" in str(info.value)
