"""Where a lash adjuster's plunger is moved once a turn (the per-turn model: a finger's pivot
with rigid contacts, or newmark-linear), `campipe validate` and `campipe study` say so, with
the model's stated error, and point at what carries it within the turn; where it is carried,
they say nothing. And a lash the cam's ramps do not take up, said the same way."""

import math

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import STUDIES

from campipe.cli import main
from campipe.constants import RPM
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.study.spec.notes import per_turn_note, ramp_note

NEWMARK = {"run.integrator": "newmark-linear", "run.dt": "1 us"}


def test_the_cases_moved_once_a_turn_are_counted_over_every_axis():
    """The bundled finger (rigid contacts, a speed sweep of 5) moves its plunger once a turn
    in every case; its compliant copy and the bucket's chain under modal-exact carry it; the
    bucket under newmark-linear does not (4 cases). Fails on a copy that counts a finger's
    pivot as carried by modal-exact, or counts the speed sweep's combinations only."""
    finger = load_study(STUDIES / "finger-follower-hla.yaml")
    assert per_turn_note(finger.cases).startswith("5 cases move the lash adjuster's plunger")
    assert per_turn_note(load_study(STUDIES / "finger-follower-hla-compliant.yaml").cases) is None
    assert per_turn_note(load_study(STUDIES / "lash-adjuster.yaml").cases) is None
    bucket = load_study(STUDIES / "lash-adjuster.yaml", NEWMARK)
    note = per_turn_note(bucket.cases)
    assert note.startswith(f"{len(bucket.cases)} cases move") and "Compliant contacts" in note
    assert per_turn_note(load_study(STUDIES / "quickstart.yaml").cases) is None


def test_validate_and_study_say_it(tmp_path):
    result = CliRunner().invoke(
        main, ["validate", "--no-estimate", str(STUDIES / "finger-follower-hla.yaml")]
    )
    assert result.exit_code == 0, result.output
    assert "lash adjuster: 5 cases move the lash adjuster's plunger once a turn" in result.output
    # the spec's engine speeds beside the cam's (a new user saw only the cam's)
    assert "(the engine's 2000, 4000, 6000, 7000, 9000 rpm)" in result.output
    quiet = CliRunner().invoke(
        main, ["validate", "--no-estimate", str(STUDIES / "lash-adjuster.yaml")]
    )
    assert quiet.exit_code == 0 and "lash adjuster:" not in quiet.output
    study = load_study(
        STUDIES / "finger-follower-hla.yaml",
        {"run.revolutions": 2, "sweep.engine_speed": ["4000 rpm"]},
    )
    report = run_study(study, tmp_path / "finger.nc", scheduler="synchronous")
    assert [n for n in report.notes if "once a turn" in n] == [per_turn_note(study.cases)]
    again = run_study(study, tmp_path / "finger.nc", scheduler="synchronous")
    assert not [n for n in again.notes if "once a turn" in n]  # nothing computed: no note


def test_a_lash_the_ramps_do_not_take_up_is_noted_and_lands_on_the_flank(tmp_path):
    """The bundled bucket's ramps climb 0.3 mm over 30° (0.01 mm a degree): with 0.2 mm of
    lash (its seat at 0.21 mm of valve lift, the lash and the train's compression under the
    preload) the valve lands at the ramp's velocity, within 2 %, and nothing is said; with
    0.5 mm (seat 0.51 mm) `campipe validate` and `campipe study` say it lands on the flank
    at 2.58 times that by the cam's kinematics, and the engine's landing at 1000 rpm is that
    within 3 % (campipe before: accepted silently; a fresh pair of eyes found 0.0259 mm a
    degree at 3000 rpm). The bundled studies with a rocker's lash (design-spring, lash-ramp)
    say nothing: their ramps take the lash up at the valve, through the ratio; nor do smooth
    ramps under the seat. Broken copies: the seat compared with the cam's ramp height
    without the rocker's ratio (the rocker's studies noted), the velocities compared without
    the seat above the ramp (smooth ramps' 0.1–0.25 mm noted, 1.97 times), the note left
    out."""
    sets = {"sweep.model.lash": ["0.2 mm", "0.5 mm"], "sweep.speed": ["1000 rpm"]}
    study = load_study(STUDIES / "bucket-tappet-lash.yaml", sets)
    note = ramp_note(study.cases)
    assert note.startswith("1 case takes up more lash than the cam's ramps: the valve leaves")
    assert "at up to 2.58 times the ramp's velocity" in note and "0.5101 mm of valve" in note
    for name in ("bucket-tappet-lash", "design-spring", "lash-ramp", "finger-follower"):
        assert ramp_note(load_study(STUDIES / f"{name}.yaml").cases) is None, name
    # smooth ramps (their velocity rises along them, twice the mean at their end) take up
    # the bundled lashes too: nothing to say; 0.5 mm lands on the flank
    smooth = {**sets, "profile.ramp_shape": "smooth"}
    within = {**smooth, "sweep.model.lash": ["0.1 mm", "0.2 mm", "0.25 mm"]}
    assert ramp_note(load_study(STUDIES / "bucket-tappet-lash.yaml", within).cases) is None
    beyond = ramp_note(load_study(STUDIES / "bucket-tappet-lash.yaml", smooth).cases)
    assert beyond.startswith("1 case takes up more lash than the cam's ramps")
    report = run_study(study, tmp_path / "bucket.nc", scheduler="synchronous")
    assert note in report.notes
    with xr.open_dataset(tmp_path / "bucket.nc") as ds:
        per_degree = ds.max_seating_velocity.values / (1000 * RPM) * 1e3 * math.radians(1.0)
    ramp = 0.3 / 30  # mm a degree
    assert abs(per_degree[0] / ramp - 1) < 0.02
    assert abs(per_degree[1] / ramp / 2.58 - 1) < 0.03
    shown = CliRunner().invoke(
        main,
        ["validate", "--no-estimate", str(STUDIES / "bucket-tappet-lash.yaml"),
         "--set", "sweep.model.lash=[0.1 mm, 0.5 mm]"],
    )  # fmt: skip
    assert "lash: 6 cases take up more lash than the cam's ramps" in shown.output


def validated(study: str, setting: str):
    """``campipe validate --no-estimate`` of a bundled study with one ``--set``, passed."""
    result = CliRunner().invoke(
        main, ["validate", "--no-estimate", str(STUDIES / study), "--set", setting]
    )
    assert result.exit_code == 0, result.output
    return result


def test_a_valve_spring_s_rate_in_the_wrong_unit_is_noted():
    """A spring rate written in N/m for N/mm (the bundled finger's 30 N/mm as 30 N/m) holds
    its 180 N preload at 6 m: campipe validate notes it with the deflection and the keys; no
    bundled study is noted (their springs take their preloads over 6-16 mm). Fails on a copy
    without the note, or one that notes the thesis's 16 mm."""
    from campipe.study.spec.notes import spring_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert spring_note(load_study(spec).cases) is None, spec.name
    slip = load_study(STUDIES / "finger-follower.yaml", {"model.spring_rate": "35 N/m"})
    note = spring_note(slip.cases)
    assert note.startswith(f"{len(slip.cases)} cases' valve springs hold their preload")
    assert "220 N over 0.035 N/mm is 6286 mm" in note
    result = validated("finger-follower.yaml", "model.spring_rate=35 N/m")
    assert "spring: 7 cases' valve springs hold their preload" in result.output


def test_a_chain_s_coil_clash_against_the_thesis_s_assumed_travel_is_noted(tmp_path):
    """A chain's coil-clash margin (``record: [spring]``) taken against the thesis's assumed
    spring travel to solid (40.64 mm, the key's default) is noted by validate and study,
    naming the key; a travel given, the thesis's own train (whose travel it is) and a run
    that does not record the spring are not. Fails on a copy without the note, or one that
    notes the thesis's spring-surge study."""
    from campipe.study.spec.notes import travel_note

    bucket = STUDIES / "bucket-tappet-lash.yaml"
    record = {"run.record": ["spring"], "sweep.speed": ["2000 rpm"], "sweep.model.lash": ["0.2 mm"]}
    study = load_study(bucket, record)
    note = travel_note(study.cases, study.record)
    assert note is not None and "layout direct-acting" in note and "40.64 mm" in note
    given = load_study(bucket, {**record, "model.spring_travel_to_solid": "9 mm"})
    assert travel_note(given.cases, given.record) is None
    unrecorded = load_study(bucket, {k: v for k, v in record.items() if k != "run.record"})
    assert travel_note(unrecorded.cases, unrecorded.record) is None
    surge = load_study(STUDIES / "spring-surge.yaml")
    assert "spring" in surge.record and travel_note(surge.cases, surge.record) is None
    report = run_study(study, tmp_path / "bucket.nc", scheduler="synchronous")
    assert note in report.notes
    shown = CliRunner().invoke(
        main,
        ["validate", "--no-estimate", str(bucket), "--set", "run.record=[spring]"],
    )  # fmt: skip
    assert "spring: the coil-clash margin of layout direct-acting" in shown.output


def test_a_contact_stiffness_far_beyond_a_valve_train_s_is_noted():
    """The bundled compliant studies' contacts are within ten times the stiffest a valve
    train's steel contact has ((π/2)·E*·w of a 100 mm line contact, 1.79e10 N/m, computed
    here from the modulus; (4/3)·E*·√R' at R' = 1 m for Hertz), so none is noted; the
    contact-stiffness study with a helper's 1e14 N/m is (a run of its turn took 92 s),
    naming the key and the ratio. Fails on a copy without the note, or one that
    notes the bundled studies."""
    from campipe.study.spec.notes import contact_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert contact_note(load_study(spec).cases) is None, spec.name
    pair = 30e6 * 4.4482216152605 / 0.0254**2 / (2 * (1 - 0.3**2))
    line = math.pi / 2 * pair * 0.1
    stiff = load_study(
        STUDIES / "contact-stiffness.yaml", {"sweep.model.cam_contact_stiffness": ["1e14 N/m"]}
    )
    note = contact_note(stiff.cases)
    assert note.startswith(f"model.cam_contact_stiffness 1e+14 N/m is {1e14 / line:.3g}×")
    assert f"({line:.3g} N/m, from contact_modulus)" in note


def test_a_cam_speed_beyond_any_valve_train_s_is_noted():
    """``speed: 9000 rps`` (540 000 rpm, a unit slip for rpm) is noted by campipe validate,
    counting the cases over a speed sweep without building them; no bundled study (the
    thesis's fastest, 20 000 rpm) is. Fails on a copy without the note, or one that notes
    the bundled studies."""
    from campipe.study.spec.notes import speed_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert speed_note(load_study(spec).cases) is None, spec.name
    slip = load_study(STUDIES / "quickstart.yaml", {"sweep.speed": ["6000 rpm", "9000 rps"]})
    note = speed_note(slip.cases)
    assert note.startswith("2 cases turn the cam faster than 30000 rpm")  # 2 seats
    assert "(the fastest 540000 rpm)" in note
    result = validated("quickstart.yaml", "sweep.speed=[6000 rpm, 9000 rps]")
    assert "speed: 2 cases turn the cam faster than 30000 rpm" in result.output


def test_a_spring_preload_a_soft_chain_gives_under_is_noted():
    """Without lash, ``spring_preload`` is the spring's force at the train's unstressed
    reference; on the base circle the chain's links give under it and the spring pushes
    P₀·k/(k + k_s), k the links in series (closed form, here): 83.33 N for 250 N on links of
    1e6 and 20 N/mm under a 40 N/mm spring (a helper's chain, read as 250 N installed). It
    is noted with the preload that installs 250 N; the thesis's train (0.5 % less) and no
    bundled study are. Fails on a copy without the note, or one that notes the thesis."""
    from campipe.model import valve_train
    from campipe.model.spring import base_circle_force
    from campipe.study.spec.notes import preload_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert preload_note(load_study(spec).cases) is None, spec.name
    chain = valve_train("thesis-1971", {
        "layout": "lumped", "masses": ["50 g", "1 g", "60 g"],
        "stiffnesses": ["1e6 N/mm", "20 N/mm"], "spring_rate": "40 N/mm",
        "spring_preload": "250 N", "damping_ratios": [0.05],
    })  # fmt: skip
    k = 1 / (1 / 1e9 + 1 / 2e4)  # N/m
    assert base_circle_force(chain) == pytest.approx(250 * k / (k + 4e4), rel=1e-9)
    thesis = valve_train()
    assert 0.99 < base_circle_force(thesis) / thesis.spring_preload < 0.999
    study = load_study(STUDIES / "quickstart.yaml", {
        "model.layout": "lumped", "model.masses": ["50 g", "1 g", "60 g"],
        "model.stiffnesses": ["1e6 N/mm", "20 N/mm"], "model.spring_rate": "40 N/mm",
        "model.spring_preload": "250 N", "model.damping_ratios": [0.05],
    })  # fmt: skip
    note = preload_note(study.cases)
    assert note is not None and "the spring pushes 83.33 N (66.7 % less)" in note
    assert "for 250 N there give 750 N" in note


def test_a_mass_in_the_wrong_unit_is_noted():
    """A lever's inertia in kg·m² for kg·mm² (the bundled finger's 40 kg·mm² as 40 kg·m²)
    reduces to the valve as (J + m_r·a²)/b², computed here: 19 750 kg; a bucket's valve mass
    in kg for g; each noted naming the key; no bundled study is (their masses 8-60 g, the
    thesis's derived from its members). Fails on a copy without the note, or one that notes
    the bundled studies."""
    from campipe.study.spec.notes import mass_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert mass_note(load_study(spec).cases) is None, spec.name
    slip = load_study(STUDIES / "finger-follower.yaml", {"model.lever_inertia": "40 kg*m**2"})
    reduced = (40.0 + 0.010 * 0.030**2) / 0.045**2
    note = mass_note(slip.cases)
    assert note.startswith(f"{len(slip.cases)} cases have a mass far from a valve train's")
    assert "model.lever_inertia gives the lever's mass reduced to the valve" in note
    assert f" {reduced * 1e3:.4g} g (outside 0.1 g to 5 kg)" in note
    bucket = load_study(STUDIES / "bucket-tappet-lash.yaml", {"model.valve_mass": "46 kg"})
    assert "model.valve_mass 4.6e+04 g" in mass_note(bucket.cases)
    result = validated("finger-follower.yaml", "model.lever_inertia=40 kg*m**2")
    assert "mass: 7 cases have a mass far from a valve train's grams" in result.output


def test_a_lever_whose_reduced_mass_moves_far_from_its_rest_value_is_noted():
    """The dynamics hold a lever's mass reduced to the valve at its rest value; its angle α
    moves it by cos²α₀/cos²α. The bundled finger tilted 10° down (α₀ = −10°): at the nose
    the valve's lift v puts the pallet arm at sin α = sin α₀ − v/b, computed here from the
    kinematics' largest lift (`campipe model`'s table), a factor beyond 1.1,
    noted with it; the bundled studies are not (the level finger's 6.6 %). Fails on a copy
    without the note, or one that notes the bundled studies."""
    from campipe.model.levers import lever_of
    from campipe.profiles.levers import cam_kinematics, cam_of
    from campipe.study.spec.notes import lever_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert lever_note(load_study(spec).cases) is None, spec.name
    tilted = load_study(STUDIES / "finger-follower.yaml", {"model.lever_rest_angle": "-10 deg"})
    case = tilted.cases[0].case
    theta = np.radians(np.arange(0.0, 360.0, 0.5))
    lift = cam_kinematics(cam_of(case.profile), case.train, theta).valve_lift.max()
    b, rest = lever_of(case.train).pallet_arm, math.radians(-10)
    factor = (math.cos(rest) / math.cos(math.asin(math.sin(rest) - lift / b))) ** 2
    assert factor > 1.1
    note = lever_note(tilted.cases)
    assert note.startswith(f"{len(tilted.cases)} cases' levers turn enough")
    assert f"by up to {factor - 1.0:+.1%} over the cam's turn" in note
    assert "model.lever_rest_angle -10°" in note


def test_an_adjuster_started_past_the_dry_lash_is_noted():
    """The bundled bucket's plunger started 0.5 mm out on its 0.2 mm of lash (a chain
    engineer's slip on theirs) takes up 0.3 mm more than the lash: the valve starts held off
    its seat, which it is below −P·(1/k_hla + 1/k_stem + 1/k_contact) = −220 N × (1/20000 +
    1/30000 + 1/60000) mm/N = −0.022 mm, computed here; noted with both. The bundled studies
    are not, nor an extension the lash takes (0.2 mm: effective lash 0). Fails on a copy
    without the note, or one that notes a pumped-up start."""
    from campipe.study.spec.notes import extension_note

    for spec in sorted(STUDIES.glob("*.yaml")):
        assert extension_note(load_study(spec).cases) is None, spec.name
    spec = STUDIES / "lash-adjuster.yaml"
    held = -220.0 * (1 / 20000 + 1 / 30000 + 1 / 60000)  # mm
    slip = load_study(spec, {"model.hla_extension": "0.5 mm"})
    note = extension_note(slip.cases)
    assert note is not None and note.startswith("4 cases start the lash adjuster extended")
    assert "leaves an effective lash of -0.3 mm" in note
    assert f"below the {held:.3g} mm at which the valve is held off its seat" in note
    pumped = load_study(spec, {"model.hla_extension": "0.2 mm"})
    assert extension_note(pumped.cases) is None
    result = validated("lash-adjuster.yaml", "model.hla_extension=0.5 mm")
    assert "lash adjuster: 4 cases start the lash adjuster extended past" in result.output
