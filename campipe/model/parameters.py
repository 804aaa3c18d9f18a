"""The valve-train model description: parameter metadata, presets, and their resolution.

Every parameter is declared once here (name, long name, SI units, thesis units) and that
declaration feeds ``campipe model --set``, the study specs, the JSON Schema and the archive.
Parameter names are flat and the same everywhere: an element's length and diameter are
``<element>_length`` and ``<element>_diameter``.

Elements (thesis Ch. II, Table II):

========================  =====================================================================
``pushrod``               element 1, axial bar from the cam follower (q1) to the rocker (q2)
``rocker_pushrod_arm``    element 2, Euler–Bernoulli beam from the pushrod end to the pivot
``rocker_valve_arm``      element 3, Euler–Bernoulli beam from the pivot to the valve end
``spring``                element 4, the valve spring: stiffness ``spring_rate``; its mass is
                          that of the equivalent wire of ``spring_length`` × ``spring_diameter``
``valve_stem``            element 5, axial bar from the rocker valve end (q4) to the valve (q7)
========================  =====================================================================

Each element is a *member* that ``<member>_elements`` divides into that many equal finite
elements (1, the default, is the thesis's model); the internal nodes' coordinates come after
q1 … q7 (:mod:`campipe.model.coordinates`).

Damping (``damping_kind``): ``modal``, the thesis's (``damping_ratios``, thesis Eq. 23);
``rayleigh``, C = α·M + β·K (``rayleigh_alpha``, ``rayleigh_beta``); ``loss-factor``, each
member's loss factor η (``<member>_loss_factor``) as structural damping: every mode damped by
ζ = η/2 weighted by the share of its strain energy the member stores.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from campipe.errors import did_you_mean, excerpt
from campipe.model.checks import (
    CHAINS,
    LAYOUTS,
    PUSHROD_ROCKER,
    ModelParameterError,
    resolve_layout,
)
from campipe.model.contact_keys import (  # noqa: F401  (the contacts' names, re-exported)
    CONTACT_CONSTANTS,
    CONTACT_LAWS,
    check_contacts,
    contact_parameters,
)
from campipe.model.declared import Parameter
from campipe.model.hla import HLA_KEYS
from campipe.model.levers import lever_parameters
from campipe.units import (
    QuantityError,
    convert,
    parse_angular,
    parse_quantity,
    read_quantity,
)

ELEMENTS = ("pushrod", "rocker_pushrod_arm", "rocker_valve_arm", "spring", "valve_stem")
#: Coordinates per node of each member: a bar's node moves along it, a beam's node translates
#: and rotates.
NODE_COORDINATES = {
    "pushrod": 1,
    "rocker_pushrod_arm": 2,
    "rocker_valve_arm": 2,
    "spring": 1,
    "valve_stem": 1,
}
#: The thesis's seven coordinates (and modes).
N_DOF = 7
#: Most finite elements a member may be divided into: dense matrices of a few hundred
#: coordinates at most.
MAX_ELEMENTS = 64
#: Where a train's ``lash`` is measured: at the rocker's valve end (a designer's feeler gauge
#: between the rocker and the valve stem; the default) or at the cam, between the base circle
#: and the follower (:mod:`campipe.model.lash`).
LASH_SIDES = ("valve", "cam")
#: Damping kinds: the thesis's modal damping, Rayleigh's, per-member loss factors.
DAMPING_KINDS = ("modal", "rayleigh", "loss-factor")
MAX_MASSES = 64  # most masses of a lumped chain
_LAYOUT = "valve-train layout: " + ", ".join(LAYOUTS) + " (campipe.model.layouts)"


def _element_parameters() -> list[Parameter]:
    names = {
        "pushrod": "pushrod",
        "rocker_pushrod_arm": "rocker arm, pushrod side",
        "rocker_valve_arm": "rocker arm, valve side",
        "spring": "valve spring equivalent wire",
        "valve_stem": "valve stem",
    }
    out = []
    for element, label in names.items():
        out.append(Parameter(f"{element}_length", f"{label} length", "m", "in", 0.0))
        out.append(Parameter(f"{element}_diameter", f"{label} diameter", "m", "in", 0.0))
    for element, label in names.items():
        out.append(
            Parameter(
                f"{element}_mass",
                f"{label} mass given directly (none: from its geometry and specific_weight)",
                "kg",
                "lb",
                0.0,
                allow_none=True,
                default="none",
            )
        )
    return out


def _refinement_parameters() -> list[Parameter]:
    return [
        Parameter(
            f"{element}_elements",
            f"number of equal finite elements of the {element.replace('_', ' ')}",
            "",
            "",
            1.0,
            exclusive_minimum=False,
            integer=True,
            default=1,
            maximum=MAX_ELEMENTS,
        )
        for element in ELEMENTS
    ]


def _loss_factor_parameters() -> list[Parameter]:
    return [
        Parameter(
            f"{element}_loss_factor",
            f"loss factor η of the {element.replace('_', ' ')} (damping_kind loss-factor)",
            "",
            "",
            0.0,
            exclusive_minimum=False,
            default=0,
        )
        for element in ELEMENTS
    ]


def _chain_list(name: str, what: str, units: str, shown: str) -> Parameter:
    return Parameter(
        name, f"lumped chain's {what} (layout lumped)", units, shown, 0.0,
        length=MAX_MASSES, min_length=0, default=[],
    )  # fmt: skip


def _hla(name: str, what: str, units: str, shown: str) -> Parameter:
    zero = name == "hla_extension"  # (campipe.model.hla)
    return Parameter(name, what, units, shown, 0.0, exclusive_minimum=not zero,
                     allow_none=not zero, default="0 m" if zero else "none")  # fmt: skip


def _direct(name: str, what: str, units: str, shown: str) -> Parameter:
    shared = name in ("valve_mass", "stem_stiffness")
    layouts = "layouts direct-acting and the levers" if shared else "layout direct-acting"
    return Parameter(
        name, f"{what} ({layouts})", units, shown, 0.0, allow_none=True,
        default="none",
    )  # fmt: skip


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in [
        Parameter("layout", _LAYOUT, "", "", 0.0, choices=LAYOUTS, default=PUSHROD_ROCKER),
        _chain_list("masses", "masses from the cam side, the last the valve", "kg", "kg"),
        _chain_list(
            "stiffnesses", "stiffnesses between neighbours, from the cam side", "N/m", "N/mm"
        ),
        _direct("tappet_mass", "bucket tappet's mass with its shim", "kg", "kg"),
        _direct("valve_mass", "valve's mass with retainer, keepers, spring share", "kg", "kg"),
        _direct("stem_stiffness", "valve stem's axial stiffness, tip to head", "N/m", "N/mm"),
        _direct("tappet_contact_stiffness", "tappet's contact on the stem tip", "N/m", "N/mm"),
        *lever_parameters(),
        *(_hla(*row) for row in HLA_KEYS),
        *_element_parameters(),
        Parameter("elastic_modulus", "elastic modulus of all members", "Pa", "lbf/in**2", 0.0),
        Parameter("specific_weight", "specific weight of all members", "N/m**3", "lbf/in**3", 0.0),
        Parameter("spring_rate", "valve spring rate", "N/m", "lbf/in", 0.0),
        Parameter(
            "spring_preload",
            "installed valve spring force: the valve on its seat (with lash); without lash, "
            "the force with the train unstressed (on the base circle its give lowers it by "
            "the spring's share, a fraction k_s/(k + k_s))",
            "N",
            "lbf",
            0.0,
            exclusive_minimum=False,
        ),
        Parameter(
            "damping_ratios",
            "modal damping ratios, lowest mode first (the last for the rest)",
            "",
            "",
            0.0,
            exclusive_minimum=False,
            length=N_DOF,
        ),
        *_refinement_parameters(),
        Parameter(
            "lash",
            "valve lash: the clearance of the seated train on the cam's base circle, measured "
            "where lash_side says (none: the case's seat decides); it places the seat "
            "(campipe.model.lash_seat), where valve lift reads 0",
            "m",
            "in",
            0.0,
            exclusive_minimum=False,
            default="none",
            allow_none=True,
        ),
        Parameter(
            "lash_side",
            "where the lash is measured: valve (at the rocker's valve end, against the valve "
            "stem) or cam (between the cam's base circle and the follower)",
            "",
            "",
            0.0,
            choices=LASH_SIDES,
            default="valve",
        ),
        Parameter(
            "spring_travel_to_solid",
            "valve spring compression from its installed length to solid (coil clash)",
            "m",
            "in",
            0.0,
            default="1.6 in",
        ),
        Parameter(
            "damping_kind",
            "damping model: " + ", ".join(DAMPING_KINDS),
            "",
            "",
            0.0,
            choices=DAMPING_KINDS,
            default="modal",
        ),
        Parameter(
            "rayleigh_alpha",
            "Rayleigh damping's mass coefficient α (C = α·M + β·K)",
            "1/s",
            "s**-1",
            0.0,
            exclusive_minimum=False,
            default="0 s**-1",
        ),
        Parameter(
            "rayleigh_beta",
            "Rayleigh damping's stiffness coefficient β (C = α·M + β·K)",
            "s",
            "s",
            0.0,
            exclusive_minimum=False,
            default="0 s",
        ),
        *_loss_factor_parameters(),
        *contact_parameters(),
    ]
}

#: The thesis's values (Table II and Ch. II), in its inch–pound–second units. The thesis never
#: states the spring preload, yet without one the follower cannot stay on the cam at 9000 rpm;
#: 151 lbf is calibrated so that separation begins between 9000 and 9524 rpm with the harmonic
#: cam, as its Figures 15–22 show (then about 53° of each turn off the cam at 9524 rpm, the
#: thesis ≈ 50°, and 220° at 11000 rpm, the thesis ≈ 180°).
THESIS_1971: dict[str, object] = {
    "pushrod_length": "9.0 in",
    "pushrod_diameter": "0.3 in",
    "rocker_pushrod_arm_length": "1.0 in",
    "rocker_pushrod_arm_diameter": "0.6 in",
    "rocker_valve_arm_length": "1.5 in",
    "rocker_valve_arm_diameter": "0.6 in",
    "spring_length": "36.0 in",
    "spring_diameter": "0.07 in",
    "valve_stem_length": "3.0 in",
    "valve_stem_diameter": "0.3 in",
    "elastic_modulus": "30e6 lbf/in**2",
    "specific_weight": "0.283 lbf/in**3",
    "spring_rate": "245 lbf/in",
    "spring_preload": "151 lbf",
    "damping_ratios": [0.5, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1],
}

PRESETS: dict[str, dict[str, object]] = {"thesis-1971": THESIS_1971}


@dataclass(frozen=True)
class ValveTrain:
    """One valve train, every value in SI (see ``PARAMETERS`` for the units)."""

    pushrod_length: float  # [m]
    pushrod_diameter: float  # [m]
    rocker_pushrod_arm_length: float  # [m] pushrod end to pivot
    rocker_pushrod_arm_diameter: float  # [m]
    rocker_valve_arm_length: float  # [m] pivot to valve end
    rocker_valve_arm_diameter: float  # [m]
    spring_length: float  # [m] equivalent wire length (mass only)
    spring_diameter: float  # [m] equivalent wire diameter (mass only)
    valve_stem_length: float  # [m]
    valve_stem_diameter: float  # [m]
    elastic_modulus: float  # [Pa]
    specific_weight: float  # [N/m³]
    spring_rate: float  # [N/m]
    spring_preload: float  # [N] installed force (seated with lash; unstressed train without)
    damping_ratios: tuple[float, ...]  # [-] lowest mode first, the last for the rest
    pushrod_elements: int  # [-] equal finite elements of each member; 1 is the thesis's
    rocker_pushrod_arm_elements: int  # [-]
    rocker_valve_arm_elements: int  # [-]
    spring_elements: int  # [-]
    valve_stem_elements: int  # [-]
    lash: float  # [m] clearance of a seated train, on ``lash_side``; NaN: none (the seat)
    spring_travel_to_solid: float  # [m] installed length minus solid length
    damping_kind: str  # one of DAMPING_KINDS
    rayleigh_alpha: float  # [1/s] C = α·M + β·K
    rayleigh_beta: float  # [s]
    pushrod_loss_factor: float  # [-] η of each member (damping_kind "loss-factor")
    rocker_pushrod_arm_loss_factor: float  # [-]
    rocker_valve_arm_loss_factor: float  # [-]
    spring_loss_factor: float  # [-]
    valve_stem_loss_factor: float  # [-]
    pushrod_mass: float = math.nan  # [kg] each member's mass given directly; NaN: from ρ·A·L
    rocker_pushrod_arm_mass: float = math.nan  # [kg]
    rocker_valve_arm_mass: float = math.nan  # [kg]
    spring_mass: float = math.nan  # [kg]
    valve_stem_mass: float = math.nan  # [kg]
    lash_side: str = "valve"  # one of LASH_SIDES: where ``lash`` is measured
    cam_contact: str = "rigid"  # one of CONTACT_LAWS
    cam_contact_stiffness: float = 0.0  # [N/m] k; 0: from the line contact
    cam_contact_damping: float = 0.0  # [N·s/m] c
    cam_hertz_constant: float = 0.0  # [N/m^1.5] K; 0: from the radius
    cam_hunt_crossley: float = 0.0  # [s/m] α
    cam_contact_width: float = 0.0  # [m] line contact length; 0: none
    #: [-] e of a rigid impact (0: plastic, the thesis's), or of a landing on a kelvin-voigt
    #: contact (its damping then derived from e: ``contact.KelvinVoigt.from_train``)
    cam_restitution: float = 0.0
    seat_contact: str = "rigid"  # one of CONTACT_LAWS
    seat_contact_stiffness: float = 0.0  # [N/m]
    seat_contact_damping: float = 0.0  # [N·s/m]
    seat_hertz_constant: float = 0.0  # [N/m^1.5]
    seat_hunt_crossley: float = 0.0  # [s/m]
    seat_contact_width: float = 0.0  # [m]
    seat_restitution: float = 0.0  # [-]
    cam_curvature_radius: float = 0.0  # [m] the cam's at the contact; 0: not given
    cam_roller_radius: float = 0.0  # [m] 0: a flat-faced follower
    seat_contact_radius: float = 0.0  # [m] 0: not given
    contact_modulus: float = 30e6 * 4.4482216152605 / 0.0254**2  # [Pa] both bodies (steel)
    contact_poisson: float = 0.3  # [-]
    layout: str = PUSHROD_ROCKER  # one of LAYOUTS
    masses: tuple[float, ...] = ()  # [kg] a lumped chain's, the cam's first, the valve last
    stiffnesses: tuple[float, ...] = ()  # [N/m] between neighbouring masses, the cam's first
    tappet_mass: float = math.nan  # [kg] direct-acting: the bucket tappet with its shim
    valve_mass: float = math.nan  # [kg] direct-acting: valve, retainer, keepers, spring share
    stem_stiffness: float = math.nan  # [N/m] direct-acting: the valve stem, tip to head
    tappet_contact_stiffness: float = math.nan  # [N/m] direct-acting: tappet on the stem tip
    pivot_to_roller: float = math.nan  # [m] levers (campipe.model.levers): pivot to roller
    pivot_to_pallet: float = math.nan  # [m] pivot to the pallet's centre of curvature
    cam_base_radius: float = math.nan  # [m] the cam's base circle
    lever_rest_angle: float = 0.0  # [rad] the pallet arm above the horizontal, valve closed
    cam_offset: float = 0.0  # [m] cam centre from the roller's rest centre, towards the pallet
    lever_inertia: float = math.nan  # [kg·m²] the lever about its pivot
    roller_mass: float = 0.0  # [kg] the roller with its axle
    lever_stiffness: float = math.nan  # [N/m] the lever at the pallet, along the valve
    hla_stiffness: float = math.nan  # [N/m] lash adjuster (campipe.model.hla); NaN: none
    hla_leak_down: float = math.nan  # [N·s/m] leak-down coefficient c_L
    hla_check_force: float = math.nan  # [N] check force F_c
    hla_pump_up: float = math.nan  # [N·s/m] pump-up coefficient c_P
    hla_travel: float = math.nan  # [m] plunger travel
    hla_extension: float = 0.0  # [m] plunger extension at the start

    def replace(self, **changes: Any) -> ValveTrain:
        """A copy with some values (SI) changed."""
        return dataclasses.replace(self, **changes)

    # The hash is the dataclass's (of every field, in order), computed once per train: the
    # engine's per-train caches hash a train three times a call, and each hash read all its
    # fields (1.6 µs). ``dataclasses.replace`` makes a new train, hashed afresh.
    def __hash__(self) -> int:
        return self._hash

    @functools.cached_property
    def _hash(self) -> int:
        return hash(tuple(getattr(self, f.name) for f in dataclasses.fields(self)))

    def __getstate__(self) -> dict[str, object]:
        """The fields without the cached hash: a string's hash differs between processes
        (``PYTHONHASHSEED``), so a train sent to another keeps none from this one."""
        return {k: v for k, v in self.__dict__.items() if k != "_hash"}

    def as_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)

    @property
    def chain(self) -> bool:
        """A chain of masses (layout lumped, or built as one: :mod:`campipe.model.layouts`)."""
        return self.layout in CHAINS

    def elements_of(self, member: str) -> int:
        """The number of finite elements ``member`` (a name of ``ELEMENTS``) is divided into."""
        return int(getattr(self, f"{member}_elements"))

    @property
    def n_coordinates(self) -> int:
        """Number of system coordinates: the thesis's seven, and those of the internal nodes
        of refined members (a bar's n − 1 internal nodes one each, a beam's two each); a
        lumped chain's masses, seven at least (:mod:`campipe.model.layouts`)."""
        if self.chain:
            return max(N_DOF, len(self.masses))
        return N_DOF + sum((self.elements_of(m) - 1) * NODE_COORDINATES[m] for m in ELEMENTS)


def parse_parameter(
    name: str, value: object, key: str | None = None
) -> float | int | str | tuple[float, ...]:
    """Turn a spec value (quantity string, or numbers for dimensionless) into SI.

    Parameters
    ----------
    name : str
        Parameter name (a key of ``PARAMETERS``).
    value : object
        A quantity string such as ``"245 lbf/in"``; for ``damping_ratios`` a list of numbers;
        for a count (``spring_elements``) a whole number; for ``damping_kind`` a word.
    key : str, optional
        The key path to name in errors (defaults to ``name``).
    """
    key = key or name
    if name not in PARAMETERS:
        close = difflib.get_close_matches(name, PARAMETERS, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ModelParameterError.at(
            key,
            f"unknown model parameter {name!r}; {hint}known parameters: " + ", ".join(PARAMETERS),
            found=name,
            expected="a model parameter",
        )
    p = PARAMETERS[name]
    if p.allow_none and (value is None or value == "none"):
        return math.nan
    if p.choices:
        return _choice(p, value, key)
    if p.integer:
        return _count(p, value, key)
    try:
        if p.length:
            return _list(p, value, key)
        if p.units == "rad":  # pint's radian is dimensionless: a bare 0.1 is refused here
            v = parse_angular(value, p.units, key, p.thesis_units)
        else:
            v = parse_quantity(value, p.units, key, p.thesis_units)
    except QuantityError as exc:
        raise ModelParameterError(
            str(exc), key=exc.key, found=exc.found, expected=exc.expected, reason=exc.reason
        ) from None
    _check_range(p, v, key, value)
    return v


def _list(p: Parameter, value: object, key: str) -> tuple[float, ...]:
    if isinstance(value, str):  # a list of quantities splits at its commas only
        inner = value.strip("[]() ")
        parts = inner.split(",") if p.units else inner.replace(",", " ").split()
        value = [v.strip() for v in parts if v.strip()]
    items = value if isinstance(value, (list, tuple)) else None
    if items is None or not p.min_length <= len(items) <= (p.length if p.units else math.inf):
        hint = f"with units, e.g. [1 {p.thesis_units}, 2 {p.thesis_units}], at most {p.length}"
        if not p.units:
            hint = f"lowest mode first ({p.length} for the thesis's model; a shorter list "
            hint += "gives its last value to the modes above)"
        raise ModelParameterError.at(
            key,
            f"expected a list of numbers, {hint}, found {excerpt(value)}",
            found=value,
            expected=f"a list of {p.min_length} or more numbers",
        )
    out = tuple(
        parse_quantity(_number(v), p.units, f"{key}[{i}]", p.thesis_units)
        for i, v in enumerate(items)
    )
    for i, (v, raw) in enumerate(zip(out, items, strict=True)):
        _check_range(p, v, f"{key}[{i}]", raw)
    return out


def _choice(p: Parameter, value: object, key: str) -> str:
    if isinstance(value, str) and value in p.choices:
        return value
    expected = "one of: " + ", ".join(p.choices)
    raise ModelParameterError.at(
        key,
        f"found {excerpt(value)}, expected {expected}{did_you_mean(value, p.choices)}",
        found=value,
        expected=expected,
    )


def _count(p: Parameter, value: object, key: str) -> int:
    number = _number(value) if isinstance(value, str) else value
    if isinstance(number, numbers.Real) and not isinstance(number, bool):
        x = float(number)
        if math.isfinite(x) and x.is_integer() and p.minimum <= x <= p.maximum:
            return int(x)
    expected = f"a whole number from {p.minimum:g} to {p.maximum:g}"
    raise ModelParameterError.at(
        key,
        f"found {excerpt(value)}, expected {expected} (1 keeps the member one element, "
        "as in the thesis; 4 divides it into four equal elements)",
        found=value,
        expected=expected,
    )


def _number(v: object) -> object:
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


def _check_range(p: Parameter, v: float, key: str, raw: object) -> None:
    bad = v <= p.minimum if p.exclusive_minimum else v < p.minimum
    if bad or not math.isfinite(v) or v > p.maximum:
        relation = "greater than" if p.exclusive_minimum else "at least"

        written = _written_units(raw, p)

        def shown(bound: float) -> str:  # a bound in the units the value was written in
            if not written:
                return f"{bound:g}"
            value = convert(bound, p.units, written) if math.isfinite(bound) else bound
            return f"{value:.6g} {written}"

        expected = f"a finite value {relation} {shown(p.minimum)}"
        if math.isfinite(p.maximum):
            expected += f" and at most {shown(p.maximum)}"
        raise ModelParameterError.at(
            key, f"found {raw!r}, expected {expected}", found=raw, expected=expected
        )


def _written_units(raw: object, p: Parameter) -> str:
    """The units a refused value was written in ("-50 N": "N"), where they convert to the
    parameter's; else the thesis's (its shown units); "" for a number without units."""
    if not p.thesis_units:
        return ""
    if isinstance(raw, str):
        try:
            units = f"{read_quantity(raw, '').units:~}"
            convert(1.0, units, p.units)
        except Exception:  # text pint does not take as a quantity of these units
            return p.thesis_units
        return units
    return p.thesis_units


def valve_train(
    preset: str = "thesis-1971", overrides: Mapping[str, object] | None = None, key_prefix: str = ""
) -> ValveTrain:
    """Resolve a preset plus overrides into a :class:`ValveTrain` in SI.

    Parameters
    ----------
    preset : str
        A key of ``PRESETS``.
    overrides : mapping, optional
        Parameter name → value with units (``{"spring_rate": "260 lbf/in"}``).
    key_prefix : str
        Prefix for key paths in error messages (``"model."`` for specs).
    """
    if preset not in PRESETS:
        raise ModelParameterError.at(
            f"{key_prefix}preset",
            f"unknown preset {preset!r}; known presets: " + ", ".join(PRESETS),
            found=preset,
            expected="one of: " + ", ".join(PRESETS),
        )
    values = {**DEFAULTS, **PRESETS[preset], **(overrides or {})}
    resolved = {name: parse_parameter(name, v, key_prefix + name) for name, v in values.items()}
    train = ValveTrain(**resolved)  # type: ignore[arg-type]
    train = resolve_layout(train, overrides or {}, ELEMENTS, key_prefix)
    modes = len(train.masses) if train.chain else train.n_coordinates
    given = "damping_ratios" in (overrides or {})
    if train.chain and train.damping_kind == "rayleigh" and not given:
        return _checked(train.replace(damping_ratios=()), key_prefix)  # (the thesis's unused)
    if train.chain and not given:
        raise ModelParameterError.at(
            key_prefix + "damping_ratios",
            f"layout {train.layout} needs its own: the preset's are the thesis's train's; give "
            f"1 to {modes} ratios of the chain's modes, lowest first (e.g. [0.05])",
            found=None,
            expected=f"1 to {modes} damping ratios",
        )
    mode_damping_ratios(train.damping_ratios, modes, key_prefix + "damping_ratios")
    return _checked(train, key_prefix)


def _checked(train: ValveTrain, key_prefix: str) -> ValveTrain:
    check_contacts(train, key_prefix)
    return train


def thesis_train() -> ValveTrain:
    """The ``thesis-1971`` preset."""
    return valve_train("thesis-1971")


def mode_damping_ratios(
    ratios: tuple[float, ...], n_modes: int, key: str = "damping_ratios"
) -> tuple[float, ...]:
    """One damping ratio per mode, lowest first: the ratios given, then the last of them for
    every mode above (``[0.5, 0.1]`` is 0.5 on the fundamental and 0.1 on all the others).

    Raises
    ------
    ModelParameterError
        No ratio, or more ratios than the train has modes.
    """
    if not 1 <= len(ratios) <= n_modes:
        expected = f"1 to {n_modes} ratios, lowest mode first"
        raise ModelParameterError.at(
            key,
            f"found {len(ratios)} ratios for a train of {n_modes} modes; give 1 to {n_modes} "
            "(a shorter list gives its last value to the modes above)",
            found=ratios,
            expected=expected,
        )
    return tuple(ratios) + (ratios[-1],) * (n_modes - len(ratios))


#: The parameters declared with a default, at it (spec form): the refinement, the spring's
#: travel and the damping kinds the thesis does not have.
DEFAULTS: dict[str, object] = {
    name: p.default for name, p in PARAMETERS.items() if p.default is not None
}


@functools.cache
def _default_values() -> dict[str, object]:
    """DEFAULTS in SI, parsed on first use (parsing loads pint, which `campipe --help` need
    not)."""
    return {name: parse_parameter(name, v) for name, v in DEFAULTS.items()}


def _same(a: object, b: object) -> bool:
    """Equal values, NaN (none) equal to NaN."""
    nan = isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    return nan or a == b


def defining_values(train: ValveTrain) -> dict[str, object]:
    """Parameter name → SI value of the parameters that set ``train`` apart: all of them, but
    a parameter declared with a default is left out at its default (a study's case ids hash
    these, and a case written before such a parameter existed keeps its id)."""
    out = {}
    for name in PARAMETERS:
        value = getattr(train, name)
        defaults = _default_values()
        if name not in defaults or not _same(value, defaults[name]):
            out[name] = value
    return out
