"""Study specs: the schema, safe YAML, and every class of bad input refused with its key path."""

import jsonschema
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from study_helpers import ROOT, STUDIES, changed, write_spec

from campipe.io.spec_yaml import SpecFileError, parse_spec_text, read_spec
from campipe.model import PARAMETERS
from campipe.study import SpecError, check_spec, expand, load_study
from campipe.study.spec.fields import CASE_FIELDS, PROFILE_FIELDS, TOP_LEVEL, sweep_keys
from campipe.study.spec.schema import schema_text, study_schema

BASE = {
    "name": "t",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "speed": "9000 rpm",
    "run": {"revolutions": 1},
}
#: Cases in each example spec.
EXAMPLE_CASES = {
    "quickstart": 8,
    "thesis-no-seat": 4,
    "thesis-seat": 5,
    "thesis-machining-error": 4,
    "thesis-undamped": 2,
    "thesis-polydyne": 3,
    "thesis-member-loads": 1,
    "separation-map": 297,
    "lash-ramp": 27,
    "spring-surge": 57,
    "contact-stiffness": 39,
    "valve-bounce": 21,
    "design-spring": 2,
    "design-spring-rate": 2,
    "bucket-tappet-lash": 18,
    "finger-follower": 7,
    "lash-adjuster": 4,
    "lash-adjuster-compliant": 2,
    "finger-follower-hla": 5,
    "finger-follower-hla-compliant": 2,
}


def refused(raw, **kw) -> SpecError:
    """The SpecError a spec raises, checked and expanded."""
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw, **kw))
    return info.value


def with_(**changes):
    return changed(BASE, **changes)


def test_schema_file_is_generated_from_the_key_table():
    path = ROOT / "schemas" / "study.schema.json"
    assert path.read_text() == schema_text()
    jsonschema.Draft202012Validator.check_schema(study_schema())
    # The model block is the model's own schema.
    from campipe.model.schema import model_schema

    assert study_schema()["$defs"]["model"]["properties"] == model_schema()["properties"]


@pytest.mark.parametrize("name", sorted(EXAMPLE_CASES))
def test_every_example_spec_validates(name):
    path = STUDIES / f"{name}.yaml"
    raw, _ = read_spec(path)
    validator = jsonschema.Draft202012Validator(study_schema())
    assert [e.message for e in validator.iter_errors(raw)] == []
    assert len(load_study(path).cases) == EXAMPLE_CASES[name]


def test_every_spec_in_studies_is_listed():
    assert {p.stem for p in STUDIES.glob("*.yaml")} == set(EXAMPLE_CASES)


ISSUE_EXAMPLE = """
name: separation-map            # archive defaults to <name>.nc beside the spec (or -o PATH)
model:                          # preset plus overrides; any model parameter by name
  preset: thesis-1971
  spring_preload: 151 lbf
profile: {kind: harmonic, lift: 1 in}     # or polydyne-345 / polydyne-4567; or table
defects: []                     # e.g. [{kind: flat, from: 268 deg, to: 272 deg}]
closure: force                  # or form
seat: none                      # or a valve lift such as 0.1 in
speed: 9000 rpm
run: {revolutions: 4, integrator: default, output_every: 1 deg}   # dt: 1 us for newmark-linear
sweep:                          # full grid over these axes (any key above, model.<param> too)
  speed: {from: 1000 rpm, to: 20000 rpm, num: 39}
  seat: [none, 0.05 in, 0.1 in]
cases:                          # optional explicit list, each overriding the base
  - {profile: {kind: polydyne-4567, lift: 1 in, rise: 90 deg, dwell: 90 deg, fall: 90 deg}, closure: form}
replay: {where: "speed_rpm == 11000"}    # cases to log to rerun while the study runs
"""  # noqa: E501 (the issue's text, verbatim)


def test_the_issue_example_works_exactly(tmp_path):
    path = write_spec(tmp_path, ISSUE_EXAMPLE)
    raw, _ = read_spec(path)
    assert not list(jsonschema.Draft202012Validator(study_schema()).iter_errors(raw))
    study = load_study(path)
    assert len(study.cases) == 39 * 3
    rpm = [c.values["speed"] * 30 / 3.141592653589793 for c in study.cases[::3]]
    assert rpm == pytest.approx([1000 + 500 * i for i in range(39)], rel=1e-12)
    assert [c.values["seat"] for c in study.cases[:3]][1:] == pytest.approx([0.00127, 0.00254])
    assert {c.values["profile"] for c in study.cases} == {"polydyne-4567 1 in 90/90/90/90 deg"}
    assert {c.case.closure for c in study.cases} == {"form"}
    assert study.spec.replay == "speed_rpm == 11000"
    assert len({c.case_id for c in study.cases}) == 117


@pytest.mark.parametrize(
    "text",
    [
        "!!python/object/apply:os.system ['touch {marker}']",
        "name: !!python/object/apply:os.system ['touch {marker}']",
        "name: !!python/name:os.system",
        "name: !!python/object:collections.OrderedDict {}",
    ],
)
def test_the_loader_uses_safe_yaml(tmp_path, text):
    marker = tmp_path / "pwned"
    with pytest.raises(SpecFileError, match="plain data"):
        parse_spec_text(text.replace("{marker}", str(marker)), "evil.yaml")
    assert not marker.exists()


def test_a_key_written_twice_is_refused():
    with pytest.raises(SpecFileError, match=r"line 3: key 'speed' appears twice"):
        parse_spec_text("name: t\nspeed: 9000 rpm\nspeed: 9524 rpm\n")


def test_a_merge_key_s_keys_may_be_overridden_as_yaml_says():
    """``{<<: *base, spring_preload: 130 lbf}`` takes the merged mapping with the key written
    beside it overriding the merged one (PyYAML's safe_load agrees); a key written twice
    beside a merge is still refused. Broken copy (a reliability helper's spec): refused as
    a key written twice."""
    import yaml

    text = (
        "name: t\nmodel: &m {preset: thesis-1971, spring_preload: 151 lbf}\n"
        "cases:\n  - {model: {<<: *m, spring_preload: 130 lbf}}\n"
    )
    parsed = parse_spec_text(text)
    assert parsed["cases"][0]["model"] == {"preset": "thesis-1971", "spring_preload": "130 lbf"}
    assert parsed == yaml.safe_load(text)
    twice = text.replace("130 lbf}}", "130 lbf, spring_preload: 120 lbf}}")
    with pytest.raises(SpecFileError, match=r"line 4: key 'spring_preload' appears twice"):
        parse_spec_text(twice)


def test_bad_yaml_names_the_file():
    with pytest.raises(SpecFileError, match="x.yaml: not valid YAML"):
        parse_spec_text("name: [unclosed", "x.yaml")


# Each class of bad input: (spec, key path, words the message must hold).
BAD = [
    # unknown keys, with a did-you-mean
    (with_(sped="9000 rpm"), "sped", "did you mean 'speed'"),
    (with_(model__spring_rat="245 lbf/in"), "model.spring_rat", "did you mean 'spring_rate'"),
    (with_(run__revolution=2), "run.revolution", "did you mean 'revolutions'"),
    (with_(profile__lfit="1 in"), "profile.lfit", "did you mean 'lift'"),
    (with_(sweep={"sped": ["9000 rpm"]}), "sweep.sped", "did you mean 'speed'"),
    (with_(closure="forced"), "closure", "did you mean 'force'"),
    # wrong types
    (with_(run__revolutions="four"), "run.revolutions", "expected a number"),
    (with_(profile="harmonic"), "profile", "expected a mapping"),
    (with_(defects={"kind": "flat"}), "defects", "expected a list of defects"),
    (with_(speed=["9000 rpm"]), "speed", "expected a quantity"),
    (with_(speed=["9000 rpm"]), "speed", "list its values under sweep: {speed: [...]}"),
    (with_(model__seat_restitution=[0, 0.5]), "model.seat_restitution", "expected a number"),
    (with_(model__seat_restitution=1.5), "model.seat_restitution", "at most 1"),
    (with_(run__record="q"), "run.record", "expected a list"),
    # bare numbers and wrong dimensions
    (with_(speed=9000), "speed", "bare number"),
    (with_(seat=0.1), "seat", "bare number"),
    (with_(run__dt=1e-6), "run.dt", "bare number"),
    (with_(speed="9000 in"), "speed", "angle"),
    (
        with_(defects=[{"kind": "flat", "from": 268, "to": "272 deg"}]),
        "defects[0].from",
        "bare number",
    ),
    (with_(model__spring_rate="245"), "model.spring_rate", "without units"),
    # empty grids
    (with_(sweep={"speed": []}), "sweep.speed", "empty list"),
    (
        with_(sweep={"speed": {"from": "1 rpm", "to": "2 rpm", "num": 0}}),
        "sweep.speed.num",
        "integer ≥ 1",
    ),
    (with_(cases=[]), "cases", "empty list"),
    (with_(sweep={}), "sweep", "empty"),
    # impossible values
    (with_(profile__lift="-1 in"), "profile.lift", "greater than 0"),
    (with_(seat="2 in"), "seat", "below the full valve lift 1.5 in"),
    (with_(sweep={"seat": ["none", "2 in"]}), "sweep.seat[1]", "full valve lift"),
    (with_(run__integrator="newmark-linear", run__dt="5 us"), "run.dt", "stability limit"),
    (
        with_(
            defects=[{"kind": "bump", "center": "90 deg", "height": "-0.1 in", "width": "20 deg"}]
        ),
        "defects",
        "below the base circle",
    ),
    (
        with_(
            profile={
                "kind": "polydyne-345",
                "lift": "1 in",
                "rise": "180 deg",
                "dwell": "180 deg",
                "fall": "90 deg",
            }
        ),
        "profile",
        "one turn",
    ),
    (with_(speed="-9000 rpm"), "speed", "greater than 0"),
    # structure of axes, cases and samples
    (with_(zip={"speed": ["1 rpm", "2 rpm"], "seat": ["none"]}), "zip", "equal lengths"),
    (with_(sweep={"run.revolutions": [1, 2]}), "sweep.run.revolutions", "whole study"),
    (with_(cases=[{"run": {"revolutions": 2}}]), "cases[0].run.revolutions", "whole study"),
    (
        with_(sweep={"speed": ["1000 rpm"]}, cases=[{"speed": "2000 rpm"}]),
        "cases[0].speed",
        "also varied by sweep.speed",
    ),
    (with_(sweep={"speed": ["9000 rpm", 9000]}), "sweep.speed[1]", "bare number"),
    (
        with_(
            sample={
                "method": "latin-hypercube",
                "n": 0,
                "seed": 1,
                "ranges": {"speed": {"from": "1 rpm", "to": "2 rpm"}},
            }
        ),
        "sample.n",
        "≥ 1",
    ),
    (
        with_(
            sample={
                "method": "latin-hypercub",
                "n": 2,
                "seed": 1,
                "ranges": {"speed": {"from": "1 rpm", "to": "2 rpm"}},
            }
        ),
        "sample.method",
        "did you mean 'latin-hypercube'",
    ),
    (
        with_(
            sample={
                "method": "latin-hypercube",
                "n": 2,
                "seed": 1,
                "ranges": {"closure": {"from": "a", "to": "b"}},
            }
        ),
        "sample.ranges.closure",
        "unknown key",
    ),
    (with_(replay={"where": "open('os')"}), "replay.where", "a call is not allowed"),
    # missing pieces
    ({k: v for k, v in BASE.items() if k != "speed"}, "speed", "missing"),
    ({k: v for k, v in BASE.items() if k != "name"}, "name", "missing"),
    (with_(profile={"kind": "polydyne-345", "lift": "1 in"}), "profile.rise", "missing"),
    (
        with_(profile={"kind": "table", "file": "nowhere.csv"}),
        "profile.file",
        "relative to the spec",
    ),
]


@pytest.mark.parametrize(("raw", "path", "words"), BAD, ids=[b[1] + ":" + b[2] for b in BAD])
def test_bad_input_is_refused_with_its_key_path(raw, path, words):
    error = refused(raw)
    assert path in error.paths, str(error)
    problem = error.problems[error.paths.index(path)]
    assert words in problem.message, str(error)


def test_all_problems_are_reported_at_once():
    error = refused(with_(speed=9000, seat=0.1, sped=1))
    assert {"speed", "seat", "sped"} <= set(error.paths)
    assert str(error).startswith("spec: 3 problems")


def test_a_problem_in_many_cases_is_reported_once_with_the_cases():
    error = refused(with_(seat="1.6 in", sweep={"speed": ["1000 rpm", "2000 rpm", "3000 rpm"]}))
    assert error.paths == ["seat"]
    assert "(3 cases: 0, 1, 2)" in str(error)


# -- property tests: generated bad specs ------------------------------------------------------

DIMENSIONAL = [
    "speed",
    "seat",
    "profile__lift",
    "run__dt",
    "run__output_every",
    "model__spring_rate",
    "model__pushrod_length",
    "model__spring_preload",
]
CONTAINERS = {
    "": list(TOP_LEVEL),
    "model": ["preset", *PARAMETERS],
    "run": [k.removeprefix("run.") for k in CASE_FIELDS if k.startswith("run.")],
    "profile": ["kind", *PROFILE_FIELDS],
}
NUMBERS = st.one_of(st.integers(1, 10**6), st.floats(1e-3, 1e6, allow_nan=False))
WRONG_TYPES = st.one_of(
    st.lists(st.integers(), max_size=2),
    st.booleans(),
    st.dictionaries(st.sampled_from("abc"), st.integers(), max_size=2),
)


@st.composite
def bad_specs(draw):
    """(spec, expected key path) for one generated mistake."""
    kind = draw(st.sampled_from(["unknown", "bare", "type", "empty", "lift", "seat", "dt"]))
    if kind == "unknown":
        where = draw(st.sampled_from(sorted(CONTAINERS)))
        key = draw(
            st.from_regex(r"[a-z]{1,8}(_[a-z]{1,8}){0,2}", fullmatch=True).filter(
                lambda k: k not in CONTAINERS[where]
            )
        )
        return with_(
            **{f"{where}__{key}" if where else key: "1 in"}
        ), f"{where}.{key}" if where else key
    if kind == "bare":
        key = draw(st.sampled_from(DIMENSIONAL))
        return with_(**{key: draw(NUMBERS)}), key.replace("__", ".")
    if kind == "type":
        key = draw(st.sampled_from([*DIMENSIONAL, "closure", "run__revolutions"]))
        return with_(**{key: draw(WRONG_TYPES)}), key.replace("__", ".")
    if kind == "empty":
        key = draw(st.sampled_from(sweep_keys()))
        return with_(sweep={key: []}), f"sweep.{key}"
    if kind == "lift":
        x = draw(st.floats(0, 10, allow_nan=False))
        return with_(profile__lift=f"{-x} in"), "profile.lift"
    if kind == "seat":
        x = draw(st.floats(1.5, 100, allow_nan=False))
        return with_(seat=f"{x} in"), "seat"
    x = draw(st.floats(3.3, 1000, allow_nan=False))
    return with_(run__integrator="newmark-linear", run__dt=f"{x} us"), "run.dt"


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad_specs())
def test_generated_bad_specs_are_refused_with_their_key_path(case):
    raw, path = case
    error = refused(raw)
    assert path in error.paths, str(error)


@settings(max_examples=40, deadline=None)
@given(
    speed=st.floats(100, 20000),
    seat=st.one_of(st.none(), st.floats(0, 1.45)),
    closure=st.sampled_from(["force", "form"]),
)
def test_generated_good_specs_are_accepted_by_checker_and_schema(speed, seat, closure):
    raw = with_(
        speed=f"{speed} rpm", seat="none" if seat is None else f"{seat} in", closure=closure
    )
    assert not list(jsonschema.Draft202012Validator(study_schema()).iter_errors(raw))
    study = expand(check_spec(raw))
    assert len(study.cases) == 1
    assert study.cases[0].case.speed == pytest.approx(speed * 3.141592653589793 / 30, rel=1e-12)


def test_schema_refuses_the_shape_level_mistakes():
    validator = jsonschema.Draft202012Validator(study_schema())
    for raw, path in [
        (with_(speed=9000), ["speed"]),
        (with_(sped="1 rpm"), []),
        (with_(sweep={"speed": []}), ["sweep", "speed"]),
        (with_(run__record=["x"]), ["run", "record", 0]),
    ]:
        errors = list(validator.iter_errors(raw))
        assert errors, raw
        assert any(list(e.absolute_path) == path for e in errors), [e.message for e in errors]


def test_overrides_apply_before_checking():
    spec = check_spec(
        with_(sweep={"speed": ["1000 rpm", "2000 rpm"]}),
        overrides={
            "run.revolutions": 2,
            "sweep.speed": ["3000 rpm"],
            "model.spring_preload": "140 lbf",
        },
    )
    assert spec.base["run"]["revolutions"] == 2
    assert spec.sweep == {"speed": ["3000 rpm"]}
    assert spec.base["model"]["spring_preload"] == "140 lbf"
    error = refused(BASE, overrides={"run.revolution": 2})
    assert error.paths == ["run.revolution"]


def test_yaml_key_order_and_comments_do_not_matter(tmp_path):
    a = write_spec(
        tmp_path, "name: t\nspeed: 9000 rpm\nprofile: {kind: harmonic, lift: 1 in}\n", "a.yaml"
    )
    b = write_spec(
        tmp_path,
        "# c\nprofile: {lift: 1 in, kind: harmonic}\nname: t\nspeed: 9000 rpm  # c\n",
        "b.yaml",
    )
    assert load_study(a).cases[0].case_id == load_study(b).cases[0].case_id


def test_example_yaml_round_trips_through_safe_dump():
    raw, _ = read_spec(STUDIES / "separation-map.yaml")
    assert yaml.safe_load(yaml.safe_dump(raw)) == raw


def test_the_run_block_follows_the_engines_run_settings():
    """Every RunSettings field has a spec key with metadata; defaults are the engine's."""
    import dataclasses

    from campipe.engine import RunSettings
    from campipe.study.spec.fields import RUN_DEFAULTS, RUN_SETTINGS, undeclared_run_settings

    assert undeclared_run_settings() == []
    assert set(RUN_DEFAULTS) == {f.name for f in dataclasses.fields(RunSettings)} | {
        "record",
        "compression",
    }
    assert set(RUN_SETTINGS) == {f.name for f in dataclasses.fields(RunSettings)}
    settings = expand(check_spec(BASE)).cases[0].settings
    defaults = RunSettings()
    for name in RUN_SETTINGS:
        if name not in ("revolutions", "integrator"):
            assert getattr(settings, name) == getattr(defaults, name), name


def test_settings_the_engine_refuses_are_refused_before_running():
    error = refused(with_(run__fidelity="reduced"))
    assert error.paths == ["run.fidelity"] and "expected one of: full" in str(error)


def test_the_docs_spec_example_is_valid():
    text = (ROOT / "docs" / "studies.md").read_text()
    block = text.split("## The spec")[1].split("```yaml")[1].split("```")[0]
    raw = yaml.safe_load(block)
    assert not list(jsonschema.Draft202012Validator(study_schema()).iter_errors(raw))
    study = expand(check_spec(raw))
    assert len(study.cases) == 2 * 39 * 3 * 2 * 4
    assert len({c.case_id for c in study.cases}) == len(study.cases)


def test_a_boolean_is_not_a_number_even_after_the_number_was_seen():
    """Parsed values are cached; True == 1 in Python, but not in a spec."""
    expand(check_spec(with_(run__revolutions=1)))
    error = refused(with_(run__revolutions=True))
    assert error.paths == ["run.revolutions"] and "expected a number" in str(error)


def test_a_ramp_as_high_as_the_lift_is_refused_at_its_key_in_its_units(tmp_path):
    """``ramp_height: 2 in`` on a 1 in lift is refused at ``profile.ramp_height``, as
    written, beside the lift. Broken copy (a reliability helper's spec): refused at
    ``profile`` as "got 0.0508 m"."""
    spec = write_spec(
        tmp_path,
        """
        name: t
        profile: {kind: polydyne-345, lift: 1 in, rise: 90 deg, dwell: 0 deg, fall: 90 deg,
                  ramp_height: 2 in, ramp_duration: 30 deg}
        speed: 3000 rpm
        """,
    )
    with pytest.raises(SpecError) as caught:
        load_study(spec)
    assert caught.value.paths == ["profile.ramp_height"]
    assert "found '2 in', expected a ramp below the lift ('1 in')" in str(caught.value)


def test_an_archive_given_as_the_spec_is_told_so(tmp_path):
    """A netCDF file (HDF5's signature) given where a spec goes is told it looks like an
    archive and which commands read one; other binary text is told it is not UTF-8 text.
    Broken copy (a reliability helper's run): both "not UTF-8 text"."""
    archive = tmp_path / "run.nc"
    archive.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(128, 256)))
    with pytest.raises(SpecFileError, match=r"a netCDF file \(an archive\?\), not the spec"):
        read_spec(archive)
    other = tmp_path / "other.yaml"
    other.write_bytes(bytes(range(128, 256)))
    with pytest.raises(SpecFileError, match="not UTF-8 text; the spec is a text file"):
        read_spec(other)


def test_a_speed_with_its_units_twice_says_how_it_was_read(tmp_path):
    """``speed: 9000 rpm rpm`` reads as rpm², which names no single angle: the refusal says
    so (a reliability helper was told only that it "names no angle")."""
    spec = write_spec(tmp_path, "name: t\nspeed: 9000 rpm rpm\n")
    with pytest.raises(SpecError, match=r"speed: found '9000 rpm rpm' \(read as rpm²\)"):
        load_study(spec)
