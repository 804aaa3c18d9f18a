"""`campipe replay` and a study's `replay:`: rerun recordings read back with RrdReader."""

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal
from study_helpers import STUDIES

from campipe.cli import main
from campipe.io.rerun_replay import NANOS, SERIES, nanos, read_recording
from campipe.model import thesis_train
from campipe.replay import sketch

#: Two cases at 11000 rpm, two turns: no seat, and the valve seat at 0.1 in (it bounces).
STUDY = [
    "--set",
    "run.revolutions=2",
    "--set",
    "sweep.speed=[11000 rpm]",
    "--scheduler",
    "synchronous",
    "--no-progress",
]
SKETCH = {"cam", "pushrod", "rocker", "stem", "head", "spring", "retainer", "follower"}


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    """(with q and the spec's replay selection, without q): the same two cases."""
    folder = tmp_path_factory.mktemp("replay")
    with_q, without_q = folder / "with-q.nc", folder / "without-q.nc"
    out = invoke(
        "study",
        STUDIES / "quickstart.yaml",
        "-o",
        with_q,
        *STUDY,
        "--set",
        "run.record=[q]",
        "--set",
        'replay={where: "seat > 0"}',
    )
    assert out.exit_code == 0, out.output
    assert f"replay 'seat > 0' recorded in {folder / 'with-q.rrd'}" in out.stderr
    out = invoke("study", STUDIES / "quickstart.yaml", "-o", without_q, *STUDY)
    assert out.exit_code == 0, out.output
    return with_q, without_q


@pytest.fixture(scope="module")
def seated(archives):
    """The case with the seat: its archive row and its recording read back."""
    ds = xr.load_dataset(archives[0])
    row = int(np.flatnonzero(ds["seat"].values > 0)[0])
    out = invoke(
        "replay",
        archives[0],
        "--case",
        ds["case"].values[row],
        "-o",
        archives[0].with_name("seated.rrd"),
        "--units",
        "mm-deg",
    )
    assert out.exit_code == 0, out.output
    assert out.stdout.strip() == str(archives[0].with_name("seated.rrd"))
    return ds, row, read_recording(archives[0].with_name("seated.rrd"))


def test_replay_holds_every_series_exactly_at_every_cam_angle(seated):
    ds, row, rec = seated
    root = f"cases/{ds['case'].values[row]}"
    angle = ds["cam_angle"].values
    assert angle.size == 721
    for name, (path, words, units, factor, _) in SERIES.items():
        label = f"{words} [{units}]" if units else words
        e = rec[f"{root}/{path}"]
        assert e.static["SeriesLines:names"] == [label]
        # cam_angle: one nanosecond of the timeline per 1e-9 degree, the archive's own values
        assert_array_equal(e.times["cam_angle"], np.round(angle * 1e9).astype(np.int64))
        assert_array_equal(e.times["time"], nanos(ds["time"].values[row]))
        # exactly the archive's values, in the display units (mm = m × 1000, N, 1–4)
        assert_array_equal(e.scalars(), ds[name].values[row].astype(float) * factor)
    assert SERIES["valve_lift"][2] == "mm" and SERIES["valve_lift"][3] == 1000.0
    # the only timelines in the recording are the replay's own: no wall clock, no log tick
    assert {t for e in rec.values() for t in e.times} == {"cam_angle", "time"}


def test_replay_shows_the_units_query_shows(archives, tmp_path):
    """--units in-lbf: lifts in inches and forces in pounds-force, labelled so, equal to the
    archive's SI values converted by the inch and the pound-force (exact definitions, an
    independent conversion); --units si: the archive's values as stored. Broken copy: the
    series always in mm and N (the recording before --units): off by 25.4 and 4.45."""
    ds = xr.load_dataset(archives[0])
    row = int(np.flatnonzero(ds["seat"].values > 0)[0])
    case = ds["case"].values[row]
    for system, lift, force, to_lift, to_force in (
        ("in-lbf", "in", "lbf", 1 / 0.0254, 1 / 4.4482216152605),
        ("si", "m", "N", 1.0, 1.0),
    ):
        path = tmp_path / f"{system}.rrd"
        out = invoke("replay", archives[0], "--case", case, "-o", path, "--units", system)
        assert out.exit_code == 0, out.output
        rec = read_recording(path)
        valve = rec[f"cases/{case}/lift/valve"]
        assert valve.static["SeriesLines:names"] == [f"valve lift [{lift}]"]
        assert_allclose(valve.scalars(), ds["valve_lift"].values[row] * to_lift, rtol=1e-12)
        cam = rec[f"cases/{case}/force/cam"]
        assert cam.static["SeriesLines:names"] == [f"cam contact force [{force}]"]
        assert_allclose(cam.scalars(), ds["cam_force"].values[row] * to_force, rtol=1e-12)
        doc = rec[f"cases/{case}/parameters"].static["TextDocument:text"][0]
        assert f"lifts in {lift}, contact forces in {force}," in doc
        texts = [t[0] for t in rec[f"cases/{case}/events"].columns["TextLog:text"]]
        assert all(f" {lift}/s, " in t for t in texts)  # the velocities: in/s, m/s


def test_replay_holds_the_events_at_their_angles(seated):
    """Each event at its angle and time, its text in the units asked for (--units mm-deg:
    the velocity per degree of the case's cam angle, v·1000/(6·rpm) mm/deg; the impulse in
    N·s), as the parameters document says. Broken copy: the velocity always in m/s."""
    ds, row, rec = seated
    n = int(ds["event_count"].values[row])
    start = int(ds["event_count"].values[:row].sum())
    ev = ds.isel(event=slice(start, start + n))
    assert int(ds["seat_impacts"].values[row]) >= 2  # it bounces on its seat
    e = rec[f"cases/{ds['case'].values[row]}/events"]
    assert_array_equal(e.times["cam_angle"], nanos(ev["event_cam_angle"].values))
    assert_array_equal(e.times["time"], nanos(ev["event_time"].values))
    names = {1: "cam separation", 2: "cam impact", 3: "seat separation", 4: "seat impact"}
    texts = [t[0] for t in e.columns["TextLog:text"]]
    for text, kind, angle, velocity, impulse in zip(
        texts,
        ev["event_kind"].values,
        ev["event_cam_angle"].values,
        ev["event_velocity"].values,
        ev["event_impulse"].values,
        strict=True,
    ):
        assert text.startswith(f"{names[kind]} at {angle:.4f}°")
        per_degree = velocity * 1000 / (6 * ds["speed_rpm"].values[row])
        assert f"velocity {per_degree:.4g} mm/deg" in text
        assert (f"impulse {impulse:.4g} N·s" in text) == (kind in (2, 4))
    levels = [t[0] for t in e.columns["TextLog:level"]]
    assert levels == ["WARN" if k in (2, 4) else "INFO" for k in ev["event_kind"].values]
    doc = rec[f"cases/{ds['case'].values[row]}/parameters"].static["TextDocument:text"][0]
    assert "lifts in mm, contact forces in N," in doc and "jump in mm/deg" in doc


def test_replay_draws_the_mechanism_from_q(seated):
    ds, row, rec = seated
    root = f"cases/{ds['case'].values[row]}/sketch"
    assert {k.removeprefix(root + "/") for k in rec if k.startswith(root)} == (
        SKETCH
        | {"valve", "frame/seat", "frame/pivot", "frame/ground", "frame/spring_plate", "frame/note"}
    )
    geom = sketch.Geometry.from_train(thesis_train())
    q = ds["q"].values[row]
    seat_q7 = float(np.median(q[:, 6] - ds["valve_lift"].values[row]) + ds["seat"].values[row])
    qd = sketch.displayed_coordinates(
        q, ds["cam_lift"].values[row], ds["contact_state"].values[row], geom, 10.0, seat_q7
    )
    for name, strips in sketch.moving_parts(qd, geom).items():
        e = rec[f"{root}/{name}"]
        assert len(e.columns["LineStrips2D:strips"]) == 721
        drawn = np.array([s[0] for s in e.columns["LineStrips2D:strips"]])
        assert_allclose(drawn, strips * 1000, rtol=1e-6, atol=1e-4)  # float32 millimetres
    # the follower's dot: red while off the cam, and off it while the state says II or IV
    colours = np.array([c[0] for c in rec[f"{root}/follower"].columns["Points2D:colors"]])
    off = np.isin(ds["contact_state"].values[row], [2, 4])
    assert off.sum() > 100
    assert_array_equal(colours == colours[off][0], off)
    # the cam turns clockwise: its outline at 90° is the outline at 0° turned by −90°
    cam = rec[f"{root}/cam"].columns["LineStrips2D:strips"]
    c = geom.cam_centre * 1000
    p0, p90 = np.asarray(cam[0][0]) - c, np.asarray(cam[90][0]) - c
    assert_allclose(p90, p0 @ np.array([[0.0, 1.0], [-1.0, 0.0]]).T, atol=2e-4)
    doc = rec[f"cases/{ds['case'].values[row]}/parameters"].static["TextDocument:text"][0]
    assert "| speed_rpm | 11000 | rpm |" in doc and "×10" in doc


def test_blueprint_places_the_sketch_beside_the_plots(archives):
    from rerun.chunk import RrdReader

    reader = RrdReader(archives[0].with_name("seated.rrd"))
    parts = {}
    for chunk in reader.store(store=reader.blueprints()[0]).stream():
        rb = chunk.to_record_batch()
        parts[rb.schema.metadata[b"rerun:entity_path"].decode().lstrip("/")] = {
            n: rb.column(n).to_pylist()[-1] for n in rb.schema.names
        }
    views = {k: v for k, v in parts.items() if "ViewBlueprint:class_identifier" in v}
    kind = {k: v["ViewBlueprint:class_identifier"][0] for k, v in views.items()}
    origin = {k: v["ViewBlueprint:space_origin"][0] for k, v in views.items()}
    (sketch_view,) = [k for k in views if kind[k] == "2D"]
    assert origin[sketch_view].endswith("/sketch")
    (row,) = [
        v for v in parts.values() if v.get("ContainerBlueprint:contents", [""])[0] == sketch_view
    ]
    assert row["ContainerBlueprint:container_kind"] == [2]  # horizontal: side by side
    beside = parts[row["ContainerBlueprint:contents"][1]]["ContainerBlueprint:contents"]
    assert [origin[v].rsplit("/", 1)[-1] for v in beside if v in origin] == [
        "lift",
        "force",
        "contact_state",
    ]
    assert parts["time_panel"]["TimePanelBlueprint:timeline"] == ["cam_angle"]


def test_a_study_records_its_replay_selection_as_it_runs(archives):
    """The study's own recording holds the same content as `campipe replay --where`."""
    live = read_recording(archives[0].with_name("with-q.rrd"))
    out = invoke(
        "replay", archives[0], "--where", "seat > 0", "-o", archives[0].with_name("where.rrd")
    )
    assert out.exit_code == 0, out.output
    again = read_recording(archives[0].with_name("where.rrd"))
    assert len({k.split("/")[1] for k in live if k.startswith("cases/")}) == 1
    assert_same(live, again)


def test_a_study_with_nothing_to_compute_records_its_selection_from_the_archive(archives):
    """A rerun finds the archive up to date (no batch computed, no hook called); the recording
    is made again from the archive, with the same content."""
    path = archives[0].with_name("with-q.rrd")
    first = read_recording(path)
    path.unlink()
    out = invoke(
        "study",
        STUDIES / "quickstart.yaml",
        "-o",
        archives[0],
        *STUDY,
        "--set",
        "run.record=[q]",
        "--set",
        'replay={where: "seat > 0"}',
    )
    assert out.exit_code == 0, out.output
    assert "up to date" in out.stderr
    assert_same(read_recording(path), first)


def test_an_archive_without_q_replays_by_running_its_cases_again(archives, seated):
    ds, row, rec = seated
    out = invoke(
        "replay",
        archives[1],
        "--case",
        ds["case"].values[row],
        "-o",
        archives[1].with_name("rerun.rrd"),
        "--units",
        "mm-deg",
    )
    assert out.exit_code == 0, out.output
    assert_same(read_recording(archives[1].with_name("rerun.rrd")), rec)


def test_two_replays_of_an_archive_are_identical(archives):
    from rerun.chunk import RrdReader

    paths = [archives[0].with_name(f"twice-{i}.rrd") for i in range(2)]
    for path in paths:
        out = invoke("replay", archives[0], "--where", "speed_rpm == 11000", "-o", path)
        assert out.exit_code == 0, out.output
    a, b = (read_recording(p) for p in paths)
    assert len({k.split("/")[1] for k in a if k.startswith("cases/")}) == 2
    assert_same(a, b)
    ids = [RrdReader(p).recordings()[0].recording_id for p in paths]
    assert ids[0] == ids[1] and ids[0].startswith("campipe-")


def test_where_selecting_nothing_writes_nothing(archives):
    path = archives[0].with_name("nothing.rrd")
    out = invoke("replay", archives[0], "--where", "speed_rpm > 20000", "-o", path)
    assert out.exit_code == 2  # a problem with the input (docs/studies.md)
    assert (
        "--where 'speed_rpm > 20000' selects none of the archive's 2 cases; nothing "
        "written" in out.output
    )
    assert not path.exists()
    assert not list(path.parent.glob(".nothing.rrd*"))


def test_missing_archive_unknown_case_and_bad_options_are_clear_errors(archives, tmp_path):
    out = invoke("replay", tmp_path / "none.nc", "--case", "abc", "-o", tmp_path / "x.rrd")
    assert out.exit_code == 2 and f"{tmp_path / 'none.nc'}: no such archive" in out.output
    out = invoke("replay", archives[0], "--case", "0123456789abcdef", "-o", tmp_path / "x.rrd")
    assert out.exit_code == 2
    assert "--case 0123456789abcdef: no such case among the archive's 2 cases" in out.output
    out = invoke("replay", archives[0], "--where", "__import__('os')", "-o", tmp_path / "x.rrd")
    assert out.exit_code == 2 and "is not allowed" in out.output
    out = invoke("replay", archives[0], "-o", tmp_path / "x.rrd")
    assert out.exit_code == 2 and "give --case ID (repeatable) or --where EXPR" in out.output
    out = invoke("replay", archives[0], "--where", "seat > 0", "--spawn", "-o", "x.rrd")
    assert out.exit_code == 2 and "-o and --spawn exclude each other" in out.output
    missing = tmp_path / "missing" / "x.rrd"
    out = invoke("replay", archives[0], "--where", "seat > 0", "-o", missing)
    assert out.exit_code == 2 and "Traceback" not in out.output
    assert f"its folder {missing.parent} does not exist" in out.output
    assert not missing.parent.exists()
    assert not list(tmp_path.glob("*.rrd"))


def test_spawn_opens_the_viewer_with_the_blueprint_and_writes_no_file(archives, monkeypatch):
    import rerun as rr

    opened = {}

    def spawn(self, *, default_blueprint=None, **kwargs):
        opened["blueprint"] = default_blueprint
        self.memory_recording()  # instead of a viewer: keep the data in memory

    monkeypatch.setattr(rr.RecordingStream, "spawn", spawn)
    before = sorted(archives[0].parent.iterdir())
    out = invoke("replay", archives[0], "--where", "seat > 0", "--spawn")
    assert out.exit_code == 0, out.output
    assert out.stdout == "" and "campipe replay: 1 case" in out.stderr
    assert opened["blueprint"] is not None
    assert sorted(archives[0].parent.iterdir()) == before


def test_import_campipe_replay_does_not_import_rerun():
    code = (
        "import sys, campipe, campipe.cli, campipe.replay.sketch, campipe.replay.cases, "
        "campipe.replay.live; print('rerun' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def assert_same(a, b):
    """Two recordings read back hold the same entities, timelines and values."""
    assert sorted(a) == sorted(b)
    for name in a:
        x, y = a[name], b[name]
        assert x.static == y.static, name
        assert list(x.times) == list(y.times), name
        for t in x.times:
            assert_array_equal(x.times[t], y.times[t])
        assert x.columns == y.columns, name
    assert NANOS == 10**9


@pytest.mark.slow
def test_processes_scheduler_records_the_selection_from_the_archive(tmp_path):
    """Worker processes cannot log into this process's recording: the cases come from the
    finished archive instead, q computed again; in the spec's units (the quickstart writes
    inches), as campipe replay and query show it."""
    out = invoke(
        "study",
        STUDIES / "quickstart.yaml",
        "-o",
        tmp_path / "p.nc",
        *STUDY[:4],
        "--set",
        'replay={where: "seat > 0"}',
        "--scheduler",
        "processes",
        "--workers",
        "2",
        "--no-progress",
    )
    assert out.exit_code == 0, out.output
    rec = read_recording(tmp_path / "p.rrd")
    ds = xr.load_dataset(tmp_path / "p.nc")
    row = int(np.flatnonzero(ds["seat"].values > 0)[0])
    entity = rec[f"cases/{ds['case'].values[row]}/lift/valve"]
    assert entity.static["SeriesLines:names"] == ["valve lift [in]"]
    assert_allclose(entity.scalars(), ds["valve_lift"].values[row] / 0.0254, rtol=1e-12)


def test_a_replay_of_several_cases_shows_its_progress(archives, tmp_path):
    """Each step over the cases (sketching, logging) counts them on a progress line."""
    from campipe.replay.record import replay_archive
    from campipe.study.run.progress import Progress

    bars: list[tuple[str, Progress, list[str]]] = []

    def bar(total, unit):
        lines: list[str] = []
        bars.append((unit, Progress(total, lines.append, interval=0.0, unit=unit, then=""), lines))
        return bars[-1][1]

    path, cases = replay_archive(
        archives[0], where="speed_rpm > 0", output=tmp_path / "two.rrd", progress=bar
    )
    assert path == tmp_path / "two.rrd" and len(cases) == 2
    assert [(unit, b.total, b.done) for unit, b, _ in bars] == [
        ("cases sketched", 2, 2),
        ("cases logged", 2, 2),
    ]
    assert bars[1][2][-1] == "[########################] 2/2 cases logged, done\n"
