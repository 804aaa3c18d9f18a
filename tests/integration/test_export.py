"""``campipe export`` (issue 37): a case's histories as a table with units in its header,
the unit system ``mm-deg`` (per degree at each case's cam speed) in export, query, plot and
``campipe.open_study``, and the output rule for the table written."""

from __future__ import annotations

import csv
import sys

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_allclose

import campipe
from campipe.cli import main

DEG_PER_S_PER_RPM = 6.0  # 360° a turn, 60 s a minute


def _export(archive, *args):
    return CliRunner().invoke(main, ["export", str(archive), *map(str, args)])


def _read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    return head, {h: [r[j] for r in body] for j, h in enumerate(head)}


def _ids(archive, speed_rpm, seat_none=True):
    with xr.open_dataset(archive) as ds:
        pick = (ds.speed_rpm.values == speed_rpm) & (np.isinf(ds.seat.values) == seat_none)
        return [str(c) for c in ds.case.values[pick]]


def test_mm_deg_columns_are_the_archive_s_si_histories_per_degree_of_cam_angle(
    small_archive, tmp_path
):
    """Two cases at 6000 and 11000 rpm: valve_velocity [mm/deg] is v·1000/(ω·180/π) and
    valve_acceleration [mm/deg^2] a·1000/(ω·180/π)² with each case's own ω, lift in mm,
    forces in N, to 1e-9. Fails on a copy that converts at one speed for every case, or
    per radian (ω in rad/s)."""
    slow, fast = _ids(small_archive.archive, 6000)[0], _ids(small_archive.archive, 11000)[0]
    out = tmp_path / "h.csv"
    result = _export(
        small_archive.archive, "--case", slow, "--case", fast[:8], "--units", "mm-deg", "-o", out
    )
    assert result.exit_code == 0, result.output
    head, cols = _read_csv(out)
    assert head[:3] == ["case", "cam_angle [deg]", "time [s]"]
    assert "valve_velocity [mm/deg]" in head and "valve_acceleration [mm/deg^2]" in head
    assert "valve_lift [mm]" in head and "cam_force [N]" in head and "q3 [rad]" in head
    with xr.open_dataset(small_archive.archive) as ds:
        n = ds.sizes["cam_angle"]
        assert len(cols["case"]) == 2 * n
        assert cols["case"][:n] == [slow] * n and cols["case"][n:] == [fast] * n
        for k, cid in enumerate((slow, fast)):
            case = ds.sel(case=cid)
            w = float(case.speed_rpm) * DEG_PER_S_PER_RPM  # ω·180/π [deg/s]
            part = slice(k * n, (k + 1) * n)
            v = np.array(cols["valve_velocity [mm/deg]"][part], float)
            a = np.array(cols["valve_acceleration [mm/deg^2]"][part], float)
            lift = np.array(cols["valve_lift [mm]"][part], float)
            force = np.array(cols["cam_force [N]"][part], float)
            assert_allclose(v, case.valve_velocity.values * 1000 / w, rtol=1e-9, atol=1e-12)
            assert_allclose(a, case.valve_acceleration.values * 1000 / w**2, rtol=1e-9, atol=1e-12)
            assert_allclose(lift, case.valve_lift.values * 1000, rtol=1e-9, atol=1e-12)
            assert_allclose(force, case.cam_force.values, rtol=0, atol=0)
        # the two speeds differ, so a single speed for both would not pass above
        assert np.abs(np.array(cols["valve_velocity [mm/deg]"][:n], float)).max() > 0.1


def test_si_csv_holds_the_stored_values_to_the_bit(small_archive, tmp_path):
    """Unconverted values are written whole (repr): the CSV reads back to the archive's
    floats exactly. Fails on a copy that rounds every value (e.g. to 6 digits)."""
    cid = _ids(small_archive.archive, 9524, seat_none=False)[0]
    out = tmp_path / "si.csv"
    assert _export(small_archive.archive, "--case", cid, "--units", "si", "-o", out).exit_code == 0
    head, cols = _read_csv(out)
    assert "valve_velocity [m/s]" in head
    with xr.open_dataset(small_archive.archive) as ds:
        stored = ds.valve_velocity.sel(case=cid).values
        contact = ds.contact_state.sel(case=cid).values
    assert np.array_equal(np.array(cols["valve_velocity [m/s]"], float), stored)
    assert [int(c) for c in cols["contact_state"]] == contact.tolist()
    # a force out of contact is stored as +0.0 (the engine's negated zero was -0.0) and
    # written as 0.0, not "-0.0"
    with xr.open_dataset(small_archive.archive) as ds:
        force = ds.cam_force.sel(case=cid).values
    assert np.any(force == 0) and not np.signbit(force[force == 0]).any()
    assert "-0.0" not in cols["cam_force [N]"]
    assert np.array_equal(np.array(cols["cam_force [N]"], float), force)


def test_mat_carries_the_csv_s_columns_and_units(small_archive, tmp_path):
    """A .mat (scipy.io) holds the CSV's numbers, the units by column, the case ids as
    case_id (case is a MATLAB keyword). Fails on a copy that writes another unit system or
    drops the units."""
    from scipy.io import loadmat

    cid = _ids(small_archive.archive, 11000)[0]
    args = ["--case", cid, "--units", "in-lbf"]
    assert _export(small_archive.archive, *args, "-o", tmp_path / "h.csv").exit_code == 0
    assert _export(small_archive.archive, *args, "-o", tmp_path / "h.mat").exit_code == 0
    _, cols = _read_csv(tmp_path / "h.csv")
    mat = loadmat(tmp_path / "h.mat", simplify_cells=True)
    assert mat["units"]["valve_velocity"] == "in/s"
    assert mat["campipe_export"] == "small"
    assert list(mat["case_id"]) == [cid] * len(cols["case"])
    assert_allclose(mat["valve_lift"], np.array(cols["valve_lift [in]"], float), rtol=0, atol=0)


def test_parquet_carries_the_csv_s_columns_and_units(small_archive, tmp_path):
    """A .parquet (where pyarrow is installed) holds the CSV's header as its column names,
    its numbers, and each column's units in its metadata. Fails on a copy that writes
    another unit system or drops the units."""
    pytest.importorskip("pyarrow")
    import json

    import pyarrow.parquet as pq

    cid = _ids(small_archive.archive, 11000)[0]
    args = ["--case", cid, "--units", "in-lbf"]
    assert _export(small_archive.archive, *args, "-o", tmp_path / "h.csv").exit_code == 0
    _, cols = _read_csv(tmp_path / "h.csv")
    assert _export(small_archive.archive, *args, "-o", tmp_path / "h.parquet").exit_code == 0
    table = pq.read_table(tmp_path / "h.parquet")
    assert table.column_names == list(cols)
    assert_allclose(
        table.column("valve_lift [in]").to_numpy(), np.array(cols["valve_lift [in]"], float)
    )
    units = json.loads(table.schema.metadata[b"units"])
    assert units["valve_velocity"] == "in/s" and units["cam_force"] == "lbf"


def test_parquet_without_pyarrow_is_refused_naming_the_fix(small_archive, tmp_path, monkeypatch):
    """Without pyarrow (an import that fails), parquet is refused before any file is
    written, naming pip install pyarrow and the other formats; exit status 2. Fails on a
    copy that imports pyarrow unguarded (a traceback) or writes a partial file."""
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    cid = _ids(small_archive.archive, 6000)[0]
    out = tmp_path / "h.parquet"
    result = _export(small_archive.archive, "--case", cid, "-o", out)
    assert result.exit_code == 2
    assert "pip install pyarrow" in result.output and "csv or mat" in result.output
    assert not out.exists()


def test_the_output_rule_keeps_the_archive_the_spec_and_others_files(small_archive, tmp_path):
    """Never the archive or its spec (not even with --overwrite); another file only with
    --overwrite; its own export is replaced on a rerun. Fails on a copy that writes without
    campipe.io.outputs.check_output."""
    cid = _ids(small_archive.archive, 6000)[0]
    for target in (small_archive.archive, small_archive.spec):
        result = _export(
            small_archive.archive, "--case", cid, "--format", "csv", "-o", target, "--overwrite"
        )
        assert result.exit_code == 2 and "which this command reads" in result.output
    notes = tmp_path / "notes.csv"
    notes.write_text("my,own\n1,2\n")
    result = _export(small_archive.archive, "--case", cid, "-o", notes)
    assert result.exit_code == 2 and "--overwrite" in result.output
    assert "is a file that is not a csv table campipe export wrote;" in " ".join(
        result.output.split()
    )
    assert notes.read_text() == "my,own\n1,2\n"
    assert _export(small_archive.archive, "--case", cid, "-o", notes, "--overwrite").exit_code == 0
    assert notes.read_text().startswith("case,cam_angle [deg]")
    # its own file, from a rerun: replaced without --overwrite
    assert (
        _export(small_archive.archive, "--case", cid, "-o", notes, "--units", "si").exit_code == 0
    )
    mat = tmp_path / "x.mat"
    from scipy.io import savemat

    savemat(mat, {"a": np.arange(3.0)})
    result = _export(small_archive.archive, "--case", cid, "-o", mat)
    assert result.exit_code == 2 and "campipe export" in result.output


def test_cases_by_where_and_refusals_name_the_option(small_archive, tmp_path):
    """--where picks the cases (three without a seat: 3 × the samples rows); an unknown id
    and no selection are refused naming --case. Fails on a copy that takes the first case
    when none matches."""
    out = tmp_path / "w.csv"
    result = _export(small_archive.archive, "--where", "seat is none", "-o", out)
    assert result.exit_code == 0, result.output
    _, cols = _read_csv(out)
    with xr.open_dataset(small_archive.archive) as ds:
        assert len(cols["case"]) == 3 * ds.sizes["cam_angle"]
    result = _export(small_archive.archive, "--case", "ffff", "-o", out)
    assert result.exit_code == 2 and "--case" in result.output
    result = _export(small_archive.archive, "-o", out)
    assert result.exit_code == 2 and "--case ID" in result.output


def test_open_study_in_mm_deg_converts_each_case_at_its_speed(small_archive):
    """open_study(path, units="mm-deg"): valve velocity per degree at each speed of the grid,
    seat and lift in mm, units attributes renamed; the default stays SI, untouched. Fails on
    a copy that ignores units= or converts per second."""
    si = campipe.open_study(small_archive.archive)
    mm = campipe.open_study(small_archive.archive, units="mm-deg")
    assert si.valve_velocity.attrs["units"] == "m/s"
    assert mm.valve_velocity.attrs["units"] == "mm/deg"
    assert mm.valve_acceleration.attrs["units"] == "mm/deg^2"
    assert mm.seat.attrs["units"] == "mm"
    assert_allclose(mm.seat.values, [-np.inf, 2.54])
    w = si.speed_rpm * DEG_PER_S_PER_RPM
    assert_allclose(mm.valve_velocity, si.valve_velocity * 1000 / w, rtol=1e-12)
    assert_allclose(mm.valve_acceleration, si.valve_acceleration * 1000 / w**2, rtol=1e-12)
    assert_allclose(mm.cam_force, si.cam_force, rtol=0)
    with xr.open_dataset(small_archive.archive) as flat:
        assert np.array_equal(
            si.valve_velocity.stack(c=("speed_rpm", "seat")).transpose("c", ...).values,
            flat.valve_velocity.values,
        )
    inch = campipe.open_study(small_archive.archive, units="in-lbf")
    assert_allclose(inch.valve_lift, si.valve_lift / 0.0254, rtol=1e-12)
    with pytest.raises(ValueError, match="expected one of: si, in-lbf, mm-deg"):
        campipe.open_study(small_archive.archive, units="mm")


def test_query_in_mm_deg_shows_impact_velocities_per_degree(small_archive):
    """query --units mm-deg: the seat in mm, a seating velocity in mm/deg at its case's
    speed. Fails on a copy whose query ignores the cam speed."""
    result = CliRunner().invoke(
        main,
        [
            "query",
            str(small_archive.archive),
            "--units",
            "mm-deg",
            "--format",
            "csv",
            "--columns",
            "speed_rpm,seat,max_seating_velocity",
            "--where",
            "seat is not none",
        ],
    )
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert lines[0] == "speed_rpm [rpm],seat [mm],max_seating_velocity [mm/deg]"
    with xr.open_dataset(small_archive.archive) as ds:
        keep = np.isfinite(ds.seat.values)
        speed = ds.speed_rpm.values[keep]
        v = ds.max_seating_velocity.values[keep]
    for line, s, vs in zip(lines[1:], speed, v, strict=True):
        cells = line.split(",")
        assert float(cells[1]) == 2.54
        assert float(cells[2]) == pytest.approx(vs * 1000 / (s * DEG_PER_S_PER_RPM), rel=1e-12)
