"""studies/spring-surge.yaml in a quick variant: valve-spring surge with 1, 4 and 16 spring
elements, and the spring's histories and metrics in an archive."""

import math

import numpy as np
import xarray as xr
from numpy.testing import assert_allclose, assert_array_equal
from study_helpers import INCH, LBF, STUDIES

from campipe.constants import STANDARD_GRAVITY
from campipe.engine import member_loads, run_batch
from campipe.model import spring_clash_margin, system_matrices, thesis_train
from campipe.study import load_study
from campipe.study.run.execute import run_study

SPEEDS = [2000, 8000, 9000]


def run_surge(tmp_path, **overrides):
    """The quick variant's archive and its resolved cases."""
    quick = {"run.revolutions": 2, "sweep.speed": [f"{s} rpm" for s in SPEEDS], **overrides}
    study = load_study(STUDIES / "spring-surge.yaml", quick)
    run_study(study, tmp_path / "surge.nc", scheduler="threads")
    return xr.load_dataset(tmp_path / "surge.nc"), study.cases


def alone(resolved):
    """A study case run alone through the engine, every coordinate sampled."""
    return run_batch([resolved.case], resolved.settings)


def surge_frequency(train) -> float:
    """The spring's fixed–fixed surge frequency π·√(k/m_s) [rad/s], f = (1/2)·√(k/m_s)."""
    density = train.specific_weight / STANDARD_GRAVITY
    m_s = density * math.pi * train.spring_diameter**2 / 4 * train.spring_length
    return math.pi * math.sqrt(train.spring_rate / m_s)


def test_spring_surge(tmp_path):
    """At 2000 rpm the spring force barely depends on n; at 8000 and 9000 rpm the refined
    spring surges: its peak force (n = 16: 599.7 and 695.5 lbf) far above the one-element
    spring's (517.7, 519.4 lbf), which cannot surge, and its coils clash (the margin below
    zero). n = 4 and n = 16 agree more closely than n = 1 and n = 4 (convergence in n). The
    16-element train has a mode within 3 % of the fixed–fixed surge frequency (4983 against
    4880 rad/s: q4 is not quite fixed), and the surge shows in the spring force through the
    cam harmonic nearest it."""
    ds, _ = run_surge(tmp_path)
    assert ds.sizes["case"] == 9
    cell = {
        (int(s), int(n)): i
        for i, (s, n) in enumerate(zip(ds.speed_rpm.values, ds.spring_elements.values, strict=True))
    }
    peak = ds.max_spring_force.values / LBF
    margin = ds.min_spring_clash_margin.values / INCH
    f = {k: peak[i] for k, i in cell.items()}
    assert_allclose([f[2000, 1], f[2000, 4], f[2000, 16]], 516.1, rtol=0.005)
    assert_allclose([f[9000, 1], f[9000, 4], f[9000, 16]], [519.4, 668.6, 695.5], rtol=0.005)
    assert_allclose([f[8000, 1], f[8000, 16]], [517.7, 599.7], rtol=0.005)
    for s in (8000, 9000):
        assert abs(f[s, 16] - f[s, 4]) < 0.25 * abs(f[s, 4] - f[s, 1])
        assert margin[cell[s, 1]] > 0.09 and margin[cell[s, 16]] < 0.0
    assert np.all(margin[[cell[2000, n] for n in (1, 4, 16)]] > 0.1)

    train = thesis_train().replace(spring_elements=16)
    omega = system_matrices(train).frequencies
    surge = omega[np.argmin(np.abs(omega / surge_frequency(train) - 1))]
    assert abs(surge / surge_frequency(train) - 1) < 0.03
    one = system_matrices(thesis_train()).frequencies
    assert np.min(np.abs(one / surge - 1)) > 0.5  # one element has no mode near it
    # The 345's symmetric 90/90/90/90 schedule has odd harmonics only: the 5th (4189 rad/s
    # at 8000 rpm, 4712 at 9000) is the one nearest the surge. It dominates the force the
    # refined spring adds, amplified from the cam's lift the more the nearer the surge.
    turn = (ds.cam_angle.values >= 360) & (ds.cam_angle.values < 720)
    gain = {}
    for s in (8000, 9000):
        f16, f1 = (ds.spring_force.values[cell[s, n], turn] for n in (16, 1))
        added = np.abs(np.fft.rfft(f16 - f1))[1:20]
        lift = np.abs(np.fft.rfft(ds.cam_lift.values[cell[s, 1], turn]))[1:20]
        assert np.argmax(added) + 1 == 5, (s, added)
        gain[s] = added[4] / lift[4]
    assert gain[9000] > 1.5 * gain[8000], gain


def test_one_spring_element_is_the_unrefined_run_to_the_bit(tmp_path):
    """The study's n = 1 cases, batched with 4- and 16-element springs, hold the numbers of
    the thesis train run alone through the engine; their spring force is the member load and
    their clash margin spring_clash_margin of the stored q (n = 1: all its coordinates)."""
    ds, cases = run_surge(tmp_path, **{"run.record": ["spring", "q"]})
    ones = np.flatnonzero(ds.spring_elements.values == 1)
    assert len(ones) == len(SPEEDS)
    for i in ones:
        assert cases[i].case.train == thesis_train()
        res = alone(cases[i])
        assert_array_equal(ds.valve_lift.values[i], res.valve_lift[0])
        assert_array_equal(ds.q.values[i], res.q[0])
        assert_array_equal(
            ds.spring_force.values[i], member_loads(thesis_train(), res.q[0])["spring_force"]
        )
        assert_array_equal(
            ds.spring_clash_margin.values[i], spring_clash_margin(thesis_train(), ds.q.values[i])
        )
        assert_array_equal(ds.max_spring_element_force.values[i], ds.spring_force.values[i])


def test_the_refined_cases_clash_margin_is_the_models_of_their_coordinates(tmp_path):
    """A refined case's stored clash margin and largest element force are the model's
    functions of its full coordinates (the archive's q holds q1 … q7 only), and the
    per-revolution metrics are the histories' extremes in each turn."""
    ds, cases = run_surge(tmp_path, **{"sweep.speed": ["9000 rpm"], "run.record": ["spring", "q"]})
    i = int(np.flatnonzero(ds.spring_elements.values == 16)[0])
    train = cases[i].case.train
    assert train.spring_elements == 16
    res = alone(cases[i])
    assert res.q.shape[2] == 22 and ds.sizes["dof"] == 7
    assert_array_equal(ds.q.values[i], res.q[0, :, :7])
    margin = spring_clash_margin(train, res.q[0])
    assert_array_equal(ds.spring_clash_margin.values[i], margin)
    by_rev = ds.min_spring_clash_margin_by_rev.values[i]
    angle = ds.cam_angle.values
    assert_array_equal(by_rev, [margin[angle < 360].min(), margin[angle >= 360].min()])
    assert ds.min_spring_clash_margin.values[i] == by_rev.min()
    assert ds.max_spring_force.values[i] == ds.max_spring_element_force.values[i].max()
    assert ds.max_spring_force.attrs["units"] == "N"
    assert ds.spring_clash_margin.attrs["units"] == "m"
