"""A spec that sweeps the speed on an axis of its own expands to a ``SpeedSweep``: its other
axes' combinations resolved once each, a case built from one of them and a speed when asked
for. Checked here against resolving every case on its own (``expand(..., by_speed=False)``),
case by case, and for what ``campipe validate`` needs of it without building the cases."""

import textwrap

import pytest
import yaml
from click.testing import CliRunner

from campipe.cli import main
from campipe.study import SpecError
from campipe.study.run.batches import plan_batches
from campipe.study.run.sizing import count_batches
from campipe.study.spec.check import check_spec
from campipe.study.spec.expand import expand
from campipe.study.spec.resolve import SpeedSweep

SPECS = {
    "speed inside two sweeps": """
        name: a
        profile: {kind: harmonic, lift: 1 in}
        run: {revolutions: 1, output_every: 10 deg}
        sweep:
          seat: [none, 0.1 in, 0.3 in]
          speed: [6000 rpm, 9000 rpm, 9524 rpm, 11000 rpm]
          model.spring_preload: [120 lbf, 151 lbf]
        """,
    "speed first, cases, zip and a lash": """
        name: b
        profile: {kind: harmonic, lift: 1 in}
        run: {revolutions: 1, output_every: 10 deg}
        sweep:
          speed: [3000 rpm, 7000 rpm, 12000 rpm]
        zip:
          model.spring_rate: [200 lbf/in, 245 lbf/in]
          model.spring_preload: [140 lbf, 160 lbf]
        cases:
          - profile: {kind: polydyne-4567, lift: 0.4 in, rise: 90 deg, dwell: 90 deg, fall: 90 deg}
            closure: form
          - {model: {lash: 0.01 in}}
          - {seat: 0.2 in, run: {integrator: newmark-linear, dt: 1 us}}
        """,
    "speed last with a sample": """
        name: c
        profile: {kind: harmonic, lift: 1 in}
        run: {revolutions: 1, output_every: 10 deg}
        sample:
          method: latin-hypercube
          n: 5
          seed: 3
          ranges: {model.spring_preload: {from: 120 lbf, to: 180 lbf}}
        sweep:
          speed: [5000 rpm, 10000 rpm]
        """,
}


def _spec(text: str, tmp_path):
    return check_spec(yaml.safe_load(textwrap.dedent(text)), textwrap.dedent(text), tmp_path)


@pytest.mark.parametrize("name", SPECS)
def test_each_case_is_what_resolving_it_alone_gives(name, tmp_path):
    """Same order, index, id, engine inputs (the same train and profile objects), run
    settings and archive values (their order too), case by case.

    Broken copy: a stride of the axes before the speed's instead of after it gives other
    cases' trains at the wrong indices, and a canonical speed left at the first speed gives
    every speed one id."""
    swept = expand(_spec(SPECS[name], tmp_path))
    each = expand(_spec(SPECS[name], tmp_path), by_speed=False)
    assert isinstance(swept.cases, SpeedSweep) and isinstance(each.cases, list)
    assert len(swept.cases) == len(each.cases) > 1
    for a, b in zip(swept.cases, each.cases, strict=True):
        assert (a.index, a.case_id) == (b.index, b.case_id)
        assert a.case.train is b.case.train and a.case.profile is b.case.profile
        assert (a.case.speed, a.case.closure) == (b.case.speed, b.case.closure)
        assert repr(a.case.seat) == repr(b.case.seat)  # NaN: no seat
        assert a.settings == b.settings
        assert repr(a.values) == repr(b.values)
    assert len({c.case_id for c in swept.cases}) == len(swept.cases)
    assert [c.case_id for c in swept.cases[-3:]] == [c.case_id for c in each.cases[-3:]]
    assert swept.cases[-1].case_id == each.cases[-1].case_id


@pytest.mark.parametrize("size", [1, 4, 7, 256])
def test_the_batch_count_is_what_planning_the_batches_gives(size, tmp_path):
    """``count_batches`` (by the other axes' combinations) against ``plan_batches`` over
    every case, with cases in two run-settings groups of different sizes."""
    study = expand(_spec(SPECS["speed first, cases, zip and a lash"], tmp_path))
    cases = list(study.cases)
    assert len({c.settings for c in cases}) == 2
    assert count_batches(study.cases, size) == len(plan_batches(cases, (), size))


@pytest.mark.parametrize(
    ("speeds", "seats", "problem"),
    [
        ("[6000 rpm, 9000 rpm]", "[{seat: 0.1 in}, {seat: 2.54 mm}]", "are the same case"),
        ("[6000 rpm, -9000 rpm]", "[{seat: 0.1 in}]", "sweep.speed[1]"),
        ("[6000 rpm, 9000 rpm]", "[{seat: 0.1 in}, {seat: 2 in}]", "cases[1].seat"),
    ],
)
def test_a_problem_is_reported_as_resolving_each_case_reports_it(speeds, seats, problem, tmp_path):
    """Two equal cases (one seat written twice), a speed the engine refuses, a seat above
    the valve's lift: the same error, naming the same cases, as the case-by-case expansion
    (which is then what reports it)."""
    text = f"""
        name: d
        profile: {{kind: harmonic, lift: 1 in}}
        sweep:
          speed: {speeds}
        cases: {seats}
        """
    errors = []
    for by_speed in (True, False):
        with pytest.raises(SpecError) as info:
            expand(_spec(text, tmp_path), by_speed=by_speed)
        errors.append(str(info.value))
    assert errors[0] == errors[1]
    assert problem in errors[0]


def test_validate_builds_no_case_of_a_million(tmp_path, monkeypatch):
    """``campipe validate --no-estimate`` of a 1000 × 1000 speed sweep counts its cases,
    batches and archive from the 1000 other-axis combinations: it builds one case (the
    first, for its run line), not a million.

    Broken copy: planning the batches over ``loaded.cases`` builds all of them."""
    built = []
    build = SpeedSweep._build
    monkeypatch.setattr(SpeedSweep, "_build", lambda self, i: built.append(i) or build(self, i))
    (tmp_path / "m.yaml").write_text(
        textwrap.dedent(
            """
            name: m
            profile: {kind: harmonic, lift: 1 in}
            run: {revolutions: 2, output_every: 10 deg}
            sweep:
              speed: {from: 1000 rpm, to: 20000 rpm, num: 1000}
              model.spring_preload: {from: 100 lbf, to: 200 lbf, num: 1000}
            """
        )
    )
    args = ["validate", str(tmp_path / "m.yaml"), "--no-estimate", "--max-cases", "1000000"]
    out = CliRunner().invoke(main, [*args, "--max-archive-gb", "1000", "--workers", "2"])
    assert out.exit_code == 0, out.output
    assert "1000000 cases" in out.output
    assert "batches: 3907 of up to 256 cases" in out.output  # ⌈1e6 / 256⌉, one settings group
    assert built == [0]


def test_the_simulated_time_is_summed_without_building_a_case(tmp_path, monkeypatch):
    """``estimate.simulated_seconds`` of a speed sweep (turns of the other axes' combinations
    × Σ 2π/ω over the speeds) against the sum case by case, with no case built; and the
    value by hand: one turn at each of 6000, 9000, 9524 and 11000 rpm, 3 seats × 2 preloads."""
    from campipe.study.run.estimate import simulated_seconds

    swept = expand(_spec(SPECS["speed inside two sweeps"], tmp_path))
    each = expand(_spec(SPECS["speed inside two sweeps"], tmp_path), by_speed=False)
    monkeypatch.setattr(SpeedSweep, "_build", lambda self, i: pytest.fail("a case was built"))
    total = simulated_seconds(swept)
    assert total == pytest.approx(simulated_seconds(each), rel=1e-12)
    assert total == pytest.approx(3 * 2 * sum(60 / rpm for rpm in (6000, 9000, 9524, 11000)))


@pytest.mark.parametrize(
    "canonical",
    [
        {"model": {"spring_rate": 42.0}, "seat": None, "speed": 1.0, "zeta": [1, 2]},
        {"speed": 1.0},  # the speed alone
        {"aaa": "speed", "speed": 1.0},  # the key's text as another's value
        {"speed": 1.0, "zz": {"speed": 2.0}},  # a nested key of the same name
        {"a": "\x00speed\x00", "speed": 1.0},  # a value that is the mark itself
    ],
)
def test_a_speeds_case_id_hashes_the_whole_canonical_json(canonical):
    """``speed_case_ids`` hashes the JSON before the speed once: each id is still
    ``case_id`` of the whole canonical parameters, for speeds whose JSON differs (negative
    zero, exponents, many digits)."""
    from campipe.study.spec.resolve import case_id, clean_value, speed_case_ids

    ids = speed_case_ids(canonical)
    for speed in (-0.0, 0.0, 1e-300, 628.3185307179587, 1.5e22, 1047.1975511965977, 7.0):
        assert ids(speed) == case_id({**canonical, "speed": clean_value(speed)}), speed
    with pytest.raises(ValueError):
        ids(float("nan"))
