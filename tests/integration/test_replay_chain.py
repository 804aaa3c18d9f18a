"""`campipe replay` of a chain of masses (a finger follower's, in valve-side coordinates):
boxes and springs on the turning cam, each box where the archive's q puts it."""

import numpy as np
import xarray as xr
from click.testing import CliRunner
from numpy.testing import assert_allclose
from study_helpers import STUDIES

from campipe.cli import main
from campipe.io.rerun_replay import read_recording

BOX_PITCH = 0.020  # a box (8 mm) and a link (12 mm): the drawing's spacing [m]


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_finger_follower_replays_as_boxes_and_springs(tmp_path):
    """At ×1 the cam's mass's box stands on the cam at its displacement x1 = −q1 and the
    valve's box 20 mm above at x2 = q7 (the archive's q, read here), and the valve spring
    runs from the valve's box to a fixed plate; at ×10 the valve's box is the rigid chain's
    (the kinematic lift, or the seat where it holds) plus ten times the deviation. Fails on a
    copy that draws the chain with the thesis's rocker (q4, a placeholder) or reads q1 as
    positive along the lift."""
    archive = tmp_path / "ff.nc"
    out = invoke(
        "study", STUDIES / "finger-follower.yaml", "-o", archive,
        "--set", "run.revolutions=2", "--set", "sweep.speed=[2000 rpm, 6000 rpm]",
        "--set", "run.record=[q]", "--scheduler", "synchronous", "--no-progress",
    )  # fmt: skip
    assert out.exit_code == 0, out.output
    ds = xr.load_dataset(archive)
    row = int(np.argmax(ds["speed_rpm"].values))  # 6000 rpm: it leaves the cam
    case = ds["case"].values[row]
    q = ds["q"].values[row]
    x1, x2 = -q[:, 0], q[:, 6]
    for magnify in (1, 10):
        rrd = tmp_path / f"ff-{magnify}.rrd"
        out = invoke("replay", archive, "--case", case, "-o", rrd, "--magnify", magnify)
        assert out.exit_code == 0, out.output
        rec = read_recording(rrd)
        root = f"cases/{case}/sketch"
        assert {"mass_1", "mass_2", "link_1", "spring"} <= {
            k.removeprefix(root + "/") for k in rec if k.startswith(root)
        }
        bottoms = [
            np.array([min(p[1] for p in s[0]) for s in rec[f"{root}/{m}"].columns[
                "LineStrips2D:strips"]]) / 1000
            for m in ("mass_1", "mass_2")
        ]  # fmt: skip
        if magnify == 1:
            assert_allclose(bottoms[0], x1, atol=1e-7)  # float32 millimetres
            assert_allclose(bottoms[1], BOX_PITCH + x2, atol=1e-7)
            spring = rec[f"{root}/spring"].columns["LineStrips2D:strips"]
            tops = np.array([s[0][-1][1] for s in spring]) / 1000
            assert_allclose(tops, 2 * BOX_PITCH, atol=1e-7)  # the fixed plate
        else:
            lift = ds["cam_lift"].values[row]
            seat = float(np.median(x2 - ds["valve_lift"].values[row]))  # x2 on the seat
            rigid = np.maximum(lift, seat)
            state = ds["contact_state"].values[row]
            expected = np.where(
                np.isin(state, [3, 4]), x2, np.maximum(rigid + 10 * (x2 - rigid), seat)
            )
            assert_allclose(bottoms[1], BOX_PITCH + expected, atol=1e-6)
