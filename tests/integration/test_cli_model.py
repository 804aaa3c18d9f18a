"""`campipe model`: its JSON equals the numerics layer; its text shows the thesis layout."""

import json
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from campipe.cli import main
from campipe.model import (
    COORDINATES,
    newmark_linear_stability_limit,
    system_matrices,
    thesis_train,
    valve_train,
)


def run(*args):
    return CliRunner().invoke(main, ["model", *args], catch_exceptions=False)


def test_json_matches_the_numerics_layer():
    result = run("--set", "spring_rate=260 lbf/in", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    sm = system_matrices(valve_train("thesis-1971", {"spring_rate": "260 lbf/in"}))
    assert out["natural_frequencies"] == sm.frequencies.tolist()
    assert out["natural_frequencies"] == sorted(out["natural_frequencies"])
    assert_allclose(np.array(out["natural_frequencies_hz"]) * 2 * np.pi, sm.frequencies, rtol=1e-15)
    assert_allclose(out["mass_matrix"], sm.mass, rtol=0)
    assert_allclose(out["stiffness_matrix"], sm.stiffness, rtol=0)
    assert_allclose(out["damping_matrix"], sm.damping, rtol=0)
    assert [c["symbol"] for c in out["coordinates"]] == [f"q{i}" for i in range(1, 8)]
    assert out["coordinates"][0]["positive"].startswith("down")
    assert set(out["stability_limit_s"]) == {"I", "II", "III", "IV"}
    assert out["stability_limit_s"]["II"] == newmark_linear_stability_limit(
        sm.mass, sm.stiffness, 2
    )
    # The override took effect: K44 includes the 260 lbf/in spring.
    base = system_matrices(valve_train())
    assert_allclose(
        np.array(out["stiffness_matrix"])[3, 3] - base.stiffness[3, 3],
        15 * 4.4482216152605 / 0.0254,
        rtol=1e-9,
    )


def test_text_shows_the_thesis_layout():
    result = run()
    assert result.exit_code == 0
    text = result.output
    assert "Mass matrix [M] (Figure 11)" in text
    assert "    15.54    -7.77" in text  # M11, M12 ×1e-5 lbf·s²/in
    # ω1 in rad/s, Hz (679.1/2π = 108.08) and rpm (679.1·60/2π): fails on a copy that prints
    # the rad/s figure as Hz
    assert "679.1" in text and "108.1" in text and "6485.3" in text
    assert "  II     3.2364 µs" in text


def test_a_spec_with_a_drive_shows_each_mode_at_the_engine_s_speed_too():
    """The bundled finger with its lash adjuster (drive: cam_per_crank 0.5): each natural
    frequency as the cam speed whose first order meets it (ω·60/2π) and the engine's, twice
    that; a spec without a drive shows the cam's alone (a user read the rpm column as the
    engine's). Broken copy: the engine's column the cam's."""
    spec = Path(__file__).parents[2] / "studies" / "finger-follower-hla.yaml"
    result = run("--spec", str(spec))
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    head = lines.index("  mode          rad/s           Hz        cam rpm     engine rpm      ζ")
    assert "engine rpm: the crank's, by drive.cam_per_crank 0.5" in lines[head - 1]
    w, hz, cam, engine = (float(v) for v in lines[head + 1].split()[1:5])
    assert hz == pytest.approx(w / (2 * math.pi), abs=0.06)
    assert cam == pytest.approx(w * 60 / (2 * math.pi), abs=0.6)  # (w printed to 0.1)
    assert engine == pytest.approx(2 * cam, abs=0.11)
    assert "engine rpm" not in run().output
    # the JSON too, each list with its units named
    report = json.loads(run("--spec", str(spec), "--json").output)
    w = np.array(report["natural_frequencies"])
    assert_allclose(report["natural_frequencies_rpm"], w * 60 / (2 * math.pi), rtol=1e-12)
    assert_allclose(report["natural_frequencies_engine_rpm"], w * 120 / (2 * math.pi), rtol=1e-12)
    assert "cam" in report["units"]["natural_frequencies_rpm"]
    assert "natural_frequencies_engine_rpm" not in json.loads(run("--json").output)


def test_a_finger_s_adjuster_is_shown_in_the_link_it_stiffens():
    """The bundled finger on its adjuster: the listed ``stiffnesses`` (the finger's and the
    stem's) are not what the matrices hold, so the command shows the link with the adjuster
    in series as seen at the pallet, 1/(1/k + g₀²/k_hla) with g₀ = (b − a)/a (the hand's, from
    the spec's 10000 and 50000 N/mm in series, 20000 N/mm and arms of 22 and 36 mm), equal to
    the stiffness matrix's (a user read 10000 N/mm where K held 8470); the JSON the same in
    SI, with the adjuster's seated stiffness g₀²·(that link) in series with it. Broken copy:
    the adjuster at the pallet without its g₀²."""
    spec = Path(__file__).parents[2] / "studies" / "finger-follower-hla.yaml"
    g0 = (36 - 22) / 22
    link = 1.0 / (1.0 / 10000e3 + 1.0 / 50000e3)  # the finger and the stem [N/m]
    hand = 1.0 / (1.0 / link + g0**2 / 20000e3)
    text = run("--spec", str(spec)).output
    row = next(line for line in text.splitlines() if "(link next to the cam)" in line)
    assert float(row.split(")")[1].split()[0]) == pytest.approx(hand / 1e3, rel=1e-5)
    report = json.loads(run("--spec", str(spec), "--json").output)
    assert report["adjuster"]["link_stiffness"] == pytest.approx(hand, rel=1e-12)
    assert report["stiffness_matrix"][0][0] == pytest.approx(hand, rel=1e-12)
    seated = 1.0 / (1.0 / 20000e3 + 1.0 / (g0**2 * link))
    assert report["adjuster"]["seated_stiffness"] == pytest.approx(seated, rel=1e-12)


def test_bad_override_is_a_usage_error_naming_the_key():
    result = CliRunner().invoke(main, ["model", "--set", "spring_rate=260"])
    assert result.exit_code == 2
    assert "spring_rate" in result.output and "with units" in result.output


def test_console_script_runs():
    out = subprocess.run(["campipe", "model", "--json"], capture_output=True, text=True, check=True)
    assert_allclose(json.loads(out.stdout)["natural_frequencies"][0], 679.1, rtol=1e-3)


def test_convergence_lists_the_refined_trains_frequencies_and_orders():
    """``--convergence spring_elements``: each row is the train's lowest frequencies with the
    spring in n elements, and the fundamental's observed order is the consistent-mass 2.
    Fails if a row comes from another refinement or the order from the wrong rows."""
    result = run("--convergence", "spring_elements", "--modes", "3", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["elements"] == [1, 2, 4, 8, 16]
    for n, row in zip(out["elements"], out["natural_frequencies"], strict=True):
        sm = system_matrices(valve_train(overrides={"spring_elements": n}))
        assert row == sm.frequencies[:3].tolist()
    assert abs(out["observed_orders"][0] - 2) < 0.05
    text = run("--convergence", "spring_elements", "--modes", "3").output
    rows = [line.split() for line in text.splitlines() if line.split()[:1] in (["1"], ["16"])]
    assert [float(v) for v in rows[1][1:]] == pytest.approx(out["natural_frequencies"][4], 1e-6)
    assert "order" in text
    bad = CliRunner().invoke(main, ["model", "--convergence", "spring"])
    assert bad.exit_code == 2 and "spring_elements" in bad.output


def test_a_refined_train_lists_its_appended_coordinates():
    """``--set spring_elements=3``: nine coordinates, the thesis's seven first, then the
    spring's two internal nodes; 9×9 matrices; the preset's seven ratios cover nine modes
    (the last for the rest). Fails if the appended coordinates are unnamed or the modes'
    ratios are cut at seven."""
    out = json.loads(run("--set", "spring_elements=3", "--json").output)
    names = [c["name"] for c in out["coordinates"]]
    assert names[:7] == [c.name for c in COORDINATES] and names[7:] == ["spring_1", "spring_2"]
    assert np.shape(out["mass_matrix"]) == (9, 9)
    assert_allclose(out["modal_damping_ratios"], [0.5] + [0.1] * 8, rtol=1e-7)
    assert out["parameters"]["spring_elements"] == {"value": 3, "units": "1"}


def test_the_model_page_shows_what_the_commands_print():
    """docs/model.md's ``campipe model --convergence`` blocks are the commands' output
    (``python docs/model_outputs.py`` rewrites them). Fails when the page is stale."""
    import runpy
    from pathlib import Path

    script = runpy.run_path(str(Path(__file__).parents[2] / "docs" / "model_outputs.py"))
    page = script["PAGE"].read_text()
    assert script["rewritten"](page) == page, "run python docs/model_outputs.py"


FINGER_SETS = [
    "layout=finger-follower",
    "pivot_to_roller=30 mm",
    "pivot_to_pallet=45 mm",
    "cam_base_radius=18 mm",
    "cam_roller_radius=9 mm",
    "lever_inertia=40 kg*mm**2",
    "roller_mass=10 g",
    "valve_mass=60 g",
    "lever_stiffness=15 N/um",
    "stem_stiffness=60 N/um",
    "spring_rate=35 N/mm",
    "spring_preload=220 N",
    "damping_ratios=[0.05]",
]


def test_the_kinematic_ratio_table_of_a_finger_and_the_thesis_s_constant():
    """A finger follower's table (every 45°, the harmonic cam of 6 mm): on the base circle
    (90°, the cam straight above the roller, the lever level) the ratio is b/a = 45/30 and the
    valve lift 0; its masses and Hz are the two-mass chain's ((J + m·a²)/b², the valve); the
    thesis's rocker prints its constant arm ratio 1.5 in / 1.0 in. Fails on a copy that
    tabulates the ratio as a/b, or leaves the lever's keys out of the parameters shown. The
    reduced mass's factor over the turn is cos²α₀/cos²α of the lever's angle at each lift.
    """
    args = [a for s in FINGER_SETS for a in ("--set", s)]
    result = run(*args, "--ratio-step", "45", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    k = out["kinematic_ratio"]
    assert_allclose(np.degrees(k["cam_angle"]), np.arange(0, 360, 45.0))
    assert k["ratio"][2] == pytest.approx(1.5, rel=1e-12)
    assert k["valve_lift"][2] == pytest.approx(0.0, abs=1e-15)
    assert max(k["valve_lift"]) == pytest.approx(1.5 * 0.006, rel=0.02)
    # the reduced mass's factor cos²α₀/cos²α: the level lever at sin α = −v/b
    v = np.array(k["valve_lift"])
    assert_allclose(k["reduced_mass_factor"], 1.0 / (1.0 - (v / 0.045) ** 2), rtol=1e-12)
    m1 = (40e-6 + 0.010 * 0.030**2) / 0.045**2
    assert_allclose(np.diag(out["mass_matrix"]), [m1, 0.060], rtol=1e-12)
    assert {"pivot_to_roller", "valve_mass", "stem_stiffness"} <= set(out["parameters"])
    text = run(*args).output
    assert "Kinematic ratio over the cam turn" in text and " Hz " in text and " mass\n" in text
    thesis = json.loads(run("--json").output)["kinematic_ratio"]
    assert thesis["constant"] == pytest.approx(1.5, rel=1e-9)


def _two_mass_frequencies(m1, m2, k, at1, at2):
    """ω [rad/s] of two masses joined by k, with springs to ground at1 (on m1) and at2 (on
    m2): the roots of det(K − ω²M) = 0, a quadratic in ω²."""
    a, b, c = m1 * m2, -(m1 * (k + at2) + m2 * (k + at1)), (k + at1) * (k + at2) - k * k
    root = np.sqrt(b * b - 4 * a * c)
    return np.sqrt(np.array([(-b - root) / (2 * a), (-b + root) / (2 * a)]))


def test_compliant_contacts_at_their_static_load_and_the_frequencies_they_close():
    """A two-mass chain with a kelvin-voigt cam and a hertz seat: the cam carries the spring's
    preload, k at the follower and the chain's frequencies with it a spring to ground at m1
    (the seat open) the quadratic's; the seat's tangent stiffness at the preload is
    1.5·K^(2/3)·F^(1/3), its frequencies with that spring at the valve (the cam open). A
    rigid train lists none. Fails on a copy that puts the contact's spring on the other
    mass or linearises hertz at δ for F = 1 N."""
    m1, m2, k, ks, p, kc, kh = 0.05, 0.06, 2e7, 4e4, 250.0, 3e8, 1e10
    sets = [
        "layout=lumped",
        f"masses=[{m1} kg, {m2} kg]",
        f"stiffnesses=[{k} N/m]",
        f"spring_rate={ks} N/m",
        f"spring_preload={p} N",
        "damping_ratios=[0.05, 0.05]",
        "cam_contact=kelvin-voigt",
        f"cam_contact_stiffness={kc} N/m",
        "cam_contact_damping=30 N*s/m",
        "seat_contact=hertz",
        f"seat_hertz_constant={kh} N/m**1.5",
    ]
    result = run(*[a for s in sets for a in ("--set", s)], "--json")
    assert result.exit_code == 0, result.output
    cam, seat = json.loads(result.output)["compliant_contacts"]
    assert (cam["contact"], cam["law"], seat["contact"], seat["law"]) == (
        "cam", "kelvin-voigt", "seat", "hertz",
    )  # fmt: skip
    assert cam["static_load"] == pytest.approx(p, rel=1e-9)
    assert (cam["stiffness"], cam["damping"], cam["ratio"]) == (kc, 30.0, 1.0)
    assert_allclose(cam["natural_frequencies"], _two_mass_frequencies(m1, m2, k, kc, ks), rtol=1e-9)
    tangent = 1.5 * kh ** (2 / 3) * p ** (1 / 3)
    assert seat["static_load"] == pytest.approx(p, rel=1e-9)
    assert seat["stiffness"] == pytest.approx(tangent, rel=1e-9)
    assert_allclose(
        seat["natural_frequencies"], _two_mass_frequencies(m1, m2, k, 0.0, ks + tangent), rtol=1e-9
    )
    text = run(*[a for s in sets for a in ("--set", s)]).output
    assert "Compliant contacts, linearised at their static load" in text
    assert "natural frequencies, the seat closed (cam open) [Hz]" in text
    rigid = json.loads(run("--json").output)
    assert rigid["compliant_contacts"] == [] and "Compliant contacts" not in run().output


def test_a_finger_s_roller_contact_is_k_over_r_squared_at_the_valve():
    """The level finger of FINGER_SETS (ratio b/a = 1.5 on the base circle, its kinematic
    table's at 90°) with a kelvin-voigt roller: the roller carries the preload times 1.5, the
    valve side feels k/1.5² (and c/1.5²), and the two-mass chain (the lever reduced to the
    pallet, (J + m·a²)/b²; the lever and stem in series) rings with k/1.5² at its first mass.
    Fails on a copy that reflects the contact's stiffness by r, not r², or takes the
    preload as the roller's load."""
    kc, c = 2e8, 50.0
    sets = [*FINGER_SETS, "cam_contact=kelvin-voigt", f"cam_contact_stiffness={kc} N/m",
            f"cam_contact_damping={c} N*s/m"]  # fmt: skip
    out = json.loads(run(*[a for s in sets for a in ("--set", s)], "--json").output)
    (cam,) = out["compliant_contacts"]
    r = out["kinematic_ratio"]["ratio"][3]  # 90°, every 30°
    assert r == pytest.approx(1.5, rel=1e-12)
    assert cam["ratio"] == pytest.approx(1.5, rel=1e-12)
    assert cam["static_load"] == pytest.approx(220.0 * 1.5, rel=1e-9)
    assert cam["valve_side_stiffness"] == pytest.approx(kc / 2.25, rel=1e-12)
    assert cam["valve_side_damping"] == pytest.approx(c / 2.25, rel=1e-12)
    m1 = (40e-6 + 0.010 * 0.030**2) / 0.045**2
    link = 1.0 / (1.0 / 15e6 + 1.0 / 60e6)
    expected = _two_mass_frequencies(m1, 0.060, link, kc / 2.25, 35e3)
    assert_allclose(cam["natural_frequencies"], expected, rtol=1e-9)
    # the pallet's mass is struck, the valve free (a diagonal mass matrix): c/r² on k/r² and m1
    assert cam["struck_mass"] == pytest.approx(m1, rel=1e-12)
    zeta = (c / 2.25) / (2.0 * np.sqrt(kc / 2.25 * m1))
    assert cam["contact_damping_ratio"] == pytest.approx(zeta, rel=1e-12)


def _landing(zeta: float) -> float:
    """A unit mass landing at 1 m/s on a spring (ω = 1) and dashpot (2ζ) that let go where
    their force reaches zero, integrated by solve_ivp (DOP853): the rebound speed."""
    from scipy.integrate import solve_ivp

    def force(t, y):
        return y[0] + 2.0 * zeta * y[1]

    force.terminal, force.direction = True, -1.0
    sol = solve_ivp(
        lambda t, y: [y[1], -force(t, y)], (0.0, 50.0), [0.0, 1.0], method="DOP853",
        rtol=1e-12, atol=1e-14, events=force,
    )  # fmt: skip
    (t,) = sol.t_events[0]
    return -float(sol.y_events[0][0][1])


@pytest.mark.parametrize("zeta", [0.0, 0.01, 0.3, 0.7, 0.99, 1.0, 1.5, 4.0])
def test_the_restitution_of_a_released_contact_is_an_integrated_landing_s(zeta):
    """``released_restitution`` against a landing integrated by solve_ivp, to 1e-8; it is not
    the classic exp(−πζ/√(1 − ζ²)) (which holds the dashpot in tension until δ = 0): a copy
    returning that fails at ζ = 0.3 (0.373 against 0.284)."""
    from campipe.model.landing import released_restitution

    assert released_restitution(zeta) == pytest.approx(_landing(zeta), rel=1e-8, abs=1e-12)
    if 0.3 <= zeta < 1.0:
        assert abs(released_restitution(zeta) - np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))) > 1e-3


def test_a_one_mass_chain_s_contact_damping_and_restitution_are_its_closed_forms():
    """One mass on its spring (its damping ratio ζ₁ with the mass free: c₁ = 2ζ₁√(k_s·m)) on
    a kelvin-voigt cam: closed, one mode at √((k_s + k)/m) with ζ = (c₁ + c)/(2√((k_s + k)·m));
    the mass struck is m, the contact's own ζ = c/(2√(k·m)) and its restitution
    ``released_restitution``'s. A damped hertz seat's restitution is null (it depends on the
    speed); an undamped one's 1. The model shown is the follower's own, m, k_s and c₁ (its
    valve's mirror, a coordinate of the engine's, taken out: shown with it, the mass was 2m).
    Fails on a copy that leaves the contact's dashpot out of the modes' damping, or keeps the
    mirror's share in the matrices shown."""
    from campipe.model.landing import released_restitution

    m, ks, kc, c, z1 = 0.08, 40e3, 2e8, 400.0, 0.05
    sets = [
        "layout=lumped", f"masses=[{m} kg]", "stiffnesses=[]", f"spring_rate={ks} N/m",
        "spring_preload=250 N", f"damping_ratios=[{z1}]", "cam_contact=kelvin-voigt",
        f"cam_contact_stiffness={kc} N/m", f"cam_contact_damping={c} N*s/m",
        "seat_contact=hertz", "seat_hertz_constant=1e10 N/m**1.5", "seat_hunt_crossley=0.2 s/m",
    ]  # fmt: skip
    result = run(*[a for s in sets for a in ("--set", s)], "--json")
    assert result.exit_code == 0, result.output
    cam, seat = json.loads(result.output)["compliant_contacts"]
    c1 = 2.0 * z1 * np.sqrt(ks * m)
    assert_allclose(cam["natural_frequencies"], [np.sqrt((ks + kc) / m)], rtol=1e-12)
    assert_allclose(cam["damping_ratios"], [(c1 + c) / (2 * np.sqrt((ks + kc) * m))], rtol=1e-9)
    assert cam["struck_mass"] == pytest.approx(m, rel=1e-15)
    zeta = c / (2.0 * np.sqrt(kc * m))
    assert cam["contact_damping_ratio"] == pytest.approx(zeta, rel=1e-12)
    assert cam["restitution"] == pytest.approx(released_restitution(zeta), rel=1e-12)
    assert seat["restitution"] is None
    text = run(*[a for s in sets for a in ("--set", s)]).output
    assert f"a landing rebounds with e = {released_restitution(zeta):.3f}" in text
    assert "depends on the landing's speed" in text
    undamped = [s for s in sets if not s.startswith("seat_hunt")]
    out = json.loads(run(*[a for s in undamped for a in ("--set", s)], "--json").output)
    assert out["compliant_contacts"][1]["restitution"] == 1.0
    assert out["mass_matrix"] == [[m]]
    assert_allclose(out["stiffness_matrix"], [[ks]], rtol=1e-12)
    assert_allclose(out["damping_matrix"], [[c1]], rtol=1e-12)
    assert_allclose(out["natural_frequencies"], [np.sqrt(ks / m)], rtol=1e-12)


def test_the_natural_frequencies_with_the_follower_on_the_cam():
    """What a designer tunes a valve spring against: the train's frequencies with its
    follower held on the cam (configuration I). A bucket tappet's is the valve on its stem
    and spring, √((k_link + k_s)/m_valve), the link the stem and the tappet's contact in
    series, to 1e-10; the thesis train's, the eigenvalues of the free partition's M⁻¹K
    (numpy's general eigensolver, not the symmetric one campipe uses), to 1e-9; a one-mass
    chain has none (a rigid follower). Broken copy: the free-free frequencies printed
    under the name."""
    bucket = [
        "--set", "layout=direct-acting", "--set", "tappet_mass=45 g", "--set", "valve_mass=65 g",
        "--set", "stem_stiffness=30000 N/mm", "--set", "tappet_contact_stiffness=60000 N/mm",
        "--set", "spring_rate=35 N/mm", "--set", "spring_preload=220 N",
        "--set", "damping_ratios=[0.05]",
    ]  # fmt: skip
    out = CliRunner().invoke(main, ["model", *bucket, "--json"])
    assert out.exit_code == 0, out.output
    link = 1.0 / (1.0 / 30000e3 + 1.0 / 60000e3)
    held = json.loads(out.output)["natural_frequencies_on_the_cam"]
    assert_allclose(held, [math.sqrt((link + 35e3) / 0.065)], rtol=1e-10)
    text = CliRunner().invoke(main, ["model", *bucket]).output
    assert "with the follower on the cam (configuration I: q1 held)" in text
    assert "17556.5       2794.2" in text
    # a layout beyond the thesis's reads in metric units (it read 199.855 lbf/in, 49.458 lbf)
    assert "Parameters (metric units)" in text and "rad/in" not in text
    assert "spring_rate                    35 N/mm" in text
    assert "spring_preload                 220 N" in text
    assert "Parameters (thesis units)" in CliRunner().invoke(main, ["model"]).output
    thesis = json.loads(CliRunner().invoke(main, ["model", "--json"]).output)
    sm = system_matrices(thesis_train())
    free = slice(1, None)
    roots = np.linalg.eigvals(np.linalg.solve(sm.mass[free, free], sm.stiffness[free, free]))
    assert_allclose(thesis["natural_frequencies_on_the_cam"], np.sqrt(np.sort(roots.real)),
                    rtol=1e-9)  # fmt: skip
    one = ["--set", "layout=lumped", "--set", "masses=[0.08 kg]", "--set", "stiffnesses=[]",
           "--set", "spring_rate=40 N/mm", "--set", "spring_preload=250 N",
           "--set", "damping_ratios=[0.05]"]  # fmt: skip
    rigid = CliRunner().invoke(main, ["model", *one, "--json"])
    assert rigid.exit_code == 0, rigid.output
    assert json.loads(rigid.output)["natural_frequencies_on_the_cam"] == []


def test_a_spec_s_model_and_its_case(tmp_path):
    """`campipe model --spec`: the bundled bucket study's model without restating it (its
    on-the-cam frequency the closed form √((k_link + k_s)/m_valve)), case --case N's lash
    where the spec sweeps it (said on stderr), a model key set over the spec's, and refusals
    naming --case and a swept key; a lever layout's ratio table under the spec's cam. Broken
    copies: the preset's train shown (the thesis layout); the case's index ignored (the first
    case's 0.1 mm); the table under --cam-lift's harmonic cam (its largest lift 6 mm)."""
    from study_helpers import STUDIES

    spec = str(STUDIES / "bucket-tappet-lash.yaml")
    out = CliRunner().invoke(main, ["model", "--spec", spec, "--case", "2", "--json"])
    assert out.exit_code == 0, out.output
    report = json.loads(out.output[out.output.index("{") :])
    assert (
        report["layout"] == "direct-acting" and report["spec"] == "bucket-tappet-lash.yaml (case 2)"
    )
    assert report["parameters"]["lash"]["value"] == pytest.approx(0.25e-3)
    link = 1.0 / (1.0 / 30000e3 + 1.0 / 60000e3)
    assert_allclose(report["natural_frequencies_on_the_cam"], [math.sqrt((link + 35e3) / 0.065)],
                    rtol=1e-10)  # fmt: skip
    text = CliRunner().invoke(main, ["model", "--spec", spec, "--case", "2"])
    assert "varies model.lash across its 18 cases; shown: case 2's (lash 0.25 mm)" in text.output
    assert "spec bucket-tappet-lash.yaml (case 2), layout direct-acting" in text.output
    rate = CliRunner().invoke(main, ["model", "--spec", spec, "--set", "spring_rate=40 N/mm"])
    assert "spring_rate                    40 N/mm" in rate.output
    swept = CliRunner().invoke(main, ["model", "--spec", spec, "--set", "lash=0.2 mm"])
    assert swept.exit_code == 2 and "varies model.lash" in swept.output
    assert "choose a case with --case N" in swept.output
    beyond = CliRunner().invoke(main, ["model", "--spec", spec, "--case", "18"])
    assert beyond.exit_code == 2 and "has cases 0 … 17" in beyond.output
    alone = CliRunner().invoke(main, ["model", "--case", "1"])
    assert alone.exit_code == 2 and "give the spec" in alone.output
    # A lever layout's ratio table runs under the spec's cam, not --cam-lift's harmonic one:
    # the finger's largest valve lift is the spec's 6.5 mm cam through its ratio (about 1.5).
    finger = CliRunner().invoke(
        main, ["model", "--spec", str(STUDIES / "finger-follower.yaml"), "--json"]
    )
    table = json.loads(finger.output[finger.output.index("{") :])["kinematic_ratio"]
    assert table["cam"].startswith("the spec's cam, polydyne-4567")
    assert max(table["cam_lift"]) == pytest.approx(6.5e-3, rel=1e-9)
    assert 9.5e-3 < max(table["valve_lift"]) < 1.0e-2


def test_stability_limits_of_a_chain_leave_its_placeholders_out():
    """A chain's stability limits are its own masses' (the placeholders, decoupled and below
    every mode, set none): a one-mass chain is free only in II, where √12/ω with ω = √(k/m)
    of the mass on its spring; a two-mass chain held at both ends (III) has nothing free, and
    in II its limit is √12 over its higher free frequency, the larger root of
    m₁m₂ω⁴ − (m₁(k + k_s) + m₂k)ω² + k·k_s. Broken copy: the limits of the full seven coordinates
    (III 0.45 of the chain's lowest frequency: a placeholder's, 13 ms)."""
    one = run("--set", "layout=lumped", "--set", "masses=[100 g]", "--set", "stiffnesses=[]",
              "--set", "spring_rate=40 N/mm", "--set", "spring_preload=250 N",
              "--set", "damping_ratios=[0]", "--json")  # fmt: skip
    assert one.exit_code == 0, one.output
    limits = json.loads(one.output)["stability_limit_s"]
    assert limits["I"] is None and limits["III"] is None and limits["IV"] is None
    assert limits["II"] == pytest.approx(np.sqrt(12) / np.sqrt(40e3 / 0.1), rel=1e-12)
    m1, m2, k, ks = 0.05, 0.06, 20000e3, 40e3
    two = run("--set", "layout=lumped", "--set", "masses=[0.05 kg, 0.06 kg]",
              "--set", "stiffnesses=[20000 N/mm]", "--set", "spring_rate=40 N/mm",
              "--set", "spring_preload=250 N", "--set", "damping_ratios=[0.05, 0.05]")  # fmt: skip
    assert two.exit_code == 0, two.output
    assert "III      none: nothing is free" in two.output
    a, b, c = m1 * m2, -(m1 * (k + ks) + m2 * k), k * ks
    high = np.sqrt((-b + np.sqrt(b * b - 4 * a * c)) / (2 * a))
    line = next(x for x in two.output.splitlines() if x.strip().startswith("II "))
    assert float(line.split()[1]) == pytest.approx(np.sqrt(12) / high * 1e6, abs=1e-4)


def test_a_spec_written_in_mm_shows_the_thesis_s_train_in_metric_units(tmp_path):
    """``campipe model --spec`` of the thesis's preset written in N and mm lists its
    parameters in the trade's metric units (the pushrod's 9 in as 228.6 mm, the preload as
    given, 600 N); written in inches and pounds, in the thesis's. A helper's spec in N and mm
    was shown in lbf and in."""
    body = "model: {preset: thesis-1971, spring_preload: %s}\nprofile: {kind: harmonic, lift: %s}\n"

    def shown(name: str, preload: str, lift: str) -> str:
        path = tmp_path / f"{name}.yaml"
        path.write_text(f"name: {name}\n" + body % (preload, lift) + "speed: 3000 rpm\n")
        out = CliRunner().invoke(main, ["model", "--spec", str(path)])
        assert out.exit_code == 0, out.output
        return out.output

    metric = shown("metric", "600 N", "7 mm")
    assert "Parameters (metric units)" in metric
    assert re.search(r"pushrod_length +228\.6 mm", metric)
    assert re.search(r"spring_preload +600 N", metric)
    thesis = shown("thesis", "151 lbf", "1 in")
    assert "Parameters (thesis units)" in thesis
    assert re.search(r"pushrod_length +9 in", thesis)


def _printed_matrix(text: str, title: str) -> np.ndarray:
    """The matrix printed under the line starting ``title`` (its scale ×1eN applied)."""
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith(title))
    scale = float(re.search(r"×(\S+)", lines[at]).group(1))
    rows = []
    for line in lines[at + 2 :]:
        if not line.strip():
            break
        rows.append([float(v) for v in line.split()[1:]])
    return np.array(rows) * scale


def test_a_chain_s_printed_matrices_give_its_modes():
    """A layout beyond the thesis's prints its matrices to six significant digits: the
    bundled finger's K holds 12.035 beside 12.000 ×1e6 N/m (its spring's rate, in the
    fourth digit), and its modes recomputed from the printed M and K are the numerics
    layer's to 2e-3 (a valve-train engineer recomputed the first 7 % off from the two
    decimals printed before). Broken copy: two decimals for every layout."""
    spec = Path(__file__).parents[2] / "studies" / "finger-follower.yaml"
    result = CliRunner().invoke(main, ["model", "--spec", str(spec)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    m = _printed_matrix(result.output, "Mass matrix")
    k = _printed_matrix(result.output, "Stiffness matrix")
    recomputed = np.sort(np.sqrt(np.linalg.eigvals(np.linalg.solve(m, k)).real))
    as_json = CliRunner().invoke(main, ["model", "--spec", str(spec), "--json"])
    frequencies = json.loads(as_json.output)["natural_frequencies"]
    assert_allclose(recomputed, np.sort(frequencies)[: recomputed.size], rtol=2e-3)


def test_the_damping_ratios_on_the_cam_are_the_held_train_s_decay():
    """`campipe model` prints each on-cam mode's damping ratio with the train's one C: the
    decay of the held train's own motion. Against the eigenvalues of its free partition's
    state matrix (numpy's general eigensolver), −Re λ/|λ|, to 2e-4 (the ratio is the
    diagonal of Φᵀ C Φ: modes the damping couples decay a little differently), for the
    thesis's modal ratios and for η = 0.02 on every member, whose fundamental on the cam is
    damped at half of η/2 (docs/model.md, Damping). Broken copy: the free train's ratios
    printed under the name (0.5 for the thesis's first, η/2 for the loss factor's)."""
    members = ["pushrod", "rocker_pushrod_arm", "rocker_valve_arm", "spring", "valve_stem"]
    loss = {f"{m}_loss_factor": 0.02 for m in members}
    for changes in ({}, {"damping_kind": "loss-factor", **loss}):
        sets = [a for k, v in changes.items() for a in ("--set", f"{k}={v}")]
        out = CliRunner().invoke(main, ["model", *sets, "--json"])
        assert out.exit_code == 0, out.output
        zeta = np.array(json.loads(out.output)["modal_damping_ratios_on_the_cam"])
        sm = system_matrices(thesis_train().replace(**changes))
        free = slice(1, None)
        m, k, c = (x[free, free] for x in (sm.mass, sm.stiffness, sm.damping))
        state = np.block(
            [[np.zeros((6, 6)), np.eye(6)], [-np.linalg.solve(m, k), -np.linalg.solve(m, c)]]
        )
        roots = np.linalg.eigvals(state)
        roots = roots[roots.imag > 0]
        roots = roots[np.argsort(np.abs(roots))]
        assert_allclose(zeta, -roots.real / np.abs(roots), rtol=2e-4)
    assert zeta[0] < 0.6 * 0.01  # η/2 = 0.01 on the free train's modes, not on the cam's
