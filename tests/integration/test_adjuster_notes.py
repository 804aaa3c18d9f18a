"""Where a lash adjuster's plunger is moved once a turn (the per-turn model: a finger's pivot
with rigid contacts, or newmark-linear), `campipe validate` and `campipe study` say so, with
the model's stated error, and point at what carries it within the turn; where it is carried,
they say nothing."""

from click.testing import CliRunner
from study_helpers import STUDIES

from campipe.cli import main
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.study.spec.resolve import per_turn_note

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
