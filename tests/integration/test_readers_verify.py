"""Readers that check (issue 39, item 6): ``query``, ``plot``, ``replay`` and ``open_study``
refuse an archive whose bytes changed after campipe wrote it, naming the variable, in an
uncompressed archive and in a zstd one; ``--no-verify`` skips the check."""

import shutil

import netCDF4
import numpy as np
import pytest
from click.testing import CliRunner
from study_helpers import write_spec

import campipe
import campipe.io.archive
from campipe.cli import main
from campipe.io.archive import ArchiveDamagedError, check, damaged
from campipe.study import load_study
from campipe.study.archive.open import open_archive
from campipe.study.run.execute import run_study

SPEC = """
name: flip
profile: {{kind: harmonic, lift: 1 in}}
run: {{revolutions: 2, output_every: 4 deg, compression: {compression}}}
sweep:
  speed: [6000 rpm, 9524 rpm, 11000 rpm]
"""


def _run(tmp_path_factory, compression):
    d = tmp_path_factory.mktemp(f"flip-{compression}")
    spec = write_spec(d, SPEC.format(compression=compression))
    path = d / "flip.nc"
    run_study(load_study(spec), path, scheduler="synchronous")
    return path


@pytest.fixture(scope="module", params=["none", "zstd"])
def archive(request, tmp_path_factory):
    return _run(tmp_path_factory, request.param)


@pytest.fixture(scope="module")
def uncompressed(tmp_path_factory):
    """An uncompressed archive: its histories' values are found by their bytes."""
    return _run(tmp_path_factory, "none")


def _flipped(archive, tmp_path, name="max_cam_force"):
    """A copy of ``archive`` (with its spec) with one byte flipped inside ``name``'s stored
    values: the 3 cases' values are one chunk of 24 bytes, stored as written even under zstd
    (too short to compress), so they are found by their bytes; the byte flipped is the
    first value's second-highest, which moves it by a large fraction."""
    shutil.copy(archive.parent / "spec.yaml", tmp_path / "spec.yaml")
    copy = tmp_path / archive.name
    data = bytearray(archive.read_bytes())
    with netCDF4.Dataset(archive) as ds:
        values = np.asarray(ds[name][:])
    offset = data.find(values.tobytes())
    assert offset > 0 and data.count(values.tobytes()) == 1
    data[offset + 6] ^= 0x10
    copy.write_bytes(bytes(data))
    return copy, values


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_flipped_byte_in_a_variable_is_named_by_every_reader(archive, tmp_path):
    """open_study, query, plot and replay each refuse the damaged copy (exit status 1, the
    variable named, nothing drawn or recorded) and read the untouched archive.
    Broken copy, open_archive: the check left out (``verify`` ignored): query prints the
    changed force with exit status 0 (uncompressed) or HDF5's bare "HDF error"."""
    copy, values = _flipped(archive, tmp_path)
    assert damaged(archive) == []
    assert damaged(copy) == ["max_cam_force"]
    with pytest.raises(ArchiveDamagedError) as caught:
        campipe.open_study(copy)
    assert caught.value.found == ["max_cam_force"]
    assert "max_cam_force" in str(caught.value) and "--no-verify" in str(caught.value)
    with campipe.open_study(archive) as ds:
        np.testing.assert_array_equal(ds["max_cam_force"].values, values)

    png, rrd = tmp_path / "f.png", tmp_path / "f.rrd"
    for args in (
        ["query", copy],
        ["query", copy, "--summary"],
        ["plot", "metric", copy, "-o", png],
        ["replay", copy, "--where", "speed_rpm > 0", "-o", rrd],
    ):
        out = invoke(*args)
        assert out.exit_code == 1, (args, out.output)
        assert "damaged: max_cam_force differs" in out.output, out.output
        assert "Traceback" not in out.output
    assert not png.exists() and not rrd.exists()
    assert invoke("query", archive).exit_code == 0


def test_fletcher32_finds_a_flipped_byte_in_a_chunk_even_unverified(archive, tmp_path):
    """Every chunked variable carries HDF5's Fletcher-32, so even read without the check
    (--no-verify, or plain xarray) the damaged chunk fails to read rather than giving a
    wrong force. Broken copy, NetCDFWriter: no fletcher32=True: the uncompressed copy reads
    a changed max_cam_force silently."""
    copy, values = _flipped(archive, tmp_path)
    with netCDF4.Dataset(archive) as ds:
        assert ds["max_cam_force"].filters()["fletcher32"]
        assert ds["valve_lift"].filters()["fletcher32"]
    with pytest.raises(RuntimeError, match="HDF error"):
        with netCDF4.Dataset(copy) as ds:
            ds["max_cam_force"][:]
    out = invoke("query", copy, "--no-verify")
    assert out.exit_code == 1 and "Traceback" not in out.output
    assert "cannot read the archive (NetCDF: HDF error)" in out.output
    assert "without --no-verify" in out.output


def test_an_archive_edited_and_saved_again_is_refused_unless_no_verify(archive, tmp_path):
    """A value changed through netCDF4 and saved (HDF5's chunk checksums recomputed, so
    only the stored SHA-256 knows) is refused naming the variable by query and export;
    --no-verify reads the edited value. Broken copy, damaged: only read failures counted,
    not digests compared."""
    shutil.copy(archive.parent / "spec.yaml", tmp_path / "spec.yaml")
    copy = tmp_path / archive.name
    shutil.copy(archive, copy)
    with netCDF4.Dataset(copy, "a") as ds:
        ds["max_cam_force"][0] = 4448.2216152605  # 1000 lbf
        ds["steps"][1] = 7
    assert damaged(copy) == ["max_cam_force", "steps"]
    assert damaged(copy, ["max_cam_force", "valve_lift"]) == ["max_cam_force"]
    with pytest.raises(ArchiveDamagedError, match="max_cam_force, steps differ"):
        check(copy)
    out = invoke("query", copy, "--columns", "max_cam_force", "--units", "in-lbf")
    assert out.exit_code == 1 and "max_cam_force, steps" in out.output
    out = invoke("query", copy, "--columns", "max_cam_force", "--units", "in-lbf", "--no-verify")
    assert out.exit_code == 0 and "1000" in out.output.splitlines()[2], out.output
    with open_archive(copy, verify=False) as ds:
        assert ds["steps"].values[1] == 7
    # campipe export likewise: refused, then written with --no-verify
    table = tmp_path / "h.csv"
    out = invoke("export", copy, "--where", "speed_rpm > 0", "-o", table)
    assert out.exit_code == 1 and "max_cam_force, steps" in out.output and not table.exists()
    out = invoke("export", copy, "--where", "speed_rpm > 0", "-o", table, "--no-verify")
    assert out.exit_code == 0 and table.stat().st_size > 0, out.output


def test_a_pipe_as_an_archive_is_refused_not_waited_on(tmp_path):
    """A FIFO given as the archive: the readers would block opening it. Broken copy,
    open_archive: no regular-file check: this test hangs."""
    import os

    fifo = tmp_path / "pipe.nc"
    os.mkfifo(fifo)
    out = invoke("query", fifo)
    assert out.exit_code == 1 and "not a regular file" in out.output


def test_closing_open_study_s_grid_closes_its_file(archive):
    """open_study returns a new dataset (the grid) over the opened file: closing it closes
    the file. Broken copy, open_study: the grid returned without ``set_close``: the file
    stays open, and netCDF-C 4.10 with HDF5 2.2 crashed the process when it was opened
    again a few times (``campipe.io.archive.open_dataset``)."""
    from campipe.io.archive import open_elsewhere

    with campipe.open_study(archive) as ds:
        assert ds["max_cam_force"].dims == ("speed_rpm",)
        assert open_elsewhere(archive)
    assert not open_elsewhere(archive)


def test_a_foreign_netcdf_is_refused_not_shown_as_no_cases(tmp_path):
    """A netCDF file campipe did not write: query, plot and open_study refuse it (exit
    status 1), not "(0 of 0 cases)" with status 0. Broken copy, open_archive: no check of
    the case variable and layout attribute: query exits 0."""
    path = tmp_path / "foreign.nc"
    with netCDF4.Dataset(path, "w") as ds:
        ds.createDimension("x", 3)
        ds.createVariable("t", "f8", ("x",))[:] = [1.0, 2.0, 3.0]
    for args in (["query", path], ["plot", "metric", path, "-o", tmp_path / "f.png"]):
        out = invoke(*args)
        assert out.exit_code == 1, out.output
        assert "not a campipe archive" in out.output and "0 of 0" not in out.output
    with pytest.raises(campipe.io.archive.ArchiveFileError, match="not a campipe archive"):
        campipe.open_study(path)


def test_query_leaves_the_histories_it_never_reads_unchecked(uncompressed, tmp_path):
    """A flipped byte inside a history (valve_lift): query, which reads no history, skips
    their check (unread_dims) and answers; plot histories and open_study refuse, naming
    valve_lift. Broken copy, damaged: skip_dims ignored: query refuses too (its check then
    reads every history, the bulk of an archive)."""
    copy, _ = _flipped(uncompressed, tmp_path, "valve_lift")
    assert damaged(copy) == ["valve_lift"]
    assert damaged(copy, skip_dims=["cam_angle"]) == []
    assert invoke("query", copy).exit_code == 0
    out = invoke("plot", "histories", copy, "--where", "speed_rpm > 9000", "-o", tmp_path / "h.png")
    assert out.exit_code == 1 and "damaged: valve_lift differs" in out.output, out.output
    with pytest.raises(ArchiveDamagedError, match="valve_lift"):
        campipe.open_study(copy)


def test_an_archive_whose_attributes_hdf5_cannot_open_is_damaged(monkeypatch, tmp_path):
    """A flipped byte in an archive's header can leave HDF5 unable to open its attributes
    (netCDF4 raises AttributeError: "Can't open HDF5 attribute", as a helper's archive did):
    ``damaged`` names its attributes, so every reader refuses it as damaged instead of
    stopping with a traceback (campipe replay did). Broken copy: the AttributeError escapes."""
    import contextlib

    import campipe.io.archive as archive_io

    class Header:
        def set_auto_mask(self, flag):
            pass

        def ncattrs(self):
            raise AttributeError("NetCDF: Can't open HDF5 attribute")

    monkeypatch.setattr(archive_io, "open_dataset", lambda path: contextlib.nullcontext(Header()))
    assert archive_io.damaged(tmp_path / "any.nc") == ["attributes"]


def test_an_archive_hdf5_cannot_open_is_told_damaged_alike_by_every_reader(archive, tmp_path):
    """An archive cut to half its length: HDF5 cannot open it. query, plot and replay each
    exit 1 (the environment's, not the input's) saying its structure is damaged and to restore
    it or run the study again. Broken copy: replay exited 2, and each gave HDF5's bare error."""
    cut = tmp_path / archive.name
    data = archive.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    for args in (
        ("query", cut),
        ("plot", "metric", cut, "-o", tmp_path / "m.png"),
        ("replay", cut, "--where", "speed_rpm > 0", "-o", tmp_path / "r.rrd"),
    ):
        out = invoke(*args)
        assert out.exit_code == 1, (args, out.output)
        assert "its structure is damaged" in out.output and "run the study again" in out.output
