"""`campipe model`: its JSON equals the numerics layer; its text shows the thesis layout."""

import json
import subprocess

import numpy as np
from click.testing import CliRunner
from numpy.testing import assert_allclose

from campipe.cli import main
from campipe.model import newmark_linear_stability_limit, system_matrices, valve_train


def run(*args):
    return CliRunner().invoke(main, ["model", *args], catch_exceptions=False)


def test_json_matches_the_numerics_layer():
    result = run("--set", "spring_rate=260 lbf/in", "--json")
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    sm = system_matrices(valve_train("thesis-1971", {"spring_rate": "260 lbf/in"}))
    assert out["natural_frequencies"] == sm.frequencies.tolist()
    assert out["natural_frequencies"] == sorted(out["natural_frequencies"])
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
    assert "679.1" in text and "6485.3" in text  # ω1 in rad/s and rpm
    assert "  II     3.2364 µs" in text


def test_bad_override_is_a_usage_error_naming_the_key():
    result = CliRunner().invoke(main, ["model", "--set", "spring_rate=260"])
    assert result.exit_code == 2
    assert "spring_rate" in result.output and "with units" in result.output


def test_console_script_runs():
    out = subprocess.run(["campipe", "model", "--json"], capture_output=True, text=True, check=True)
    assert_allclose(json.loads(out.stdout)["natural_frequencies"][0], 679.1, rtol=1e-3)
