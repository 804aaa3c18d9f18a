"""campipe.open_study: an archive that analyses like a grid, with the cases without a seat
kept by every grouping (no seat is -inf, a real value)."""

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from numpy.testing import assert_array_equal
from study_helpers import INCH, LBF, write_spec

import campipe
from campipe.study import load_study
from campipe.study.run.execute import run_study

SWEEP = """
name: grid
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 1, output_every: 2 deg}
sweep:
  speed: [11000 rpm, 6000 rpm, 9524 rpm]
  seat: [none, 0.1 in]
"""

MIXED = """
name: mixed
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 1, output_every: 5 deg}
sweep:
  speed: [6000 rpm, 9000 rpm]
zip:
  model.spring_preload: [120 lbf, 151 lbf]
  model.spring_rate: [200 lbf/in, 245 lbf/in]
cases:
  - {seat: none}
  - {seat: 0.1 in}
"""


def _run(tmp_path_factory, text, name):
    d = tmp_path_factory.mktemp(name)
    archive = d / f"{name}.nc"
    run_study(load_study(write_spec(d, text)), archive, scheduler="synchronous")
    return archive


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    return _run(tmp_path_factory, SWEEP, "grid")


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    return _run(tmp_path_factory, MIXED, "mixed")


def test_a_speed_by_seat_sweep_opens_as_a_grid_with_every_case(sweep):
    grid = campipe.open_study(sweep)
    flat = xr.load_dataset(sweep)
    assert grid.valve_lift.dims == ("speed_rpm", "seat", "cam_angle")
    assert grid.separation_deg_per_rev.dims == ("speed_rpm", "seat")
    # the spec's order, no seat as -inf
    assert_array_equal(grid.speed_rpm, [11000.0, 6000.0, 9524.0])
    assert_array_equal(grid.seat, [-np.inf, 0.1 * INCH])
    assert grid.seat.attrs["units"] == "m" and "no seat" in grid.seat.attrs["comment"]
    assert sorted(grid.case_id.values.ravel()) == sorted(flat.case.values)
    for speed in grid.speed_rpm.values:
        for seat in grid.seat.values:
            cell = grid.sel(speed_rpm=speed, seat=seat)
            case = flat.sel(case=str(cell.case_id.values))
            assert float(case.speed_rpm) == speed and float(case.seat) == seat
            assert_array_equal(cell.valve_lift, case.valve_lift)
            assert float(cell.separation_deg_per_rev) == float(case.separation_deg_per_rev)
    # no seat at 6000 rpm stays on the cam; at 11000 rpm it does not
    sep = grid.separation_deg_per_rev.sel(seat=-np.inf)
    assert float(sep.sel(speed_rpm=6000)) == 0 and float(sep.sel(speed_rpm=11000)) > 50


def test_the_flat_archive_keeps_the_cases_without_a_seat_in_every_grouping(sweep):
    flat = xr.load_dataset(sweep)
    ids = flat.case.values
    assert str(flat.sel(case=ids[3]).case.values) == ids[3]
    groups = flat.separation_deg_per_rev.groupby("seat").mean()
    assert_array_equal(groups.seat, [-np.inf, 0.1 * INCH])
    none = flat.separation_deg_per_rev.values[flat.seat.values == -np.inf]
    assert float(groups.sel(seat=-np.inf)) == pytest.approx(none.mean()) and none.size == 3
    table = flat.separation_deg_per_rev.to_dataframe().pivot_table(
        index="speed_rpm", columns="seat", values="separation_deg_per_rev"
    )
    assert table.shape == (3, 2) and not table.isna().any().any()
    assert flat.sortby("seat").sizes["case"] == 6
    assert_array_equal(flat.sortby("seat").seat[:3], [-np.inf] * 3)
    stacked = flat.set_index(case=["speed_rpm", "seat"]).unstack("case")
    assert stacked.separation_deg_per_rev.notnull().sum() == 6


def test_zip_rows_and_case_entries_stay_along_case(mixed):
    grid = campipe.open_study(mixed)
    flat = xr.load_dataset(mixed)
    assert flat.sizes["case"] == 8
    assert grid.valve_lift.dims == ("speed_rpm", "case", "cam_angle")
    assert grid.sizes["speed_rpm"] == 2 and grid.sizes["case"] == 4
    assert_array_equal(grid.speed_rpm, [6000.0, 9000.0])
    # along case: entry (seat) outermost, then the zip rows
    preload = grid.spring_preload.values / LBF
    assert_array_equal(np.round(preload, 9), [[120, 151, 120, 151]] * 2)
    assert_array_equal(grid.seat.values, [[-np.inf, -np.inf, 0.1 * INCH, 0.1 * INCH]] * 2)
    for i, speed in enumerate(grid.speed_rpm.values):
        for r in range(4):
            case = flat.sel(case=str(grid.case_id.values[i, r]))
            assert float(case.speed_rpm) == speed
            assert float(case.spring_preload) == grid.spring_preload.values[i, r]
            assert_array_equal(grid.valve_lift.values[i, r], case.valve_lift.values)
    # each event carries its case's id
    assert_array_equal(grid.event_case_id.values, flat.case.values[flat.event_case.values])
    assert "event_case" not in grid.variables


def test_a_study_that_is_not_a_grid_of_plain_values_opens_as_stored(tmp_path):
    spec = write_spec(
        tmp_path,
        """
        name: vector
        profile: {kind: harmonic, lift: 1 in}
        speed: 9000 rpm
        run: {revolutions: 1, output_every: 10 deg}
        sweep:
          model.damping_ratios: [[0, 0, 0, 0, 0, 0, 0], [0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05]]
        """,
    )
    run_study(load_study(spec), tmp_path / "vector.nc", scheduler="synchronous")
    ds = campipe.open_study(tmp_path / "vector.nc")
    assert ds.valve_lift.dims == ("case", "cam_angle") and ds.sizes["case"] == 2
    assert ds.damping_ratios.dims == ("case", "mode")
    ds.close()


def test_pandas_keeps_no_seat_too():
    frame = pd.DataFrame({"seat": [-np.inf, 0.00254, -np.inf], "x": [1.0, 2.0, 3.0]})
    assert frame.groupby("seat").x.sum().to_dict() == {-np.inf: 4.0, 0.00254: 2.0}
    assert frame.groupby(pd.Series([np.nan, 1.0, np.nan])).x.sum().to_dict() == {1.0: 2.0}
