"""The archive's compression (``run.compression``): zstd by default, zlib or none on request;
the values, their checksums and the reuse of results do not depend on it, and a reader or
writer without the compression's HDF5 plugin is told what to do."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import netCDF4
import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import ROOT, SMALL_SPEC, write_spec

from campipe.cli import main
from campipe.io.archive import (
    ATTRIBUTES_ENTRY,
    CHECKSUM_ATTR,
    COMPRESSIONS,
    read_attrs,
    verify,
)
from campipe.study.run.batches import parts_directory


def _spec(directory, compression=None):
    """The small study's spec, with ``run.compression`` if given."""
    extra = f", compression: {compression}" if compression else ""
    run = "run: {revolutions: 2"
    return write_spec(directory, SMALL_SPEC.replace(run, run + extra))


def _study(*args):
    return CliRunner().invoke(main, ["study", *map(str, args), "--no-progress"])


def _filters(path):
    with netCDF4.Dataset(path) as ds:
        return ds["valve_lift"].filters(), ds["max_cam_force"].filters()


@pytest.mark.parametrize("compression", sorted(COMPRESSIONS))
def test_a_writer_compresses_incompressible_rows_as_asked_and_reads_them_back(
    tmp_path, compression
):
    """Random doubles do not compress: each compression still stores them (a filter that
    refuses an incompressible chunk would fail here), its filter is the one named, and the
    values and checksums read back."""
    from campipe.io.archive import NetCDFWriter, VariableSpec

    rows = np.random.default_rng(2).normal(size=(20, 300))
    specs = [VariableSpec("history", ("case", "sample"), "f8", {})]
    path = tmp_path / "w.nc"
    with NetCDFWriter(path, {"case": 20, "sample": 300}, specs, {}, compression) as w:
        w.write("history", rows[:8], slice(0, 8))
        w.write("history", rows[8:], slice(8, 20))
        w.commit()
    assert verify(path) == []
    with netCDF4.Dataset(path) as ds:
        np.testing.assert_array_equal(ds["history"][:], rows)
        found = ds["history"].filters()
    assert found["zstd"] == (compression == "zstd") and found["zlib"] == (compression == "zlib")
    assert found["shuffle"] == (compression == "zlib")


def test_the_default_is_zstd_and_another_compression_reuses_every_case(
    small_archive_copy, tmp_path
):
    """The default archive is zstd. Asking for zlib afterwards rewrites it from the cases it
    holds (none computed again) with the same values and the same checksums; none stores
    the rows as they are, larger than either."""
    spec, archive = small_archive_copy.spec, small_archive_copy.archive
    assert _study(spec).exit_code == 0
    histories, metrics = _filters(archive)
    assert histories["zstd"] and metrics["zstd"]
    zstd = xr.load_dataset(archive)
    sums = json.loads(read_attrs(archive)[CHECKSUM_ATTR])
    sizes = {"zstd": archive.stat().st_size}
    for compression in ("zlib", "none"):
        _spec(tmp_path, compression)
        result = _study(spec)
        assert result.exit_code == 0, result.output
        assert "(6 reused, 0 computed" in result.output
        histories, _ = _filters(archive)
        assert histories["zlib"] == (compression == "zlib") and not histories["zstd"]
        assert verify(archive) == []
        again_sums = json.loads(read_attrs(archive)[CHECKSUM_ATTR])
        # the same but for the attributes (the spec's text)
        assert again_sums.pop(ATTRIBUTES_ENTRY) != sums[ATTRIBUTES_ENTRY]
        assert again_sums == {k: v for k, v in sums.items() if k != ATTRIBUTES_ENTRY}
        again = xr.load_dataset(archive)
        for name in zstd.variables:
            np.testing.assert_array_equal(again[name].values, zstd[name].values, err_msg=name)
        sizes[compression] = archive.stat().st_size
    assert sizes["none"] > max(sizes["zstd"], sizes["zlib"])


def test_run_compression_is_one_of_three_and_shared_by_the_study(tmp_path):
    result = CliRunner().invoke(main, ["validate", str(_spec(tmp_path, "lz4"))])
    assert result.exit_code == 2
    assert "run.compression: found 'lz4', expected one of: zstd, zlib, none" in result.output
    spec = _spec(tmp_path)
    spec.write_text(spec.read_text() + "  run.compression: [zlib, zstd]\n")
    result = CliRunner().invoke(main, ["validate", str(spec)])
    assert result.exit_code == 2 and "sweep.run.compression: the whole study shares it" in (
        result.output
    )


def _campipe(args, cwd):
    """campipe in a process of its own whose HDF5 finds no filter plugin."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "HDF5_PLUGIN_PATH": str(cwd / "no-plugins")}
    cmd = [sys.executable, "-m", "campipe", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)


def test_without_the_plugin_reading_and_writing_say_what_to_do_and_lose_nothing(
    small_archive_copy, tmp_path
):
    """With HDF5_PLUGIN_PATH naming a folder without netCDF's plugins, a zstd archive cannot
    be read, nor one written: each message says why and names the fixes. The run stops
    before it computes anything (one batch at a time: the archive is created first) and the
    archive already there is left as it was: the same command, the plugins found again,
    reuses its cases."""
    spec, archive = small_archive_copy.spec, small_archive_copy.archive
    shutil.rmtree(small_archive_copy.parts)  # only the archive holds the cases
    assert _study(spec).exit_code == 0
    before = archive.read_bytes()
    query = _campipe(["query", "small.nc"], tmp_path)
    assert query.returncode == 1 and "Traceback" not in query.stderr
    assert "cannot read as an archive" in query.stderr
    assert "found no HDF5 plugin" in query.stderr and "unset HDF5_PLUGIN_PATH" in query.stderr
    spec.write_text(spec.read_text().replace("11000 rpm", "12000 rpm"))
    args = ["study", "spec.yaml", "--scheduler", "synchronous", "--no-progress"]
    failed = _campipe(args, tmp_path)
    assert failed.returncode == 1 and "Traceback" not in failed.stderr
    assert "small.nc: cannot write" in failed.stderr and "found no HDF5 plugin" in failed.stderr
    assert "set run.compression: zlib" in failed.stderr
    assert archive.read_bytes() == before
    assert not list(parts_directory(archive).glob("batch-*"))
    result = _study(spec, "--overwrite")  # the edit leaves out the 11000 rpm cases
    assert result.exit_code == 0, result.output
    assert "(4 reused, 2 computed" in result.output and verify(archive) == []


def test_a_netcdf4_without_zstd_is_refused_naming_the_key(tmp_path, monkeypatch):
    """A netCDF4 built without zstd (not its wheel) cannot write the default: the error says
    so and names run.compression, before any file is made."""
    from campipe.io.archive import ArchiveWriteError, NetCDFWriter, VariableSpec

    monkeypatch.setattr(netCDF4, "__has_zstandard_support__", 0)
    specs = [VariableSpec("history", ("case",), "f8", {})]
    with pytest.raises(ArchiveWriteError, match="set run.compression: zlib"):
        NetCDFWriter(tmp_path / "w.nc", {"case": 2}, specs, {})
    assert list(tmp_path.iterdir()) == []
    with NetCDFWriter(tmp_path / "w.nc", {"case": 2}, specs, {}, "zlib") as w:
        w.write("history", np.ones(2))
        w.commit()
    assert verify(tmp_path / "w.nc") == []
