"""The uncertainty a never-repeating case's window means carry (``<metric>_uncertainty``, the
standard error by batch means), against independent longer runs of the same train.

The thesis train (harmonic 1 in) past the onset: at 9524 rpm with the seat at 0.1 in (the
README's quickstart case), 13000, 14000 and 15000 rpm, the response does not repeat within the
default 48 turns (``period_turns`` 0); without a seat at 9524 rpm and with it at 13000 rpm it
settles (NaN).
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import INCH, write_spec

from campipe.cli import main
from campipe.constants import RPM
from campipe.engine import Case, RunSettings, run_batch
from campipe.engine.metrics import METRICS, batch_means_error
from campipe.model import thesis_train
from campipe.profiles.shapes import harmonic
from campipe.study import load_study
from campipe.study.run.execute import run_study

SPEC = """
name: chaos
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: auto, max_revolutions: CAP}
sweep:
  speed: [9524 rpm, 13000 rpm, 14000 rpm, 15000 rpm]
  seat: [none, 0.1 in]
"""
#: The coverage factor: a difference of two independent estimates of the same mean lies
#: within 3 of its standard errors (sqrt of the sum of the squares) but rarely (0.3 % for a
#: normal estimate; batch means from 4 batches are rougher, so this is not much looser).
COVERAGE = 3.0


def _run(directory, cap: int) -> xr.Dataset:
    spec = write_spec(directory, SPEC.replace("CAP", str(cap)), name=f"chaos{cap}.yaml")
    path = directory / f"chaos{cap}.nc"
    run_study(load_study(spec), path, scheduler="synchronous")
    return xr.load_dataset(path)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> tuple[xr.Dataset, xr.Dataset, str]:
    directory = tmp_path_factory.mktemp("chaos")
    return _run(directory, 48), _run(directory, 96), str(directory / "chaos48.nc")


def test_the_uncertainty_is_stored_for_the_means_of_cases_that_never_repeat(runs):
    """One variable per mean metric (`<summary>_uncertainty`, the metric's units), finite
    where period_turns is 0, NaN where the response settled (its mean is exact). Fails on a
    copy that stores the batch-means figure for settled cases too (9524 rpm without a seat
    and 13000 rpm with it: their window is a period or two, whose batches differ)."""
    ds = runs[0]
    expected = {m.uncertainty for m in METRICS if m.uncertainty and m.record is None}
    stored = {n for n in ds.data_vars if n.endswith("_uncertainty")}
    assert stored == expected
    never = ds.period_turns.values == 0
    assert never.sum() == 6 and (~never).sum() == 2
    error = ds.separation_deg_per_rev_uncertainty
    assert error.attrs["units"] == ds.separation_deg_per_rev.attrs["units"] == "degree"
    assert "standard error of the window mean by batch means" in error.attrs["long_name"]
    for name in expected:
        values = ds[name].values
        assert np.all(np.isnan(values[~never])), name
        assert np.all(np.isfinite(values[never])), name
    # smaller than one turn's spread over the window, larger than nothing
    per_turn = np.where(ds.measured.values == 1, ds.separation_deg.values, np.nan)[never]
    spread = np.nanstd(per_turn, axis=1, ddof=1)
    assert np.all((error.values[never] > 0) & (error.values[never] < spread))


def test_it_covers_the_mean_of_a_run_twice_as_long(runs):
    """The same study with run.max_revolutions 96: its window (the second half, turns 49–96)
    follows the first run's (turns 25–48), a second estimate of the same mean. Each difference
    lies within COVERAGE standard errors of the two (a NaN, where the longer run settled,
    counting as 0; 9524 rpm with the seat, which the single settling check took for a period
    of 4 at turns 92–95 there, now reads 146.04 ± 0.42° against 145.90 ± 0.60°). Fails
    on a copy that divides the batch means' spread by √turns instead of √batches (0.24° at
    9524 rpm: the 0.95° difference is 4 of them), or stores 0."""
    short, long, _ = runs
    never = short.period_turns.values == 0
    for name in ("separation_deg_per_rev", "cam_impacts"):
        a, b = short[name].values[never], long[name].values[never]
        ua = short[f"{name}_uncertainty"].values[never]
        ub = np.nan_to_num(long[f"{name}_uncertainty"].values[never])
        assert np.all(np.abs(a - b) <= COVERAGE * np.hypot(ua, ub)), (name, a, b, ua, ub)
    assert never.sum() == 6


def test_it_covers_the_mean_of_a_long_fixed_run():
    """Against the engine's fixed-length path (one run of 400 turns, its first 100 left out:
    300 turns, its own batch-means error small beside ours): every never-repeating case's
    difference within COVERAGE standard errors. Fails as the test above does."""
    cases = [
        Case(thesis_train(), harmonic(INCH), s * RPM, z)
        for s in (9524, 13000, 14000, 15000)
        for z in (np.nan, 0.1 * INCH)
    ]
    auto = run_batch(cases, RunSettings(revolutions=None))
    never = auto.period_turns == 0
    ours = np.degrees(auto.separation)
    ours_error = batch_means_error(np.degrees(auto.separation_per_rev), auto.measured)
    fixed = run_batch(cases, RunSettings(revolutions=400, warmup=100, max_events=16384))
    theirs = np.degrees(fixed.separation)
    theirs_error = batch_means_error(np.degrees(fixed.separation_per_rev), fixed.measured)
    assert never.sum() == 6
    bound = COVERAGE * np.hypot(ours_error, theirs_error)
    assert np.all(np.abs(ours - theirs)[never] <= bound[never])


def test_query_shows_a_never_repeating_mean_with_its_uncertainty(runs):
    """The table reads ``145.9 ± 0.6`` in the mean's column for the quickstart's seated
    9524 rpm case and the plain number for a settled one; the summary lists the case with its
    no-follow and uncertainty; CSV keeps the two numbers apart. Fails on a copy that leaves
    the table's cells as stored (145.903)."""
    path = runs[2]
    ds = runs[0]
    seated = int(np.flatnonzero((ds.speed_rpm.values == 9524) & np.isfinite(ds.seat.values))[0])
    value = float(ds.separation_deg_per_rev.values[seated])
    error = float(ds.separation_deg_per_rev_uncertainty.values[seated])
    case = str(ds.case.values[seated])
    table = CliRunner().invoke(main, ["query", path, "--where", "speed_rpm == 9524"]).output
    header = table.splitlines()[0].split()
    assert "separation_deg_per_rev" in header and "separation_deg_per_rev_uncertainty" not in header
    assert 0.2 <= error < 1.0  # one significant digit, the first decimal place
    shown = f"{value:.1f} ± {error:.1f}"
    line = next(row for row in table.splitlines() if row.startswith(case))
    assert shown in line, (shown, line)
    settled = str(ds.case.values[int(np.flatnonzero(ds.period_turns.values > 0)[0])])
    assert "±" not in next(row for row in table.splitlines() if row.startswith(settled))
    summary = CliRunner().invoke(main, ["query", path, "--summary"]).output
    assert f"{case} (separation_deg_per_rev {shown} degree)" in summary
    csv = CliRunner().invoke(main, ["query", path, "--format", "csv"]).output
    head = csv.splitlines()[0].split(",")
    j = head.index("separation_deg_per_rev_uncertainty [degree]")
    row = next(r for r in csv.splitlines() if r.startswith(case)).split(",")
    assert float(row[j]) == pytest.approx(error, rel=1e-12)


def test_a_fixed_run_stores_no_uncertainty(tmp_path):
    """run.revolutions fixed (the digest's study): no ``_uncertainty`` variable at all. Fails
    on a copy that declares them for every run (the mixed study's digest would change)."""
    spec = write_spec(
        tmp_path, SPEC.replace("revolutions: auto, max_revolutions: CAP", "revolutions: 2")
    )
    path = tmp_path / "fixed.nc"
    run_study(load_study(spec), path, scheduler="synchronous")
    with xr.open_dataset(path) as ds:
        assert not [n for n in ds.data_vars if n.endswith("_uncertainty")]
        assert "separation_deg_per_rev" in ds


def test_plot_metric_bars_a_never_repeating_mean_with_its_uncertainty(runs):
    """``campipe plot metric`` draws ± one standard error on each ringed case (and none on a
    settled one). Fails on a copy that rings the cases without their bars."""
    from campipe.plot.figures import figure
    from campipe.study.spec.plots import PlotRequest

    ds = runs[0]
    fig = figure(ds, PlotRequest("metric"))
    bars = [c for c in fig.axes[0].collections if c.get_gid() == "uncertainty"]
    assert len(bars) == 1
    segments = bars[0].get_segments()
    never = ds.period_turns.values == 0
    assert len(segments) == never.sum()
    half = sorted((s[1, 1] - s[0, 1]) / 2 for s in segments)
    expected = sorted(ds.separation_deg_per_rev_uncertainty.values[never])
    np.testing.assert_allclose(half, expected, rtol=1e-9)
