"""Running studies: the archive against the engine, schedulers, resume after a kill, reuse."""

import json
import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import zipfile

import netCDF4
import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_array_equal
from study_helpers import INCH, SMALL_SPEC, load, write_spec

from campipe import kernel_cache
from campipe.cli import main
from campipe.engine import MEMBER_LOADS, member_loads, run_batch
from campipe.io.archive import ArchiveBusyError, lock_path, verify, writing
from campipe.io.spec_yaml import parse_spec_text
from campipe.study import check_spec, expand, load_study
from campipe.study.run.batches import parts_directory, plan_batches
from campipe.study.run.execute import run_study
from campipe.study.run.resume import ArchiveExistsError
from campipe.study.spec.variables import VARIABLES


def test_the_archive_holds_the_engine_results(small_archive):
    study, report, archive = small_archive.study, small_archive.report, small_archive.archive
    assert (report.cases, report.computed, report.batches) == (6, 6, 3)
    ds = xr.load_dataset(archive)
    ref = run_batch([c.case for c in study.cases], study.cases[0].settings)
    assert_array_equal(ds.case.values, [c.case_id for c in study.cases])
    assert_array_equal(ds.speed_rpm.values, [6000, 6000, 9524, 9524, 11000, 11000])
    assert_array_equal(ds.seat.values, [-np.inf, 0.1 * INCH] * 3)
    assert set(ds.profile.values) == {"harmonic 1 in"} and set(ds.defects.values) == {"none"}
    assert_array_equal(ds.cam_angle.values, np.arange(721.0))
    assert_array_equal(ds.revolution.values, [1, 2])
    for name, values in [
        ("time", ref.time),
        ("cam_lift", ref.cam_lift),
        ("follower_lift", ref.follower_lift),
        ("valve_lift", ref.valve_lift),
        ("cam_force", ref.cam_force),
        ("seat_force", ref.seat_force),
        ("contact_state", ref.contact_state),
        ("q", ref.q),
        ("separation_deg", np.degrees(ref.separation_per_rev)),
        ("cam_impacts", ref.cam_impacts),
        ("max_seating_velocity", ref.max_seating_velocity),
    ]:
        assert_array_equal(ds[name].values, values, err_msg=name)
    # Summaries over the measured revolutions (the periodic start measures every one).
    assert_array_equal(ds.measured.values, np.ones((6, 2)))
    assert_array_equal(ds.separation_deg_per_rev, np.degrees(ref.separation_per_rev).mean(axis=1))
    assert_array_equal(ds.seated_off_cam_deg, np.degrees(ref.seated_off_cam_per_rev))
    assert_array_equal(ds.seat_impacts_by_rev, ref.seat_impacts_per_rev)
    assert_array_equal(ds.max_seating_velocity, ref.max_seating_velocity_per_rev.max(axis=1))
    assert_array_equal(ds.valve_acceleration, ref.valve_acceleration)
    for i, c in enumerate(study.cases):
        loads = member_loads(c.case.train, ref.q[i])
        for name in MEMBER_LOADS:
            assert_array_equal(ds[name].values[i], loads[name])
        # events: CF contiguous ragged array, case by case
        mine = ds.event_case.values == i
        assert ds.event_count.values[i] == mine.sum() == ref.events[i].shape[0]
        assert_array_equal(ds.event_time.values[mine], ref.events[i][:, 0])
        assert_array_equal(ds.event_kind.values[mine], ref.events[i][:, 1])
        assert_array_equal(
            ds.event_cam_angle.values[mine], np.degrees(ref.events[i][:, 0] * c.case.speed)
        )
    offsets = np.concatenate([[0], np.cumsum(ds.event_count.values)])
    assert_array_equal(ds.event_case.values, np.repeat(np.arange(6), np.diff(offsets)))
    assert ds.event_count.attrs["sample_dimension"] == "event"


def test_the_archive_carries_cf_metadata_from_the_table(small_archive):
    archive, spec_path = small_archive.archive, small_archive.spec
    ds = xr.open_dataset(archive)
    for name, var in VARIABLES.items():
        if name in ds.variables:
            for key, value in var.attrs().items():
                got = ds[name].attrs[key]
                assert np.array_equal(got, value) if key == "flag_values" else got == value, name
    assert ds.cam_force.attrs == {"long_name": VARIABLES["cam_force"].long_name, "units": "N"}
    assert ds.speed_rpm.attrs["units"] == "rpm" and ds.seat.attrs["units"] == "m"
    assert ds.stem_force.attrs["units"] == "N" and ds.rocker_moment.attrs["units"] == "N*m"
    assert list(ds.dof.values) == [f"q{i}" for i in range(1, 8)]
    assert list(ds.dof_units.values) == ["m", "m", "rad", "m", "rad", "rad", "m"]
    assert {"speed_rpm", "seat", "profile", "defects", "closure", "case"} <= set(ds.coords)
    assert "case_id" not in ds.variables and ds.indexes["case"].dtype.kind in "OU"
    a = ds.attrs
    assert a["Conventions"] == "CF-1.10" and a["campipe_version"] == "0.1.0"
    assert a["spec"] == spec_path.read_text()
    assert "numpy==" in a["dependency_versions"] and "netcdf-c==" in a["dependency_versions"]
    assert a["host"] and re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", a["date_created"])
    assert json.loads(a["study_axes"]) == [
        {"key": "speed", "name": "speed_rpm", "kind": "sweep", "size": 3},
        {"key": "seat", "name": "seat", "kind": "sweep", "size": 2},
    ]
    # compressed (zstd by default), up to eight cases per chunk (this study has six)
    enc = ds.valve_lift.encoding
    assert enc["zstd"] and enc["complevel"] == 1 and enc["chunksizes"] == (6, 721)
    assert ds.q.encoding["chunksizes"] == (6, 721, 7)
    with netCDF4.Dataset(archive) as nc:
        assert nc["cam_force"].filters()["zstd"] and not nc["cam_force"].filters()["zlib"]
    # smaller than its raw arrays (float histories barely compress; time and flags do)
    raw = sum(ds[v].nbytes for v in ds.variables)
    assert os.path.getsize(archive) < raw


def _schedulers(tmp_path, spec_text):
    from distributed import LocalCluster

    path = write_spec(tmp_path, spec_text)
    study = load_study(path)
    out = {}
    for name in ("synchronous", "threads", "processes"):
        report = run_study(study, tmp_path / f"{name}.nc", scheduler=name, workers=2, batch_size=2)
        assert report.computed == len(study.cases)
        out[name] = load(tmp_path / f"{name}.nc")
    # in this process, but over TCP on the loopback, as a remote cluster is reached
    with LocalCluster(
        n_workers=1,
        threads_per_worker=2,
        processes=False,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=":0",
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        report = run_study(
            study, tmp_path / "distributed.nc", scheduler=cluster.scheduler_address, batch_size=2
        )
        assert report.batches == 3
    out["distributed"] = load(tmp_path / "distributed.nc")
    return out


def test_synchronous_threaded_processes_and_distributed_archives_are_identical(tmp_path):
    out = _schedulers(tmp_path, SMALL_SPEC)
    xr.testing.assert_identical(out["synchronous"], out["threads"])
    xr.testing.assert_identical(out["synchronous"], out["processes"])
    xr.testing.assert_identical(out["synchronous"], out["distributed"])
    assert out["synchronous"].sizes["case"] == 6
    sums = {name: _variable_checksums(tmp_path / f"{name}.nc") for name in out}
    assert all(s == sums["synchronous"] for s in sums.values())  # bit for bit


def _variable_checksums(path):
    sums = json.loads(netCDF4.Dataset(path).getncattr("campipe_checksums"))
    sums.pop("/attributes")
    return sums


def test_batches_stored_by_the_workers_or_by_this_process_make_the_same_archive(
    tmp_path, monkeypatch
):
    """On a cluster whose workers reach the archive's folder (here, this machine) each
    worker writes its own batch files and this process only assembles; with
    workers_store=False the workers return their batches and this process stores them. The
    two archives are the same, variable for variable (their checksums are equal)."""
    import threading

    from distributed import LocalCluster

    import campipe.study.run.workers as workers

    study = load_study(write_spec(tmp_path, SMALL_SPEC))
    stored_by = []
    real = workers._store

    def spied(*args):
        stored_by.append(threading.current_thread() is threading.main_thread())
        return real(*args)

    monkeypatch.setattr(workers, "_store", spied)
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
    ) as cluster:
        address = cluster.scheduler_address
        by_workers = run_study(study, tmp_path / "workers.nc", scheduler=address, batch_size=2)
        assert stored_by == [False] * 3  # written in the workers' threads
        stored_by.clear()
        by_client = run_study(
            study, tmp_path / "client.nc", scheduler=address, batch_size=2, workers_store=False
        )
        assert stored_by == [True] * 3  # written here
    assert by_workers.computed == by_client.computed == 6
    assert not list(parts_directory(tmp_path / "workers.nc").parent.glob("*.parts"))
    xr.testing.assert_identical(load(tmp_path / "workers.nc"), load(tmp_path / "client.nc"))
    assert _variable_checksums(tmp_path / "workers.nc") == _variable_checksums(
        tmp_path / "client.nc"
    )


def test_a_finished_study_is_not_run_again(small_archive_copy):
    study, archive = small_archive_copy.study, small_archive_copy.archive
    before = os.stat(archive).st_mtime_ns
    report = run_study(study, archive, scheduler="synchronous")
    assert report.up_to_date and report.computed == 0
    assert os.stat(archive).st_mtime_ns == before


def test_a_changed_spec_reuses_only_the_unchanged_cases(tmp_path):
    two = SMALL_SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm, 9524 rpm]")
    archive = tmp_path / "small.nc"
    first = run_study(load_study(write_spec(tmp_path, two)), archive, scheduler="synchronous")
    assert (first.computed, first.reused) == (4, 0)
    study = load_study(write_spec(tmp_path, SMALL_SPEC))
    grown = run_study(study, archive, scheduler="synchronous")
    assert (grown.computed, grown.reused) == (2, 4)
    fresh = run_study(study, tmp_path / "fresh.nc", scheduler="synchronous")
    xr.testing.assert_identical(load(archive), load(tmp_path / "fresh.nc"))
    assert fresh.computed == 6
    # a changed model parameter changes every id: nothing stale is reused
    stiffer = SMALL_SPEC.replace("name: small", "name: small\nmodel: {spring_preload: 160 lbf}")
    edited = load_study(write_spec(tmp_path, stiffer))
    with pytest.raises(ArchiveExistsError, match="6 of the 6 cases it holds are not in this"):
        run_study(edited, archive, scheduler="synchronous")  # they would be removed
    xr.testing.assert_identical(load(archive), load(tmp_path / "fresh.nc"))  # untouched
    changed = run_study(edited, archive, scheduler="synchronous", overwrite=True)
    assert (changed.computed, changed.reused) == (6, 0)
    # the cases it replaced are named by count (a helper lost 28 of 32 cases so, silently)
    assert any("6 of the 6 cases it holds" in n and "--overwrite" in n for n in changed.notes)
    assert not any("cases it holds" in n for n in grown.notes)  # a grown sweep drops none
    ds = xr.load_dataset(archive)
    assert not set(ds.case.values) & {c.case_id for c in study.cases}


def test_batches_share_run_settings_and_are_cut_to_size():
    spec = SMALL_SPEC.replace(
        "run: {revolutions: 2, record: [q, member_loads]}",
        "run: {revolutions: 2, integrator: newmark-linear}",
    )
    spec += "  run.dt: [1 us, 0.5 us]\n"
    study = expand(check_spec(parse_spec_text(spec)))
    plans = plan_batches(study.cases, (), 4)
    assert [p.size for p in plans] == [4, 2, 4, 2]
    for p in plans:
        assert len({c.settings for c in p.cases}) == 1
    assert sorted(c.index for p in plans for c in p.cases) == list(range(12))


def test_interleaved_batches_fill_shared_chunks_and_batch_files_are_uncompressed(tmp_path):
    """Two run settings alternate along the study, so each batch writes every other row and
    each archive chunk of eight cases is filled by several batches; the archive still holds
    each case's own results. Batch files (kept here) are written uncompressed."""
    spec = SMALL_SPEC.replace(
        "run: {revolutions: 2, record: [q, member_loads]}", "run: {revolutions: 1}"
    )
    spec = spec.replace(
        "[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm, 8000 rpm, 9524 rpm, 11000 rpm, 12000 rpm]"
    )
    spec += "  run.tolerance: [1e-12 s, 1e-6 s]\n"
    study = load_study(write_spec(tmp_path, spec))
    assert len(study.cases) == 20
    archive = tmp_path / "mixed.nc"
    run_study(study, archive, scheduler="synchronous", batch_size=3, keep_parts=True)
    ds = load(archive)
    assert ds.valve_lift.encoding["chunksizes"] == (8, 361)  # one turn, every degree
    by_settings = {}
    for c in study.cases:
        by_settings.setdefault(c.settings, []).append(c)
    for settings, cases in by_settings.items():
        rows = [c.index for c in cases]
        assert set(np.diff(rows)) == {2}  # every other row of the archive
        ref = run_batch([c.case for c in cases], settings, full_state=False)
        assert_array_equal(ds.valve_lift.values[rows], ref.valve_lift)
        assert_array_equal(ds.cam_impacts.values[rows], ref.cam_impacts)
    parts = list(parts_directory(archive).glob("batch-*.npz"))
    assert len(parts) == 8
    with zipfile.ZipFile(parts[0]) as z:  # uncompressed: only the archive is compressed
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_STORED}
        assert "valve_lift.npy" in z.namelist()


def test_an_assembly_from_batch_files_reads_each_once_wherever_its_rows_fall(tmp_path, monkeypatch):
    """The archive assembled from the batch files a run kept (as a client assembles what
    its workers stored) is the run's own; a batch file whose rows span two of the assembly's
    blocks is read once, kept for the next block and then dropped, not read for each block.
    Here 20 cases in batches of 6 and blocks of 8 (one chunk): the second and third files
    span two blocks. Files are read ahead, on a thread of their own, while the block before
    compresses. Broken copy, run: the file not kept (each of them read twice)."""
    from collections import Counter

    from campipe.study.run import assembly, resume

    spec = SMALL_SPEC.replace(
        "[6000 rpm, 9524 rpm, 11000 rpm]", "{from: 6000 rpm, to: 11000 rpm, num: 10}"
    )
    study = load_study(write_spec(tmp_path, spec))
    assert len(study.cases) == 20
    archive = tmp_path / "run.nc"
    run_study(study, archive, scheduler="synchronous", batch_size=6, keep_parts=True)
    found, _ = resume.find_results(study, archive, archive_usable=False)
    assert {path.suffix for path, _, _ in found.values()} == {".npz"}
    reads: Counter = Counter()
    threads: set[str] = set()
    read = assembly.read_batch

    def counted(path):
        reads.update([path])
        threads.add(threading.current_thread().name.split("_")[0])
        return read(path)

    monkeypatch.setattr(assembly, "read_batch", counted)
    monkeypatch.setattr(assembly, "ASSEMBLY_BYTES", 1)  # a block per chunk of eight cases
    target = tmp_path / "assembled.nc"
    assembly.assemble(study, target, found)
    assert len(reads) == 4 and set(reads.values()) == {1}
    assert threads == {"MainThread", "campipe-read"}  # the first block's, then read ahead
    xr.testing.assert_equal(load(target), load(archive))
    assert verify(target) == []


KILLED = """
name: slow
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 4, integrator: newmark-linear, dt: 1 us}
sweep:
  speed: {from: 500 rpm, to: 730 rpm, num: 24}
"""


def test_a_killed_study_resumes_computing_only_the_missing_batches(tmp_path):
    killed = tmp_path / "killed"
    killed.mkdir()
    spec = write_spec(killed, KILLED)
    cmd = [
        sys.executable,
        "-m",
        "campipe",
        "study",
        str(spec),
        "--scheduler",
        "synchronous",
        "--batch-size",
        "1",
        "--no-progress",
        "--keep-parts",
    ]
    parts = parts_directory(killed / "slow.nc")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not list(parts.glob("batch-*.npz")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.005)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert not (killed / "slow.nc").exists()  # never a half-written archive
    # the killed run's lock names it; the rerun takes it over (its process is gone)
    assert json.loads(lock_path(killed / "slow.nc").read_text())["pid"] == proc.pid
    done = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("batch-*.npz")}
    assert 1 <= len(done) < 24
    rerun = subprocess.run(cmd, capture_output=True, text=True, check=True)
    assert (
        f"({len(done)} reused, {24 - len(done)} computed in {24 - len(done)} batches)"
        in rerun.stderr
    ), rerun.stderr
    for p, stamp in done.items():  # the stored batches were read, not redone
        assert (p.stat().st_ino, p.stat().st_mtime_ns) == stamp
    assert not list(parts.glob(".*.tmp"))  # the killed run's temporary file is gone
    assert not lock_path(killed / "slow.nc").exists()
    # the same as a study that was never interrupted
    whole = tmp_path / "whole"
    whole.mkdir()
    report = run_study(
        load_study(write_spec(whole, KILLED)), whole / "slow.nc", scheduler="threads", batch_size=5
    )
    assert report.computed == 24
    xr.testing.assert_identical(load(killed / "slow.nc"), load(whole / "slow.nc"))


def test_a_second_run_on_a_busy_archive_stops_and_touches_nothing(small_archive, tmp_path):
    """While another live process holds the archive's lock, a run (API or CLI) stops with an
    error naming the holder and the lock, and leaves the holder's files alone; once the
    holder is gone its lock is taken over and released at the end."""
    study, archive, spec = small_archive.study, small_archive.archive, small_archive.spec
    target = tmp_path / "small.nc"
    lock = lock_path(target)
    parts = parts_directory(target)
    parts.mkdir()
    in_progress = parts / ".batch-x.npz.1-2-3.tmp"  # the holder's batch being written
    in_progress.write_bytes(b"partial")
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        lock.write_text(
            json.dumps(
                {"pid": holder.pid, "host": socket.gethostname(), "started": "2026-11-22T08:00:00Z"}
            )
        )
        with pytest.raises(
            ArchiveBusyError,
            match=(
                rf"small.nc is being written by process {holder.pid} on .* since "
                rf"2026-11-22T08:00:00Z.* remove {re.escape(str(lock))}"
            ),
        ):
            run_study(study, target, scheduler="synchronous")
        result = CliRunner().invoke(main, ["study", str(spec), "-o", str(target), "--no-progress"])
        assert result.exit_code == 1 and "is being written by process" in result.output
        assert "Traceback" not in result.output
        assert in_progress.exists() and lock.exists() and not target.exists()
    finally:
        holder.kill()
        holder.wait()
    report = run_study(study, target, scheduler="synchronous")
    assert report.computed == 6 and not lock.exists() and not in_progress.exists()
    xr.testing.assert_identical(load(target), load(archive))


@pytest.mark.parametrize(
    "content",
    [
        {"pid": 2**22 + 12345, "host": "another-host", "started": "2026-11-22T08:00:00Z"},
        None,  # empty: its writer has not filled it in yet
    ],
)
def test_a_lock_that_cannot_be_checked_is_left_alone(tmp_path, content):
    """A lock from another host (its process cannot be checked) or one still empty is never
    taken over."""
    target = tmp_path / "a.nc"
    lock = lock_path(target)
    lock.write_text(json.dumps(content) if content else "")
    with pytest.raises(ArchiveBusyError, match="another-host" if content else "another run"):
        with writing(target):
            pass
    assert lock.read_text() == (json.dumps(content) if content else "")


def test_stale_and_temporary_files_are_ignored_and_cleaned(small_archive, tmp_path):
    study, archive = small_archive.study, small_archive.archive
    target = tmp_path / "small.nc"
    parts = parts_directory(target)
    parts.mkdir()
    # a batch file of another study (other ids) and a temporary file from a killed run
    other = load_study(
        write_spec(
            tmp_path,
            SMALL_SPEC.replace("name: small", "name: small\nmodel: {spring_preload: 160 lbf}"),
            "o.yaml",
        )
    )
    run_study(other, tmp_path / "other.nc", scheduler="synchronous", keep_parts=True)
    for p in parts_directory(tmp_path / "other.nc").glob("batch-*.npz"):
        p.rename(parts / p.name)
    (parts / ".batch-x.npz.1-2-3.tmp").write_bytes(b"partial")
    report = run_study(study, target, scheduler="synchronous")
    assert (report.computed, report.reused) == (6, 0)
    assert not parts.exists()
    xr.testing.assert_identical(load(target), load(archive))


def test_import_campipe_does_not_pull_in_distributed_or_rerun():
    code = (
        "import sys, campipe, campipe.cli, campipe.study.run.execute, campipe.study.query.tables; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('distributed', 'rerun')]; "
        "print(bad); sys.exit(bool(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


HEAVY = ("numba", "scipy", "pint", "dask", "distributed", "xarray", "netCDF4", "rerun")


def _loaded_by(args, cwd=None, env=None) -> tuple[str, list[str]]:
    """Run the CLI in a fresh interpreter (with ``env`` added to this one's environment); its
    stderr and the heavy packages it imported."""
    code = (
        "import sys\n"
        "from campipe.cli import main\n"
        f"main({list(args)!r}, standalone_mode=False)\n"
        f"heavy = sorted({{m.split('.')[0] for m in sys.modules}} & {set(HEAVY)!r})\n"
        "print('loaded:', *heavy)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=cwd,
        check=True,
        env={**os.environ, **(env or {})},
    )
    return out.stderr, out.stdout.splitlines()[-1].split()[1:]


def test_help_loads_none_of_the_heavy_packages():
    _, heavy = _loaded_by(["--help"])
    assert heavy == []


def test_commands_that_run_no_kernel_do_not_import_numba(small_archive, tmp_path):
    """A query of an archive, the model's matrices and a spec's check without the estimate
    (which runs the engine) import no numba: the disk cache they read finds its folder without
    it (``kernel_cache.cache_folder``), and the estimate imports the engine only when it runs.
    The estimate itself does.

    Broken copy: ``kernel_cache`` importing numba at its top, or ``study.estimate`` importing
    the engine at its top, loads numba in the first or the third command."""
    archive, spec = small_archive.archive, small_archive.spec
    _, heavy = _loaded_by(["query", str(archive), "--summary"])
    assert "numba" not in heavy and "xarray" in heavy  # it did read the archive
    _, heavy = _loaded_by(["model"])
    assert "numba" not in heavy
    _, heavy = _loaded_by(["validate", str(spec), "--no-estimate"])
    assert "numba" not in heavy
    _, heavy = _loaded_by(["validate", str(spec)], cwd=tmp_path)
    assert "numba" in heavy


def test_a_finished_study_answers_from_its_spec_text_and_the_archive_alone(
    small_archive_copy, tmp_path
):
    """Rerunning a finished study reads the spec's text and verifies the archive's checksums:
    no unit is parsed and no model built (pint, SciPy, numba stay unloaded). Another
    override, or an archive without the spec's key, takes the full check (still up to
    date where the cases are the same)."""

    from campipe.study.run.resume import finished

    spec, archive = small_archive_copy.spec, small_archive_copy.archive
    stderr, heavy = _loaded_by(["study", str(spec), "--no-progress"])
    assert "up to date (6 cases, checksums verified)" in stderr
    assert heavy == ["netCDF4"]
    assert finished(spec, {}, archive).up_to_date
    stderr, heavy = _loaded_by(["study", str(spec), "--no-progress", "--set", "speed=9000 rpm"])
    assert "6 cases (6 reused, 0 computed" in stderr and "scipy" in heavy  # the full check

    assert finished(spec, {"speed": "9000 rpm"}, archive).up_to_date
    assert finished(spec, {}, archive) is None  # written with another override
    assert finished(spec, {"speed": "9000 rpm"}, tmp_path / "elsewhere.nc") is None


def test_a_warm_one_case_study_reads_what_earlier_runs_kept(tmp_path):
    """Run again, a one-case study reads its quantities' values, its train's modes and block
    forms where the first run kept them (``campipe.units``, ``campipe.disk_cache``): pint
    stays unloaded, no file of modes or block forms is added, and the archive is the same,
    bit for bit. A train of another spring then solves and keeps its modes. (The runs keep
    their files under ``tmp_path``, ``XDG_CACHE_HOME``, and share this process's compiled
    kernels, ``NUMBA_CACHE_DIR``.)

    Broken copies: with ``units._kept`` computing every time, pint is loaded; with
    ``disk_cache.read`` finding nothing, the second run writes its modes again."""
    one = SMALL_SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm]")
    spec = write_spec(tmp_path, one.replace("seat: [none, 0.1 in]", "seat: [none]"))
    archive = tmp_path / "small.nc"
    env = {"XDG_CACHE_HOME": str(tmp_path / "home")}
    kept = tmp_path / "home" / "campipe" / "kernels" / kernel_cache.source_hash()[:16]

    def files(kind: str) -> list[tuple[str, int]]:
        return sorted((p.name, p.stat().st_mtime_ns) for p in (kept / kind).iterdir())

    _loaded_by(["study", str(spec), "--no-progress"], cwd=tmp_path, env=env)
    first = load(archive)
    modes, forms = files("modes"), files("block-forms")
    assert modes and forms
    archive.unlink()
    run = ["study", str(spec), "--no-progress"]
    stderr, heavy = _loaded_by(run, cwd=tmp_path, env=env)
    assert "1 cases (0 reused, 1 computed" in stderr
    assert "numba" in heavy and "pint" not in heavy
    assert files("modes") == modes and files("block-forms") == forms  # read, not written
    xr.testing.assert_identical(load(archive), first)
    stiffer = ["--set", f"model.spring_rate={random.uniform(250, 260):.6f} lbf/in"]
    _loaded_by([*run, "-o", "other.nc", *stiffer], cwd=tmp_path, env=env)
    assert {name for name, _ in files("modes")} - {name for name, _ in modes}  # new ones


def test_the_first_run_says_what_it_compiles(tmp_path, monkeypatch):
    """Before numba compiles a kernel the study says so on the terminal (here the cache is
    made to look empty)."""
    import campipe.engine.kernels as kernels

    monkeypatch.setattr(kernels, "uncompiled", lambda settings: ["modal-exact"])
    spec = write_spec(tmp_path, SMALL_SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm]"))
    result = CliRunner().invoke(main, ["study", str(spec), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "campipe study: compiling modal-exact with numba" in result.stderr
    monkeypatch.setattr(kernels, "uncompiled", lambda settings: [])
    (tmp_path / "small.nc").unlink()
    result = CliRunner().invoke(main, ["study", str(spec), "--no-progress"])
    assert "compiling" not in result.stderr


def test_validate_says_what_it_compiles_and_records_it_for_the_next_run(tmp_path):
    """``campipe validate`` compiles the kernels its estimate runs as a study does, saying so
    first, and records them as compiled, so that the next command says nothing. (Its own
    cache folder, ``XDG_CACHE_HOME``, holds no record; the kernels themselves are in this
    process's numba cache, ``NUMBA_CACHE_DIR``.)

    Broken copy: the notice alone (``compile_notice``, as before): the estimate then loaded
    the kernels in its own process, recorded nothing, and every later validate or first study
    said again that it compiles."""
    one = SMALL_SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm]")
    spec = write_spec(tmp_path, one.replace("seat: [none, 0.1 in]", "seat: [none]"))
    env = {"XDG_CACHE_HOME": str(tmp_path / "home")}
    first, _ = _loaded_by(["validate", str(spec)], cwd=tmp_path, env=env)
    assert "campipe validate: compiling" in first and "modal-exact" in first
    again, _ = _loaded_by(["validate", str(spec)], cwd=tmp_path, env=env)
    assert "compiling" not in again


def test_no_seat_is_minus_inf_and_speed_rounds_to_whole_rpm(small_archive):
    ds = xr.open_dataset(small_archive.archive)
    assert (ds.seat.values[::2] == -np.inf).all()
    assert ds.seat.attrs["comment"].startswith("-inf: no seat")
    assert ds.seat.values[1] == pytest.approx(0.00254, rel=1e-15)
    assert (ds.speed_rpm.values == np.round(ds.speed_rpm.values)).all()
    assert math.isnan(ds.dt.values[0]) or ds.dt.values[0] > 0


def test_the_batch_hook_sees_every_batch_and_the_replay_selection(tmp_path):
    """The replay hook: called once per computed batch with its data; replay.where picks
    cases by parameters and metrics (logging them to rerun is a later feature)."""
    from campipe.study.query.tables import replay_mask

    spec = SMALL_SPEC + 'replay: {where: "speed_rpm == 9524 and separation_deg_per_rev > 0"}\n'
    study = load_study(write_spec(tmp_path, spec))
    seen = {}

    def hook(plan, data):
        assert [c.case_id for c in plan.cases] == list(data.case_ids)
        for c, keep in zip(plan.cases, replay_mask(study, plan, data), strict=True):
            seen[c.index] = bool(keep)

    run_study(study, tmp_path / "r.nc", scheduler="threads", batch_size=2, on_batch=hook)
    assert sorted(seen) == list(range(6))
    ds = xr.load_dataset(tmp_path / "r.nc")
    expected = (ds.speed_rpm.values == 9524) & (ds.separation_deg_per_rev.values > 0)
    assert [seen[i] for i in range(6)] == expected.tolist() and expected.sum() == 2
    assert ds.attrs["replay_where"] == "speed_rpm == 9524 and separation_deg_per_rev > 0"


def test_memory_is_bounded_by_the_batch_not_the_study(tmp_path, monkeypatch):
    """Each computed batch is stored before many more are computed, and the archive is
    assembled a few rows at a time."""
    import threading

    import campipe.study.run.assembly as assembly
    import campipe.study.run.workers as workers

    spec = SMALL_SPEC.replace(
        "[6000 rpm, 9524 rpm, 11000 rpm]", "{from: 3000 rpm, to: 12000 rpm, num: 20}"
    )
    lock = threading.Lock()
    live = {"now": 0, "max": 0, "rows": 0}
    compute, store, read = workers.compute_batch, workers._store, assembly.read_batch

    def counted_compute(plan):
        data = compute(plan)
        with lock:
            live["now"] += 1
            live["max"] = max(live["max"], live["now"])
        return data

    def counted_store(*args):
        out = store(*args)
        with lock:
            live["now"] -= 1
        return out

    def counted_read(path):
        arrays = read(path)
        live["rows"] = max(live["rows"], len(arrays["case"]))
        return arrays

    monkeypatch.setattr(workers, "compute_batch", counted_compute)
    monkeypatch.setattr(workers, "_store", counted_store)
    monkeypatch.setattr(assembly, "read_batch", counted_read)
    study = load_study(write_spec(tmp_path, spec))
    report = run_study(study, tmp_path / "m.nc", scheduler="threads", workers=2, batch_size=1)
    assert report.batches == 40
    assert live["max"] <= 3  # two workers, at most one batch waiting to be stored
    assert live["rows"] <= 1  # the archive is filled batch file by batch file


def test_a_stored_batch_is_not_kept_by_its_finished_future(tmp_path, monkeypatch):
    """Issue 39, item 4: at most two batches a worker in flight, each future dropped once its
    batch is stored, so the batches alive at once (computed, not yet freed) stay a few
    whatever the study's length. Broken copy, run_local: every batch submitted at once and
    waited on with as_completed (the futures list keeps every result to the end): all 40
    stay alive."""
    import threading
    import weakref

    import campipe.study.run.workers as workers

    spec = SMALL_SPEC.replace(
        "[6000 rpm, 9524 rpm, 11000 rpm]", "{from: 3000 rpm, to: 12000 rpm, num: 20}"
    )
    lock = threading.Lock()
    refs: list = []
    most = [0]
    compute = workers.compute_batch

    def counted_compute(plan):
        data = compute(plan)
        with lock:
            refs.append(weakref.ref(data))
            most[0] = max(most[0], sum(r() is not None for r in refs))
        return data

    monkeypatch.setattr(workers, "compute_batch", counted_compute)
    study = load_study(write_spec(tmp_path, spec))
    report = run_study(study, tmp_path / "m.nc", scheduler="threads", workers=2, batch_size=1)
    assert report.batches == 40 and len(refs) == 40
    assert most[0] <= 8  # 2 workers × 2 in flight, and what the assembly holds to write


def test_the_engine_threads_leave_a_core_to_the_archive(small_archive, tmp_path):
    """The archive is written in the calling thread, one chunk after another: the study's
    serial stage. The batch threads run WORKER_NICENESS below it (Linux), so it gets a core
    when it has rows to write; the archive is the same."""
    import threading

    from campipe.study.run.workers import WORKER_NICENESS

    study, archive = small_archive.study, small_archive.archive
    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    seen = set()

    def hook(plan, data):  # runs in the batch's worker thread
        seen.add(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))

    target = tmp_path / "niced.nc"
    run_study(study, target, scheduler="threads", workers=2, batch_size=2, on_batch=hook)
    lowered = min(own + WORKER_NICENESS, 19) if sys.platform.startswith("linux") else own
    assert seen == {lowered}
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own
    xr.testing.assert_identical(load(target), load(archive))
