"""A hydraulic lash adjuster under a finger follower's pivot (campipe.model.levers,
campipe.engine.lash_adjuster): the valve lift with the pivot raised against a hand calculation
of the lever's geometry written here, the pivot's load against the lever's statics, and the
leak-down and pump-up over a turn at a crawl against the quasi-static closed form."""

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad
from scipy.optimize import brentq

from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.metrics import MAX_CAM_FORCE
from campipe.model import ModelParameterError, system_matrices, valve_train
from campipe.model.levers import base_take_up, kinematic_state, lever_of, pivot_gain
from campipe.profiles import evaluate, harmonic

RPM = 2.0 * math.pi / 60.0
A, B, RB, RR = 0.030, 0.045, 0.018, 0.009
KL, KS, RATE, PRELOAD = 15e6, 60e6, 35e3, 220.0
HLA_K, CHECK, DRY, TRAVEL = 20000e3, 25.0, 0.15e-3, 1e-3
LIFT = 0.006
FINGER = {
    "layout": "finger-follower",
    "pivot_to_roller": "30 mm",
    "pivot_to_pallet": "45 mm",
    "cam_base_radius": "18 mm",
    "cam_roller_radius": "9 mm",
    "lever_inertia": "40 kg*mm**2",
    "roller_mass": "10 g",
    "valve_mass": "60 g",
    "lever_stiffness": "15 N/um",
    "stem_stiffness": "60 N/um",
    "spring_rate": "35 N/mm",
    "spring_preload": "220 N",
    "damping_ratios": [0.05],
    "lash": "0.15 mm",
    "hla_stiffness": "20000 N/mm",
    "hla_leak_down": "2000 N*s/mm",
    "hla_check_force": "25 N",
    "hla_pump_up": "20 N*s/mm",
    "hla_travel": "1 mm",
}


def finger(**changes):
    return valve_train("thesis-1971", {**FINGER, **changes}, key_prefix="model.")


class Hand:
    """The finger's geometry worked out here, in polar coordinates about the cam's centre:
    the pivot at (0, e), the roller's centre X = P + a·(cos α, sin α) at the pitch radius
    R + h(s) of the cam direction it lies in (s = ψ₀ + θ − direction of X − c), solved for α
    by Brent's method; the cam's centre fixed at rest (e = 0, the arm at α₀, the cam
    ``offset`` towards the pallet)."""

    def __init__(self, alpha0=0.0, offset=0.0, lift=LIFT):
        self.alpha0, R = alpha0, RB + RR
        rest = A * np.array([math.cos(alpha0), math.sin(alpha0)])
        self.c = rest + np.array([offset, math.sqrt(R * R - offset * offset)])
        self.psi0 = math.atan2(rest[1] - self.c[1], rest[0] - self.c[0])
        self.cam = harmonic(lift)
        self.scale = lift / LIFT  # 0: the base circle alone

    def _d(self, alpha, e):
        return np.array([A * math.cos(alpha), e + A * math.sin(alpha)]) - self.c

    def gap(self, alpha, theta, e):
        d = self._d(alpha, e)
        s = self.psi0 + theta - math.atan2(d[1], d[0])
        return float(np.hypot(*d) - (RB + RR + self.scale * evaluate(self.cam, s)[0]))

    def angle(self, theta, e):
        return brentq(lambda x: self.gap(x, theta, e), self.alpha0 - 0.6, self.alpha0 + 0.1,
                      xtol=1e-15)  # fmt: skip

    def valve_lift(self, theta, e):
        """The pallet centre's fall from its rest (pivot at the origin, arm at α₀)."""
        return B * math.sin(self.alpha0) - e - B * math.sin(self.angle(theta, e))

    def roller_force(self, theta, pallet, e=0.0):
        """The cam's normal force N [N] on the roller under a pallet force ``pallet`` [N] by
        the lever's moments about the pivot, and the normal n (see :meth:`pivot_load`)."""
        alpha = self.angle(theta, e)
        d = self._d(alpha, e)
        phi = math.atan2(d[1], d[0])
        h, dh, _ = evaluate(self.cam, self.psi0 + theta - phi)
        e_r = np.array([math.cos(phi), math.sin(phi)])
        e_phi = np.array([-math.sin(phi), math.cos(phi)])
        n = (RB + RR + self.scale * h) * e_r + self.scale * dh * e_phi
        n /= np.linalg.norm(n)
        u = np.array([math.cos(alpha), math.sin(alpha)])
        return -B * math.cos(alpha) * pallet / (A * (u[0] * n[1] - u[1] * n[0])), n

    def pivot_load(self, theta, e, pallet):
        """The adjuster's load [N] under a pallet force ``pallet`` [N] (up on the lever) by the
        lever's statics (no inertia): the cam's normal force N along the pitch curve's outward
        normal n (ρ·e_r + h'(s)·e_φ in polar form) from the moments about the pivot, then the
        pivot's vertical reaction from the forces, R = −F − N·n_y."""
        alpha = self.angle(theta, e)
        d = self._d(alpha, e)
        phi = math.atan2(d[1], d[0])
        s = self.psi0 + theta - phi
        h, dh, _ = evaluate(self.cam, s)
        e_r, e_phi = (
            np.array([math.cos(phi), math.sin(phi)]),
            np.array([-math.sin(phi), math.cos(phi)]),
        )
        n = (RB + RR + h) * e_r + dh * e_phi
        n /= np.linalg.norm(n)
        u = np.array([math.cos(alpha), math.sin(alpha)])
        normal = -B * math.cos(alpha) * pallet / (A * (u[0] * n[1] - u[1] * n[0]))
        return -pallet - normal * n[1]


def test_the_pivot_raised_moves_the_valve_as_the_lever_s_geometry_does():
    """With the pivot raised by e = 0.4 mm, the valve lift over the turn equals the hand
    calculation's (a tilted finger under an offset cam, and a level one); on the base circle
    it is the take-up, and for the level finger under its cam the take-up is e·(b − a)/a to
    second order in e (the arm's swing: within 2e-4 of it at 0.4 mm, 4 times less at half of
    it); the rest gain is (b − a)/a = 0.5 for the level finger. Fails on a copy that raises
    the cam with the pivot (no take-up), or that takes the take-up as e·b/a (the roller held
    instead of on the cam)."""
    theta = np.radians([0.0, 45.0, 90.0, 150.0, 200.0, 250.0, 270.0, 300.0])
    e = 0.4e-3
    for alpha0, offset in ((math.radians(5.0), 0.004), (0.0, 0.0)):
        hand, base = Hand(alpha0, offset), Hand(alpha0, offset, lift=1e-30)
        train = finger(lever_rest_angle=f"{math.degrees(alpha0)} deg", cam_offset=f"{offset} m")
        lever = dataclasses.replace(lever_of(train), pivot_height=e)
        state = kinematic_state(lever, lambda s: evaluate(harmonic(LIFT), s)[:2], theta)
        expected = [hand.valve_lift(t, e) for t in theta]
        assert_allclose(state.valve_lift, expected, atol=1e-12)
        take_up = base_take_up(lever_of(train), e)
        assert take_up == pytest.approx(base.valve_lift(1.0, e), abs=1e-13)
    level = lever_of(finger())
    assert pivot_gain(finger()) == pytest.approx((B - A) / A, rel=1e-12)
    for height, bound in ((e, 2e-4), (e / 2, 0.5e-4)):
        linear = height * (B - A) / A
        assert abs(base_take_up(level, height) / linear - 1.0) < bound
    # the adjuster seen at the pallet: its stiffness over the gain squared, in the link
    link = 1.0 / (1.0 / KL + 1.0 / KS + 0.5**2 / HLA_K)
    assert system_matrices(finger()).stiffness[0, 6] == pytest.approx(link, rel=1e-12)


def test_the_engine_s_excitation_is_the_raised_pivot_s_lift():
    """A run started with the plunger out 0.3 mm drives the finger with the raised pivot's
    kinematic valve lift (the hand calculation's, at the output samples, to 1e-11 m) in its
    first turn, and its effective lash is the dry lash less the take-up at the valve. Fails
    on a copy that raises the valve-side lift by the extension itself (a chain's rule)."""
    e = 0.3e-3
    hand = Hand()
    train = finger(hla_extension="0.3 mm", hla_leak_down="1e9 N*s/mm", hla_pump_up="1e9 N*s/mm")
    run = run_batch(
        [Case(train, harmonic(LIFT), 100 * RPM)],
        RunSettings(revolutions=1, output_every=math.radians(10)),
    )
    assert run.status[0] == 0
    assert_allclose(run.cam_lift[0], [hand.valve_lift(t, e) for t in run.cam_angle], atol=1e-11)
    take_up = Hand(lift=1e-30).valve_lift(0.0, e)
    assert run.hla_lash_per_rev[0, 0] == pytest.approx(DRY - take_up, rel=1e-9)
    assert take_up == pytest.approx(0.5 * e, rel=1e-4)


def pallet_force(hand: Hand, e: float, k: float, contact: float = math.inf):
    """The pallet's force [N] at a crawl against the cam angle, the pivot raised by ``e``
    (the hand's valve lift v): 0 while the cam has not taken the dry lash ℓ up, and with the
    roller's and the seat's contact stiffness ``contact`` [N/m] (inf: rigid) in series. The
    roller's seen at the valve is k_c/r², r the lever ratio of the hand's statics (the
    roller's force per pallet force), so the link and the roller give
    k_e = 1/(1/k + r²/k_c). Seated, the valve sits in its seat by p = (P₀ − F)/k_c (the
    spring's load, its installed force, less the pallet's), which takes lash up:
    F = k_e·(v − ℓ + p); off its seat by x > 0, where that reaches P₀,
    F = k_e·(v − ℓ − x) = P₀ + k_s·x (rigid: from the lift-off load on, the link and the
    spring in series)."""
    held = PRELOAD  # the spring's load on the seated valve: its installed force

    def force(theta):
        v = hand.valve_lift(theta, e)
        give = 0.0 if math.isinf(contact) else hand.roller_force(theta, 1.0, e)[0] ** 2 / contact
        k_e = 1.0 / (1.0 / k + give)
        seated = k_e * (v - DRY + held / contact) / (1.0 + k_e / contact)
        if seated <= 0.0:
            return 0.0
        if seated <= held:
            return seated
        x = (k_e * (v - DRY) - held) / (k_e + RATE)
        return k_e * (v - DRY - x)

    return force


def check_valve_turn(load) -> tuple[float, float, float, float]:
    """(θ_c, θ_o, ∫ (R − F_c)⁺ dθ, ∫ (F_c − R)⁺ dθ) of a turn of the pivot's load ``load(θ)``:
    the check valve closes where R rises through F_c on the opening flank (θ_c, Brent's root
    in 95° … 270°) and opens where it falls on the closing flank (θ_o in 270° … 449°); the
    excess over θ_c … θ_o and the deficit from θ_o − 2π to θ_c by quadrature."""
    t_close = brentq(lambda x: load(x) - CHECK, math.radians(95), math.radians(270))
    t_open = brentq(lambda x: load(x) - CHECK, math.radians(270), math.radians(449))
    above = quad(lambda x: load(x) - CHECK, t_close, t_open, limit=200, epsabs=1e-9)[0]
    below = CHECK * (t_close - t_open + 2 * math.pi)
    below -= quad(load, t_open - 2 * math.pi, t_close, limit=200)[0]
    return t_close, t_open, above, below


def test_leak_down_and_pump_up_over_a_turn_at_a_crawl():
    """At 10 rpm (a turn of 6 s, inertia and damping forces under 1e-3 N) the pivot's load is
    the statics' (:meth:`Hand.pivot_load`) under the quasi-static pallet force; over the turn
    the plunger leaks down ∫ (R − F_c)⁺ dt / c_L while the check valve is closed and pumps up
    ∫ (F_c − R)⁺ dt / c_P while it is open (capacity-limited here), integrated here by
    quadrature between the switches (Brent's roots of R − F_c). The engine's two turns (the
    second with the pivot raised by the first's net extension) agree to 2e-4 (the kinks
    where the cam takes the lash up fall between its 0.05° samples). Fails on a copy that
    takes the adjuster's load as the pallet's force (about twice the leak-down), or leaves
    the adjuster out of the link (a stiffer link, another force)."""
    omega, slow, start = 10 * RPM, 2e9, 0.1e-3
    hla = {"hla_leak_down": "2e6 N*s/mm", "hla_pump_up": "2e6 N*s/mm", "hla_extension": "0.1 mm"}
    run = run_batch(
        [Case(finger(**hla), harmonic(LIFT), omega)],
        RunSettings(revolutions=2, output_every=math.radians(0.05)),
    )
    assert run.status[0] == 0
    hand = Hand()
    k = 1.0 / (1.0 / KL + 1.0 / KS + 0.25 / HLA_K)
    extension = start
    for turn in range(2):
        pallet = pallet_force(hand, extension, k)

        def load(theta, pallet=pallet, e=extension):
            return hand.pivot_load(theta, e, pallet(theta))

        _, _, above, below = check_valve_turn(load)
        found = run.lash_adjuster[0, turn]
        assert found[0] == pytest.approx(extension, rel=1e-9)
        assert found[1] == pytest.approx(above / (omega * slow), rel=2e-4)
        assert found[2] == pytest.approx(below / (omega * slow), rel=2e-4)
        extension = extension - found[1] + found[2]


def test_a_lever_s_cam_impacts_are_the_roller_s_closing_on_the_cam():
    """Past its onset (harmonic 6 mm at 12000 rpm cam speed, tilted and offset) the finger
    leaves the cam and lands again, several times a turn. Each cam impact's closing velocity
    at the cam is the valve side's over the lever ratio at the impact's angle (the hand's
    roller force per unit pallet force, by the lever's moments: an independent statics), its
    impulse r times the valve side's; each turn's max_cam_impact_velocity the largest of them
    (of at least the capture velocity). The thesis's train keeps its own. Fails on a copy
    that multiplies by r, or keeps the valve side's turn maxima."""
    from campipe.engine.levers import at_the_cam
    from campipe.engine.metrics import MAX_CAM_IMPACT_VELOCITY
    from campipe.engine.settings import DEFAULT_CAPTURE_VELOCITY
    from campipe.vocabulary import CAM_IMPACT, EV_IMPULSE, EV_KIND, EV_TIME, EV_VELOCITY

    own = {k: v for k, v in FINGER.items() if not k.startswith("hla") and k != "lash"}
    train = valve_train(
        "thesis-1971", {**own, "lever_rest_angle": "5 deg", "cam_offset": "4 mm"},
        key_prefix="model.",
    )  # fmt: skip
    case = Case(train, harmonic(LIFT), 12000 * RPM)
    valve_side = run_batch([case], RunSettings(revolutions=3))
    roller = at_the_cam(valve_side, [case])
    before, after = valve_side.events[0], roller.events[0]
    cam = before[:, EV_KIND] == CAM_IMPACT
    assert cam.sum() >= 6  # it lands more than once a turn
    hand = Hand(math.radians(5.0), 0.004)
    angle = case.speed * before[cam, EV_TIME]
    r = np.array([hand.roller_force(t % (2 * math.pi), 1.0)[0] for t in angle])
    assert r.min() > 1.05 and np.ptp(r) > 0.05  # the ratio differs between the impacts
    assert_allclose(after[cam, EV_VELOCITY], before[cam, EV_VELOCITY] / r, rtol=1e-7)
    assert_allclose(after[cam, EV_IMPULSE], before[cam, EV_IMPULSE] * r, rtol=1e-7)
    assert_allclose(after[~cam], before[~cam], rtol=0, atol=0)  # every other event as it was
    turn = np.floor(angle / (2 * math.pi)).astype(int)
    counted = before[cam, EV_VELOCITY] >= DEFAULT_CAPTURE_VELOCITY
    for k in range(3):
        here = (turn == k) & counted
        expected = (before[cam, EV_VELOCITY] / r)[here].max() if here.any() else 0.0
        assert roller.per_rev[0, k, MAX_CAM_IMPACT_VELOCITY] == pytest.approx(expected, rel=1e-7)
    assert roller.max_cam_impact_velocity[0] < valve_side.max_cam_impact_velocity[0] / 1.05
    thesis = Case(valve_train("thesis-1971"), harmonic(LIFT), 12000 * RPM)
    kept = run_batch([thesis], RunSettings(revolutions=1))
    assert at_the_cam(kept, [thesis]) is kept


def test_a_centre_pivot_rocker_takes_no_adjuster():
    """A centre-pivot rocker's pivot is a shaft: its adjuster is refused naming the key.
    Fails on a copy that lets any lever take one."""
    with pytest.raises(ModelParameterError) as info:
        finger(layout="centre-pivot-rocker")
    assert info.value.key == "model.hla_stiffness" and "finger-follower" in str(info.value)


def test_a_lever_s_archived_cam_force_is_the_roller_s_force_on_the_cam(tmp_path):
    """A finger's archive stores as ``cam_force`` the cam's normal force on the roller: the
    engine's valve-side force F (the pallet's, driving the reduced lever) turned into the
    roller's by the lever's moments about its pivot, worked out here (:meth:`Hand.roller_force`,
    a tilted finger under an offset cam), at every sample; each turn's
    ``max_cam_force_by_rev`` is the largest of them to the samples' resolution: at least the
    samples' largest, at most the valve side's largest (the samples' or the engine's own)
    times the largest ratio. The thesis's train keeps its own cam force. Fails on a copy
    that keeps the valve-side force (2/3 of it) or scales only the histories (a maximum below
    the samples')."""
    import xarray as xr
    import yaml

    from campipe.study import load_study
    from campipe.study.run.execute import run_study

    own = {k: v for k, v in FINGER.items() if not k.startswith("hla") and k != "lash"}
    model = {**own, "lever_rest_angle": "5 deg", "cam_offset": "4 mm"}
    spec = {
        "name": "finger-cam-force",
        "model": model,
        "profile": {"kind": "harmonic", "lift": "6 mm"},
        "sweep": {"speed": ["1000 rpm", "4000 rpm"]},
        "run": {"revolutions": 2, "output_every": "2 deg"},
    }
    path = tmp_path / "finger.yaml"
    path.write_text(yaml.safe_dump(spec))
    run_study(load_study(path), tmp_path / "finger.nc", scheduler="synchronous")
    ds = xr.load_dataset(tmp_path / "finger.nc")
    study = load_study(path)
    hand = Hand(math.radians(5.0), 0.004)
    theta = np.radians(ds["cam_angle"].values)
    per_unit = np.array([hand.roller_force(t, 1.0)[0] for t in theta])
    for i, resolved in enumerate(study.cases):
        engine = run_batch([resolved.case], resolved.settings)
        valve_side = engine.cam_force[0]
        assert valve_side.min() > 50.0  # it follows the cam at both speeds
        assert_allclose(ds["cam_force"].values[i], valve_side * per_unit, rtol=1e-6)
        largest = ds["max_cam_force_by_rev"].values[i]
        for k in range(2):
            turn = (theta >= 2 * math.pi * k - 1e-9) & (theta <= 2 * math.pi * (k + 1) + 1e-9)
            sampled = (valve_side * per_unit)[turn].max()
            # the engine's own largest (the valve side's, on its steps' grid)
            step = max(engine.per_rev[0, k, MAX_CAM_FORCE], valve_side[turn].max())
            assert sampled * (1 - 1e-9) <= largest[k] <= step * per_unit.max() * (1 + 1e-9)
            assert largest[k] > 1.4 * step  # the roller's, about b/a of the valve side's
    thesis = run_batch([Case(valve_train("thesis-1971"), harmonic(LIFT), 1000 * RPM)],
                       RunSettings(revolutions=1))  # fmt: skip
    from campipe.engine.levers import at_the_cam

    same = at_the_cam(thesis, [Case(valve_train("thesis-1971"), harmonic(LIFT), 1000 * RPM)])
    assert same is thesis


def test_a_pivot_moved_turn_by_turn_gives_the_roller_its_turn_s_ratio():
    """With rigid contacts the pivot's adjuster moves once a turn, and each turn runs on the
    pivot raised by its extension (0.3 mm at the start here, leaking down). The roller's
    force at the cam is the pallet's times that turn's lever ratio: at samples on the cam,
    the hand's geometry with the pivot raised by the turn's extension, to 1e-9; so no sample
    of a turn's history exceeds the turn's max_cam_force (the engine's own maximum of the
    roller's force). Broken copy: the ratio of the pivot at rest (0.06 % off here; a
    helper's finger study read histories 0.38 N above their turn's maximum)."""
    from campipe.engine.plunger import EXTENSION

    case = Case(finger(hla_extension="0.3 mm"), harmonic(LIFT), 1000 * RPM)
    valve_side = run_batch([case], RunSettings(revolutions=3))
    extension = valve_side.lash_adjuster[0, :, EXTENSION]
    assert extension[0] == pytest.approx(3e-4) and np.all(np.diff(extension) < -1e-6)
    assert_turn_ratios(valve_side, case, extension)


def assert_turn_ratios(valve_side, case, extension) -> None:
    """Each turn k's roller force over the pallet's at samples on the cam's flank and nose
    (200° and 270°) is the hand's ratio with the pivot raised by ``extension[k]``, to 1e-9,
    and no sample of the turn's roller force exceeds its max_cam_force."""
    from campipe.engine.levers import at_the_cam

    roller = at_the_cam(valve_side, [case])
    theta = np.asarray(valve_side.cam_angle)
    hand = Hand()
    for k in range(len(extension)):
        turn = (theta >= 2 * math.pi * k) & (theta <= 2 * math.pi * (k + 1))
        for degrees in (200, 270):
            j = 360 * k + degrees
            assert valve_side.contact_state[0, j] == 1
            ratio = roller.cam_force[0, j] / valve_side.cam_force[0, j]
            expected = hand.roller_force(theta[j] % (2 * math.pi), 1.0, extension[k])[0]
            assert ratio == pytest.approx(expected, rel=1e-9)
        assert roller.cam_force[0, turn].max() <= roller.per_rev[0, k, MAX_CAM_FORCE]


def test_a_check_valve_s_switch_is_in_the_configuration_the_contacts_leave():
    """The bundled finger-follower-hla's train at 9000 engine rpm leaves its cam and lands
    again in most turns, and its check valve switches between the samples. Each switch's
    configuration (from, to) is the one the contact events before it leave: every event
    starts where the last contact event left the train. Broken copy: the sample's before
    the switch (5 breaks in 8 turns: a switch 0.01° after a separation read 1 → 1)."""
    from study_helpers import STUDIES

    from campipe.study import load_study
    from campipe.vocabulary import CHECK_VALVE_OPENS, EV_FROM, EV_KIND, EV_TIME, EV_TO

    study = load_study(STUDIES / "finger-follower-hla.yaml")
    case = max((c.case for c in study.cases), key=lambda c: c.speed)
    result = run_batch([case], RunSettings(revolutions=8))
    events = result.events[0][np.argsort(result.events[0][:, EV_TIME], kind="stable")]
    kinds = events[:, EV_KIND].astype(int)
    assert (kinds == 1).sum() > 20 and (kinds == CHECK_VALVE_OPENS).sum() > 20
    state = result.contact_state[0, 0]
    for row in events:
        assert row[EV_FROM] == state, row
        if row[EV_KIND] <= 4:  # a separation or an impact
            state = row[EV_TO]
        else:
            assert row[EV_TO] == row[EV_FROM]
