"""Nothing lost, nothing wrong: checksums on reuse and "up to date", the engine's fingerprint,
per-case status, and no file replaced without asking."""

import shutil
import zipfile

import netCDF4
import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import SMALL_SPEC, load, write_spec

import campipe.study.run.results as results
from campipe.cli import main
from campipe.io import batch_file
from campipe.io.archive import CHECKSUM_ATTR, read_attrs, verify
from campipe.study import load_study
from campipe.study.run.batches import parts_directory
from campipe.study.run.execute import run_study
from campipe.vocabulary import CHATTER, EVENTS_TRUNCATED, OK, STATUS, STATUS_FLAGS


def test_a_writers_checksums_are_those_read_back_however_its_rows_came(tmp_path):
    """``NetCDFWriter`` checksums a variable written in row order as the rows come (on a
    thread of its own), and reads back one written out of order: either way the checksums
    are what :func:`verify` computes from the file, for blocks, appends and text.
    An aborted writer leaves no file. Broken copy, run: each update's rows counted after it
    is hashed (in the background) instead of when it is written: the appends' start rows go
    wrong."""
    from campipe.io.archive import NetCDFWriter, VariableSpec

    rng = np.random.default_rng(1)
    history = rng.normal(size=(40, 17))
    specs = [
        VariableSpec("history", ("case", "sample"), "f8", {"units": "m"}),
        VariableSpec("shuffled", ("case",), "f8", {}),
        VariableSpec("events", ("event",), "i8", {}),
        VariableSpec("label", ("case",), "str", {}),
    ]
    sizes = {"case": 40, "sample": 17, "event": None}
    path = tmp_path / "w.nc"
    with NetCDFWriter(path, sizes, specs, {"title": "t"}) as w:
        for lo in range(0, 40, 16):  # three blocks, the last one short
            w.write("history", history[lo : lo + 16], slice(lo, min(lo + 16, 40)))
        w.write("shuffled", np.arange(20.0), slice(20, 40))  # out of order: read back
        w.write("shuffled", np.arange(20.0), slice(0, 20))
        for n in (3, 0, 5):
            w.append("events", np.arange(n, dtype=np.int64))
        w.write("label", np.array([f"case {k}" for k in range(40)], dtype=object))
        w.commit()
    assert verify(path) == []
    with netCDF4.Dataset(path) as ds:
        np.testing.assert_array_equal(ds["history"][:], history)
        np.testing.assert_array_equal(ds["events"][:], [0, 1, 2, 0, 1, 2, 3, 4])
    w = NetCDFWriter(tmp_path / "gone.nc", sizes, specs, {})
    w.write("history", history, slice(0, 40))
    w.abort()
    assert list(tmp_path.iterdir()) == [path]


def _flip(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x40
    path.write_bytes(bytes(data))


def test_every_file_carries_checksums_that_verify(small_archive):
    archive = small_archive.archive
    assert verify(archive) == []
    attrs = read_attrs(archive)
    assert attrs["campipe_layout"] == "campipe-archive-3"
    assert attrs["campipe_numerics"].startswith("campipe 0.1.0; source ")
    assert attrs["spec_file"] == "spec.yaml"
    with netCDF4.Dataset(archive) as ds:
        sums = __import__("json").loads(ds.getncattr(CHECKSUM_ATTR))
        assert set(sums) == {*ds.variables, "/attributes"}
    batches = sorted(parts_directory(archive).glob("batch-*.npz"))
    assert len(batches) == 3  # six cases, two a batch
    for path in batches:
        with zipfile.ZipFile(path) as z:  # every member carries the zip's CRC-32
            assert {"case.npy", "valve_lift.npy", "attributes.npy"} <= set(z.namelist())
        assert batch_file.verify(path) == []
        assert batch_file.read_attrs(path)["campipe_layout"] == "campipe-archive-3"


def test_a_flipped_byte_in_a_batch_files_data_is_detected_and_recomputed(
    small_archive, small_archive_copy, tmp_path
):
    study = small_archive_copy.study
    (tmp_path / "small.nc").unlink()  # the batch files alone must supply the cases
    batch = sorted(parts_directory(tmp_path / "small.nc").glob("batch-*.npz"))[1]
    lift = batch_file.read(batch)["valve_lift"][0, 100:104]
    offset = batch.read_bytes().find(lift.tobytes())
    assert offset > 0  # batch files are uncompressed: the values are there as written
    _flip(batch, offset + 3)
    report = run_study(study, tmp_path / "small.nc", scheduler="synchronous", batch_size=2)
    assert (report.computed, report.reused) == (2, 4)
    assert any(str(batch) in n and "failed its checks" in n for n in report.notes)
    xr.testing.assert_identical(load(tmp_path / "small.nc"), load(small_archive.archive))


def test_a_batch_file_edited_and_saved_again_is_recomputed(
    small_archive, small_archive_copy, tmp_path
):
    """A batch file read, one value changed and saved again with numpy (every member, its
    attributes and its content hash copied): the zip's CRC-32s are new and pass, the content
    hash does not; its cases are computed again and the archive equals the untouched one.
    Broken copy, batch_file.verify: the CRCs alone checked: the edited lift reaches the
    archive."""
    study = small_archive_copy.study
    (tmp_path / "small.nc").unlink()
    batch = sorted(parts_directory(tmp_path / "small.nc").glob("batch-*.npz"))[1]
    with np.load(batch, allow_pickle=False) as z:
        members = {name: z[name] for name in z.files}
    assert set(members) >= {batch_file.ATTRS, batch_file.HASH, "valve_lift", "case"}
    members["valve_lift"] = members["valve_lift"].copy()
    members["valve_lift"][0, 100] += 1e-3
    with open(batch, "wb") as f:
        np.savez(f, **members)
    with zipfile.ZipFile(batch) as z:
        assert z.testzip() is None  # the CRCs are the new content's
    assert batch_file.verify(batch) == [
        "its content differs from its hash (edited and saved again?)"
    ]
    report = run_study(study, tmp_path / "small.nc", scheduler="synchronous", batch_size=2)
    assert (report.computed, report.reused) == (2, 4)
    assert any(str(batch) in n and "failed its checks" in n for n in report.notes)
    xr.testing.assert_identical(load(tmp_path / "small.nc"), load(small_archive.archive))


@pytest.mark.parametrize("fraction", [0.3, 0.45, 0.6, 0.75, 0.9])
def test_a_flipped_byte_anywhere_in_a_batch_file_never_reaches_the_archive(
    small_archive, small_archive_copy, tmp_path, fraction
):
    study = small_archive_copy.study
    (tmp_path / "small.nc").unlink()
    batch = sorted(parts_directory(tmp_path / "small.nc").glob("batch-*.npz"))[0]
    _flip(batch, int(fraction * batch.stat().st_size))
    run_study(study, tmp_path / "small.nc", scheduler="synchronous", batch_size=2)
    xr.testing.assert_identical(load(tmp_path / "small.nc"), load(small_archive.archive))


@pytest.mark.parametrize("damage", ["zeroed tail", "truncated", "empty"])
def test_what_a_system_crash_leaves_of_a_batch_file_is_recomputed(
    small_archive, small_archive_copy, tmp_path, damage
):
    """Batch files are not synced to the disk: after a system crash one may hold zeros where
    its data had not reached the disk, end early, or be empty. Each fails its checks, is
    named, and its cases are computed again; the archive equals the untouched one."""
    study = small_archive_copy.study
    (tmp_path / "small.nc").unlink()
    batch = sorted(parts_directory(tmp_path / "small.nc").glob("batch-*.npz"))[2]
    data = batch.read_bytes()
    half = len(data) // 2
    batch.write_bytes(
        {
            "zeroed tail": data[:half] + bytes(len(data) - half),
            "truncated": data[:half],
            "empty": b"",
        }[damage]
    )
    report = run_study(study, tmp_path / "small.nc", scheduler="synchronous", batch_size=2)
    assert (report.computed, report.reused) == (2, 4)
    assert any(str(batch) in n and "failed its checks" in n for n in report.notes)
    xr.testing.assert_identical(load(tmp_path / "small.nc"), load(small_archive.archive))


def test_a_flipped_byte_in_the_archive_is_not_up_to_date_and_is_recomputed(small_archive, tmp_path):
    """The archive is compressed: bytes at several places of it are flipped in turn. Each
    damage that changes a value or attribute is detected before "up to date", and the
    rerun's archive always equals the untouched one."""
    pristine = small_archive.archive.read_bytes()
    size = len(pristine)
    detected = 0
    for fraction in np.linspace(0.1, 0.95, 16):
        d = tmp_path / f"f{fraction:.2f}"
        d.mkdir()
        shutil.copy(small_archive.spec, d / "spec.yaml")
        (d / "small.nc").write_bytes(pristine)
        _flip(d / "small.nc", int(fraction * size))
        damaged = bool(verify(d / "small.nc"))
        report = run_study(load_study(d / "spec.yaml"), d / "small.nc", scheduler="synchronous")
        assert report.up_to_date == (not damaged)
        if damaged:
            detected += 1
            assert report.computed == 6 and "failed its checks" in report.notes[0]
        xr.testing.assert_identical(load(d / "small.nc"), load(small_archive.archive))
    assert detected >= 3  # the others hit bytes no value or attribute is read from


def test_results_of_another_engine_are_never_reused(small_archive_copy, tmp_path, monkeypatch):
    study = small_archive_copy.study
    for module in ("resume", "workers", "keys"):
        monkeypatch.setattr(
            f"campipe.study.run.{module}.numerics_fingerprint",
            lambda: "campipe 9; source x; numpy==9",
        )
    monkeypatch.setattr(results, "numerics_fingerprint", lambda: "campipe 9; source x; numpy==9")
    report = run_study(study, tmp_path / "small.nc", scheduler="synchronous", batch_size=2)
    assert not report.up_to_date and (report.computed, report.reused) == (6, 0)
    assert any("computed by another campipe (campipe 0.1.0" in n for n in report.notes)
    assert read_attrs(tmp_path / "small.nc")["campipe_numerics"] == "campipe 9; source x; numpy==9"


# -- per-case status ------------------------------------------------------------------------


def test_a_failing_case_is_recorded_by_case_id_and_the_others_finish(tmp_path, monkeypatch):
    """A chattering case (simulated here) is the engine's to avoid; the study's part is to
    record it, name it by case id and finish every other case."""
    real = results.run_batch

    def chatter_on_9524(cases, settings, **kwargs):
        assert kwargs["on_failure"] == "record"
        out = real(cases, settings, **kwargs)
        for i, c in enumerate(cases):
            if abs(c.speed - 9524 * np.pi / 30) < 1e-6:
                out.status[i] = CHATTER
                out.valve_lift  # noqa: B018 - a property; the arrays below are the engine's
                out.q[i] = np.nan
                out.separation_per_rev[i] = np.nan
        return out

    monkeypatch.setattr(results, "run_batch", chatter_on_9524)
    spec = write_spec(tmp_path, SMALL_SPEC)
    result = CliRunner().invoke(
        main,
        ["study", str(spec), "--scheduler", "synchronous", "--batch-size", "4", "--no-progress"],
    )
    assert result.exit_code == 0, result.output
    ds = xr.load_dataset(tmp_path / "small.nc")
    failed = ds.case.values[ds.status.values == CHATTER]
    assert len(failed) == 2 and (ds.speed_rpm.values[ds.status.values == CHATTER] == 9524).all()
    assert (ds.status.values[ds.speed_rpm.values != 9524] == OK).all()
    assert np.isfinite(ds.valve_lift.values[ds.status.values == OK]).all()
    assert np.isnan(ds.separation_deg_per_rev.values[ds.status.values == CHATTER]).all()
    assert f"2 cases failed: {failed[0]} (chatter), {failed[1]} (chatter)" in result.stderr
    # what to do about it, once per status (a helper's step_limit said nothing)
    assert result.stderr.count("chatter: contact events kept recurring at one instant") == 1
    assert "run.integrator: newmark-linear" in result.stderr
    assert ds.status.attrs["flag_meanings"] == dict(STATUS_FLAGS)["flag_meanings"]
    summary = CliRunner().invoke(main, ["query", str(tmp_path / "small.nc"), "--summary"])
    assert f"failed: {failed[0]} (chatter), {failed[1]} (chatter)" in summary.output
    others = CliRunner().invoke(
        main, ["query", str(tmp_path / "small.nc"), "--summary", "--where", "speed_rpm != 9524"]
    )
    assert "small: 4 cases (of 6, where speed_rpm != 9524)" in others.output
    assert "failed" not in others.output


def test_events_beyond_max_events_are_a_visible_status(tmp_path):
    spec = write_spec(
        tmp_path,
        SMALL_SPEC.replace("run: {revolutions: 2,", "run: {revolutions: 2, max_events: 2,"),
    )
    result = CliRunner().invoke(main, ["study", str(spec), "--scheduler", "synchronous"])
    assert result.exit_code == 0, result.output
    ds = xr.load_dataset(tmp_path / "small.nc")
    truncated = ds.status.values == EVENTS_TRUNCATED
    assert truncated.any() and (ds.event_count.values[truncated] == 2).all()
    assert "kept only run.max_events events" in result.stderr
    assert STATUS[EVENTS_TRUNCATED] in result.stderr


# -- nothing replaced without asking -------------------------------------------------------


def _study(tmp_path, output=None, *extra):
    spec = tmp_path / "spec.yaml"
    args = ["study", str(spec), "--scheduler", "synchronous", "--no-progress", *extra]
    return CliRunner().invoke(main, args + (["-o", str(output)] if output else []))


@pytest.mark.parametrize("target", ["spec", "text", "other-spec"])
def test_a_file_that_is_not_this_studys_archive_is_refused(small_archive, tmp_path, target):
    shutil.copy(small_archive.spec, tmp_path / "spec.yaml")
    if target == "spec":
        victim = tmp_path / "spec.yaml"
    elif target == "text":
        victim = tmp_path / "notes.txt"
        victim.write_text("my notes\n")
    else:  # a second spec with the same name, in the same folder: the same default archive
        # (another study: an identical one is the same study, moved or copied)
        text = small_archive.spec.read_text()
        (tmp_path / "first.yaml").write_text(text.replace(", 11000 rpm", ""))
        first = CliRunner().invoke(
            main, ["study", str(tmp_path / "first.yaml"), "--scheduler", "synchronous"]
        )
        assert first.exit_code == 0, first.output
        victim = tmp_path / "small.nc"
    before = victim.read_bytes()
    result = _study(tmp_path, None if target == "other-spec" else victim)
    assert result.exit_code == 2, result.output
    assert f"{victim}: exists and is" in result.stderr and "--overwrite" in result.stderr
    assert "Traceback" not in result.output
    assert victim.read_bytes() == before
    assert not list(tmp_path.glob("*.lock")) and not list(tmp_path.glob("*.parts"))


@pytest.mark.parametrize("parts", [False, True])
def test_an_archive_moved_with_its_spec_is_still_this_study_s(small_archive, tmp_path, parts):
    """An archive moved (or copied) to another folder with its spec, or run from a copy of
    the spec beside it, is the same study (its study_key): up to date, or resumed, not
    refused as another spec's because the spec's path relative to it changed (a helper's
    moved cluster archive: "the parts archive of another spec", and --overwrite does not
    apply to parts). Broken copy: the spec's relative path alone deciding."""
    spec = tmp_path / "a" / "spec.yaml"
    spec.parent.mkdir()
    shutil.copy(small_archive.spec, spec)
    first = tmp_path / "a" / ("small.parts" if parts else "small.nc")
    run_study(load_study(spec), first, scheduler="synchronous", parts=parts)
    moved = tmp_path / "b" / first.name
    moved.parent.mkdir()
    shutil.move(first, moved)
    again = run_study(load_study(spec), moved, scheduler="synchronous", parts=parts)
    assert again.up_to_date and again.computed == 0
    beside = tmp_path / "b" / "spec.yaml"
    shutil.copy(spec, beside)
    third = run_study(load_study(beside), moved, scheduler="synchronous", parts=parts)
    assert third.up_to_date and third.computed == 0


def test_overwrite_replaces_another_studys_archive_reusing_the_cases_it_shares(
    small_archive, tmp_path
):
    other = tmp_path / "other.yaml"
    other.write_text(SMALL_SPEC.replace("name: small", "name: other").replace(", 11000 rpm", ""))
    shutil.copy(small_archive.spec, tmp_path / "spec.yaml")
    assert (
        CliRunner().invoke(main, ["study", str(other), "-o", str(tmp_path / "small.nc")]).exit_code
        == 0
    )
    assert _study(tmp_path).exit_code == 2
    result = _study(tmp_path, None, "--overwrite")
    assert result.exit_code == 0, result.output
    assert "(4 reused, 2 computed in 1 batches)" in result.stderr
    xr.testing.assert_identical(load(tmp_path / "small.nc"), load(small_archive.archive))


def test_an_edited_spec_removes_its_archive_s_cases_only_with_overwrite(
    small_archive_copy, tmp_path
):
    """A rerun of a narrower sweep would remove cases the archive holds: refused, naming how
    many and the two ways on, the archive left byte for byte and nothing computed; with
    --overwrite it replaces them and says so. Broken copy it fails on: the run that only
    noted the cases it removed (a helper lost 28 of 32 cluster cases to it)."""
    assert _study(tmp_path).exit_code == 0
    archive = tmp_path / "small.nc"
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    (tmp_path / "spec.yaml").write_text(SMALL_SPEC.replace(", 11000 rpm", ""))
    files[tmp_path / "spec.yaml"] = (tmp_path / "spec.yaml").read_bytes()
    result = _study(tmp_path)
    assert result.exit_code == 2, result.output
    assert f"{archive}: 2 of the 6 cases it holds are not in this run's spec" in result.stderr
    assert "another path (-o)" in result.stderr and "with --overwrite" in result.stderr
    assert "Traceback" not in result.output
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files
    result = _study(tmp_path, None, "--overwrite")
    assert result.exit_code == 0, result.output
    assert "2 of the 6 cases it holds are not in this run's spec" in result.stderr
    assert "removed (--overwrite)" in result.stderr
    assert xr.load_dataset(archive).sizes["case"] == 4


def test_an_archive_of_an_older_layout_is_refused_and_replaced_only_with_overwrite(
    small_archive_copy, tmp_path
):
    """Layout 2 stored the ids as case_id and no seat as NaN: never mixed with layout 3."""
    study = small_archive_copy.study
    shutil.rmtree(parts_directory(tmp_path / "small.nc"))
    archive = tmp_path / "small.nc"
    with netCDF4.Dataset(archive, "a") as ds:
        ds.setncattr("campipe_layout", "campipe-archive-2")
    before = archive.read_bytes()
    result = _study(tmp_path)
    assert result.exit_code == 2, result.output
    assert (
        f"{archive}: exists and is an archive in another layout (campipe-archive-2; this "
        "campipe writes campipe-archive-3)" in result.stderr
    )
    assert "replace it with --overwrite" in result.stderr
    assert archive.read_bytes() == before
    report = run_study(study, archive, scheduler="synchronous", overwrite=True)
    assert report.computed == 6 and read_attrs(archive)["campipe_layout"] == "campipe-archive-3"


@pytest.mark.parametrize("target", ["spec", "lift-table"])
def test_the_study_s_own_inputs_are_never_replaced_not_even_with_overwrite(tmp_path, target):
    """`campipe study SPEC -o SPEC --overwrite` (or `-o` its lift table) is refused, naming
    the file and that --overwrite does not replace it, and the file is left byte for byte: a
    user who replaced the spec or the table with the archive lost them (the table's values
    are stored nowhere else). Broken copy: --overwrite lets any file go."""
    table = tmp_path / "cam.csv"
    table.write_text("angle [deg],lift [in]\n0,0\n90,0.5\n180,1\n270,0.5\n")
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "name: inputs\nmodel: {preset: thesis-1971}\nprofile: {kind: table, file: cam.csv}\n"
        "speed: 6000 rpm\nrun: {revolutions: 1, output_every: 2 deg}\n"
    )
    victim = spec if target == "spec" else table
    before = victim.read_bytes()
    result = _study(tmp_path, victim, "--overwrite")
    assert result.exit_code == 2, result.output
    assert f"{victim}: exists and is" in result.stderr
    assert "never replaced, not even with --overwrite" in result.stderr
    assert "replace it with --overwrite" not in result.stderr
    assert victim.read_bytes() == before
    assert _study(tmp_path, tmp_path / "out.nc").exit_code == 0  # the inputs still serve
