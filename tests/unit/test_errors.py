"""One error base: every campipe exception is a CampipeError carrying key, found and expected,
and the study layer maps errors by those attributes, never by taking their text apart."""

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import campipe
from campipe.engine import (
    Case,
    CaseError,
    RunSettings,
    RunSettingsError,
    StabilityError,
    check_run,
    resolve_integrator,
)
from campipe.errors import CampipeError
from campipe.model import ModelParameterError, parse_parameter, thesis_train
from campipe.profiles import harmonic
from campipe.study import SpecError, check_spec, expand
from campipe.study.spec.fields import SpecProblem
from campipe.units import QuantityError, parse_angular, parse_quantity

ROOT = Path(campipe.__file__).parent
#: The builtin each error also is, so callers that caught it before keep working.
BUILTINS = {
    "QuantityError": ValueError,
    "ModelParameterError": ValueError,
    "RunSettingsError": ValueError,
    "StabilityError": ValueError,
    "CaseError": ValueError,
    "IntegrationError": RuntimeError,
    "DefectiveModesError": ValueError,
    "ChatterError": RuntimeError,
    "SpecFileError": ValueError,
    "LiftTableError": ValueError,
    "ArchiveFileError": RuntimeError,
    "ArchiveBusyError": RuntimeError,
    "SpecProblem": ValueError,
    "SpecError": ValueError,
    "QueryError": ValueError,
    "ReplayError": ValueError,
}


def campipe_exceptions() -> dict[str, type]:
    """Every exception class defined in a campipe module, by name."""
    found = {}
    for info in pkgutil.walk_packages([str(ROOT)], "campipe."):
        if info.name == "campipe.__main__":
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (
                inspect.isclass(obj)
                and issubclass(obj, BaseException)
                and obj.__module__ == info.name
            ):
                found[name] = obj
    return found


#: Not errors a caller handles but a stop, as KeyboardInterrupt is: a read left inside HDF5
#: (``campipe.io.watch``) holds the library, so a handler that takes a damaged file as one to
#: compute again (``except Exception``) must not catch it and go on to write netCDF; and
#: SIGTERM in a running command (``campipe.cli.base.Terminated``, a KeyboardInterrupt, so that
#: a run does on it what it does on Ctrl-C). Checked below to stay outside Exception.
STOPS = ("ReadStalled", "Terminated")


def test_every_campipe_exception_derives_from_campipe_error_and_its_builtin():
    classes = campipe_exceptions()
    assert set(BUILTINS) <= set(classes)
    for name, cls in classes.items():
        if name in STOPS:
            assert not issubclass(cls, Exception), name
            continue
        assert issubclass(cls, CampipeError), name
        if name in BUILTINS:
            assert issubclass(cls, BUILTINS[name]), name


def test_quantity_errors_carry_key_found_and_expected():
    with pytest.raises(QuantityError) as info:
        parse_quantity(9000, "rad/s", "speed", "rpm")
    e = info.value
    assert (e.key, e.found, e.expected) == ("speed", 9000, "a quantity in rpm")
    assert str(e) == f"speed: {e.reason}" and "bare number" in e.reason
    with pytest.raises(QuantityError) as info:
        parse_angular("1 Hz", "rad/s", "speed", "rpm")
    assert (info.value.key, info.value.found) == ("speed", "1 Hz")


def test_model_parameter_errors_carry_the_element_key():
    with pytest.raises(ModelParameterError) as info:
        parse_parameter(
            "damping_ratios", [0.5, -0.1, 0.1, 0.1, 0.1, 0.1, 0.1], "model.damping_ratios"
        )
    e = info.value
    assert (e.key, e.found) == ("model.damping_ratios[1]", -0.1)
    assert str(e) == f"{e.key}: {e.reason}"


@pytest.mark.parametrize(
    ("name", "raw", "bound"),
    [("spring_preload", "-50 N", "at least 0 N"), ("spring_preload", "-5 lbf", "at least 0 lbf"),
     ("valve_mass", "-5 g", "greater than 0 g"), ("valve_mass", "-5e-3 kg", "greater than 0 kg")],
)  # fmt: skip
def test_a_bound_is_shown_in_the_units_the_value_was_written_in(name, raw, bound):
    """A refused value's bound in its own units (campipe before: '-50 N' was told "at least 0
    lbf", the thesis's units, in an SI spec)."""
    with pytest.raises(ModelParameterError) as info:
        parse_parameter(name, raw, f"model.{name}")
    assert info.value.expected == f"a finite value {bound}"


def test_engine_errors_name_the_run_key_as_an_attribute():
    with pytest.raises(RunSettingsError) as info:
        resolve_integrator("euler")
    assert (info.value.key, info.value.found) == ("run.integrator", "euler")
    case = Case(thesis_train(), harmonic(0.0254), 1000.0)
    with pytest.raises(RunSettingsError) as info:
        check_run([case], RunSettings(fidelity="reduced"))
    assert (info.value.key, info.value.found) == ("run.fidelity", "reduced")
    assert "'reduced' was removed: it saved at most a fifth" in str(info.value)
    with pytest.raises(RunSettingsError) as info:
        check_run([case], RunSettings(tolerance=0.0))
    assert info.value.key == "run.tolerance"
    with pytest.raises(CaseError) as info:
        check_run([case, Case(thesis_train(), harmonic(0.0254), -1.0)], RunSettings())
    assert (info.value.key, info.value.found) == ("speed", -1.0)
    assert str(info.value) == "speed: case 1 has -1.0 rad/s, expected > 0"


def test_a_stability_error_keeps_its_key_found_and_a_reason_without_the_case():
    case = Case(thesis_train(), harmonic(0.0254), 1000.0)
    with pytest.raises(StabilityError) as info:
        check_run([case, case], RunSettings(integrator="newmark-linear", dt=5e-6))
    e = info.value
    assert isinstance(e, RunSettingsError)
    assert (e.key, e.found) == ("run.dt", 5e-6)
    assert str(e).startswith(
        "run.dt: 5 µs is beyond the stability limit of newmark-linear for case 0 ("
    )
    assert e.reason == str(e).removeprefix("run.dt: ").replace(" for case 0", "")
    assert e.expected.startswith("a step below ")


def test_the_study_reports_an_engine_error_at_its_key_with_its_reason():
    raw = {
        "name": "s",
        "profile": {"kind": "harmonic", "lift": "1 in"},
        "speed": "9000 rpm",
        "run": {"integrator": "newmark-linear", "dt": "5 us"},
    }
    with pytest.raises(SpecError) as info:
        expand(check_spec(raw))
    (problem,) = info.value.problems
    assert problem.key == problem.path == "run.dt"
    assert problem.found == pytest.approx(5e-6) and "for case 0" not in problem.message
    assert problem.message.startswith("5 µs is beyond the stability limit of newmark-linear (")


def test_spec_problem_from_an_error_takes_its_attributes():
    error = QuantityError.at("seat", "found '1'", found="1", expected="a quantity in in")
    problem = SpecProblem.from_error(error)
    assert (problem.path, problem.message, problem.found, problem.expected) == (
        "seat",
        "found '1'",
        "1",
        "a quantity in in",
    )
    assert SpecProblem.from_error(error, "sweep.seat[0]").path == "sweep.seat[0]"


def test_no_caller_takes_an_error_message_apart():
    """``str(exc).partition(...)``, ``.removeprefix``, ``.split`` and the like on an error's text
    are refused everywhere in campipe: errors are mapped by their attributes."""
    methods = {"partition", "rpartition", "removeprefix", "removesuffix", "split", "rsplit"}
    for path in ROOT.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        handlers = [n for n in ast.walk(tree) if isinstance(n, ast.ExceptHandler) and n.name]
        for handler in handlers:
            for node in ast.walk(handler):
                if (
                    isinstance(node, ast.Call)
                    and isinstance(node.func, ast.Attribute)
                    and node.func.attr in methods
                    and isinstance(node.func.value, ast.Call)
                    and isinstance(node.func.value.func, ast.Name)
                    and node.func.value.func.id == "str"
                    and any(
                        isinstance(a, ast.Name) and a.id == handler.name
                        for a in node.func.value.args
                    )
                ):
                    pytest.fail(f"{path}:{node.lineno}: {ast.unparse(node)}")
