"""A lumped chain (model.layout: lumped) through the command line: `campipe model` prints its
modes, `campipe study` runs, archives and `campipe query` selects its cases."""

import json
import math

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import write_spec

from campipe.cli import main
from campipe.engine.onset import CONFIRM_OFFSET

M1, M2, LINK, RATE, PRELOAD = 0.05, 0.06, 20000e3, 40e3, 250.0
MODEL = (
    "{layout: lumped, masses: [0.05 kg, 0.06 kg], stiffnesses: [20000 N/mm], "
    "spring_rate: 40 N/mm, spring_preload: 250 N, damping_ratios: [0.05, 0.05]}"
)
SETS = [
    "--set", "layout=lumped",
    "--set", "masses=[0.05 kg, 0.06 kg]",
    "--set", "stiffnesses=[20000 N/mm]",
    "--set", "spring_rate=40 N/mm",
    "--set", "spring_preload=250 N",
    "--set", "damping_ratios=[0.05, 0.05]",
]  # fmt: skip


def invoke(*args):
    return CliRunner().invoke(main, list(args))


def test_campipe_model_prints_the_chain_s_two_modes():
    """The JSON's natural frequencies are the two-mass chain's closed form (every mass free:
    the roots of m1·m2·ω⁴ − (m1·(k + ks) + m2·k)·ω² + k·ks), its coordinates the cam's mass
    and the valve only (no placeholders), each mode damped 0.05; the text names the layout.
    Fails on a copy that shows the placeholders' modes or the thesis's parameters."""
    out = invoke("model", *SETS, "--json")
    assert out.exit_code == 0, out.output
    report = json.loads(out.output)
    a, b, c = M1 * M2, -(M1 * (LINK + RATE) + M2 * LINK), LINK * RATE
    roots = [(-b - s * math.sqrt(b * b - 4 * a * c)) / (2 * a) for s in (1, -1)]
    np.testing.assert_allclose(report["natural_frequencies"], np.sqrt(roots), rtol=1e-10)
    np.testing.assert_allclose(report["modal_damping_ratios"], [0.05, 0.05], rtol=1e-9)
    assert [(x["symbol"], x["name"]) for x in report["coordinates"]] == [
        ("q1", "cam_mass"),
        ("q7", "valve"),
    ]
    assert report["layout"] == "lumped" and "pushrod_length" not in report["parameters"]
    assert report["parameters"]["masses"]["value"] == [M1, M2]
    text = invoke("model", *SETS).output
    assert "layout lumped" in text and "pushrod_length" not in text
    assert f"{math.sqrt(roots[0]):14.1f}" in text  # 602.9 rad/s


def test_a_lumped_study_runs_archives_and_queries(tmp_path):
    """The issue's chain over speeds and a seat: below its onset (about 10 400 rpm) it
    follows the cam, at 16 000 rpm it leaves it; the archive's q holds the cam's mass and the
    valve with NaN on the placeholders; the spring force is P + ks·q7 and the chain's single
    link carries the pushrod's and the stem's force, each named for the chain's link (and its
    q and dof_units for its coordinates, translations all), not the thesis's members; the
    query selects by speed; the export leaves out what is NaN in every row (the placeholders,
    the rocker's moment) and shows the mm spec's lengths in mm, its seating velocity in m/s.
    Fails on a copy that writes the placeholders' zeros, or measures the spring on the cam's
    side, or names the thesis's members and rotations on a chain."""
    spec = write_spec(
        tmp_path,
        f"""
    name: lumped-chain
    model: {MODEL}
    profile: {{kind: harmonic, lift: 10 mm}}
    speed: 3000 rpm
    sweep: {{speed: [3000 rpm, 9000 rpm, 16000 rpm], seat: [none, 0 mm]}}
    run: {{revolutions: 2, record: [q, member_loads, spring]}}
    """,
    )
    archive = tmp_path / "chain.nc"
    out = invoke("study", str(spec), "-o", str(archive), "--scheduler", "synchronous")
    assert out.exit_code == 0, out.output
    ds = xr.load_dataset(archive)
    assert ds.sizes["case"] == 6 and (ds.status == 0).all()
    speed = ds.speed_rpm.values
    sep = ds.separation_deg.values
    assert (sep[speed < 10000] == 0).all() and (sep[speed > 10000] > 100).all()
    q = ds.q.values
    assert np.isnan(q[:, :, 1:6]).all() and np.isfinite(q[:, :, [0, 6]]).all()
    # valve lift from the valve's static position on the base circle, −P/(k + ks)
    ref = -PRELOAD / (LINK + RATE)
    np.testing.assert_allclose(ds.valve_lift.values, q[:, :, 6] - ref, atol=1e-12)
    np.testing.assert_allclose(ds.spring_force.values, PRELOAD + RATE * q[:, :, 6], rtol=1e-12)
    np.testing.assert_allclose(ds.pushrod_force, ds.stem_force, rtol=0)
    link = LINK * (-q[:, :, 0] - q[:, :, 6])  # k·(x1 − x2), x1 = −q1
    np.testing.assert_allclose(ds.pushrod_force.values, link, rtol=1e-9, atol=1e-6)
    assert np.isnan(ds.rocker_moment.values).all()
    assert "chain's first mass" in ds.follower_lift.attrs["long_name"]  # not the pushrod's
    assert "link next to the cam" in ds.pushrod_force.attrs["long_name"]
    assert "link next to the valve" in ds.stem_force.attrs["long_name"]
    assert "q1 cam_mass" in ds.q.attrs["comment"] and "q7 valve" in ds.q.attrs["comment"]
    assert "rad" not in ds.q.attrs["comment"] and list(ds.dof_units.values) == ["m"] * 7
    lift = ds.valve_lift.values[speed == 3000].max()
    assert abs(lift - 0.01 * LINK / (LINK + RATE)) < 2e-3 * 0.01  # dynamic within 0.2 %
    table = invoke("query", str(archive), "--where", "speed_rpm > 5000", "--format", "json")
    assert table.exit_code == 0, table.output
    rows = json.loads(table.output)["cases"]
    assert sorted(r["speed_rpm"] for r in rows) == [9000, 9000, 16000, 16000]
    out = invoke(
        "export", str(archive), "--where", "speed_rpm > 5000", "-o", str(tmp_path / "e.csv")
    )
    assert out.exit_code == 0, out.output
    assert "left out, NaN in every row exported" in out.output
    assert "q2, q3, q4, q5, q6, rocker_moment" in out.output
    header = (tmp_path / "e.csv").read_text().splitlines()[0].split(",")
    assert "q1 [mm]" in header and "q7 [mm]" in header and "valve_lift [mm]" in header
    assert "valve_velocity [m/s]" in header and not any(h.startswith("q2") for h in header)
    from campipe.plot.figures import figure
    from campipe.study.spec.plots import check_plot

    titles = [ax.get_title() for ax in figure(ds, check_plot({"kind": "histories"})).axes]
    assert "first mass lift (cam lift dotted)" in titles  # not the thesis's pushrod foot


def test_campipe_model_refuses_convergence_on_a_chain():
    """--convergence refines the thesis's members, which a chain has none of: a usage error
    naming the layout, not a table of unchanged frequencies. Fails on a copy that refines the
    preset's members beside the chain."""
    out = invoke("model", *SETS, "--convergence", "spring_elements")
    assert out.exit_code == 2
    assert "layout lumped has none" in out.output


MIXED = """\
name: mixed-chains
model: {layout: lumped, masses: [0.08 kg], stiffnesses: [], spring_rate: 40 N/mm,
        spring_preload: 250 N, damping_ratios: [0.0]}
profile: {kind: harmonic, lift: 8 mm}
closure: force
run: {revolutions: 1}
sweep:
  speed: [3000 rpm, 20000 rpm]
cases:
  - {}
  - {model: {masses: [0.04 kg, 0.06 kg], stiffnesses: [20000 N/mm]}}
"""


def test_chains_of_different_lengths_share_a_study_and_an_onset_file(tmp_path):
    """A one-mass and a two-mass chain in one spec: the archive's and the onset file's list
    coordinates are as wide as the longest list, NaN beyond a shorter one, and query shows
    each case's own list; the one-mass chain's onset is its closed form
    ω² = 2(P₀ + k·h)/(m·h) (undamped), and so is where it leaves the cam just above it, and
    the two-mass chain's onset the same as in a spec of its own. Broken copies: the
    archive's list width taken from the last list coordinate (the stiffnesses': a ValueError
    writing the masses), the onset file's lists along its combinations only (a ValueError),
    the first separation's angle not taken within its turn (980.5° for 260.5°)."""
    spec = write_spec(tmp_path, MIXED, "mixed.yaml")
    out = invoke("study", str(spec), "-o", str(tmp_path / "mixed.nc"))
    assert out.exit_code == 0, out.output
    with xr.open_dataset(tmp_path / "mixed.nc") as ds:
        masses = ds.masses.values
    assert masses.shape == (4, 2) and np.isnan(masses[:2, 1]).all()
    np.testing.assert_allclose(masses[2:], [[0.04, 0.06]] * 2)
    shown = invoke("query", str(tmp_path / "mixed.nc"), "--columns", "masses,stiffnesses")
    assert "nan" not in shown.output and "0.04, 0.06        20000" in shown.output
    onset = invoke("onset", str(spec), "-o", str(tmp_path / "mixed-onset.nc"), "--format", "json")
    assert onset.exit_code == 0, onset.output
    rows = json.loads(onset.output[onset.output.index("{") : onset.output.rindex("}") + 1])
    one, two = rows["cases"]
    m, h = 0.08, 0.008
    closed = math.sqrt(2 * (250.0 + 40e3 * h) / (m * h)) * 30 / math.pi
    assert one["masses"] == [0.08] and one["onset_speed_rpm"] == pytest.approx(closed, abs=0.1)
    # Where it leaves the cam just above the onset: F = P₀ + k·h/2 + (h/2)(m·ω² − k)·sin θ on
    # the lift h/2·(1 − sin θ) first reaches zero at θ = π + asin((P₀ + k·h/2)/((h/2)(mω² − k))),
    # before the nose (270°); at the onset itself, the nose.
    w = one["onset_speed_rpm"] * (1 + CONFIRM_OFFSET) * math.pi / 30
    leaves = math.pi + math.asin((250.0 + 40e3 * h / 2) / (h / 2 * (m * w**2 - 40e3)))
    assert one["leaves_cam_at_deg"] == pytest.approx(math.degrees(leaves), abs=1e-3)
    assert 255.0 < one["leaves_cam_at_deg"] < 270.0
    alone = write_spec(tmp_path, MIXED.replace("  - {}\n", "").replace("cases:\n", "cases:\n"),
                       "alone.yaml")  # fmt: skip
    single = invoke("onset", str(alone), "-o", str(tmp_path / "alone.nc"), "--format", "json")
    solo = json.loads(single.output[single.output.index("{") : single.output.rindex("}") + 1])
    assert two["onset_speed_rpm"] == pytest.approx(solo["cases"][0]["onset_speed_rpm"], abs=0.1)
