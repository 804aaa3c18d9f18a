"""Parts archives (``campipe study --parts``): one compressed netCDF part per batch written by
its worker, an index written by the client; read back as one archive, packed into the single
file, resumed after damage, and run on a cluster of worker processes."""

import json
import os
import shutil
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_array_equal
from study_helpers import SMALL_SPEC, write_spec
from test_digest import archive_digest

import campipe
from campipe.cli import main
from campipe.io.parts import INDEX, part_files, read_index
from campipe.study import load_study
from campipe.study.archive.open import open_archive
from campipe.study.run.execute import run_study
from campipe.study.run.keys import study_key
from campipe.study.run.parts import pack
from campipe.study.run.resume import ArchiveExistsError

DATA = Path(__file__).parents[1] / "data"
#: Both integrators in turn (batches out of case order), seats, defects, events, q.
MIXED = DATA / "mixed-study.yaml"


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """The mixed study run once to a single file and once to parts (threads, batches of two
    cases: its cases alternate integrators, so the parts do not follow case order)."""
    directory = tmp_path_factory.mktemp("parts")
    study = load_study(MIXED)
    single = run_study(study, directory / "mixed.nc", scheduler="synchronous")
    parts = run_study(
        study, directory / "mixed.parts", scheduler="threads", workers=2, batch_size=2, parts=True
    )
    return study, directory, single, parts


def _without_global_attrs(ds):
    return ds.drop_attrs(deep=False)


def test_a_parts_run_reads_back_as_the_single_file_run(mixed):
    """Broken copies it fails on: an ``open_parts`` that concatenates the parts in the index's
    order without putting the cases back in the study's order (the mixed study's batches
    group its cases by integrator), or that keeps each part's own ``event_case`` rows."""
    study, directory, single, parts = mixed
    assert (parts.computed, parts.batches) == (10, 6)
    assert parts.statuses == single.statuses
    files = part_files(directory / "mixed.parts")
    assert len(files) == 6
    index = read_index(directory / "mixed.parts")
    assert index["case"] == [c.case_id for c in study.cases]
    assert sum(p["cases"] for p in index["parts"]) == 10
    with (
        xr.open_dataset(directory / "mixed.nc") as one,
        open_archive(directory / "mixed.parts") as many,
    ):
        assert many.sizes["event"] == one.sizes["event"] > 0
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))
        assert many.attrs["study_key"] == one.attrs["study_key"]
    with (
        campipe.open_study(directory / "mixed.nc") as one,
        campipe.open_study(directory / "mixed.parts") as many,
    ):
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))


def test_open_mfdataset_on_the_parts_gives_every_case_and_event(mixed):
    """The parts open with ``xarray.open_mfdataset``: per-case variables concatenated along
    ``case``, events along ``event``, each part's ``event_count`` the lengths of its cases'
    events. Broken copy it fails on: a part whose events are not its own cases' (written
    from another batch's rows), or whose ``event_count`` does not add up to its events."""
    _, directory, _, _ = mixed
    files = part_files(directory / "mixed.parts")
    options = {
        "combine": "nested",
        "data_vars": "minimal",
        "coords": "minimal",
        "compat": "override",
    }
    cases = xr.open_mfdataset(
        files, concat_dim="case", preprocess=lambda ds: ds.drop_dims("event"), **options
    )
    events = xr.open_mfdataset(
        files, concat_dim="event", preprocess=lambda ds: ds.drop_dims("case"), **options
    )
    with xr.open_dataset(directory / "mixed.nc") as one, cases, events:
        order = np.argsort(cases["case"].values)
        ref = np.argsort(one["case"].values)
        assert_array_equal(cases["case"].values[order], one["case"].values[ref])
        assert_array_equal(cases["max_cam_force"].values[order], one["max_cam_force"].values[ref])
        assert_array_equal(cases["q"].values[order], one["q"].values[ref])
        counts = cases["event_count"].values
        assert counts.sum() == events.sizes["event"] == one.sizes["event"]
        # the events of each case, found through the concatenated counts
        starts = np.concatenate([[0], np.cumsum(counts)])
        one_starts = np.concatenate([[0], np.cumsum(one["event_count"].values)])
        for row, cid in enumerate(cases["case"].values):
            at = int(np.flatnonzero(one["case"].values == cid)[0])
            assert_array_equal(
                events["event_time"].values[starts[row] : starts[row + 1]],
                one["event_time"].values[one_starts[at] : one_starts[at + 1]],
            )


def test_pack_writes_the_single_file_archive_variable_for_variable(mixed, tmp_path):
    """``pack`` against the single-file archive, with the digest test's hash of every
    variable's name, dimensions, type, attributes and values. Broken copies it fails on: a
    pack that writes the cases in the parts' order, or drops the case coordinates'
    attributes."""
    _, directory, _, _ = mixed
    packed = pack(directory / "mixed.parts", tmp_path / "packed.nc")
    assert archive_digest(packed) == archive_digest(directory / "mixed.nc")
    with netCDF4.Dataset(packed) as ds:
        assert ds.dimensions["event"].isunlimited()
        assert "campipe pack" in ds.getncattr("history")
    from campipe.io.archive import verify

    assert verify(packed) == []


def test_a_damaged_or_missing_part_is_computed_again_and_the_rest_reused(mixed, tmp_path):
    """A part with a byte changed fails its checksums: the rerun removes it, computes its
    cases again and reuses the others; the archive reads back as before. A rerun with no
    change finds the archive up to date. Broken copy it fails on: a resume that trusts a
    part without verifying it (the rerun would compute nothing, the index would name the
    damaged part)."""
    study, directory, _, _ = mixed
    archive = tmp_path / "mixed.parts"
    shutil.copytree(directory / "mixed.parts", archive)
    assert run_study(study, archive, parts=True).up_to_date
    victim = part_files(archive)[2]
    n_victim = netCDF4.Dataset(victim).dimensions["case"].size
    data = bytearray(victim.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(64)
    victim.write_bytes(bytes(data))
    report = run_study(study, archive, scheduler="synchronous", batch_size=2, parts=True)
    assert not report.up_to_date
    assert (report.reused, report.computed) == (10 - n_victim, n_victim)
    assert any("failed its checks" in n for n in report.notes)
    with xr.open_dataset(directory / "mixed.nc") as one, open_archive(archive) as again:
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(again))
    # the index gone (a run killed before it was written): every part reused, none computed
    (archive / INDEX).unlink()
    report = run_study(study, archive, scheduler="synchronous", parts=True)
    assert (report.reused, report.computed, report.up_to_date) == (10, 0, False)
    assert (archive / INDEX).is_file()


def test_a_changed_study_keeps_only_its_own_cases_in_the_index(tmp_path):
    """A spec that drops a speed: refused without --overwrite, the parts and index left as
    they were; with it the rerun reuses the parts, writes an index of the remaining cases
    only (with the new spec's attributes: the next rerun finds it up to date), and removes
    the part that holds none of them. Broken copies it fails on: an index of every part in
    the folder (the dropped speed's cases would read back), or one whose attributes are a
    reused part's (the old spec's study_key), or a rerun that removes cases unasked."""
    spec = write_spec(tmp_path, SMALL_SPEC)
    archive = tmp_path / "small.parts"
    run_study(load_study(spec), archive, scheduler="synchronous", batch_size=2, parts=True)
    assert len(part_files(archive)) == 3
    write_spec(tmp_path, SMALL_SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm]"))
    files = {p: p.read_bytes() for p in archive.iterdir()}
    with pytest.raises(ArchiveExistsError, match="4 of the 6 cases it holds are not in this"):
        run_study(load_study(spec), archive, scheduler="synchronous", parts=True)
    assert {p: p.read_bytes() for p in archive.iterdir()} == files  # the index too
    report = run_study(
        load_study(spec), archive, scheduler="synchronous", parts=True, overwrite=True
    )
    assert (report.reused, report.computed) == (2, 0)
    assert any("4 of the 6 cases it holds" in n and "removed" in n for n in report.notes)
    assert len(part_files(archive)) == 1
    with open_archive(archive) as ds:
        assert_array_equal(ds["speed_rpm"].values, [6000, 6000])
        assert ds.attrs["study_key"] == study_key(load_study(spec))  # not the old spec's
    assert run_study(load_study(spec), archive, parts=True).up_to_date


def test_a_parts_archive_never_replaces_a_file_or_a_foreign_folder(tmp_path):
    """Broken copy it fails on: a parts run that writes into any folder (or removes the
    file at its path)."""
    spec = write_spec(tmp_path, SMALL_SPEC)
    study = load_study(spec)
    (tmp_path / "file.parts").write_text("mine")
    with pytest.raises(ArchiveExistsError, match="a file"):
        run_study(study, tmp_path / "file.parts", parts=True, overwrite=True)
    assert (tmp_path / "file.parts").read_text() == "mine"
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "notes.txt").write_text("mine")
    with pytest.raises(ArchiveExistsError, match="not a parts archive"):
        run_study(study, tmp_path / "folder", parts=True)
    assert sorted(p.name for p in (tmp_path / "folder").iterdir()) == ["notes.txt"]


def test_a_study_on_two_worker_processes_equals_the_local_run(mixed, tmp_path):
    """The mixed study on a dask.distributed cluster of two worker processes (one thread
    each), each writing its batches' parts: the archive equals the local single-file run
    case for case. Broken copy it fails on: workers that write parts without their case
    coordinates (computed on the client only), or a client that indexes the parts in the
    order they finish without the study's case order."""
    from distributed import LocalCluster

    study, directory, _, _ = mixed
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        report = run_study(
            study,
            tmp_path / "mixed.parts",
            scheduler=cluster.scheduler_address,
            batch_size=2,
            parts=True,
        )
    assert (report.computed, report.batches) == (10, 6)
    with (
        xr.open_dataset(directory / "mixed.nc") as one,
        open_archive(tmp_path / "mixed.parts") as many,
    ):
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))


def test_a_relative_archive_path_reaches_a_cluster_s_workers(tmp_path, monkeypatch, mixed):
    """A parts archive given by a relative path, from a folder other than the one the
    cluster's workers started in (a helper's cluster run: refused, "a worker does not see the
    folder", everything on one machine): the workers resolve it in their own working folder,
    so the run makes it absolute first, and the archive equals the local single-file run.
    Broken copy it fails on: the path handed to the workers as given."""
    from distributed import LocalCluster

    study, directory, _, _ = mixed
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        (tmp_path / "here").mkdir()
        monkeypatch.chdir(tmp_path / "here")  # the workers stay where they started
        report = run_study(
            study, Path("mixed.parts"), scheduler=cluster.scheduler_address, parts=True
        )
    assert report.computed == 10
    with (
        xr.open_dataset(directory / "mixed.nc") as one,
        open_archive(tmp_path / "here" / "mixed.parts") as many,
    ):
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))


def test_the_command_line_writes_queries_and_packs_a_parts_archive(tmp_path):
    """``campipe study --parts`` writes ``<name>.parts``; ``campipe query`` reads the folder
    as it reads the file; ``campipe pack`` writes the single file under the output rule
    (its own earlier pack replaced, another file only with --overwrite, a part never).
    Broken copies it fails on: a query that reads only the first part, a pack that replaces
    a file it did not write, or a part of the archive it reads."""
    spec = write_spec(tmp_path, SMALL_SPEC)
    runner = CliRunner()
    result = runner.invoke(
        main, ["study", str(spec), "--parts", "--no-progress", "--batch-size", "2"]
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "small.parts" / INDEX).is_file()
    result = runner.invoke(main, ["study", str(spec), "--no-progress"])
    assert result.exit_code == 0, result.output
    query = [
        ["query", str(tmp_path / name), "--format", "csv"] for name in ("small.parts", "small.nc")
    ]
    rows = [runner.invoke(main, q) for q in query]
    assert rows[0].exit_code == 0, rows[0].output
    assert rows[0].output == rows[1].output and len(rows[0].output.splitlines()) == 7
    result = runner.invoke(
        main, ["pack", str(tmp_path / "small.parts"), "-o", str(tmp_path / "one.nc")]
    )
    assert result.exit_code == 0, result.output
    assert archive_digest(tmp_path / "one.nc") == archive_digest(tmp_path / "small.nc")
    # the output rule: its own earlier pack is replaced; a file it did not write only with
    # --overwrite; a file of the parts archive never
    result = runner.invoke(
        main, ["pack", str(tmp_path / "small.parts"), "-o", str(tmp_path / "one.nc")]
    )
    assert result.exit_code == 0, result.output
    (tmp_path / "notes.nc").write_text("mine")
    pack_to = ["pack", str(tmp_path / "small.parts"), "-o", str(tmp_path / "notes.nc")]
    result = runner.invoke(main, pack_to)
    assert result.exit_code == 2 and "exists" in result.output
    assert (tmp_path / "notes.nc").read_text() == "mine"
    assert runner.invoke(main, [*pack_to, "--overwrite"]).exit_code == 0
    part = part_files(tmp_path / "small.parts")[0]
    before = part.read_bytes()
    result = runner.invoke(
        main, ["pack", str(tmp_path / "small.parts"), "-o", str(part), "--overwrite"]
    )
    assert result.exit_code == 2 and "which this command reads" in result.output
    assert part.read_bytes() == before
    index = json.loads((tmp_path / "small.parts" / INDEX).read_text())
    assert index["attrs"]["study_name"] == "small"
    figures = []
    for name in ("small.parts", "small.nc"):
        out = tmp_path / f"{name}.png"
        result = runner.invoke(main, ["plot", "metric", str(tmp_path / name), "-o", str(out)])
        assert result.exit_code == 0, result.output
        figures.append(out.read_bytes())
    assert figures[0] == figures[1]  # the same figure, pixel for pixel


def _die_once(plan):
    """The first batch to run kills its worker process (the marker file says it did); every
    other batch, and that one again on another worker, is computed."""
    import os

    from campipe.study.run.results import compute_batch

    try:
        Path(os.environ["CAMPIPE_TEST_DIE_ONCE"]).touch(exist_ok=False)
    except FileExistsError:
        return compute_batch(plan)
    os._exit(9)


def test_a_worker_killed_mid_study_leaves_the_archive_of_an_undisturbed_run(
    mixed, tmp_path, monkeypatch
):
    """A worker process dies in its first batch: dask runs that batch again on a worker, the
    study completes into parts and equals the undisturbed single-file run. Broken copy it
    fails on: a client that indexes a batch once per attempt or a part half written by the
    dead worker (the index would name a part twice, or one that does not verify)."""
    from distributed import LocalCluster

    import campipe.study.run.workers as workers

    study, directory, _, _ = mixed
    marker = tmp_path / "died"
    monkeypatch.setenv("CAMPIPE_TEST_DIE_ONCE", str(marker))
    monkeypatch.setattr(workers, "compute_batch", _die_once)
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        report = run_study(
            study,
            tmp_path / "mixed.parts",
            scheduler=cluster.scheduler_address,
            batch_size=2,
            parts=True,
        )
    assert marker.exists()  # a worker did die
    assert (report.computed, report.batches) == (10, 6)
    index = read_index(tmp_path / "mixed.parts")
    assert len({p["file"] for p in index["parts"]}) == len(index["parts"]) == 6
    with (
        xr.open_dataset(directory / "mixed.nc") as one,
        open_archive(tmp_path / "mixed.parts") as many,
    ):
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))


def test_parts_of_a_spec_that_varied_other_keys_are_set_aside(tmp_path):
    """A spec that adds a swept key (spring_preload: its archive gains that coordinate):
    the earlier parts hold cases of the same ids (preload 151 lbf is the preset's) but not
    its variables, so they are set aside and every case is computed into parts that read
    back as the single-file run. Broken copy it fails on: a resume that reuses parts by case
    id alone (the archive would lack spring_preload in those cases' parts and not read as
    one)."""
    spec = write_spec(tmp_path, SMALL_SPEC)
    archive = tmp_path / "small.parts"
    run_study(load_study(spec), archive, scheduler="synchronous", batch_size=2, parts=True)
    write_spec(tmp_path, SMALL_SPEC + "  model.spring_preload: [151 lbf, 180 lbf]\n")
    study = load_study(spec)
    report = run_study(study, archive, scheduler="synchronous", parts=True)
    assert (report.reused, report.computed) == (0, 12)
    assert any("3 parts" in n and "other variables" in n for n in report.notes)
    run_study(study, tmp_path / "small.nc", scheduler="synchronous")
    with xr.open_dataset(tmp_path / "small.nc") as one, open_archive(archive) as many:
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))
        assert_array_equal(np.unique(many["spring_preload"].values).size, 2)


def test_replay_reads_the_cases_of_a_parts_archive(mixed, tmp_path):
    """``campipe replay``'s reader on the parts and on the single file picks the same cases
    with the same histories, events and q. Broken copy it fails on: events taken by each
    part's own ``event_case`` rows after the parts are concatenated (another case's
    events)."""
    from campipe.replay.record import replay_archive

    _, directory, _, _ = mixed
    picked = [
        replay_archive(directory / name, where="speed_rpm >= 9000", output=tmp_path / f"{k}.rrd")[1]
        for k, name in enumerate(("mixed.parts", "mixed.nc"))
    ]
    assert [c.case_id for c in picked[0]] == [c.case_id for c in picked[1]]
    assert len(picked[0]) == 8  # speeds of 9000 rpm and above
    for a, b in zip(*picked, strict=True):
        assert_array_equal(a.events["event_time"], b.events["event_time"])
        assert_array_equal(a.histories["valve_lift"], b.histories["valve_lift"])
        assert_array_equal(a.q, b.q)


def test_a_parts_run_holds_the_lock_and_stores_what_its_workers_return(tmp_path):
    """A second run on a parts archive whose lock is held stops before writing a part; on a
    cluster whose workers return their batches (workers_store=False) this process writes
    the parts, and the archive is the one the workers write. Broken copies it fails on: a
    parts run that takes no lock, or a client that drops a returned batch's part."""
    from distributed import LocalCluster

    from campipe.io.archive import ArchiveBusyError, writing

    spec = write_spec(tmp_path, SMALL_SPEC)
    study = load_study(spec)
    archive = tmp_path / "small.parts"
    with writing(archive), pytest.raises(ArchiveBusyError):
        run_study(study, archive, scheduler="synchronous", parts=True)
    assert not archive.exists() or part_files(archive) == []
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
    ) as cluster:
        for name, store in (("workers.parts", True), ("client.parts", False)):
            report = run_study(
                study,
                tmp_path / name,
                scheduler=cluster.scheduler_address,
                batch_size=2,
                parts=True,
                workers_store=store,
            )
            assert (report.computed, report.batches) == (6, 3)
    with (
        open_archive(tmp_path / "workers.parts") as a,
        open_archive(tmp_path / "client.parts") as b,
    ):
        xr.testing.assert_identical(_without_global_attrs(a), _without_global_attrs(b))
        assert a.sizes["case"] == 6


def _drop_to_nobody(dask_worker) -> int:
    """Run on a worker: make the worker process an unprivileged user (a worker on another
    machine, under another account), its scratch folder still its own to remove; its uid."""
    for folder, _, names in os.walk(dask_worker.local_directory):
        for path in [folder, *(os.path.join(folder, n) for n in names)]:
            os.chmod(path, 0o777)
    os.setgid(65534)
    os.setuid(65534)
    return os.getuid()


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="needs root")
def test_workers_that_cannot_write_the_parts_folder_stop_the_study_before_computing(tmp_path):
    """The client (root) can write the parts archive's folder, its two worker processes
    (made an unprivileged user) cannot: the probe stops the study before any batch runs,
    naming the folder and why. Broken copies it fails on: no probe (the first batch fails
    after the others computed, or the client stores what the workers return), or a probe
    whose answers are not checked."""
    from distributed import Client, LocalCluster

    from campipe.study.run.cluster import PartsPathError

    spec = write_spec(tmp_path, SMALL_SPEC)
    study = load_study(spec)
    private = tmp_path / "private"
    private.mkdir(mode=0o700)
    archive = private / "small.parts"
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    scratch.chmod(0o777)
    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            local_directory=scratch,
        ) as cluster,
        Client(cluster) as client,
    ):
        assert set(client.run(_drop_to_nobody).values()) == {65534}
        with pytest.raises(PartsPathError) as caught:
            run_study(study, archive, scheduler=cluster.scheduler_address, parts=True)
    assert caught.value.key == str(archive)
    assert "2 of 2 workers cannot write" in str(caught.value)
    assert "Permission denied" in str(caught.value) and "nothing was computed" in str(caught.value)
    assert part_files(archive) == [] and not (archive / INDEX).exists()
    assert sorted(p.name for p in archive.iterdir()) == []  # the token removed, no probe left


def test_a_cluster_run_reads_back_whole_through_open_study_and_open_mfdataset(mixed, tmp_path):
    """The mixed study on two worker processes into parts, against the same study run on
    this machine (its single file and its parts): ``open_study`` gives the same grid case
    for case, ``open_mfdataset`` every case and event, and each part holds the same cases
    and values as the local run's part of the same batch. Broken copies it fails on: a
    worker that writes a part from another batch's cases (SentBatch's index), or case
    coordinates read from the wrong case of a batch (its values)."""
    from distributed import LocalCluster

    study, directory, _, _ = mixed
    archive = tmp_path / "mixed.parts"
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        run_study(study, archive, scheduler=cluster.scheduler_address, batch_size=2, parts=True)
    with (
        campipe.open_study(directory / "mixed.nc") as one,
        campipe.open_study(archive) as many,
    ):
        xr.testing.assert_identical(_without_global_attrs(one), _without_global_attrs(many))
        assert many.sizes["case"] == 10
    files = part_files(archive)
    assert [f.name for f in files] == [f.name for f in part_files(directory / "mixed.parts")]
    for mine in files:
        with (
            xr.open_dataset(mine) as a,
            xr.open_dataset(directory / "mixed.parts" / mine.name) as b,
        ):
            xr.testing.assert_identical(_without_global_attrs(a), _without_global_attrs(b))
    options = {
        "combine": "nested",
        "data_vars": "minimal",
        "coords": "minimal",
        "compat": "override",
    }
    with (
        xr.open_mfdataset(
            files, concat_dim="case", preprocess=lambda ds: ds.drop_dims("event"), **options
        ) as cases,
        xr.open_mfdataset(
            files, concat_dim="event", preprocess=lambda ds: ds.drop_dims("case"), **options
        ) as events,
        xr.open_dataset(directory / "mixed.nc") as one,
    ):
        assert sorted(cases["case"].values) == sorted(one["case"].values)
        assert events.sizes["event"] == one.sizes["event"] == int(cases["event_count"].sum())
        order = np.argsort(cases["case"].values)
        ref = np.argsort(one["case"].values)
        assert_array_equal(cases["speed_rpm"].values[order], one["speed_rpm"].values[ref])
        assert_array_equal(cases["valve_lift"].values[order], one["valve_lift"].values[ref])


def test_parts_dir_puts_the_parts_archive_in_the_shared_folder(tmp_path):
    """``--parts-dir DIR`` writes the parts archive ``DIR/<name>.parts`` (``--parts``
    implied) and refuses ``-o`` beside it. Broken copies it fails on: a --parts-dir that
    writes the single file, or the archive beside the spec."""
    spec = write_spec(tmp_path, SMALL_SPEC)
    shared = tmp_path / "shared" / "scratch"
    runner = CliRunner()
    result = runner.invoke(
        main, ["study", str(spec), "--parts-dir", str(shared), "--no-progress", "--batch-size", "3"]
    )
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == str(shared / "small.parts")
    index = read_index(shared / "small.parts")
    assert (len(index["case"]), len(index["parts"])) == (6, 2)
    assert not (tmp_path / "small.parts").exists() and not (tmp_path / "small.nc").exists()
    both = ["study", str(spec), "--parts-dir", str(shared), "-o", str(tmp_path / "x.parts")]
    result = runner.invoke(main, both)
    assert result.exit_code == 2 and "not both" in result.output
