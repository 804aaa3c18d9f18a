"""campipe plot: each kind drawn from a small study, inspected as a matplotlib figure (its
lines, cells, labels and units), written as PNG, SVG or PDF; and a spec's plots: list."""

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from matplotlib.collections import PathCollection, QuadMesh
from matplotlib.contour import ContourSet
from matplotlib.image import imread
from numpy.testing import assert_allclose
from study_helpers import INCH, LBF, write_spec

from campipe.cli import main
from campipe.cli.base import UNIT_SYSTEMS
from campipe.cli.plot import PLOT_KINDS
from campipe.plot import plot_archive
from campipe.plot.figures import figure
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.study.spec.plots import KINDS, SYSTEMS, PlotError, PlotRequest
from campipe.vocabulary import CAM_IMPACT, CAM_SEPARATION, SEAT_IMPACT, SEAT_SEPARATION

SPEC = """
name: small-map
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 2, output_every: 2 deg}
sweep:
  speed: [6000 rpm, 9524 rpm, 11000 rpm]
  seat: [none, 0.1 in]
  model.spring_preload: [120 lbf, 180 lbf]
"""
SPEEDS = [6000.0, 9524.0, 11000.0]


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    d = tmp_path_factory.mktemp("plot")
    run_study(load_study(write_spec(d, SPEC)), d / "small-map.nc", scheduler="synchronous")
    return d / "small-map.nc"


@pytest.fixture(scope="module")
def ds(archive):
    return xr.load_dataset(archive)


def _not_blank(path):
    """The PNG's pixels: not all one colour, and a fair share not white."""
    pixels = imread(path)[..., :3]
    assert pixels.std() > 0.05
    assert (pixels.sum(axis=-1) < 2.9).mean() > 0.02


def _rows(ds, **values):
    keep = np.ones(ds.sizes["case"], bool)
    for name, v in values.items():
        keep &= np.isclose(ds[name].values, v) | (ds[name].values == v)
    return np.flatnonzero(keep)


def test_histories_overlay_the_chosen_cases_one_panel_each(archive, ds, tmp_path):
    where = "spring_preload == 120 lbf and speed_rpm >= 9524"
    path, fig = plot_archive(
        archive, PlotRequest("histories", where=where), tmp_path / "histories.png"
    )
    _not_blank(path)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in axes] == [
        "valve lift",
        "valve velocity",
        "valve acceleration",
        "follower lift (cam lift dotted)",
        "cam contact force",
        "seat contact force",
    ]
    assert [ax.get_ylabel() for ax in axes] == [
        "Valve lift [in]",
        "Valve velocity [in/s]",
        "Valve acceleration [in/s^2]",
        "Follower lift [in]",
        "Cam force [lbf]",
        "Seat force [lbf]",
    ]
    assert axes[-1].get_xlabel() == "Cam angle [deg]"
    assert "small-map: histories" in fig.get_suptitle()
    rows = _rows(ds, spring_preload=120 * LBF)
    rows = rows[ds.speed_rpm.values[rows] >= 9524]
    labels = ["9524 rpm, seat none", "9524 rpm, seat 0.1 in"]
    labels += ["11000 rpm, seat none", "11000 rpm, seat 0.1 in"]
    lift = [line for line in axes[0].get_lines() if line.get_gid() != "kinematic"]
    assert [line.get_label() for line in lift] == labels
    for line, r in zip(lift, rows, strict=True):
        assert_allclose(line.get_xdata(), ds.cam_angle.values)
        assert_allclose(line.get_ydata(), ds.valve_lift.values[r] / INCH, rtol=1e-12)
    # the follower panel: the cam once (one cam for all cases), then the four followers
    follower = axes[3].get_lines()
    assert len(follower) == 5 and follower[0].get_label() == "cam lift"
    # in grey: every case its own line style and marker, not only its shade
    assert len({(line.get_linestyle(), line.get_marker()) for line in lift}) == 4
    # events: seat events on the valve's line, cam events on the follower's
    kinds = ds.event_kind.values
    case = ds.event_case.values
    for ax, wanted in (
        (axes[0], (SEAT_SEPARATION, SEAT_IMPACT)),
        (axes[3], (CAM_SEPARATION, CAM_IMPACT)),
    ):
        marked = sum(len(c.get_offsets()) for c in ax.collections if isinstance(c, PathCollection))
        expected = (np.isin(case, rows) & np.isin(kinds, wanted)).sum()
        assert marked == expected > 0
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend[:4] == labels and {"seat impact", "cam impact"} <= set(legend)


def test_histories_of_one_turn_and_in_si(archive, ds):
    fig = figure(
        ds,
        PlotRequest(
            "histories",
            where="speed_rpm == 6000 rpm and spring_preload < 150 lbf",
            units="si",
            turn="last",
        ),
    )
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert axes[0].get_ylabel() == "Valve lift [m]" and axes[4].get_ylabel() == "Cam force [N]"
    # turn 2 of 2 drawn on 0–360° (issue 37: not at 360–720°), its values the archive's
    # samples at 360–720°
    x = axes[0].get_lines()[0].get_xdata()
    cases = [line for line in axes[0].get_lines() if line.get_gid() != "kinematic"]
    assert x[0] == 0 and x[-1] == 360 and len(cases) == 2
    assert "turn 2" in fig.get_suptitle()
    i = np.flatnonzero(
        (ds.speed_rpm.values == 6000) & (ds.spring_preload.values < 150 * 4.4482216152605)
    )[0]
    lift = ds.valve_lift.values[i][(ds.cam_angle.values >= 360) & (ds.cam_angle.values <= 720)]
    assert np.array_equal(axes[0].get_lines()[0].get_ydata(), lift)


def test_histories_in_mm_deg_are_per_degree_at_each_case_s_speed(ds):
    """--units mm-deg: lift in mm, velocity in mm/deg and acceleration in mm/deg² of cam
    angle, each case's line at its own cam speed (issue 37). Fails on a copy that converts
    every case at one speed or leaves velocity per second."""
    where = "spring_preload == 120 lbf and seat is none and speed_rpm >= 9524"
    fig = figure(ds, PlotRequest("histories", where=where, units="mm-deg"))
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_ylabel() for ax in axes[:3]] == [
        "Valve lift [mm]",
        "Valve velocity [mm/deg]",
        "Valve acceleration [mm/deg^2]",
    ]
    rows = _rows(ds, spring_preload=120 * LBF, seat=-np.inf)
    rows = rows[ds.speed_rpm.values[rows] >= 9524]
    for k, r in enumerate(rows):
        w = ds.speed_rpm.values[r] * 6.0  # deg/s
        v = axes[1].get_lines()[k].get_ydata()
        a = axes[2].get_lines()[k].get_ydata()
        assert_allclose(v, ds.valve_velocity.values[r] * 1000 / w, rtol=1e-12)
        assert_allclose(a, ds.valve_acceleration.values[r] * 1000 / w**2, rtol=1e-12)
    # each speed its own factor: the two velocity traces' peaks differ by more than rounding
    peaks = [np.abs(line.get_ydata()).max() for line in axes[1].get_lines()]
    assert abs(peaks[0] - peaks[1]) > 1e-3


def test_metric_draws_a_line_per_combination_of_the_other_axes(archive, ds, tmp_path):
    path, fig = plot_archive(archive, PlotRequest("metric"), tmp_path / "metric.png")
    _not_blank(path)
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert len(lines) == 4  # seat × preload
    assert [line.get_label() for line in lines] == [
        "seat none, spring_preload 120 lbf",
        "seat none, spring_preload 180 lbf",
        "seat 0.1 in, spring_preload 120 lbf",
        "seat 0.1 in, spring_preload 180 lbf",
    ]
    # words with units, a mean over turns per turn (issue 37)
    assert ax.get_xlabel() == "Cam speed [rpm]"
    assert ax.get_ylabel() == "No-follow [deg/turn]"
    assert fig.get_suptitle() == "small-map: No-follow against cam speed"
    for line, (seat, preload) in zip(
        lines, [(-np.inf, 120), (-np.inf, 180), (0.1 * INCH, 120), (0.1 * INCH, 180)], strict=True
    ):
        rows = _rows(ds, seat=seat, spring_preload=preload * LBF)
        assert line.get_xdata().tolist() == SPEEDS
        assert_allclose(line.get_ydata(), ds.separation_deg_per_rev.values[rows])
    # no seat, 120 lbf: on the cam at 6000 rpm, off it at 11000 rpm
    assert lines[0].get_ydata()[0] == 0 and lines[0].get_ydata()[2] > 50


def test_metric_seating_velocity_against_speed_in_chosen_units(ds):
    fig = figure(
        ds,
        PlotRequest("metric", y="max_seating_velocity", where="seat is not none", units="si"),
    )
    ax = fig.axes[0]
    assert ax.get_ylabel() == "Seating velocity [m/s]"
    assert [line.get_label() for line in ax.get_lines()] == [
        "spring_preload 533.787 N",
        "spring_preload 800.68 N",
    ]
    rows = _rows(ds, seat=0.1 * INCH, spring_preload=120 * LBF)
    assert_allclose(ax.get_lines()[0].get_ydata(), ds.max_seating_velocity.values[rows])


def test_metric_of_one_case_is_its_point_at_its_speed(ds):
    """A selection of one case (a sweep's spec run for one case, its plots: drawn as the
    study ends) is its point at its speed (campipe before: refused, "no numeric column
    varies", and `campipe study` exited with an error after writing the archive)."""
    where = "speed_rpm == 9524 rpm and seat is none and spring_preload == 120 lbf"
    fig = figure(ds, PlotRequest("metric", where=where))
    (line,) = fig.axes[0].get_lines()
    assert fig.axes[0].get_xlabel() == "Cam speed [rpm]"
    assert line.get_xdata().tolist() == [9524.0]
    assert_allclose(line.get_ydata(), ds.separation_deg_per_rev.values[_rows(
        ds, speed_rpm=9524.0, seat=-np.inf, spring_preload=120 * LBF)])  # fmt: skip


def test_map_colours_one_cell_per_case_with_its_contour(archive, ds, tmp_path):
    request = PlotRequest("map", x="speed_rpm", y="spring_preload", level="1 deg")
    path, fig = plot_archive(archive, request, tmp_path / "map.png")
    _not_blank(path)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["seat none", "seat 0.1 in"]
    for ax, seat in zip(panels, (-np.inf, 0.1 * INCH), strict=True):
        (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
        cells = mesh.get_array()
        assert cells.size == 3 * 2  # speeds × preloads
        rows = _rows(ds, seat=seat)
        expected = ds.separation_deg_per_rev.values[rows]  # speed outer, preload inner
        assert_allclose(np.asarray(cells).reshape(2, 3), expected.reshape(3, 2).T)
        assert ax.get_xlabel() == "Cam speed [rpm]" and ax.get_ylabel() == "Spring preload [lbf]"
    # without a seat the follower leaves the cam between 6000 and 9524 rpm: a contour there
    contours = [c for c in panels[0].get_children() if isinstance(c, ContourSet)]
    assert len(contours) == 1 and list(contours[0].levels) == [1.0]
    colorbar = fig.axes[-1]
    assert colorbar.get_ylabel() == "No-follow [deg/turn]"
    assert "contour at 1 degree" in fig.get_suptitle()


def test_events_put_each_case_on_a_row(archive, ds, tmp_path):
    where = "spring_preload == 120 lbf"
    path, fig = plot_archive(archive, PlotRequest("events", where=where), tmp_path / "ev.png")
    _not_blank(path)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == [f"{s:g} rpm, seat {seat}" for s in SPEEDS for seat in ("none", "0.1 in")]
    rows = _rows(ds, spring_preload=120 * LBF)
    kinds = ds.event_kind.values[np.isin(ds.event_case.values, rows)]
    marks = {c.get_label(): len(c.get_offsets()) for c in ax.collections}
    names = {1: "cam separation", 2: "cam impact", 3: "seat separation", 4: "seat impact"}
    assert marks == {names[k]: int((kinds == k).sum()) for k in np.unique(kinds)}
    # each mark sits on its case's row at its cam angle
    impacts = next(c for c in ax.collections if c.get_label() == "seat impact")
    y = impacts.get_offsets()[:, 1].astype(int)
    assert set(y) == {1, 3, 5}  # the rows with a seat
    assert ax.get_xlabel() == "Cam angle [deg]"


def test_every_format_by_its_suffix_and_errors_by_their_option(archive, tmp_path):
    runner = CliRunner()
    for suffix, magic in ((".svg", b"<?xml"), (".pdf", b"%PDF"), (".png", b"\x89PNG")):
        out = tmp_path / f"metric{suffix}"
        result = runner.invoke(main, ["plot", "metric", str(archive), "-o", str(out)])
        assert result.exit_code == 0, result.output
        assert result.output.strip() == str(out) and out.read_bytes().startswith(magic)
    bad = [
        (["plot", "metric", str(archive), "-o", str(tmp_path / "x.jpg")], "--output"),
        (["plot", "metric", str(archive), "--y", "separation"], "--y: unknown column"),
        (["plot", "histories", str(archive)], "selects 12 cases; overlay at most 10"),
        (["plot", "events", str(archive), "--where", "speed_rpm > 20000"], "selects none"),
        (["plot", "map", str(archive), "--level", "1 in"], "--level"),
        (["plot", "metric", str(archive), "--x", "seat"], "--x: seat holds none"),
        (["plot", "histories", str(archive), "--turn", "0"], "--turn"),
    ]
    for args, words in bad[1:]:
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert words in result.output and "Traceback" not in result.output
    result = runner.invoke(main, bad[0][0])
    assert result.exit_code == 2 and "expected a file ending in .png, .svg, .pdf" in result.output
    text = tmp_path / "notes.nc"
    text.write_text("not netCDF")
    result = runner.invoke(main, ["plot", "metric", str(text)])
    assert result.exit_code == 2 and f"{text}: not a netCDF file" in result.output
    query = runner.invoke(main, ["query", str(text)])
    assert query.exit_code == 2 and f"{text}: not a netCDF file" in query.output
    older = xr.load_dataset(archive).rename({"case": "case_id"})
    older.attrs["campipe_layout"] = "campipe-archive-2"
    older.to_netcdf(tmp_path / "older.nc")
    result = runner.invoke(main, ["plot", "metric", str(tmp_path / "older.nc")])
    assert result.exit_code == 2 and "another layout (campipe-archive-2)" in result.output
    assert "--overwrite" in result.output and "Traceback" not in result.output


def test_the_command_line_lists_every_kind_and_unit_system():
    assert PLOT_KINDS == tuple(KINDS) and UNIT_SYSTEMS == SYSTEMS


def test_a_spec_writes_its_plots_beside_the_archive(tmp_path):
    spec = write_spec(
        tmp_path,
        SPEC.replace("[6000 rpm, 9524 rpm, 11000 rpm]", "[6000 rpm, 11000 rpm]")
        + """
plots:
  - {kind: metric}
  - {kind: metric, y: max_cam_force, output: force.svg}
  - {kind: events, where: "seat is none", turn: last}
""",
    )
    result = CliRunner().invoke(main, ["study", str(spec), "--no-progress"])
    assert result.exit_code == 0, result.output
    written = sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".png", ".svg"))
    assert written == ["force.svg", "small-map-events.png", "small-map-metric.png"]
    assert "plots[2] (events) written to" in result.stderr
    _not_blank(tmp_path / "small-map-metric.png")


@pytest.mark.parametrize(
    ("entry", "path", "words"),
    [
        ("{kind: metrc}", "plots[0].kind", "did you mean 'metric'"),
        ("{kind: metric, z: a}", "plots[0].z", "not a key of a metric plot (a key of map plots)"),
        ("{kind: metric, y: sepration_deg_per_rev}", "plots[0].y", "unknown column"),
        ("{kind: map, output: m.jpg}", "plots[0].output", "expected a file ending in .png"),
        ('{kind: events, where: "seat > 0.00254"}', "plots[0].where", "write the number with"),
        ("{kind: histories, turn: first}", "plots[0].turn", "expected a turn"),
    ],
)
def test_a_spec_with_a_bad_plot_is_refused_at_its_key(tmp_path, entry, path, words):
    spec = write_spec(tmp_path, SPEC + f"plots:\n  - {entry}\n")
    result = CliRunner().invoke(main, ["validate", str(spec), "--no-estimate"])
    assert result.exit_code == 2
    assert f"{path}: " in result.output and words in result.output, result.output


@pytest.mark.parametrize(
    ("entry", "words"),
    [
        ("{kind: histories, turn: 99}", "plots[0].turn: found 99, but the study's histories "),
        ("{kind: events, turn: 3}", "plots[0].turn: found 3, but the study's histories cover 2"),
        (
            "{kind: map, x: speed_rpm, y: seat, level: 1 kg}",
            "plots[0].level: cannot read '1 kg' as a level of separation_deg_per_rev [degree]",
        ),
        (
            "{kind: map, x: speed_rpm, y: seat, z: max_cam_force, level: 1 deg}",
            "plots[0].level: cannot read '1 deg' as a level of max_cam_force [N]",
        ),
    ],
)
def test_plot_options_drawing_would_refuse_are_refused_before_the_run(tmp_path, entry, words):
    """validate and study refuse a turn past the run's turns and a level of another
    dimension than z's, naming the key, before anything runs: no archive written. Broken
    copy, check_spec_plots: not called by study: the archive is written, then the figure
    fails (exit status 2 after the run)."""
    spec = write_spec(tmp_path, SPEC + f"plots:\n  - {entry}\n")
    for command in (["validate", str(spec), "--no-estimate"], ["study", str(spec)]):
        result = CliRunner().invoke(main, command)
        assert result.exit_code == 2, result.output
        assert words in result.output and "Traceback" not in result.output
    assert not list(tmp_path.glob("*.nc"))


def test_every_plot_option_drawing_would_refuse_is_named_at_once(tmp_path):
    """Two refused plot options are both named, in the spec's problem list (its file and
    count first), and a level of another dimension says what to write, not pint's bare
    "DimensionalityError". Broken copy (a reliability helper's run): the first alone, as
    "(DimensionalityError)"."""
    plots = (
        "plots:\n  - {kind: map, x: speed_rpm, y: seat, level: 1 kg}\n  - {kind: events, turn: 3}\n"
    )
    spec = write_spec(tmp_path, SPEC + plots)
    result = CliRunner().invoke(main, ["validate", str(spec), "--no-estimate"])
    assert result.exit_code == 2, result.output
    assert f"{spec}: 2 problems" in result.output
    assert (
        "plots[0].level: cannot read '1 kg' as a level of separation_deg_per_rev [degree]: "
        "kg is not of its dimension: write it in degree" in result.output
    )
    assert "plots[1].turn: found 3" in result.output
    assert "DimensionalityError" not in result.output


def test_plot_options_within_the_run_pass_validate(tmp_path):
    """The bounds are the run's: turn 2 of two turns and a level in degrees pass."""
    entries = "  - {kind: events, turn: 2}\n  - {kind: map, x: speed_rpm, y: seat, level: 1 deg}\n"
    spec = write_spec(tmp_path, SPEC + "plots:\n" + entries)
    result = CliRunner().invoke(main, ["validate", str(spec), "--no-estimate"])
    assert result.exit_code == 0, result.output


def test_a_request_is_checked_like_a_spec_entry():
    from campipe.study.spec.plots import check_plot

    assert check_plot({"kind": "events", "turn": "2"}).turn == 2
    with pytest.raises(PlotError, match="x: not a key of a histories plot"):
        check_plot({"kind": "histories", "x": "speed_rpm"})


def test_a_title_wider_than_its_figure_wraps():
    """A one-panel map's title (6 in wide) of 100 characters is wrapped to the figure's width
    in lines of whole words, not cut off at both sides. Fails on a copy that sets it as one
    line."""
    from types import SimpleNamespace

    from matplotlib.figure import Figure

    from campipe.plot.figures import TITLE_CHARS_PER_INCH, set_title

    fig = Figure(figsize=(6, 4))
    what = "separation_deg_per_rev over engine_speed_rpm and spring_preload, contour at 1 degree"
    set_title(fig, SimpleNamespace(study="chain2"), what, None)
    lines = fig.get_suptitle().splitlines()
    assert len(lines) == 2 and all(len(line) <= 6 * TITLE_CHARS_PER_INCH for line in lines)
    assert " ".join(lines) == f"chain2: {what}"


LASH_SPEC = """
name: blash
model: {layout: direct-acting, tappet_mass: 0.045 kg, valve_mass: 0.065 kg,
        stem_stiffness: 30000 N/mm, tappet_contact_stiffness: 60000 N/mm,
        spring_rate: 35 N/mm, spring_preload: 220 N, damping_ratios: [0.05], lash: %s}
profile: {kind: polydyne-4567, lift: 9 mm, rise: 110 deg, dwell: 20 deg, fall: 110 deg,
          ramp_height: 0.3 mm, ramp_duration: 30 deg, ramp_shape: constant-velocity}
closure: force
speed: 300 rpm
run: {revolutions: 1, output_every: 1 deg}
"""


@pytest.mark.parametrize("lash", ["0.2 mm", "0.1 mm"])
def test_a_lash_train_s_kinematic_lift_takes_the_lash_off(tmp_path, lash):
    """A rigid train with lash opens its valve once the cam has taken the lash up: at a crawl
    (300 rpm) the dashed kinematic lift is the cam's lift less the lash, at least the seat,
    and the valve's lift lies under it by the chain's static give alone, at most the
    spring's largest force over the tappet's contact and the stem in series (hand: (220 N +
    35 N/mm·9 mm) / 20 N/µm = 27 µm). Broken copy: the lash left on (a valve engineer read
    0.15 mm of lash off a finger whose adjuster had taken it up; here 0.2 mm)."""
    spec = write_spec(tmp_path, LASH_SPEC % lash)
    run_study(load_study(spec), tmp_path / "blash.nc", scheduler="synchronous")
    ds = xr.load_dataset(tmp_path / "blash.nc")
    fig = figure(ds, PlotRequest("histories", units="si"))
    kinematic = [line for line in fig.axes[0].get_lines() if line.get_gid() == "kinematic"]
    assert len(kinematic) == 1
    drawn = np.asarray(kinematic[0].get_ydata(), float)
    gap = float(lash.split()[0]) * 1e-3
    assert_allclose(drawn, np.maximum(ds.cam_lift.values[0] - gap, 0.0), atol=1e-12)
    give = drawn - ds.valve_lift.values[0]
    assert give.max() < (220 + 35e3 * 9e-3) / 20e6 and give.min() > -1e-6
