"""A study given in engine speed (issue 37): the archive's engine speed and crank angle, the
queries and figures that read them; and the figures' seat band, angle range and limit lines."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from matplotlib.patches import Rectangle
from numpy.testing import assert_allclose
from study_helpers import INCH, write_spec

from campipe.cli import main
from campipe.plot.figures import figure
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.study.spec.plots import PlotError, PlotRequest, check_plot
from campipe.units import degree_speed

SPEC = """
name: engine
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 1}
drive: {cam_per_crank: 0.5}
sweep:
  engine_speed: [12000 rpm, 19048 rev/min]
  seat: [none, 0.1 in]
"""


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    d = tmp_path_factory.mktemp("engine")
    run_study(load_study(write_spec(d, SPEC)), d / "engine.nc", scheduler="synchronous")
    return d / "engine.nc"


@pytest.fixture(scope="module")
def ds(archive):
    return xr.load_dataset(archive)


def _query(archive, *args):
    result = CliRunner().invoke(main, ["query", str(archive), *args])
    assert result.exit_code == 0, result.output
    return result.output


def test_the_archive_carries_both_speeds_and_both_angles(ds):
    """engine_speed_rpm is the cam's speed over 0.5 and crank_angle the cam angle over it,
    with CF attributes, crank_angle a coordinate of the histories. Fails on a copy that
    stores the engine's speed as the cam's (the engine then turning at 24000 rpm)."""
    assert ds.speed_rpm.values.tolist() == [6000, 6000, 9524, 9524]
    assert ds.engine_speed_rpm.values.tolist() == [12000, 12000, 19048, 19048]
    assert ds.engine_speed_rpm.attrs["units"] == "rpm"
    assert ds.crank_angle.dims == ("cam_angle",) and ds.crank_angle.attrs["units"] == "degree"
    assert ds.crank_angle.attrs["cam_per_crank"] == 0.5
    assert_allclose(ds.crank_angle.values, 2 * ds.cam_angle.values, rtol=0)
    assert "crank_angle" in ds.valve_lift.coords and "engine_speed_rpm" in ds.valve_lift.coords


def test_where_reads_either_speed_and_the_summary_says_which(archive):
    """--where on engine_speed_rpm or speed_rpm (rev/min too) selects the same cases; the
    summary's onset names the cam speed and gives the engine's beside it, as its speed axis
    does. Fails on a copy whose onset groups the cases by engine speed (every group one
    speed: no onset), or lists the axis in cam rpm alone."""
    by_engine = _query(archive, "--where", "engine_speed_rpm > 15000 rpm", "--columns", "case")
    by_cam = _query(archive, "--where", "speed_rpm >= 9524 rev/min", "--columns", "case")
    assert by_engine == by_cam and "(2 of 4 cases)" in by_engine
    summary = _query(archive, "--summary")
    assert "separation onset (first cam speed with" in summary
    axis = next(line for line in summary.splitlines() if line.strip().startswith("speed_rpm"))
    assert axis.endswith("12000, 19048 rpm") and "rpm (the cam's); engine " in axis
    lines = summary.splitlines()
    head = next(i for i, line in enumerate(lines) if "onset_rpm" in line)
    assert lines[head].split() == ["seat", "[in]", "onset_rpm", "onset_engine_rpm"]
    assert lines[head + 1].split() == ["none", "9524", "19048"]


def test_histories_against_crank_angle_over_a_range(ds):
    """--angle crank draws the crank angle (twice the cam's), --range 100:400 only its
    samples there (and the events there); the cases are labelled by engine speed. Fails on a
    copy that ignores the range or draws cam degrees under a crank label."""
    request = check_plot(
        {"kind": "histories", "angle": "crank", "range": "100:400", "where": "seat is none"}
    )
    fig = figure(ds, request)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert axes[-1].get_xlabel() == "Crank angle [deg]"
    lines = [line for line in axes[0].get_lines() if line.get_gid() != "kinematic"]
    assert [line.get_label() for line in lines] == ["engine 12000 rpm", "engine 19048 rpm"]
    crank = 2 * ds.cam_angle.values
    inside = (crank >= 100) & (crank <= 400)
    assert_allclose(lines[0].get_xdata(), crank[inside], rtol=0)
    row = int(np.flatnonzero((ds.speed_rpm.values == 6000) & np.isinf(ds.seat.values))[0])
    assert_allclose(lines[0].get_ydata(), ds.valve_lift.values[row][inside] / INCH, rtol=1e-12)
    for ax in axes:
        for marks in ax.collections:
            x = marks.get_offsets()[:, 0]
            assert ((x >= 100 - 1e-9) & (x <= 400 + 1e-9)).all()


def test_events_chart_on_the_crank_angle_and_refusals(ds, small_archive):
    """The events chart reads the crank angle too; --angle crank without a drive, a range
    holding no sample and a range that is not LO < HI are refused at their option."""
    fig = figure(ds, PlotRequest("events", angle="crank"))
    ax = fig.axes[0]
    assert ax.get_xlabel() == "Crank angle [deg]" and ax.get_xlim() == (0.0, 720.0)
    with xr.open_dataset(small_archive.archive) as small:
        with pytest.raises(PlotError, match="no crank angle"):
            figure(small, PlotRequest("histories", angle="crank", where="speed_rpm == 6000"))
    with pytest.raises(PlotError, match="holds 0 of the samples"):
        figure(ds, PlotRequest("events", angle="crank", range=(800.0, 900.0)))
    for bad in ("400:100", "a:b", "100"):
        with pytest.raises(PlotError, match="LO:HI"):
            check_plot({"kind": "histories", "range": bad})


def test_the_seat_is_a_band_under_its_valve_lift(ds):
    """Each distinct seat of the cases drawn is a hatched band whose top is the seat's
    valve lift (0.1 in, in the spec's units), labelled seat once; no band without a seat.
    Fails on a copy that draws the seat at the cam's lift or in another unit."""
    fig = figure(ds, PlotRequest("histories", where="speed_rpm == 6000"))
    ax = fig.axes[0]
    bands = [p for p in ax.patches if isinstance(p, Rectangle) and p.get_label() == "seat"]
    assert len(bands) == 1
    top = bands[0].get_y() + bands[0].get_height()
    assert top == pytest.approx(0.1, rel=1e-12)
    assert "seat" in [t.get_text() for t in fig.legends[0].get_texts()]
    none = figure(ds, PlotRequest("histories", where="seat is none"))
    assert not [p for p in none.axes[0].patches if p.get_label() == "seat"]


def test_metric_against_engine_speed_with_limit_lines(ds):
    """--x engine_speed_rpm draws one line per seat (not one per speed), limit lines at a
    number and at a quantity converted to y's shown units. Fails on a copy that groups by
    the cam speed beside the engine's, or draws a quantity's number unconverted."""
    request = check_plot(
        {
            "kind": "metric",
            "x": "engine_speed_rpm",
            "y": "max_cam_force",
            "units": "si",
            "limit": [5000, "1000 lbf"],
        }
    )
    fig = figure(ds, request)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "Engine speed [rpm]"
    lines = [line for line in ax.get_lines() if not str(line.get_gid()).startswith("limit")]
    assert [line.get_label() for line in lines] == ["seat none", "seat 0.00254 m"]
    assert lines[0].get_xdata().tolist() == [12000, 19048]
    limits = {line.get_gid(): line.get_ydata()[0] for line in ax.get_lines()}
    assert limits["limit-0"] == 5000
    assert limits["limit-1"] == pytest.approx(1000 * 4.4482216152605, rel=1e-12)
    with pytest.raises(PlotError, match="--limit"):
        figure(ds, PlotRequest("metric", y="max_cam_force", limit=("3 in",)))
    # without --x a drive's metric is drawn against the engine's speed, as its cases are named
    default = figure(ds, check_plot({"kind": "metric", "y": "max_cam_force"})).axes[0]
    assert default.get_xlabel() == "Engine speed [rpm]"


def test_the_kinematic_lift_is_the_cam_s_times_the_rocker_ratio_floored_at_the_seat(ds):
    """The valve-lift panel overlays a rigid train's lift once per distinct curve: the cam's
    lift × 1.5 (the thesis rocker's ratio, campipe.model.lash_ratio) without a seat, and no
    lower than 0.1 in with one; close to the dynamic lift at 6000 rpm where the follower
    stays on the cam. Fails on a copy that overlays the cam's lift itself (ratio 1) or
    ignores the seat."""
    fig = figure(ds, PlotRequest("histories", where="speed_rpm == 6000"))
    ax = fig.axes[0]
    kinematic = [line for line in ax.get_lines() if line.get_gid() == "kinematic"]
    assert len(kinematic) == 2 and kinematic[0].get_label() == "kinematic lift"
    row = int(np.flatnonzero((ds.speed_rpm.values == 6000) & np.isinf(ds.seat.values))[0])
    cam = ds.cam_lift.values[row] / INCH
    assert_allclose(kinematic[0].get_ydata(), 1.5 * cam, rtol=1e-9)
    assert_allclose(kinematic[1].get_ydata(), np.maximum(1.5 * cam, 0.1), rtol=1e-9)
    dynamic = ds.valve_lift.values[row] / INCH
    assert np.abs(dynamic - 1.5 * cam).max() < 0.02  # in: the elastic train's give


def test_export_and_onset_give_the_crank_angle_and_the_engine_speed(archive, tmp_path):
    """campipe export writes crank_angle [deg] beside cam_angle (twice it); campipe onset
    gives the onset at the engine's speed beside the cam's (twice it) and says which is
    which. Fails on a copy that writes the cam's numbers under the engine's name."""
    import csv

    out = tmp_path / "e.csv"
    result = CliRunner().invoke(
        main, ["export", str(archive), "--where", "speed_rpm == 6000 and seat is none", "-o", out]
    )
    assert result.exit_code == 0, result.output
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][:4] == ["case", "cam_angle [deg]", "crank_angle [deg]", "time [s]"]
    assert all(float(r[2]) == 2 * float(r[1]) for r in rows[1:])
    spec = write_spec(tmp_path, SPEC.replace("seat: [none, 0.1 in]", "seat: [none]"))
    result = CliRunner().invoke(main, ["onset", str(spec), "-o", str(tmp_path / "o.nc")])
    assert result.exit_code == 0, result.output
    assert "onset_engine_speed_rpm the engine's" in result.output
    lines = result.output.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("onset_speed_rpm"))
    assert lines[head].split()[:2] == ["onset_speed_rpm", "onset_engine_speed_rpm"]
    cam, engine = (float(v) for v in lines[head + 2].split()[:2])
    assert 6000 < cam < 9524 and engine == pytest.approx(2 * cam, rel=1e-5)


def test_mm_degca_gives_velocities_per_degree_of_crank_angle(archive, ds, small_archive, tmp_path):
    """``--units mm-degca``: velocities and accelerations per degree of crank angle at each
    case's engine speed. Checked against the lift itself: the exported valve velocity
    [mm/degCA] integrated over the exported crank angle (trapezoids, 1° of cam, 2° of crank)
    is the valve lift's change to 0.5 % of the lift (per cam degree it would be twice it, as
    a designer found integrating mm/deg over the crank angle); the query's seating velocity
    in mm/degCA is its m/s over the engine's degrees a second. An archive without a drive is
    refused naming the units and the fix. Broken copy: the conversion at the cam's speed."""
    case = str(ds.case.values[1])  # 6000 rpm cam speed, the seat at 0.1 in
    out = tmp_path / "ca.csv"
    result = CliRunner().invoke(
        main, ["export", str(archive), "--case", case, "--units", "mm-degca", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    import csv

    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    head, body = rows[0], np.array(rows[1:])
    crank = body[:, head.index("crank_angle [deg]")].astype(float)
    lift = body[:, head.index("valve_lift [mm]")].astype(float)
    velocity = body[:, head.index("valve_velocity [mm/degCA]")].astype(float)
    integral = np.concatenate(
        [[0.0], np.cumsum(np.diff(crank) * 0.5 * (velocity[1:] + velocity[:-1]))]
    )
    assert np.abs(integral - (lift - lift[0])).max() < 5e-3 * lift.max()
    table = _query(archive, "--units", "mm-degca", "--columns", "max_seating_velocity")
    assert "[mm/degCA]" in table
    cells = [line.split()[-1] for line in table.splitlines()[2:6]]
    seated = ds.seat_impacts.values > 0  # a case without a seat impact has none
    assert [c == "none" for c in cells] == list(~seated)
    shown = np.array([float(c) for c in np.array(cells)[seated]])
    engine_deg_per_s = ds.engine_speed_rpm.values[seated] * 6.0
    expected = ds.max_seating_velocity.values[seated] * 1e3 / engine_deg_per_s
    assert_allclose(shown, expected, rtol=1e-6)
    # the speed columns the conversions read are the archive's (units sits below the study
    # layer and names them itself)
    assert {degree_speed(["mm/degCA"]), degree_speed(["mm/deg"])} <= set(ds.variables)
    refused = CliRunner().invoke(main, ["query", str(small_archive.archive), "--units", "mm-degca"])
    assert refused.exit_code != 0
    assert "engine speed (engine_speed_rpm)" in refused.output and "drive" in refused.output
