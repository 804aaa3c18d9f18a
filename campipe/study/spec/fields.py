"""The keys of a study spec, declared once.

Validation (:mod:`campipe.study.spec.check`), the JSON Schema
(:mod:`campipe.study.spec.schema`) and the archive's per-case coordinates
(:mod:`campipe.study.spec.variables`) all read these tables; the model's parameters come from
:data:`campipe.model.PARAMETERS` and the run defaults from :class:`campipe.engine.RunSettings`,
so nothing here repeats them.

A *case* is one run: a valve train (``model``), a cam (``profile`` plus ``defects``), how it is
driven (``speed``, ``seat``, ``closure``) and how it is integrated (``run``). Keys inside a case
are written as dotted paths: ``speed``, ``profile.lift``, ``model.spring_preload``, ``run.dt``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from campipe.constants import RPM
from campipe.engine import MEMBER_LOADS, SPRING_HISTORIES, RunSettings
from campipe.engine import settings as _engine_settings
from campipe.engine.settings import ALL_INTEGRATORS
from campipe.errors import CampipeError, did_you_mean, excerpt
from campipe.io.compression import COMPRESSION, COMPRESSIONS
from campipe.model import PARAMETERS, PRESETS, ModelParameterError, parse_parameter
from campipe.profiles import RAMP_SHAPES
from campipe.units import QuantityError, convert, parse_angular, parse_quantity

#: Bounds of sense on a spec's quantities [SI]: beyond them the numbers overflow or the
#: geometry stops meaning anything (a lift of a kilometre, a cam at a million rpm).
MAX_SPEED = 1e6 * RPM  # [rad/s]: 1e6 rpm
MAX_LENGTH = 1.0  # [m]: lifts, seat positions, bump heights
MAX_ANGLE = 4 * math.pi  # [rad]: defect angles, up to 720 deg (a flat may wrap past 360)


class SpecProblem(CampipeError, ValueError):
    """One problem in a spec: the key's path (``key``, also ``path``) and the message
    (``reason``, also ``message``); ``found`` and ``expected`` where the problem came from an
    error that had them."""

    def __init__(
        self, path: str, message: str, *, found: object = None, expected: str | None = None
    ) -> None:
        super().__init__(
            f"{path}: {message}" if path else message,
            key=path,
            found=found,
            expected=expected,
            reason=message,
        )
        self.path = path
        self.message = message

    @classmethod
    def from_error(cls, error: CampipeError, path: str | None = None) -> SpecProblem:
        """The problem ``error`` names: at its key (or at ``path``, where the caller knows the
        spec path better), with its reason, found and expected."""
        return cls(
            path or error.key or "", error.reason, found=error.found, expected=error.expected
        )


@dataclass(frozen=True)
class Field:
    """One key of a case, its type and its meaning."""

    key: str  # dotted path inside a case: "speed", "run.dt", "profile.lift"
    kind: str  # "quantity", "number", "integer", "choice", "text", "record" or "parameter"
    description: str  # what it means (JSON Schema description, error messages)
    units: str = ""  # SI units the numerics take (pint spelling); quantities only
    example: str = ""  # units suggested in messages and the schema ("rpm", "in", "deg")
    minimum: float | None = None  # smallest allowed SI value
    exclusive_minimum: bool = True  # minimum itself refused
    maximum: float | None = None  # largest allowed SI value (a bound on sense, not on taste)
    choices: tuple[str, ...] = ()  # allowed words ("choice"), allowed items ("record")
    allow_none: bool = False  # "none" (or null) accepted, meaning absent (seat)
    allow_default: bool = False  # "default" accepted, meaning the engine's choice (run.dt)
    allow_auto: bool = False  # "auto" accepted, meaning until settled (run.revolutions)
    archive_name: str | None = None  # name of its per-case coordinate in the archive
    archive_units: str | None = None  # units of that coordinate (pint spelling)

    @property
    def angular(self) -> bool:
        """An angle or angular speed: its units must name an angle (see parse_angular)."""
        return "rad" in self.units

    def parse(self, value: object, path: str) -> Any:
        """The value in SI (floats), a word, or None for "none"; raises SpecProblem.

        Its type follows the field's kind (a float for a quantity or number, an int for an
        integer, a str for a choice or text, a tuple for a record or a list parameter).
        Scalar values are parsed once (a grid repeats its values in every case)."""
        if isinstance(value, str | int | float | bool | None):
            return _parse_scalar(self, value, path)
        return self._parse(value, path)

    def _parse(self, value: object, path: str) -> Any:
        if self.allow_none and (value is None or value == "none"):
            return None
        if (self.allow_default and value == "default") or (self.allow_auto and value == "auto"):
            return None
        if self.kind == "quantity":
            return self._quantity(value, path)
        if self.kind in ("number", "integer"):
            return self._number(value, path)
        if self.kind == "choice":
            return _choice(value, self.choices, path, self.description)
        if self.kind == "text":
            if not isinstance(value, str) or not value.strip():
                raise SpecProblem(path, f"found {excerpt(value)}, expected a non-empty string")
            return value
        if self.kind == "parameter":
            _plain(value, path)
            try:
                return parse_parameter(self.key.removeprefix("model."), value, path)
            except ModelParameterError as exc:
                raise SpecProblem.from_error(exc) from None
        if self.kind == "record":
            if not isinstance(value, list):
                raise SpecProblem(
                    path, f"found {excerpt(value)}, expected a list of: {', '.join(self.choices)}"
                )
            return tuple(
                _choice(v, self.choices, f"{path}[{i}]", "what to record")
                for i, v in enumerate(value)
            )
        raise AssertionError(self.kind)

    def _quantity(self, value: object, path: str) -> float:
        try:
            if self.angular:
                v = parse_angular(value, self.units, path, self.example)
            else:
                v = parse_quantity(value, self.units, path, self.example)
        except QuantityError as exc:
            raise SpecProblem.from_error(exc) from None
        self._check_range(v, value, path)
        return v

    def _number(self, value: object, path: str) -> float | int:
        integer = self.kind == "integer"
        number = value if isinstance(value, int | float) and not isinstance(value, bool) else None
        if number is None or (integer and not isinstance(number, int)):
            what = "an integer" if integer else "a number"
            raise SpecProblem(path, f"found {excerpt(value)}, expected {what}")
        self._check_range(float(number), value, path)
        return int(number) if integer else float(number)

    def _check_range(self, v: float, raw: object, path: str) -> None:
        if not math.isfinite(v):
            raise SpecProblem(path, f"found {excerpt(raw)}, expected a finite value")
        if self.maximum is not None and v > self.maximum:
            shown = convert(self.maximum, self.units, self.example) if self.example else v
            unit = f" {self.example}" if self.example else ""
            raise SpecProblem(
                path,
                f"found {excerpt(raw)}, expected a value at most {shown:g}{unit}",
                found=raw,
                expected=f"at most {shown:g}{unit}",
            )
        if self.minimum is None:
            return
        if v < self.minimum or (self.exclusive_minimum and v == self.minimum):
            relation = "greater than" if self.exclusive_minimum else "at least"
            unit = f" {self.example}" if self.example else ""
            raise SpecProblem(
                path, f"found {excerpt(raw)}, expected a value {relation} {self.minimum:g}{unit}"
            )


#: Longest list a model parameter takes (damping_ratios: one per mode).
MAX_PARAMETER_LENGTH = 16


def _plain(value: object, path: str) -> None:
    """A model parameter's value is a scalar or a short list of scalars: refused otherwise
    before the model's parser sees (and quotes) it."""
    if isinstance(value, list | tuple):
        if len(value) > MAX_PARAMETER_LENGTH or not all(
            isinstance(v, str | int | float) and not isinstance(v, bool) for v in value
        ):
            raise SpecProblem(
                path,
                f"found {excerpt(value)}, expected a number or quantity, or a short list of "
                "numbers (damping_ratios)",
            )
    elif not isinstance(value, str | int | float | None) or (
        isinstance(value, str) and len(value) > 200
    ):
        raise SpecProblem(path, f"found {excerpt(value)}, expected a number or quantity")


@functools.lru_cache(maxsize=8192, typed=True)  # typed: True is not 1
def _parse_scalar(field: Field, value: object, path: str) -> Any:
    return field._parse(value, path)


def _choice(value: object, choices: Iterable[str], path: str, what: str) -> str:
    choices = tuple(choices)
    if isinstance(value, str) and value in choices:
        return value
    hint = did_you_mean(value, choices) if isinstance(value, str) else ""
    raise SpecProblem(
        path,
        f"found {excerpt(value)}, expected one of: {', '.join(choices)}{hint}"
        + (f" ({what})" if what else ""),
    )


#: Spec metadata of the engine's RunSettings fields, by field name. A spec's ``run:`` block
#: holds exactly the fields RunSettings has (plus ``record``); the defaults are RunSettings's.
_RUN_METADATA: dict[str, Field] = {
    f.key.removeprefix("run."): f
    for f in [
        Field(
            "run.revolutions",
            "number",
            "cam turns to integrate, from θ = 0; auto (the default): each case until its "
            "response repeats (with a period of up to run.max_period turns, to "
            "run.settle_tolerance) or run.max_revolutions, its metrics the settled response's "
            "and its last run.history_turns recorded",
            minimum=0.0,
            allow_auto=True,
        ),
        Field(
            "run.history_turns",
            "integer",
            "with run.revolutions: auto, the last turns whose histories and events are stored",
            minimum=1.0,
            exclusive_minimum=False,
        ),
        Field(
            "run.max_revolutions",
            "integer",
            "with run.revolutions: auto, the most turns a case runs; a case not repeating by "
            "then reports its second half's statistics (mean per turn, largest) and "
            "period_turns 0",
            minimum=2.0,
            exclusive_minimum=False,
        ),
        Field(
            "run.settle_tolerance",
            "number",
            "with run.revolutions: auto, how closely the states at turn boundaries a period "
            "apart must agree, relative to each coordinate's and velocity's range over a turn "
            "(and the distance left to the periodic response, from the transient's "
            "contraction per period)",
            minimum=0.0,
        ),
        Field(
            "run.max_period",
            "integer",
            "with run.revolutions: auto, the longest period [turns] a response is checked for",
            minimum=1.0,
            exclusive_minimum=False,
        ),
        Field(
            "run.dt",
            "quantity",
            "time step (an integrator that sizes its own steps "
            "takes it as its largest); default: the integrator's own",
            units="s",
            example="us",
            minimum=0.0,
            allow_default=True,
            archive_name="dt",
            archive_units="s",
        ),
        Field(
            "run.output_every",
            "quantity",
            "cam-angle spacing of the stored histories",
            units="rad",
            example="deg",
            minimum=0.0,
        ),
        Field(
            "run.integrator",
            "choice",
            "integrator name; default: the engine's default integrator",
            choices=("default", *ALL_INTEGRATORS),
            archive_name="integrator",
        ),
        Field(
            "run.tolerance",
            "quantity",
            "event-time tolerance of integrators that locate events (compliant: the relative "
            "tolerance, no finer than 1e-10)",
            units="s",
            example="s",
            minimum=0.0,
            archive_name="tolerance",
            archive_units="s",
        ),
        Field(
            "run.max_events",
            "integer",
            "events kept per case",
            minimum=1.0,
            exclusive_minimum=False,
            archive_name="max_events",
        ),
        Field(
            "run.max_steps",
            "integer",
            "the most integration steps of one case at run time (the compliant integrator's "
            "adaptive steps; the fixed-step integrators are bounded from the spec before the "
            "run): a case that needs more stops there with status step_limit, the others go "
            "on; campipe study and validate --max-steps set it",
            minimum=1.0,
            exclusive_minimum=False,
            archive_name="max_steps",
        ),
        Field(
            "run.fidelity",
            "choice",
            "full: every case through its events with every mode; steady: a case that follows "
            "the cam with the valve clear of its seat from its closed-form steady state (one "
            "turn, repeated), the others in full (periodic start, modal-exact)",
            choices=tuple(getattr(_engine_settings, "FIDELITIES", ("full",))),
            archive_name="fidelity",
        ),
        Field(
            "run.fidelity_tolerance",
            "quantity",
            "a valve-lift error the run accepts instead of a level: campipe takes the "
            "cheapest level whose stated error is within it (steady: 1e-9 in); default: "
            "run.fidelity as named",
            units="m",
            example="in",
            minimum=0.0,
            exclusive_minimum=False,
            allow_default=True,
            allow_none=True,
            archive_name="fidelity_tolerance",
            archive_units="m",
        ),
        Field(
            "run.start",
            "choice",
            "periodic: on the periodic steady state of configuration I (where it does not "
            "hold at θ = 0, from the latest angle where it does, unrecorded up to θ = 0); "
            "quasi-static: the thesis's start at θ = 0 (Appendix B, step 1), a transient",
            choices=tuple(getattr(_engine_settings, "STARTS", ("periodic",))),
            archive_name="start",
        ),
        Field(
            "run.warmup",
            "integer",
            "turns integrated but left out of every metric; default: 0 with the periodic "
            "start, 1 with the quasi-static",
            minimum=0.0,
            exclusive_minimum=False,
            allow_default=True,
            archive_name="warmup",
        ),
        Field(
            "run.capture_velocity",
            "quantity",
            "an impact closing slower than this leaves its contact resting (not counted; a "
            "release it closes again at once is taken back); 0: never",
            units="m/s",
            example="mm/s",
            minimum=0.0,
            exclusive_minimum=False,
            archive_name="capture_velocity",
            archive_units="m/s",
        ),
    ]
}

#: RunSettings fields in engine order (those the spec declares).
RUN_SETTINGS = tuple(f.name for f in dataclasses.fields(RunSettings) if f.name in _RUN_METADATA)


def undeclared_run_settings() -> list[str]:
    """RunSettings fields without spec metadata (a test keeps this empty)."""
    return [f.name for f in dataclasses.fields(RunSettings) if f.name not in _RUN_METADATA]


def _spec_default(name: str, value: Any) -> object:
    """A RunSettings default in spec spelling."""
    f = _RUN_METADATA[name]
    if value is None:
        return "default"
    if f.kind == "quantity":
        if f.angular and f.example == "deg":
            return f"{math.degrees(value):g} deg"
        return f"{value!r} {f.units}"
    return value


#: Keys of a case that are not model parameters, profile or defect fields.
CASE_FIELDS: dict[str, Field] = {
    f.key: f
    for f in [
        Field(
            "speed",
            "quantity",
            "cam speed",
            units="rad/s",
            example="rpm",
            minimum=0.0,
            maximum=MAX_SPEED,
            archive_name="speed_rpm",
            archive_units="rpm",
        ),
        Field(
            "seat",
            "quantity",
            "valve seat position, as a valve lift; none: no seat",
            units="m",
            example="in",
            minimum=0.0,
            exclusive_minimum=False,
            maximum=MAX_LENGTH,
            allow_none=True,
            archive_name="seat",
            archive_units="m",
        ),
        Field(
            "closure",
            "choice",
            "force: the spring holds the follower on the cam and it may separate; "
            "form: a second cam holds it, it never separates",
            choices=("force", "form"),
            archive_name="closure",
        ),
        *(_RUN_METADATA[name] for name in RUN_SETTINGS),
        Field(
            "run.record",
            "record",
            "optional histories to store: q (the thesis's seven coordinates), member_loads "
            "(all member loads, and the least force through the joints that only push, "
            "min_joint_force, per revolution) or single member loads by name, spring (the "
            "spring's force, largest element force and coil-clash margin, and their "
            "per-revolution metrics) "
            "or single spring histories by name; contact_pressure: the peak Hertz pressure "
            "at the cam and the seat per revolution; cam_normal_force: a lever layout's "
            "roller force on the cam (the cam force times the lever ratio); lash_adjuster: "
            "a hydraulic lash adjuster's extension, effective lash, leak-down and pump-up per "
            "revolution",
            choices=(
                "q",
                "member_loads",
                *MEMBER_LOADS,
                "spring",
                *SPRING_HISTORIES,
                "contact_pressure",
                "cam_normal_force",
                "lash_adjuster",
            ),  # fmt: skip
        ),
        Field(
            "run.compression",
            "choice",
            "how the archive is compressed: zstd (the default: written and read faster than "
            "zlib, the file somewhat larger; read by netCDF-C 4.9 or later with its filter "
            "plugins, as the netCDF4 wheels install them); zlib: readable by every netCDF-4 "
            "reader; none",
            choices=tuple(COMPRESSIONS),
        ),
    ]
}

#: The engine's speed, where a spec gives it instead of the cam's (with ``drive``; written as
#: the cam's ``speed`` before the spec is checked: :mod:`campipe.study.spec.drive`).
ENGINE_SPEED = Field(
    "engine_speed",
    "quantity",
    "engine (crankshaft) speed, instead of the cam's speed: the cam turns at engine_speed "
    "× drive.cam_per_crank (needs drive)",
    units="rad/s",
    example="rpm",
    minimum=0.0,
    maximum=MAX_SPEED,
    archive_name="engine_speed_rpm",
    archive_units="rpm",
)

#: Run keys whose value the whole study shares: they fix the archive's cam_angle axis, its
#: variables or its compression, so a sweep, zip, sample or case may not vary them.
STUDY_WIDE = (
    "run.revolutions",
    "run.history_turns",
    "run.max_revolutions",
    "run.settle_tolerance",
    "run.max_period",
    "run.output_every",
    "run.record",
    "run.start",
    "run.warmup",
    "run.compression",
)

#: Defaults of the run keys, in spec spelling, from the engine's RunSettings.
RUN_DEFAULTS: dict[str, object] = {
    **{
        f.name: _spec_default(f.name, f.default)
        for f in dataclasses.fields(RunSettings)
        if f.name in _RUN_METADATA
    },
    "record": [],
    "compression": COMPRESSION,
    # a spec's run length is by convergence unless it fixes one (the engine's RunSettings
    # keeps a fixed default, for its callers)
    "revolutions": "auto",
}

#: Profile kinds → their keys (all required).
PROFILE_KINDS: dict[str, tuple[str, ...]] = {
    "harmonic": ("lift",),
    "polydyne-345": ("lift", "rise", "dwell", "fall"),
    "polydyne-4567": ("lift", "rise", "dwell", "fall"),
    "table": ("file",),
}
#: Profile kinds → their optional keys: opening and closing ramps (height and duration
#: together; the shape defaults to constant-velocity).
PROFILE_OPTIONAL: dict[str, tuple[str, ...]] = {
    "polydyne-345": ("ramp_height", "ramp_duration", "ramp_shape"),
    "polydyne-4567": ("ramp_height", "ramp_duration", "ramp_shape"),
}

PROFILE_FIELDS: dict[str, Field] = {
    f.key.removeprefix("profile."): f
    for f in [
        Field(
            "profile.lift",
            "quantity",
            "full lift of the cam",
            units="m",
            example="in",
            minimum=0.0,
            maximum=MAX_LENGTH,
            archive_name="profile_lift",
            archive_units="m",
        ),
        Field(
            "profile.rise",
            "quantity",
            "angle of the rise",
            units="rad",
            example="deg",
            minimum=0.0,
            maximum=2 * math.pi,
            archive_name="profile_rise",
            archive_units="deg",
        ),
        Field(
            "profile.dwell",
            "quantity",
            "angle of the dwell at full lift",
            units="rad",
            example="deg",
            minimum=0.0,
            exclusive_minimum=False,
            maximum=2 * math.pi,
            archive_name="profile_dwell",
            archive_units="deg",
        ),
        Field(
            "profile.fall",
            "quantity",
            "angle of the fall",
            units="rad",
            example="deg",
            minimum=0.0,
            maximum=2 * math.pi,
            archive_name="profile_fall",
            archive_units="deg",
        ),
        Field(
            "profile.file",
            "text",
            "lift table CSV, relative to the spec (header 'angle [deg],lift [in]')",
            archive_name="profile_file",
        ),
        Field(
            "profile.ramp_height",
            "quantity",
            "height of the opening and closing ramps, within the full lift",
            units="m",
            example="mm",
            minimum=0.0,
            maximum=MAX_LENGTH,
            archive_name="profile_ramp_height",
            archive_units="m",
        ),
        Field(
            "profile.ramp_duration",
            "quantity",
            "cam angle of each ramp, before the rise and after the fall",
            units="rad",
            example="deg",
            minimum=0.0,
            maximum=2 * math.pi,
            archive_name="profile_ramp_duration",
            archive_units="deg",
        ),
        Field(
            "profile.ramp_shape",
            "choice",
            "constant-velocity (a velocity step at the base circle, taken up by the lash) or "
            "smooth (lift, velocity and acceleration continuous)",
            choices=RAMP_SHAPES,
            archive_name="profile_ramp_shape",
        ),
    ]
}

#: Defect kinds → their keys (all required). Defects apply in the order listed.
DEFECT_KINDS: dict[str, tuple[str, ...]] = {
    "flat": ("from", "to"),
    "bump": ("center", "height", "width"),
}

DEFECT_FIELDS: dict[str, Field] = {
    "from": Field(
        "from",
        "quantity",
        "where the flat starts",
        units="rad",
        example="deg",
        minimum=-MAX_ANGLE,
        exclusive_minimum=False,
        maximum=MAX_ANGLE,
    ),
    "to": Field(
        "to",
        "quantity",
        "where the flat ends, after from and less than a turn later (past 360 deg for a flat "
        "through 0, e.g. from 350 deg to 370 deg)",
        units="rad",
        example="deg",
        minimum=-MAX_ANGLE,
        exclusive_minimum=False,
        maximum=MAX_ANGLE,
    ),
    "center": Field(
        "center",
        "quantity",
        "angle of the bump's peak",
        units="rad",
        example="deg",
        minimum=-MAX_ANGLE,
        exclusive_minimum=False,
        maximum=MAX_ANGLE,
    ),
    "height": Field(
        "height",
        "quantity",
        "height of the bump; negative for a dent",
        units="m",
        example="in",
        minimum=-MAX_LENGTH,
        exclusive_minimum=False,
        maximum=MAX_LENGTH,
    ),
    "width": Field(
        "width",
        "quantity",
        "full width of the bump",
        units="rad",
        example="deg",
        minimum=0.0,
        maximum=2 * math.pi,
    ),
}

#: The top-level keys of a spec and what they hold.
TOP_LEVEL: dict[str, str] = {
    "name": "study name; the archive defaults to <name>.nc beside the spec",
    "description": "free text, kept in the archive",
    "model": "preset plus parameter overrides (any model parameter by name)",
    "profile": "the cam: {kind: harmonic | polydyne-345 | polydyne-4567 | table, ...}",
    "defects": "defects applied to the cam, in order: flat {from, to}, bump {center, "
    "height, width}",
    "closure": CASE_FIELDS["closure"].description,
    "seat": CASE_FIELDS["seat"].description,
    "speed": CASE_FIELDS["speed"].description,
    "drive": "the drive from the crankshaft: {cam_per_crank: 0.5}; with it, a speed may be "
    "given as the engine's (engine_speed) and the archive carries engine_speed_rpm and "
    "crank_angle",
    "engine_speed": ENGINE_SPEED.description,
    "run": "how cases are integrated and what is stored",
    "sweep": "full grid: key → list of values or {from, to, num}",
    "zip": "axes varied together: key → list of values or {from, to, num}, equal lengths",
    "cases": "explicit cases, each deep-merged over the base",
    "sample": "a sampled design: {method: latin-hypercube, n, seed, ranges: {key: {from, to}}}",
    "replay": "cases to log to rerun while the study runs: {where: EXPR}",
    "plots": "figures written beside the archive when the study finishes: a list of "
    "{kind: histories | metric | map | events, where, units, output, ...}",
    "search": "search the speed axis instead of running every case: {onset: no-follow, "
    "axis: speed}, the no-follow onset of every combination of the other axes (campipe onset)",
    "design": "the keys campipe design varies, the requirements a design must meet and the "
    "objective: {vary, require, minimize | maximize, method, max_evaluations}",
}
#: What ``search`` may ask for (``campipe onset``).
SEARCHES = {"onset": ("no-follow",), "axis": ("speed",)}

#: Keys of a case (the base's top-level keys that describe one run).
CASE_KEYS = ("model", "profile", "defects", "closure", "seat", "speed", "run")

SAMPLE_METHODS = ("latin-hypercube",)


def model_field(name: str) -> Field:
    """A Field view of a model parameter (the archive names it as the parameter)."""
    p = PARAMETERS[name]
    return Field(
        f"model.{name}",
        "parameter",
        p.long_name,
        units=p.units,
        example=p.thesis_units,
        minimum=p.minimum,
        exclusive_minimum=p.exclusive_minimum,
        allow_none=p.allow_none,
        archive_name=name,
        archive_units=p.units,
    )


@functools.cache
def varied_fields() -> Mapping[str, Field]:
    """Every key a sweep, zip or case may vary (dotted path → Field); whole ``profile`` and
    ``defects`` entries (mappings, lists) are variable too, see :data:`WHOLE_KEYS`. Built
    once (a spec's check asks for it per swept value: 5000 speeds rebuilt it 5000 times)."""
    out: dict[str, Field] = {}
    for key, f in CASE_FIELDS.items():
        if key not in STUDY_WIDE:
            out[key] = f
    out[ENGINE_SPEED.key] = ENGINE_SPEED
    for name, f in PROFILE_FIELDS.items():
        out[f"profile.{name}"] = f
    out["profile.kind"] = Field(
        "profile.kind",
        "choice",
        "profile kind",
        choices=tuple(PROFILE_KINDS),
        archive_name="profile_kind",
    )
    out["model.preset"] = Field(
        "model.preset",
        "choice",
        "named parameter set",
        choices=tuple(PRESETS),
        archive_name="preset",
    )
    for name in PARAMETERS:
        out[f"model.{name}"] = model_field(name)
    return MappingProxyType(out)


#: Keys whose values are whole structures: a sweep over them lists whole profiles or whole
#: defect lists; the archive labels them.
WHOLE_KEYS = ("profile", "defects")


def sweep_keys() -> tuple[str, ...]:
    """Keys a sweep or zip may vary."""
    return (*WHOLE_KEYS, *varied_fields())


def sample_keys() -> tuple[str, ...]:
    """Keys a sampled design may vary: the scalar quantities and numbers."""
    return tuple(
        k
        for k, f in varied_fields().items()
        if f.kind in ("quantity", "number")
        or (f.kind == "parameter" and PARAMETERS[k[6:]].continuous)
    )
