"""Every script in examples/ runs on a small archive, writes its PNG and draws what it says."""

import importlib.util
import subprocess
import sys

import matplotlib.pyplot as plt
import numpy as np
import pytest
import xarray as xr
from numpy.testing import assert_allclose
from study_helpers import INCH, ROOT

from campipe.study.query.tables import case_table, onset_table

EXAMPLES = ROOT / "examples"
SPEEDS = [6000.0, 9000.0, 9524.0, 11000.0]


@pytest.fixture
def archive(quickstart_archive):
    """The session's quickstart archive (conftest.py): 4 speeds × (no seat, seat at 0.1 in)."""
    return quickstart_archive


@pytest.fixture
def example(monkeypatch):
    """Import an example script by name (its folder on the path, as when it runs)."""
    monkeypatch.syspath_prepend(str(EXAMPLES))

    def load(name):
        spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    yield load
    plt.close("all")


def _png(path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_separation_against_speed_draws_a_line_per_seat(archive, example, tmp_path):
    out = tmp_path / "separation.png"
    fig = example("separation_vs_speed").main([str(archive), "-o", str(out)])
    _png(out)
    lines = fig.axes[0].get_lines()
    assert [line.get_label() for line in lines] == ["seat none", f"seat {0.1 * INCH:g} m"]
    ds = xr.load_dataset(archive)
    for line, no_seat in zip(lines, (True, False), strict=True):
        cases = np.flatnonzero(np.isneginf(ds.seat.values) == no_seat)
        cases = cases[np.argsort(ds.speed_rpm.values[cases])]
        assert line.get_xdata().tolist() == SPEEDS
        assert_allclose(line.get_ydata(), ds.separation_deg_per_rev.values[cases])
    # no seat: in contact at 9000 rpm after the first turn; off the cam at 9524 rpm
    assert lines[0].get_ydata()[1] == 0 and 45 <= lines[0].get_ydata()[2] <= 60


def test_valve_lift_overlays_the_chosen_cases(archive, example, tmp_path):
    module = example("valve_lift")
    out = tmp_path / "lift.png"
    fig = module.main([str(archive), "--where", "speed_rpm == 11000", "-o", str(out)])
    _png(out)
    lines = fig.axes[0].get_lines()
    assert [line.get_label() for line in lines] == ["11000 rpm, no seat", "11000 rpm, seat 2.54 mm"]
    ds = xr.load_dataset(archive)
    chosen = np.flatnonzero(ds.speed_rpm.values == 11000)
    for line, i in zip(lines, chosen, strict=True):
        assert_allclose(line.get_xdata(), ds.cam_angle.values)
        assert_allclose(line.get_ydata(), ds.valve_lift.values[i] * 1e3)
    everything = module.main([str(archive), "-o", str(tmp_path / "all.png")])
    assert len(everything.axes[0].get_lines()) == ds.sizes["case"] == 8
    with pytest.raises(SystemExit) as exc:
        module.main([str(archive), "--where", "speed_rpm > 20000", "-o", str(out)])
    assert exc.value.code == 2


def test_onset_speed_agrees_with_campipe_query(archive, example, tmp_path):
    out = tmp_path / "onset.png"
    fig = example("onset_speed").main([str(archive), "-o", str(out)])
    _png(out)
    lines = fig.axes[0].get_lines()
    # One marker per seat: the onset without a seat, "at or below" the lowest speed with it.
    assert [line.get_ydata().tolist() for line in lines] == [[9524.0], [6000.0]]
    assert [line.get_marker() for line in lines] == ["o", "v"]
    assert [line.get_label() for line in lines] == ["9524 rpm", "at or below 6000 rpm"]
    # campipe query --summary, computed by campipe's own code
    rows = onset_table(case_table(xr.load_dataset(archive)))[1:]
    assert [r.split(None, 1)[1] for r in rows] == ["9524", "at or below 6000"]


def test_an_example_runs_as_a_script(archive, tmp_path):
    """As the README gives it: ``python examples/onset_speed.py ARCHIVE -o PNG`` (it imports its
    sibling ``separation_vs_speed``)."""
    out = tmp_path / "onset.png"
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "onset_speed.py"), str(archive), "-o", str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.splitlines() == [
        "seat none: 9524 rpm",
        f"seat {0.1 * INCH:g} m: at or below 6000 rpm",
        str(out),
    ]
    _png(out)
