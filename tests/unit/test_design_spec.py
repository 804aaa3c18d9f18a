"""The ``design:`` section of a spec: what it holds in SI, and each refusal at its key path."""

import jsonschema
import pytest
from study_helpers import INCH, LBF

from campipe.constants import RPM
from campipe.study.spec.check import SpecError, check_spec
from campipe.study.spec.design import ONSET
from campipe.study.spec.schema import study_schema

BASE = {
    "name": "d",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "sweep": {"speed": {"from": "3000 rpm", "to": "20000 rpm", "num": 2}},
}
ISSUE = {
    "vary": {"model.spring_preload": {"from": "80 lbf", "to": "250 lbf"}},
    "require": {"onset_speed_rpm": {"min": "9500 rpm"}},
    "minimize": "model.spring_preload",
}


def spec(design, **base):
    return {**BASE, **base, "design": design}


def problems(raw) -> dict[str, str]:
    with pytest.raises(SpecError) as info:
        check_spec(raw)
    return {p.path: p.message for p in info.value.problems}


def test_the_issue_example_is_read_in_si_and_passes_the_schema():
    """The issue's section, exactly: the bounds in newtons, the default tolerance 1e-4 of the
    range, the onset bound in rpm; the schema accepts it. Fails on a unit slip (lbf read as
    N) or a default tolerance of another size."""
    design = check_spec(spec(ISSUE)).design
    assert design is not None
    (v,) = design.vary
    assert v.key == "model.spring_preload" and v.written == "lbf"
    assert v.low == pytest.approx(80 * LBF) and v.high == pytest.approx(250 * LBF)
    assert v.tolerance == pytest.approx(1e-4 * 170 * LBF)
    (r,) = design.require
    assert (r.key, r.minimum, r.units) == (ONSET, 9500.0, "rpm") and r.maximum != r.maximum
    assert (design.objective, design.sense, design.method) == (
        "model.spring_preload",
        "minimize",
        "local",
    )
    validator = jsonschema.Draft202012Validator(study_schema())
    assert [e.message for e in validator.iter_errors(spec(ISSUE))] == []


def test_metric_requirements_take_their_units_and_speeds():
    """A metric's bounds in its archive units (m/s), its speeds in rad/s; a metric with no
    bound is computed only. Fails if ``at`` were read in rpm as rad/s."""
    design = check_spec(
        spec(
            {
                "vary": {
                    "model.spring_preload": {"from": "80 lbf", "to": "250 lbf"},
                    "model.spring_rate": {"from": "150 lbf/in", "to": "450 lbf/in"},
                },
                "require": {
                    "max_seating_velocity": {"max": "20 in/s", "at": ["5000 rpm", "6000 rpm"]},
                    "max_cam_force": {"at": "6000 rpm"},
                },
                "maximize": "max_cam_force",
                "method": "global",
                "max_evaluations": 50,
            }
        )
    ).design
    assert design is not None
    seat, force = design.require
    assert seat.maximum == pytest.approx(20 * INCH) and seat.units == "m/s"
    assert seat.speeds == pytest.approx((5000 * RPM, 6000 * RPM))
    assert not force.bounded and force.speeds == pytest.approx((6000 * RPM,))
    assert design.vary[1].low == pytest.approx(150 * LBF / INCH)
    assert (design.sense, design.method, design.max_evaluations) == ("maximize", "global", 50)


@pytest.mark.parametrize(
    "change, path, words",
    [
        ({"vary": {"model.spring_prelod": {"from": "1 lbf", "to": "2 lbf"}}},
         "design.vary.model.spring_prelod", "did you mean"),
        ({"vary": {"speed": {"from": "1 rpm", "to": "2 rpm"}}}, "design.vary.speed", "unknown"),
        ({"vary": {"model.spring_preload": {"from": "250 lbf", "to": "80 lbf"}}},
         "design.vary.model.spring_preload", "to greater than from"),
        ({"vary": {"model.spring_preload": {"from": "80 in", "to": "250 lbf"}}},
         "design.vary.model.spring_preload.from", "lbf"),
        ({"vary": {"model.spring_preload": {"from": "80 lbf"}}},
         "design.vary.model.spring_preload.to", "missing"),
        ({"vary": {"model.spring_preload": {"from": "80 lbf", "to": "250 lbf",
                                            "tolerance": "1 rpm"}}},
         "design.vary.model.spring_preload.tolerance", "rpm"),
        ({"vary": {}}, "design.vary", "empty"),
        ({"require": {"onset_speed": {"min": "9500 rpm"}}},
         "design.require.onset_speed", "did you mean"),
        ({"require": {"onset_speed_rpm": {"min": "9500 lbf"}}},
         "design.require.onset_speed_rpm.min", "lbf"),
        ({"require": {"onset_speed_rpm": {}}}, "design.require.onset_speed_rpm", "a bound"),
        ({"require": {"onset_speed_rpm": {"min": "9 krpm", "max": "8 krpm"}}},
         "design.require.onset_speed_rpm", "above max"),
        ({"require": {"max_cam_force": {"max": "900 lbf"}}},
         "design.require.max_cam_force.at", "missing"),
        ({"require": {"max_cam_force": {"max": "900 rpm", "at": "6000 rpm"}}},
         "design.require.max_cam_force.max", "rpm"),
        ({"require": {"max_cam_force": {"max": "900 lbf", "at": "6000 lbf"}}},
         "design.require.max_cam_force.at", "lbf"),
        ({"minimize": "model.spring_rate"}, "design.minimize", "a varied key"),
        ({"maximize": "model.spring_preload"}, "design.maximize", "twice"),
        ({"minimize": ["onset_speed_rpm", "model.spring_preload", "model.spring_rate"]},
         "design.minimize", "found 3 objectives"),
        ({"method": "globl"}, "design.method", "did you mean"),
        ({"max_evaluations": 1}, "design.max_evaluations", "from 2"),
        ({"goal": 1}, "design.goal", "unknown"),
    ],
)  # fmt: skip
def test_a_bad_design_is_refused_at_its_key(change, path, words):
    """Each mistake named at its key path with what was expected. Fails if a problem were
    reported at the section (``design``) instead of the key, or not at all."""
    found = problems(spec({**ISSUE, **change}))
    assert path in found, found
    assert words in found[path], found[path]


def test_a_section_without_its_parts_names_each():
    found = problems(spec({}))
    assert set(found) >= {"design.vary", "design.require", "design.minimize"}
    assert "missing" in found["design.vary"]


def test_the_spec_may_vary_the_speed_only():
    """A design varies its keys over one base case: another axis is refused at its key. Fails
    if the seat's sweep were silently kept (the design would be evaluated at its first value)."""
    raw = spec(ISSUE, sweep={"speed": ["3000 rpm", "9000 rpm"], "seat": ["none", "0.1 in"]})
    found = problems(raw)
    assert "sweep.seat" in found and "speed only" in found["sweep.seat"]


def test_a_design_file_shows_its_varied_keys_in_the_units_the_section_wrote():
    """campipe query's units for a design file: a varied key in the units of design.vary's
    bounds (mm here, in a spec otherwise SI). Fails if the design section were not read (the
    lash would show in m)."""
    from campipe.study.query.display import display_units

    text = "name: d\ndesign:\n  vary: {model.lash: {from: 0.1 mm, to: 0.5 mm}}\n"
    attrs = {"spec": text, "study_axes": '[{"name": "lash", "key": "model.lash"}]'}
    assert display_units({"lash": "m", "onset_speed_rpm": "rpm"}, attrs) == {
        "lash": "mm",
        "onset_speed_rpm": "rpm",
    }
