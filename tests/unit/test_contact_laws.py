"""The contact laws (issue 33): each law against its closed form, and the registry: a law
registered by name is found by ``contact_law`` and run by the compliant integrator."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from campipe.constants import TWO_PI
from campipe.engine.compliant import CaseOutputs, CompliantSystem, Lift, integrate
from campipe.engine.metrics import MAX_CAM_FORCE, N_ENGINE
from campipe.model import ModelParameterError, valve_train
from campipe.model.contact import (
    LAWS,
    ContactLaw,
    Hertz,
    KelvinVoigt,
    Rigid,
    contact_law,
    register_law,
)
from campipe.model.parameters import CONTACT_CONSTANTS, CONTACT_LAWS
from campipe.profiles import Profile
from campipe.vocabulary import CAM_IMPACT, CAM_SEPARATION, EV_KIND, EV_VELOCITY

E_STAR = 210e9 / (2 * (1 - 0.3**2))  # [Pa]


def central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_kelvin_voigt_force_slopes_and_release():
    k, c = 2e6, 300.0
    law = KelvinVoigt(k, c, E_STAR, 0.0, 0.0)
    assert law.compliant and law.linear
    assert law.force(1e-5, 0.2) == pytest.approx(2e6 * 1e-5 + 300 * 0.2, rel=1e-15)  # 80 N
    assert law.force(1e-5, -0.2) == pytest.approx(-40.0, rel=1e-14)  # would pull
    assert law.slopes(1e-5, 0.2) == (k, c)
    # closed where δ > 0 and F > 0; released where F = kδ + cδ̇ reaches zero: δ̇ = −kδ/c
    delta = 1e-5
    release = -k * delta / c
    assert law.monitor(delta, release) == pytest.approx(0.0, abs=1e-20)
    assert law.monitor(delta, release * 0.99) > 0.0 > law.monitor(delta, release * 1.01)
    assert law.monitor(-1e-6, 1.0) == -1e-6  # apart: the gap
    assert law.monitor(delta, 0.0) == delta
    assert law.approach(80.0) == pytest.approx(4e-5, rel=1e-15)
    assert law.approach(-5.0) == 0.0
    assert np.isnan(law.pressure(np.array([100.0]))).all()  # no geometry


def test_hertz_force_and_its_slopes_against_finite_differences():
    k, alpha = 3e10, 0.4  # [N/m^1.5], [s/m]
    law = Hertz(k, alpha, E_STAR, 0.0, 0.01)
    assert law.compliant and not law.linear
    d, r = 2e-6, 0.3
    assert law.force(d, r) == pytest.approx(k * d**1.5 * (1 + alpha * r), rel=1e-14)
    assert law.force(d, r) == pytest.approx(95.035, rel=1e-4)
    assert law.force(-1e-6, r) == 0.0  # apart: no force, however fast
    kd, cd = law.slopes(d, r)
    assert_allclose(kd, central(lambda x: law.force(x, r), d, 1e-9), rtol=1e-6)
    assert_allclose(cd, central(lambda v: law.force(d, v), r, 1e-3), rtol=1e-9)
    assert_allclose(kd, 1.5 * k * d**0.5 * (1 + alpha * r), rtol=1e-14)
    assert law.slopes(-1e-6, r) == (0.0, 0.0)
    # the static approach inverts the force
    assert_allclose(law.force(law.approach(250.0), 0.0), 250.0, rtol=1e-14)


def test_hertz_monitor_crosses_zero_at_release():
    """With damping the force K·δ^(3/2)·(1 + α·δ̇) reaches zero at δ̇ = −1/α while δ > 0."""
    law = Hertz(3e10, 0.4, E_STAR, 0.0, 0.0)
    assert law.monitor(1e-6, -1 / 0.4) == pytest.approx(0.0, abs=1e-18)
    assert law.monitor(1e-6, -2.4) > 0.0 > law.monitor(1e-6, -2.6)
    assert law.monitor(1e-6, 0.0) == 1e-6  # δ below 1e-3·(1 + αδ̇)
    assert law.monitor(-2e-6, 5.0) == -2e-6
    undamped = Hertz(3e10, 0.0, E_STAR, 0.0, 0.0)
    assert undamped.monitor(1e-6, -100.0) == 1e-6  # releases where δ does


def test_pressures_of_a_point_and_a_line_contact():
    f = np.array([100.0, 1000.0, -3.0])
    point = Hertz(1e10, 0.0, E_STAR, 0.0, 0.01)
    expected = (6 * f.clip(0) * E_STAR**2 / (math.pi**3 * 0.01**2)) ** (1 / 3)
    assert_allclose(point.pressure(f), expected, rtol=1e-14)
    assert_allclose(point.pressure(f)[1], 2.9535e9, rtol=1e-4)
    line = KelvinVoigt(1e9, 0.0, E_STAR, 0.01, 0.005)
    assert_allclose(line.pressure(f), np.sqrt(f.clip(0) / 0.01 * E_STAR / (math.pi * 0.005)))
    assert np.isnan(Hertz(1e10, 0.0, E_STAR, 0.0, 0.0).pressure(f)).all()  # no radius


def test_rigid_holds_its_coordinate():
    train = valve_train("thesis-1971", {"cam_curvature_radius": "10 mm"})
    law = contact_law(train, "cam")
    assert type(law) is Rigid and not law.compliant
    assert law.stiffness == math.inf and law.damping == 0.0
    assert law.approach(1e4) == 0.0
    with pytest.raises(ValueError, match="holds its coordinate"):
        law.force(1e-6, 0.0)
    # a point contact's peak pressure is Hertz's only: none for a rigid one
    assert np.isnan(law.pressure(np.array([500.0]))).all()
    lined = contact_law(train.replace(cam_contact_width=0.01), "cam")
    assert_allclose(
        lined.pressure(500.0), math.sqrt(500.0 / 0.01 * lined.modulus / (math.pi * 0.01))
    )


@pytest.mark.parametrize(
    ("overrides", "cls", "stiffness"),
    [
        ({"cam_contact": "kelvin-voigt", "cam_contact_width": "10 mm"}, KelvinVoigt,
         math.pi / 2 * E_STAR * 0.01),
        ({"cam_contact": "kelvin-voigt", "cam_contact_stiffness": "1e8 N/m"}, KelvinVoigt, 1e8),
        ({"cam_contact": "hertz", "cam_curvature_radius": "10 mm"}, Hertz,
         4 / 3 * E_STAR * math.sqrt(0.01)),
        ({"cam_contact": "hertz", "cam_hertz_constant": "2e10 N/m**1.5"}, Hertz, 2e10),
    ],
)  # fmt: skip
def test_contact_law_builds_the_named_class_from_the_train(overrides, cls, stiffness):
    train = valve_train("thesis-1971", {**overrides, "contact_modulus": "210 GPa"})
    law = contact_law(train, "cam")
    assert type(law) is cls
    assert_allclose(law.stiffness, stiffness, rtol=1e-12)
    assert_allclose(law.modulus, E_STAR, rtol=1e-12)


def test_the_registry_is_the_parameter_table_s_laws():
    assert set(LAWS) == set(CONTACT_LAWS) == set(CONTACT_CONSTANTS)
    for name, cls in LAWS.items():
        assert cls.name == name and cls.constants == CONTACT_CONSTANTS[name]
    with pytest.raises(ValueError, match="registered already"):
        register_law(type("Other", (KelvinVoigt,), {}))  # the name "kelvin-voigt" again


def test_an_unknown_law_name_is_refused_with_its_key():
    train = valve_train("thesis-1971").replace(seat_contact="hertzz")
    with pytest.raises(ModelParameterError, match="did you mean 'hertz'") as info:
        contact_law(train, "seat")
    assert info.value.key == "seat_contact"


class Quadratic(ContactLaw):
    """A toy law, F = k·δ² (elastic): registered here, edited nowhere else."""

    name = "test-quadratic"
    constants = ("contact_stiffness", "contact_damping")

    def force(self, delta, rate):
        return self.stiffness * max(delta, 0.0) ** 2

    def slopes(self, delta, rate):
        return 2.0 * self.stiffness * max(delta, 0.0), 0.0

    def monitor(self, delta, rate):
        return delta

    def approach(self, force):
        return math.sqrt(max(force, 0.0) / self.stiffness)


@pytest.fixture
def quadratic():
    register_law(Quadratic)
    yield Quadratic
    del LAWS[Quadratic.name]


def test_a_registered_law_is_found_by_name_and_integrated(quadratic):
    """A mass m striking the toy law at v₀ leaves at −v₀ (elastic) after reaching
    δ_max = (3mv₀²/(2k))^(1/3) (energy: ½mv₀² = kδ³/3), the peak force k·δ_max²."""
    k, mass, v0 = 1e12, 0.1, 0.5  # [N/m²], [kg], [m/s]
    train = valve_train("thesis-1971").replace(cam_contact=quadratic.name, cam_contact_stiffness=k)
    law = contact_law(train, "cam")
    assert type(law) is quadratic and law.stiffness == k
    n, t_end = 7, 1e-3
    m = np.eye(n)
    m[0, 0] = mass
    stiffness = np.eye(n)
    stiffness[0, 0] = 0.0
    flat = Profile(np.array([0.0, TWO_PI]), np.zeros((1, 8)), np.zeros((1, 2)), "flat")
    system = CompliantSystem(
        m, np.zeros((n, n)), stiffness, np.zeros(n), law, None, math.nan,
        Lift(flat, TWO_PI / (4 * t_end)), np.ones(2 * n) * 1e-6,
    )  # fmt: skip
    z0 = np.zeros(2 * n)
    z0[0], z0[n] = -1e-8, v0
    out = CaseOutputs(
        np.zeros((5, 7)), np.zeros((5, 7)), np.zeros((5, 2)), np.zeros(5),
        np.zeros(5, np.int8), np.zeros((5, 2)), np.zeros((1, N_ENGINE)), np.zeros((16, 6)),
    )  # fmt: skip
    integrate(system, 0.0, z0, (False, False), np.linspace(0, t_end, 5), out, rtol=1e-11)
    assert out.status == 0
    ev = out.events[: out.n_events]
    assert ev[:, EV_KIND].tolist() == [CAM_IMPACT, CAM_SEPARATION]
    assert_allclose(ev[0, EV_VELOCITY], v0, rtol=1e-12)
    assert_allclose(out.v[-1, 0], -v0, rtol=1e-7)
    d_max = (3 * mass * v0**2 / (2 * k)) ** (1 / 3)
    assert_allclose(out.per_rev[0, MAX_CAM_FORCE], k * d_max**2, rtol=1e-6)
