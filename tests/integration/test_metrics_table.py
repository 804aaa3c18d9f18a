"""The metrics table (``campipe.engine.metrics``): a metric declared there reaches the engine's
results, the archive with its units and long name, and the documentation's variable table."""

from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from numpy.testing import assert_allclose
from study_helpers import write_spec

import campipe
from campipe.engine import metrics
from campipe.engine.metrics import Metric
from campipe.study import load_study
from campipe.study.run.execute import run_study

DOCS = Path(__file__).parents[2] / "docs" / "studies.md"

SPEC = """
name: toy
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 2, output_every: 5 deg}
sweep:
  speed: [9000 rpm, 11000 rpm]
  seat: [none, 0.1 in]
"""


def _twice_the_no_follow(result, trains):
    return 2.0 * result.separation_per_rev + 1.0  # [rad]: + 1 rad so no value is 0


def test_a_toy_metric_added_through_the_table_reaches_the_archive_with_its_units(tmp_path):
    """Only the row below is written: the run, the archive's variables, their units and long
    names and the grid view follow from the table. Broken copy: the archive's variables
    declared in a list of their own (study/spec/variables.py before the table) leaves the toy
    metric out of the archive."""
    toy = Metric(
        "toy_twice_no_follow",
        "toy_twice_no_follow_deg_per_rev",
        "toy_twice_no_follow_deg",
        "twice the no-follow, plus a radian",
        "degree",
        "sum",
        si_units="rad",
        source="derived",
        derive=_twice_the_no_follow,
    )
    archive = tmp_path / "toy.nc"
    with metrics.registered(toy):
        run_study(load_study(write_spec(tmp_path, SPEC)), archive, scheduler="synchronous")
    assert "toy_twice_no_follow" not in metrics.by_key()  # the table is as it was
    with xr.open_dataset(archive) as ds:
        summary, per_rev = ds["toy_twice_no_follow_deg_per_rev"], ds["toy_twice_no_follow_deg"]
        assert summary.attrs["units"] == per_rev.attrs["units"] == "degree"
        assert summary.attrs["long_name"] == (
            "twice the no-follow, plus a radian, per revolution, mean over the measured revolutions"
        )
        assert per_rev.dims == ("case", "revolution")
        # Independent of the table: the archive's own no-follow, in degrees.
        expected = 2.0 * ds["separation_deg"].values + np.degrees(1.0)
        assert_allclose(per_rev.values, expected, rtol=1e-12)
        assert_allclose(summary.values, expected.mean(axis=1), rtol=1e-12)
        assert (ds["separation_deg"].values > 0).any()  # past the onset: a real check
    grid = campipe.open_study(archive)
    assert "toy_twice_no_follow_deg_per_rev" in grid.data_vars


def test_only_a_derived_metric_registers_and_a_name_registers_once():
    engine_row = Metric("toy", "toy", "toy_by_rev", "toy", None, "count")
    with pytest.raises(ValueError, match="derived"):
        metrics.register(engine_row)
    with pytest.raises(ValueError, match="exists"):
        metrics.register(
            Metric(
                "separation",
                "s",
                "s_by_rev",
                "s",
                None,
                "max",
                source="derived",
                derive=_twice_the_no_follow,
            )  # fmt: skip
        )


def test_the_docs_variable_table_is_the_metrics_table():
    """docs/studies.md's metrics table is generated (``python -m campipe.engine.metrics``).
    Broken copy: a row edited by hand in the page."""
    text = DOCS.read_text(encoding="utf-8")
    start = text.index("<!-- generated: metrics -->") + len("<!-- generated: metrics -->")
    end = text.index("<!-- end generated -->", start)
    assert text[start:end].strip() == metrics.markdown_table()


@pytest.mark.parametrize("metric", metrics.METRICS, ids=lambda m: m.key)
def test_every_metric_reads_from_a_result_as_its_summary_says(metric):
    """A result's ``<key>`` is its ``<key>_per_rev`` reduced over the measured turns as the
    row's reduction says (mean per turn of a sum or a count, else the extreme)."""
    values = np.array([[1.0, 5.0, 3.0], [2.0, 2.0, 8.0]])
    measured = np.array([False, True, True])
    expected = {"sum": [4.0, 5.0], "count": [4.0, 5.0], "max": [5.0, 8.0], "min": [3.0, 2.0]}
    assert_allclose(metric.summarise(values, measured), expected[metric.reduction])
