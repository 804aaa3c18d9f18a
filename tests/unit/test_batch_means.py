"""The uncertainty of a window mean (``campipe.engine.metrics.batch_means_error``) and how a
table shows it (``campipe.study.query.tables.plus_minus``).

A response that never repeats reports its per-turn means over a window of turns; successive
turns are correlated, so the standard error is estimated by batch means. Checked against a
direct computation and against an AR(1) series, whose mean's variance is a closed form.
"""

from __future__ import annotations

import numpy as np
import pytest

from campipe.engine.metrics import BATCHES, METRICS, batch_means_error
from campipe.study.query.tables import plus_minus


def test_it_is_the_spread_of_four_contiguous_batch_means_over_each_case_s_window():
    """Three cases of 40 turns: one whose window is turns 16–39, one whose window is 16–39
    but whose run ended at turn 30 (NaN beyond, as a settled run's per_rev), one with a window
    of a single turn (NaN: no spread to estimate). Written out here: contiguous batches, the
    standard deviation (n − 1) of their means over √4. Fails on a copy that takes ddof 0, on
    one that interleaves the turns into batches (turn i to batch i mod 4), and on one that
    reads the NaN turns as 0."""
    rng = np.random.default_rng(7)
    values = rng.normal(100.0, 3.0, (3, 40)).cumsum(axis=1) / 10.0  # strongly correlated
    values[1, 30:] = np.nan
    measured = np.zeros((3, 40), np.bool_)
    measured[:2, 16:] = True
    measured[2, 39] = True

    def direct(turns: np.ndarray) -> float:
        means = [
            turns[j : j + len(turns) // 4].mean() for j in range(0, len(turns), len(turns) // 4)
        ]
        return float(np.std(means, ddof=1) / 2.0)

    got = batch_means_error(values, measured)
    assert got[0] == pytest.approx(direct(values[0, 16:40]), rel=1e-12)
    # 14 turns: batches of 4, 4, 3, 3 (as equal as they allow)
    turns = values[1, 16:30]
    means = [turns[0:4].mean(), turns[4:8].mean(), turns[8:11].mean(), turns[11:14].mean()]
    assert got[1] == pytest.approx(np.std(means, ddof=1) / 2.0, rel=1e-12)
    assert np.isnan(got[2])
    # one window for every case ((n_turns,) measured, a fixed run's)
    shared = batch_means_error(values[:1], measured[0])
    assert shared[0] == got[0]


def test_on_a_correlated_series_it_is_the_true_standard_error_not_the_naive_one():
    """An AR(1) series x_k = ρ x_{k−1} + e_k (ρ = 0.8, unit innovations, stationary start),
    2000 series of 2000 turns: the mean's variance is the closed form
    σ²/n (1 + 2 Σ_k (1 − k/n) ρ^k), σ² = 1/(1 − ρ²), about (1 + ρ)/(1 − ρ) = 9 times the
    naive σ²/n. The batch-means variance, averaged over the series, is within 10 % of it (and
    of the series' means' own spread, a second estimate); the naive standard error is a
    third of it, as √((1 − ρ)/(1 + ρ)) says. Fails on a copy that returns the naive standard
    error (the turns' standard deviation over √n: 3 times too small) and on one that divides
    the batch means' spread by √n instead of √batches."""
    rho, n, series = 0.8, 2000, 2000
    rng = np.random.default_rng(20261127)
    e = rng.normal(size=(series, n))
    x = np.empty((series, n))
    x[:, 0] = rng.normal(size=series) / np.sqrt(1.0 - rho**2)
    for k in range(1, n):
        x[:, k] = rho * x[:, k - 1] + e[:, k]
    k = np.arange(1, n)
    exact = (1.0 / (1.0 - rho**2)) / n * (1.0 + 2.0 * np.sum((1.0 - k / n) * rho**k))
    spread = x.mean(axis=1).var(ddof=1)
    assert spread == pytest.approx(exact, rel=0.1)  # the test's own check of its series

    batch = batch_means_error(x, np.ones(n, np.bool_))
    assert np.mean(batch**2) == pytest.approx(exact, rel=0.1)
    assert np.mean(batch**2) == pytest.approx(spread, rel=0.1)
    naive = x.std(axis=1, ddof=1) / np.sqrt(n)
    ratio = np.sqrt(np.mean(batch**2) / np.mean(naive**2))
    assert ratio == pytest.approx(np.sqrt((1 + rho) / (1 - rho)), rel=0.1)


def test_only_the_means_have_an_uncertainty():
    """A sum or a count per turn reads as a mean over the window: it has an uncertainty named
    ``<summary>_uncertainty``; an extreme (max, min) has none. Fails on a copy that gives every
    metric one."""
    for m in METRICS:
        if m.reduction in ("sum", "count"):
            assert m.uncertainty == m.summary + "_uncertainty"
        else:
            assert m.uncertainty is None
    assert BATCHES == 4


@pytest.mark.parametrize(
    ("value", "error", "shown"),
    [
        (145.90301805685002, 0.5996937606622409, "145.9 ± 0.6"),
        (8.791666666666666, 0.15774745405000748, "8.79 ± 0.16"),
        (3.3952493754466224, 0.004457404525809943, "3.395 ± 0.004"),
        (313.9, 23.4, "314 ± 20"),
        (4.0, 0.0, "4 ± 0"),
        (52.825397, float("nan"), "52.8254"),
        (9.8512e-07, 9.3e-09, "(9.85 ± 0.09)e-07"),
        (2.5e7, 1.3e5, "(2.500 ± 0.013)e+07"),
    ],
)
def test_a_mean_reads_to_its_uncertainty_s_first_digit(value, error, shown):
    """The error to one significant digit (two when the first is 1), the value to the same
    place (a very small or large value with a power of ten); no error (NaN: a settled case)
    shows the value as the table always did. Fails on a copy that prints every value with six
    digits and the error beside it."""
    assert plus_minus(value, error) == shown


def test_a_study_records_them_with_its_settling_and_a_metric_s_own_record_item():
    """Declared for runs of automatic length only (the ``settling`` item a study adds), and a
    metric recorded by its own item (the lash adjuster's leak-down) needs that item too.
    Fails on a copy that declares them always (a fixed run's archive, the digest's, would
    change) and on one that ignores the metric's own item (a run without a lash adjuster
    would have to store its leak-down's uncertainty, which it has no turns for)."""
    from campipe.study.spec.variables import SETTLING_RECORD, data_variables

    def uncertain(record):
        return {n for n in data_variables(record) if n.endswith("_uncertainty")}

    assert uncertain(()) == set()
    assert uncertain((SETTLING_RECORD,)) == {
        "separation_deg_per_rev_uncertainty",
        "seated_off_cam_deg_per_rev_uncertainty",
        "cam_impacts_uncertainty",
        "seat_impacts_uncertainty",
    }
    assert uncertain((SETTLING_RECORD, "lash_adjuster")) - uncertain((SETTLING_RECORD,)) == {
        "hla_leak_down_uncertainty",
        "hla_pump_up_uncertainty",
    }
    assert uncertain(("lash_adjuster",)) == set()
