"""Specs that are impossible or too large, refused with their key path before anything is
built; specs at the edge of the limits accepted."""

import json
import math
import sys

import numpy as np
import pytest
from study_helpers import changed, write_spec

from campipe.io.spec_yaml import MAX_DEPTH, SpecFileError, parse_spec_text
from campipe.profiles import evaluate as cam_lift
from campipe.profiles import flat, harmonic, min_lift, polydyne
from campipe.study import Limits, SpecError, check_spec, expand, load_study
from campipe.study.spec.limits import case_count
from campipe.study.where import QueryError, evaluate, parse_where
from campipe.units import QuantityError, parse_angular

BASE = {
    "name": "t",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "speed": "9000 rpm",
    "run": {"revolutions": 1},
}


def spec(**changes):
    return changed(BASE, **changes)


def refused(raw, limits=None) -> list[tuple[str, str]]:
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw), limits=limits)
    return [(p.path, p.message) for p in info.value.problems]


@pytest.mark.parametrize(
    ("raw", "path", "words"),
    [
        (
            spec(defects=[{"kind": "flat", "from": "272 deg", "to": "268 deg"}]),
            "defects[0].to",
            "at or before from '272 deg'",
        ),
        (
            spec(defects=[{"kind": "flat", "from": "10 deg", "to": "380 deg"}]),
            "defects[0].to",
            "a turn or more",
        ),
        (
            spec(sweep={"speed": ["9000 rpm", "9000.0 rpm"]}),
            "sweep.speed[1]",
            "the same value as sweep.speed[0]",
        ),
        (
            spec(sweep={"speed": {"from": "1 rpm", "to": "1 rpm", "num": 2}}),
            "sweep.speed[1]",
            "the same value",
        ),
        (
            spec(zip={"speed": ["1 rpm", "1 rpm"], "seat": ["0.1 in", "0.1 in"]}),
            "zip (row 1)",
            "the same row",
        ),
        (
            spec(cases=[{"seat": "0.1 in"}, {"seat": "0.1 in"}]),
            "cases",
            "cases 0 and 1 are the same case",
        ),
        (
            spec(run={"revolutions": 1, "output_every": "361 deg"}),
            "run.output_every",
            "longer than the run",
        ),
        (spec(speed="1e308 rpm"), "speed", "at most 1e+06 rpm"),
        (spec(profile={"kind": "harmonic", "lift": "1e300 in"}), "profile.lift", "at most 39.37"),
        (spec(model={"spring_rate": "1e300 lbf/in"}), "model", "not finite and positive"),
        (
            spec(model={"damping_ratios": list(range(100))}),
            "model.damping_ratios",
            "[0, 1, 2, 3, ...]",
        ),
        (spec(speed="9**9**9 rpm"), "speed", "units are names joined by"),
        (spec(replay={"where": "profile > 3"}), "replay.where", "profile is text"),
        (spec(replay={"where": "1"}), "replay.where", "where a condition belongs"),
    ],
)
def test_impossible_settings_are_refused_at_their_key(raw, path, words):
    problems = refused(raw)
    assert any(p == path and words in m for p, m in problems), problems


def test_an_all_zero_lift_table_is_refused(tmp_path):
    (tmp_path / "flat.csv").write_text("angle [deg],lift [in]\n0,0\n90,0\n180,0\n270,0\n")
    raw = spec(profile={"kind": "table", "file": "flat.csv"})
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw, directory=tmp_path))
    assert info.value.problems[0].path == "profile.file"
    assert "never rises above 0 in" in info.value.problems[0].message


def test_a_dwell_cam_s_table_is_read_where_its_spline_only_rings_below_the_base(tmp_path):
    """A 9 mm polydyne-4567 with its base-circle dwell, tabulated every 1° and 2° (every
    point ≥ 0): the periodic cubic spline through it rings nanometres below 0 beside the
    dwell (a helper's measured-style tables were all refused); within 1e-6 of the lift it is
    read, and its lift is the polydyne's at the table's points. A table whose points dip 1 µm
    below the base circle is still refused, its dip in the table's units. Broken copies: the
    round-off tolerance (1e-12 m) for tables too; the dip in inches."""
    cam = polydyne("4567", 9e-3, *np.radians([110, 20, 110]))
    for step in (1, 2):
        angles = np.arange(0, 360, step)
        lift = cam_lift(cam, np.radians(angles))[0]
        rows = "".join(f"{a},{float(x) * 1e3!r}\n" for a, x in zip(angles, lift, strict=True))
        (tmp_path / f"cam{step}.csv").write_text("angle [deg],lift [mm]\n" + rows)
        raw = spec(profile={"kind": "table", "file": f"cam{step}.csv"})
        profile = expand(check_spec(raw, directory=tmp_path)).cases[0].case.profile
        assert min_lift(profile) < -1e-10  # it rings below: the round-off tolerance refused it
        np.testing.assert_allclose(cam_lift(profile, np.radians(angles))[0], lift, atol=1e-15)
    lift[150] = -1e-6  # at 300°, on the base circle
    rows = "".join(f"{a},{float(x) * 1e3!r}\n" for a, x in zip(angles, lift, strict=True))
    (tmp_path / "dip.csv").write_text("angle [deg],lift [mm]\n" + rows)
    with pytest.raises(SpecError) as info:
        expand(check_spec(spec(profile={"kind": "table", "file": "dip.csv"}), directory=tmp_path))
    assert info.value.problems[0].path == "profile.file"
    assert "never below the base circle" in info.value.problems[0].message
    # in the table's own units (it read -4.01e-05 in for a table in mm)
    assert "lift falls to -0.001 mm" in info.value.problems[0].message


def test_a_flat_through_zero_is_written_past_360_degrees():
    """The harmonic cam's nose ground off from 170° through 0° to 10° (its ends at equal
    lift: h/2·(1 − sin θ) is symmetric about the nose at 270°)."""
    study = expand(check_spec(spec(defects=[{"kind": "flat", "from": "170 deg", "to": "370 deg"}])))
    wrapped = flat(harmonic(0.0254), math.radians(170), math.radians(10))
    profile = study.cases[0].case.profile
    np.testing.assert_allclose(profile.breaks, wrapped.breaks, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(profile.poly, wrapped.poly, rtol=1e-12, atol=1e-18)
    assert study.cases[0].values["defects"] == "flat 170–10 deg"


@pytest.mark.parametrize(
    ("ends", "words"),
    [
        # on the harmonic cam, h/2·(1 − sin θ), h = 1 in: the lift at 370° is
        # h/2·(sin 350° − sin 10°) = 0.17365 in below the lift at 350°
        (("350 deg", "370 deg"), "(370 deg) is 0.1736 in lower: a step in the cam"),
        # 0.5·(sin 267° − sin 272°) = 0.000380 in up; the lift comes back at 273° (symmetric
        # about the nose at 270°)
        (
            ("267 deg", "272 deg"),
            "0.0003806 in higher: a step in the cam, which no grinding "
            "makes; end it at 273 deg, where the lift comes back",
        ),  # fmt: skip
        # ends at equal lift across the base (90°): the lift dips h/2·(1 − sin 10°) below
        (("10 deg", "170 deg"), "falls 0.4132 in below it within: it would add metal"),
    ],
)
def test_a_flat_no_grinding_makes_is_refused_naming_where_it_can_end(ends, words):
    """A flat whose ends are at unequal lift steps the cam (a helper's 350–370° dropped the
    thesis's cam 0.174 in at once, 72.5° of no-follow; on a two-mass chain every case failed)
    and one whose lift dips between its ends adds metal: each refused at its defect, with
    the lifts in the spec's unit checked against the harmonic cam's closed form, and where
    the lift comes back to the start's where it does. Broken copy: no check (each runs)."""
    raw = spec(defects=[{"kind": "flat", "from": ends[0], "to": ends[1]}])
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw))
    problem = info.value.problems[0]
    assert problem.path == "defects[0]"
    assert words in problem.message, problem.message


@pytest.mark.parametrize(
    ("raw", "limits", "path", "words"),
    [
        (
            spec(
                sweep={
                    "speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 300},
                    "seat": {"from": "0 in", "to": "0.1 in", "num": 300},
                }
            ),
            Limits(cases=50_000),
            "sweep.speed",
            "cases (sweep.speed 300 × sweep.seat 300): 9e+04",
        ),
        (spec(run={"revolutions": 1, "dt": "1e-15 s"}), Limits(), "run.dt", "steps per case"),
        (
            spec(speed="0.001 rpm", run={"revolutions": 1, "integrator": "newmark-linear"}),
            Limits(),
            "run.dt",
            "6e+10",
        ),
        (
            spec(run={"revolutions": 1, "output_every": "1e-9 deg"}),
            Limits(),
            "run.output_every",
            "samples per case",
        ),
        (
            spec(run={"revolutions": 1, "max_events": 10**12}),
            Limits(),
            "run.max_events",
            "--max-events",
        ),
        (
            spec(
                run={"revolutions": 100, "output_every": "0.01 deg", "record": ["q"]},
                sweep={"speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 100}},
            ),
            Limits(samples=10**7),
            "run",
            "archive size",
        ),
    ],
)
def test_a_spec_beyond_a_limit_is_refused_before_any_case_is_built(
    raw, limits, path, words, monkeypatch
):
    expand_module = sys.modules["campipe.study.spec.expand"]

    def no_cases(spec):
        raise AssertionError("a case was built")

    monkeypatch.setattr(expand_module, "raw_cases", no_cases)
    problems = refused(raw, limits)
    assert any(p == path and words in m for p, m in problems), problems


def test_the_case_count_comes_from_the_axes_lengths():
    raw = spec(
        sweep={"speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 10}},
        zip={"seat": ["0 in", "0.05 in", "0.1 in"], "closure": ["force", "form", "force"]},
        cases=[{"model": {"spring_rate": "245 lbf/in"}}, {"model": {"spring_rate": "260 lbf/in"}}],
        sample={
            "method": "latin-hypercube",
            "n": 4,
            "seed": 1,
            "ranges": {"model.spring_preload": {"from": "140 lbf", "to": "160 lbf"}},
        },
    )
    assert case_count(check_spec(raw)) == 10 * 3 * 2 * 4


def test_raised_limits_accept_what_the_defaults_refuse(tmp_path):
    path = write_spec(tmp_path, json.dumps(spec(run={"revolutions": 1, "max_events": 200_000})))
    with pytest.raises(SpecError):
        load_study(path)
    assert load_study(path, limits=Limits(events=200_000)).cases[0].settings.max_events == 200_000


@pytest.mark.parametrize(
    "text",
    [
        "a: " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1),
        "a: &a [1, 2, 3, 4, 5, 6, 7, 8]\n"
        + "".join(
            f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 8)}]\n"
            for i in range(7)
        ),
        "a: &a [*a]",
    ],
)
def test_yaml_that_would_exhaust_memory_or_the_stack_is_refused(text):
    with pytest.raises(SpecFileError):
        parse_spec_text(text)


def test_aliases_within_the_bound_are_plain_yaml():
    raw = parse_spec_text("cam: &cam {kind: harmonic, lift: 1 in}\nprofile: *cam\n")
    assert raw["profile"] == {"kind": "harmonic", "lift": "1 in"}


@pytest.mark.parametrize("text", ["9**9**9 rpm", "9 rpm**9**9", "9 ((rpm**99)**99)**99"])
def test_quantities_evaluate_no_arithmetic(text):
    with pytest.raises(QuantityError):
        parse_angular(text, "rad/s", "speed", "rpm")


def test_where_takes_conditions_only():
    cols = {"speed_rpm": np.array([6000.0, 9000.0])}
    for text in ["1", "speed_rpm", "'form'", "speed_rpm > 1 and 2"]:
        with pytest.raises(QueryError, match="where a condition belongs"):
            parse_where(text)
    assert evaluate(parse_where("speed_rpm > 7000 and true"), cols, 2).tolist() == [False, True]
    with pytest.raises(QueryError, match="too large to compare"):
        parse_where("speed_rpm > " + "9" * 400)
    with pytest.raises(QueryError, match="cannot parse"):
        parse_where("speed_rpm == '\udcff'")


def test_long_histories_make_smaller_default_batches():
    from campipe.study.run.sizing import default_batch_size

    assert default_batch_size(1000, 2) == 125  # four batches per worker
    assert default_batch_size(10_000, 2) == 256  # at most MAX_BATCH_SIZE
    assert default_batch_size(1000, 2, samples=1441) == 125  # 4 turns at 1 deg
    assert default_batch_size(1000, 2, samples=100_000) == 16  # 512 MiB / (1e5 × 320 B)
    assert default_batch_size(1000, 2, samples=10_000_000) == 1


def test_numbers_and_booleans_read_as_yaml_1_2_reads_them():
    """A spec's ``1e-5`` is a number (PyYAML's YAML 1.1 reads it as text, and
    ``run.settle_tolerance: 1e-5`` was refused as "expected a number"), ``010`` is ten (not
    octal eight), ``1:30`` is text (not ninety, base 60), and ``no``/``off`` are text (not
    false: ``seat: no`` read as false); ``true``, hexadecimal and ``.inf`` still read.
    Python's own float() and int() are the reference. Fails on a copy with PyYAML's
    resolvers."""
    from campipe.io.spec_yaml import parse_spec_text

    got = parse_spec_text(
        "a: 1e-5\nb: 010\nc: 1:30\nd: no\ne: off\nf: true\ng: 0x1F\nh: .inf\ni: -2.5E3\n"
        "j: 9000 rpm\nk: [1e3, 2.]\n"
    )
    assert got == {
        "a": float("1e-5"), "b": int("10"), "c": "1:30", "d": "no", "e": "off", "f": True,
        "g": 31, "h": float("inf"), "i": float("-2.5E3"), "j": "9000 rpm", "k": [1000.0, 2.0],
    }  # fmt: skip
    assert isinstance(got["b"], int) and isinstance(got["a"], float)


def test_an_empty_file_a_number_for_a_name_and_tabs_are_told_what_to_do(tmp_path):
    """An empty (or comments-only) spec is told it is empty, not "found None"; a name YAML
    reads as a number is told to quote it; a tab in the indentation is told to indent with
    spaces. Fails on a copy with the bare messages."""
    from campipe.study import load_study
    from campipe.study.spec.check import SpecError

    empty = tmp_path / "empty.yaml"
    empty.write_text("# nothing yet\n")
    with pytest.raises(SpecError, match="the file is empty, or only comments"):
        load_study(empty)
    number = tmp_path / "number.yaml"
    number.write_text("name: 123\nprofile: {kind: harmonic, lift: 1 in}\nspeed: 9000 rpm\n")
    with pytest.raises(SpecError, match="quote it, name: '123'"):
        load_study(number)
    with pytest.raises(SpecFileError, match="indent with spaces"):
        parse_spec_text("name: t\nmodel:\n\tpreset: thesis-1971\n")
