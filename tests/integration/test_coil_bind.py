"""A study says when a valve spring goes solid: the model has no stop at solid, so a case
whose valve lifts past its spring's travel to solid (a train thrown far past its onset) is
not a real train's, and its numbers must not pass as one. A helper's sweep to 30 000 rpm
lifted the thesis's valve 85 mm against 40.6 mm of travel, every case ``ok``, without a
word.

Broken copy: the assembly's check left out (``Assembly.travel`` None): no note.
"""

import numpy as np
import xarray as xr
from study_helpers import write_spec

from campipe.study import load_study
from campipe.study.run.execute import run_study

SPEC = """
name: solid
model: {preset: thesis-1971, spring_travel_to_solid: %s}
profile: {kind: harmonic, lift: 1 in}
seat: 0.1 in
run: {revolutions: 3, output_every: 1 deg, record: [spring]}
sweep:
  speed: [9000 rpm, 30000 rpm]
"""


def test_a_valve_lifted_past_its_spring_s_travel_to_solid_is_noted(tmp_path):
    """At 30 000 rpm the thesis's valve is thrown past the 1.6 in its spring can travel; at
    9000 rpm it follows its 1.5 in lift. The note names 1 of 2 cases, that case and its lift
    (the archive's highest valve lift); the spring's own clash margin (record: [spring],
    from the spring's element model, not the valve's lift) is negative for that case alone.
    With 5 in of travel, nothing is noted."""
    path = tmp_path / "solid.nc"
    report = run_study(
        load_study(write_spec(tmp_path, SPEC % "1.6 in")), path, scheduler="synchronous"
    )
    notes = [n for n in report.notes if "coil bind" in n]
    assert len(notes) == 1, report.notes
    with xr.open_dataset(path) as ds:
        fast = int(np.argmax(ds.speed_rpm.values))
        highest = float(ds.valve_lift.isel(case=fast).max())
        assert highest > 1.6 * 0.0254 > float(ds.valve_lift.isel(case=1 - fast).max())
        margin = ds.min_spring_clash_margin.values
        assert margin[fast] < 0 < margin[1 - fast]
        case = str(ds.case.values[fast])
    assert (
        f"in 1 of 2 cases: case {case} at 30000 cam rpm lifts its valve {highest * 1e3:.4g} mm"
        in notes[0]
    )
    assert "past the spring's 40.64 mm travel to solid" in notes[0]
    roomy = tmp_path / "roomy"
    roomy.mkdir()
    report = run_study(
        load_study(write_spec(roomy, SPEC % "5 in")), roomy / "solid.nc", scheduler="synchronous"
    )
    assert not [n for n in report.notes if "coil bind" in n], report.notes


def test_query_summary_says_which_springs_clashed(tmp_path):
    """``campipe query --summary`` of an archive that records the spring names the cases whose
    coils clashed (min_spring_clash_margin below 0), parts archives too, where the run's own
    note is not written (a helper's cluster runs: none; its query and plot said nothing
    either). The 30 000 rpm case's margin, not the 9000 rpm one's. Broken copy: the summary
    without ``clash_lines``."""
    from click.testing import CliRunner

    from campipe.cli import main

    spec = write_spec(tmp_path, SPEC % "1.6 in")
    path = tmp_path / "solid.parts"
    run_study(load_study(spec), path, scheduler="synchronous", parts=True)
    summary = CliRunner().invoke(main, ["query", str(path), "--summary"])
    assert summary.exit_code == 0, summary.output
    lines = [x for x in summary.output.splitlines() if "coils clashed" in x]
    assert len(lines) == 1, summary.output
    assert "(min_spring_clash_margin below 0) in 1 of 2 cases" in lines[0]
    with _parts(path) as ds:
        fast = str(ds.case.values[int(np.argmax(ds.speed_rpm.values))])
    assert f"({fast})" in lines[0]


def _parts(path):
    from campipe.study.archive.open import open_archive

    return open_archive(path)


def test_a_cluster_s_parts_run_notes_the_coil_bind(tmp_path):
    """On a dask.distributed cluster each worker writes its part and returns its counts: the
    cases' highest lifts go with them (``cluster.PartCount.highest``), and the note is the
    local run's. Broken copy: a PartCount without them."""
    from distributed import LocalCluster

    spec = write_spec(tmp_path, SPEC % "1.6 in")
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        report = run_study(
            load_study(spec), tmp_path / "solid.parts", scheduler=cluster.scheduler_address,
            parts=True,
        )  # fmt: skip
    notes = [n for n in report.notes if "coil bind" in n]
    assert len(notes) == 1 and "in 1 of 2 cases: case" in notes[0], report.notes


def test_a_parts_run_notes_the_coil_bind_of_the_cases_it_computed(tmp_path):
    """A parts run (the cluster's route) notes the cases whose valve lifts past the spring's
    travel as a single-file run does, from the batches it computed (a worker returns each
    case's highest lift with its part's counts); a rerun that computes only some says of how
    many. Broken copy: the parts run without the note (a helper's cluster runs: none)."""
    spec = write_spec(tmp_path, SPEC % "1.6 in")
    path = tmp_path / "solid.parts"
    report = run_study(load_study(spec), path, scheduler="synchronous", parts=True)
    notes = [n for n in report.notes if "coil bind" in n]
    assert len(notes) == 1 and "in 1 of 2 cases: case" in notes[0], report.notes
    assert "at 30000 cam rpm" in notes[0]
    wider = SPEC.replace("[9000 rpm, 30000 rpm]", "[9000 rpm, 30000 rpm, 31000 rpm]")
    report = run_study(
        load_study(write_spec(tmp_path, wider % "1.6 in")), path, scheduler="synchronous",
        parts=True,
    )  # fmt: skip
    notes = [n for n in report.notes if "coil bind" in n]
    assert len(notes) == 1 and "in 1 of the 1 cases this run computed" in notes[0], notes
