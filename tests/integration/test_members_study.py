"""The new model parameters (issue 16) in specs, the archive and replays: element counts, the
damping kind, loss factors and damping-ratio lists of differing lengths."""

import numpy as np
import pytest
import xarray as xr
from numpy.testing import assert_array_equal
from study_helpers import write_spec

from campipe.model import thesis_train, valve_train
from campipe.replay.cases import _train_from_columns
from campipe.study import SpecError, load_study
from campipe.study.run.execute import run_study

DAMPING = """
name: damping
profile: {kind: harmonic, lift: 1 in}
model: {rayleigh_alpha: 40 s**-1, rayleigh_beta: 2e-7 s}
run: {revolutions: 1}
speed: 9000 rpm
cases:
  - {model: {damping_kind: modal, damping_ratios: [0.5, 0.1]}}
  - {model: {damping_kind: rayleigh, damping_ratios: [0.5, 0.1, 0.1], valve_stem_elements: 1}}
  - {model: {damping_kind: loss-factor, spring_loss_factor: 0.1}}
"""


def test_the_archive_types_the_new_parameters(tmp_path):
    """The damping kind is text, an element count an integer, a loss factor a float, and the
    damping-ratio lists (2, 3 and the preset's 7 values) share a 'mode' dimension as long as
    the longest, NaN beyond a shorter list. Each case's train is the one its parameters
    give. Fails if a count is archived as a float, the kind as a number, or the lists are
    cut to the shortest."""
    study = load_study(write_spec(tmp_path, DAMPING))
    assert [c.case.train.damping_kind for c in study.cases] == ["modal", "rayleigh", "loss-factor"]
    assert study.cases[2].case.train == valve_train(
        overrides={
            "rayleigh_alpha": "40 s**-1",
            "rayleigh_beta": "2e-7 s",
            "damping_kind": "loss-factor",
            "spring_loss_factor": 0.1,
        }
    )
    run_study(study, tmp_path / "damping.nc", scheduler="synchronous")
    ds = xr.load_dataset(tmp_path / "damping.nc")
    assert_array_equal(ds.damping_kind.values, ["modal", "rayleigh", "loss-factor"])
    assert ds.valve_stem_elements.dtype == np.int64
    assert_array_equal(ds.valve_stem_elements.values, [1, 1, 1])
    assert_array_equal(ds.spring_loss_factor.values, [0.0, 0.0, 0.1])
    nan = np.nan
    assert_array_equal(
        ds.damping_ratios.values,
        [
            [0.5, 0.1, nan, nan, nan, nan, nan],
            [0.5, 0.1, 0.1, nan, nan, nan, nan],
            [0.5] + [0.1] * 6,
        ],
    )


def test_a_train_is_rebuilt_from_the_archive_columns():
    """A replay without the spec's cases rebuilds the train from the columns: a count from an
    integer, the kind from text, a loss factor from a plain number, a ratio list without its
    NaN padding. Fails if a dimensionless value is read as a quantity ('0.1 1')."""
    columns = {
        "spring_elements": (np.int64(4), ""),
        "damping_kind": ("loss-factor", ""),
        "spring_loss_factor": (np.float64(0.1), "1"),
        "damping_ratios": (np.array([0.4, 0.1, np.nan]), "1"),
        "spring_rate": (np.float64(42906.0), "N/m"),
    }
    train = _train_from_columns({}, columns)
    assert train == thesis_train().replace(
        spring_elements=4,
        damping_kind="loss-factor",
        spring_loss_factor=0.1,
        damping_ratios=(0.4, 0.1),
        spring_rate=42906.0,
    )


@pytest.mark.parametrize(
    ("model", "key", "message"),
    [
        ("{spring_elements: 0}", "model.spring_elements", "expected a whole number from 1 to 64"),
        ("{spring_elements: 2.5}", "model.spring_elements", "found 2.5"),
        ("{damping_kind: viscous}", "model.damping_kind", "one of: modal, rayleigh"),
        (
            "{damping_ratios: [0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]}",
            "model.damping_ratios",
            "8 ratios for a train of 7 modes",
        ),
    ],
)
def test_bad_new_parameters_in_a_spec_name_their_key(tmp_path, model, key, message):
    """Each refused with its key path and the fix. Fails if a bad count reaches the model."""
    spec = f"name: bad\nprofile: {{kind: harmonic, lift: 1 in}}\nspeed: 9000 rpm\nmodel: {model}\n"
    with pytest.raises(SpecError) as err:
        load_study(write_spec(tmp_path, spec))
    problem = err.value.problems[0]
    assert problem.key == key and message in problem.message


def test_loss_factors_take_a_range_and_counts_a_list(tmp_path):
    """A loss factor is a plain number a sweep may range over; an element count is listed
    (a range of counts would give fractions). Fails if a loss factor's range asks for
    units."""
    spec = (
        "name: ranges\nprofile: {kind: harmonic, lift: 1 in}\nspeed: 9000 rpm\n"
        "model: {damping_kind: loss-factor}\n"
        "sweep: {model.spring_loss_factor: {from: 0, to: 0.2, num: 3}}\n"
    )
    study = load_study(write_spec(tmp_path, spec))
    assert [c.case.train.spring_loss_factor for c in study.cases] == [0.0, 0.1, 0.2]
    spec = spec.replace(
        "sweep: {model.spring_loss_factor: {from: 0, to: 0.2, num: 3}}",
        "sweep: {model.spring_elements: {from: 1, to: 4, num: 4}}",
    )
    with pytest.raises(SpecError) as err:
        load_study(write_spec(tmp_path, spec))
    assert "list its values instead of a range" in str(err.value)


def test_a_refined_train_runs_in_a_study_and_newmark_linear_refuses_it(tmp_path):
    """A study may vary spring_elements (modal-exact); newmark-linear refuses the refined
    case at run.integrator, naming modal-exact."""
    spec = (
        "name: refined\nprofile: {kind: harmonic, lift: 1 in}\nspeed: 9000 rpm\n"
        "run: {revolutions: 1, record: [spring]}\n"
        "sweep: {model.spring_elements: [1, 4]}\n"
    )
    study = load_study(write_spec(tmp_path, spec))
    run_study(study, tmp_path / "refined.nc", scheduler="synchronous")
    ds = xr.load_dataset(tmp_path / "refined.nc")
    assert_array_equal(ds.spring_elements.values, [1, 4])
    assert np.isfinite(ds.min_spring_clash_margin.values).all()
    assert ds.max_spring_force.values[1] > ds.max_spring_force.values[0]
    newmark = spec.replace("record: [spring]", "integrator: newmark-linear, dt: 1 us")
    with pytest.raises(SpecError) as err:
        load_study(write_spec(tmp_path, newmark))
    problem = err.value.problems[0]
    assert problem.key == "run.integrator" and "modal-exact" in problem.message
