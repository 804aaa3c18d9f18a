"""A fractional ``run.revolutions``: the summaries read whole turns only. The partial last
turn stays in the per-turn metrics but is left out of the summaries (2.5 turns averaged half
a turn's separation as a whole one's: 35.2° against 52.6° at 2 and 3 turns, no-follow at
9524 rpm); a spec with no whole turn after its warm-up is refused at run.revolutions."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from study_helpers import write_spec

from campipe.constants import INCH
from campipe.engine import Case, RunSettings, run_batch
from campipe.model import thesis_train
from campipe.profiles import harmonic
from campipe.study import SpecError, load_study

RPM = 2 * math.pi / 60
#: The thesis's train on the 1 in harmonic cam at 9524 rpm: it leaves the cam every turn.
CASE = Case(thesis_train(), harmonic(INCH), 9524 * RPM)
SPEC = """
name: turns
profile: {{kind: harmonic, lift: 1 in}}
speed: 9524 rpm
run: {{revolutions: {revolutions}, start: {start}}}
"""


@pytest.fixture(scope="module")
def two():
    return run_batch([CASE], RunSettings(revolutions=2, start="periodic"))


@pytest.mark.parametrize("revolutions", [2.5, 2.0001, 2.999])
def test_a_partial_last_turn_is_left_out_of_the_summaries(two, revolutions):
    """2.5 turns summarise as the 2 whole turns they hold, to the bit, for every metric; the
    partial turn's own values stay in the per-turn metrics. Broken copy: measured_turns
    without the partial turn's removal gives 35.2° (a mean with half a turn's separation)."""
    part = run_batch([CASE], RunSettings(revolutions=revolutions, start="periodic"))
    assert_array_equal(part.measured, [True, True, False])
    assert np.degrees(two.separation_per_rev[0]) == pytest.approx([52.12, 53.12], abs=0.01)  # [deg]
    for key in ("separation", "cam_impacts", "max_cam_force", "max_cam_impact_velocity"):
        assert_array_equal(part.metric(key), two.metric(key))
    assert_array_equal(part.separation_per_rev[:, :2], two.separation_per_rev)
    assert math.degrees(part.separation[0]) == pytest.approx(52.62, abs=0.01)


def test_one_and_a_half_turns_read_their_first_turn(two):
    """1.5 turns: the summary is the first whole turn's value (52.12°, not 26.4°, the mean
    with the half turn). Broken copy: the partial turn kept in the mean."""
    part = run_batch([CASE], RunSettings(revolutions=1.5, start="periodic"))
    assert_array_equal(part.measured, [True, False])
    assert_array_equal(part.separation, two.separation_per_rev[:, 0])
    assert math.degrees(part.separation[0]) == pytest.approx(52.12, abs=0.01)


def test_whole_runs_and_runs_shorter_than_a_turn_are_unchanged():
    """A whole number of turns measures every turn after the warm-up; a run shorter than one
    turn (the engine's warm-up and timing runs) reads its only, partial, turn. Broken copy:
    measured_turns dropping the last turn whenever it is partial leaves 0.5 turns nothing."""
    settings = RunSettings(revolutions=3, start="quasi-static")
    assert_array_equal(settings.measured_turns(3), [False, True, True])
    assert_array_equal(RunSettings(revolutions=0.5).measured_turns(1), [True])
    assert_array_equal(RunSettings(revolutions=3.5, warmup=1).measured_turns(4), [0, 1, 1, 0])


@pytest.mark.parametrize(
    ("revolutions", "start", "needed"), [(1.5, "quasi-static", 2), (0.5, "periodic", 1)]
)
def test_a_spec_with_no_whole_turn_after_the_warm_up_is_refused(
    tmp_path, revolutions, start, needed
):
    """1.5 turns from the quasi-static start (one turn of warm-up) or 0.5 turns leave no
    whole turn to measure: the spec is refused, naming run.revolutions and the turns needed
    (the engine itself runs them, reading the part: its warm-up and timing runs). Broken
    copy: check_settings without check_whole_turns accepts them."""
    spec = write_spec(tmp_path, SPEC.format(revolutions=revolutions, start=start))
    with pytest.raises(SpecError) as info:
        load_study(spec)
    assert "run.revolutions: found" in str(info.value)
    assert f"run at least {needed} turns" in str(info.value)
    ran = run_batch([CASE], RunSettings(revolutions=revolutions, start=start))
    assert ran.measured.tolist() == ([False, True] if start == "quasi-static" else [True])
    assert load_study(write_spec(tmp_path, SPEC.format(revolutions=2, start=start))).cases


def test_the_steady_level_measures_whole_turns_too():
    """The closed-form steady run (fidelity steady) uses the same rule: 2.5 turns summarise
    as 2. Broken copy: periodic.py's own warm-up mask."""
    steady = {"start": "periodic", "fidelity": "steady", "integrator": "modal-exact"}
    case = Case(thesis_train(), harmonic(INCH), 6000 * RPM)  # follows the cam
    whole = run_batch([case], RunSettings(revolutions=2, **steady))
    part = run_batch([case], RunSettings(revolutions=2.5, **steady))
    assert_array_equal(part.measured, [True, True, False])
    assert_allclose(part.max_cam_force, whole.max_cam_force, rtol=0, atol=0)
    assert np.isfinite(part.max_cam_force).all()
