"""The contacts' parameters (each contact's law and its constants) and the check that they go
together (:func:`check_contacts`), apart from :mod:`campipe.model.parameters`, which lists
them with the rest; the laws themselves are :mod:`campipe.model.contact`. Pure Python; a train
is read by its attributes only.
"""

from __future__ import annotations

from typing import Any

from campipe.model.declared import ModelParameterError, Parameter

#: Contact laws at the cam–follower and valve–seat contacts: the thesis's rigid plastic
#: impact, a linear spring and damper (no tension), Hertz's point contact with Hunt–Crossley
#: damping (:mod:`campipe.model.contact`).
CONTACT_LAWS = ("rigid", "kelvin-voigt", "hertz")


def contact_parameters() -> list[Parameter]:
    """Each contact's law and its constants (:mod:`campipe.model.contact`); 0 for a
    constant means "not given" (a stiffness then comes from the geometry)."""

    def zero(name, long_name, units, thesis_units):
        return Parameter(
            name, long_name, units, thesis_units, 0.0, exclusive_minimum=False,
            default=f"0 {thesis_units}",
        )  # fmt: skip

    out = []
    for contact, label in (("cam", "cam–follower"), ("seat", "valve–seat")):
        out += [
            Parameter(
                f"{contact}_contact",
                f"{label} contact law: " + ", ".join(CONTACT_LAWS),
                "",
                "",
                0.0,
                choices=CONTACT_LAWS,
                default="rigid",
            ),
            zero(
                f"{contact}_contact_stiffness",
                f"{label} contact stiffness k (kelvin-voigt; 0: from the line contact)",
                "N/m",
                "lbf/in",
            ),
            zero(
                f"{contact}_contact_damping",
                f"{label} contact damping coefficient c (kelvin-voigt)",
                "N*s/m",
                "lbf*s/in",
            ),
            zero(
                f"{contact}_hertz_constant",
                f"{label} Hertz constant K of F = K·δ^(3/2) (hertz; 0: from the radius)",
                "N/m**1.5",
                "lbf/in**1.5",
            ),
            zero(
                f"{contact}_hunt_crossley",
                f"{label} Hunt–Crossley damping factor α of F = K·δ^(3/2)·(1 + α·dδ/dt) (hertz)",
                "s/m",
                "s/in",
            ),
            zero(
                f"{contact}_contact_width",
                f"{label} line contact length (0: not a line contact)",
                "m",
                "in",
            ),
            Parameter(
                f"{contact}_restitution",
                f"{label} coefficient of restitution: of a rigid impact (0: the thesis's "
                "plastic impact), or of a landing on a kelvin-voigt contact, its damping "
                f"derived from it (0: {contact}_contact_damping's)",
                "",
                "",
                0.0,
                exclusive_minimum=False,
                default=0,
                maximum=1.0,
            ),
        ]
    out += [
        zero(
            "cam_curvature_radius",
            "cam's radius of curvature at the contact (0: not given)",
            "m",
            "in",
        ),
        zero("cam_roller_radius", "follower roller radius (0: a flat-faced follower)", "m", "in"),
        zero(
            "seat_contact_radius",
            "relative radius of curvature at the valve–seat contact (0: not given)",
            "m",
            "in",
        ),
        Parameter(
            "contact_modulus",
            "elastic modulus of both bodies at the compliant contacts",
            "Pa",
            "lbf/in**2",
            0.0,
            default="30e6 lbf/in**2",
        ),
        Parameter(
            "contact_poisson",
            "Poisson's ratio of both bodies at the compliant contacts",
            "",
            "",
            0.0,
            exclusive_minimum=False,
            default=0.3,
            maximum=0.5,
        ),
    ]
    return out


#: Each law's own constants (name suffixes): a compliant law's, the stiffness first; the rigid
#: law's coefficient of restitution (a compliant law's comes from its damping).
CONTACT_CONSTANTS = {
    "rigid": ("restitution",),
    "kelvin-voigt": ("contact_stiffness", "contact_damping"),
    "hertz": ("hertz_constant", "hunt_crossley"),
}
#: Another law's constant a law takes as well: kelvin-voigt's damping may be given as the
#: coefficient of restitution of a landing on it instead (``contact.KelvinVoigt.from_train``).
ALSO_TAKES = {"kelvin-voigt": ("restitution",)}


def _contact_geometry(train: Any, contact: str) -> tuple[float, float]:
    """(line contact length [m], relative radius of curvature R' [m]) of a contact; 0 where
    not given."""
    width = getattr(train, f"{contact}_contact_width")
    if contact == "seat":
        return width, train.seat_contact_radius
    rho, roller = train.cam_curvature_radius, train.cam_roller_radius
    if rho <= 0.0:
        return width, 0.0
    return width, rho if roller <= 0.0 else rho * roller / (rho + roller)


def check_contacts(train: Any, key_prefix: str = "") -> None:
    """Refuse a contact law's constants that do not go together, naming the key and the fix:
    another law's constants (a hertz constant under kelvin-voigt, a stiffness under rigid), a
    compliant law with no stiffness (neither given nor from its geometry), a hertz law from a
    line contact (its approach is linear in the force up to a logarithm: kelvin-voigt)."""
    if (
        train.cam_contact_width > 0.0
        and train.cam_base_radius > 0.0
        and train.cam_curvature_radius > 0.0
    ):
        raise ModelParameterError.at(
            key_prefix + "cam_curvature_radius",
            "is one radius for the whole turn, for a cam whose shape is not known: with "
            "cam_base_radius the line contact's Hertz pressure takes the cam's own radius of "
            "curvature at every angle (campipe model shows its least); leave "
            "cam_curvature_radius out",
            found=train.cam_curvature_radius,
            expected="0 (not given) with cam_base_radius and cam_contact_width",
        )
    for contact in ("cam", "seat"):
        law = getattr(train, f"{contact}_contact")
        law_key = f"{key_prefix}{contact}_contact"
        _check_restitution_damping(train, contact, law, key_prefix)
        for other, names in CONTACT_CONSTANTS.items():
            if other == law:
                continue
            for suffix in names:
                name = f"{contact}_{suffix}"
                if suffix in ALSO_TAKES.get(law, ()):
                    continue
                if getattr(train, name) != 0.0:
                    if law == "rigid":
                        fix = f"set {law_key}: {other}, or leave {name} out"
                    elif other == "rigid":
                        fix = (
                            f"a {law} contact's restitution comes from its damping "
                            f"({contact}_{CONTACT_CONSTANTS[law][1]}); leave {name} out"
                        )
                    else:
                        fix = (
                            f"{law} takes {contact}_{CONTACT_CONSTANTS[law][0]} and "
                            f"{contact}_{CONTACT_CONSTANTS[law][1]}; leave {name} out"
                        )
                    raise ModelParameterError.at(
                        key_prefix + name,
                        f"is {other}'s constant but {law_key} is {law}: {fix}",
                        found=getattr(train, name),
                        expected=f"0 (not given) with {contact}_contact {law}",
                    )
        if law == "rigid":
            continue
        width, radius = _contact_geometry(train, contact)
        stiffness = getattr(train, f"{contact}_{CONTACT_CONSTANTS[law][0]}")
        geometry = (
            f"{contact}_contact_width (a line contact)"
            if law == "kelvin-voigt"
            else ("cam_curvature_radius" if contact == "cam" else "seat_contact_radius")
            + " (a point contact)"
        )
        if law == "hertz" and stiffness == 0.0 and width > 0.0:
            raise ModelParameterError.at(
                key_prefix + f"{contact}_contact_width",
                f"a line contact under {law_key}: hertz is Hertz's point contact "
                "(F = K·δ^(3/2)); a line contact's approach is linear in its force up to a "
                f"logarithm: set {law_key}: kelvin-voigt (its stiffness then comes from the "
                f"width), or give {contact}_hertz_constant",
                found=width,
                expected=f"0 with {contact}_contact hertz",
            )
        has_geometry = width > 0.0 if law == "kelvin-voigt" else radius > 0.0
        if stiffness == 0.0 and not has_geometry:
            name = f"{contact}_{CONTACT_CONSTANTS[law][0]}"
            raise ModelParameterError.at(
                key_prefix + name,
                f"{law_key} is {law} but no stiffness: give {name} or {geometry}",
                found=0.0,
                expected=f"a positive {name}, or {geometry}",
            )


def _check_restitution_damping(train: Any, contact: str, law: str, key_prefix: str) -> None:
    """Refuse a kelvin-voigt contact given both its damping and its restitution (the one is
    derived from the other)."""
    if law != "kelvin-voigt":
        return
    restitution, damping = (
        getattr(train, f"{contact}_{suffix}") for suffix in ("restitution", "contact_damping")
    )
    if restitution != 0.0 and damping != 0.0:
        raise ModelParameterError.at(
            f"{key_prefix}{contact}_restitution",
            f"and {contact}_contact_damping both given: a kelvin-voigt contact's damping is "
            f"its own c, or derived from the restitution of a landing on it; leave one out",
            found=restitution,
            expected=f"0 (not given) with {contact}_contact_damping {damping:g} N·s/m",
        )


def impact_restitution(train: Any, contact: str) -> float:
    """The coefficient of restitution of a rigid impact at ``contact`` ("cam" or "seat"): the
    train's ``*_restitution`` where the contact is rigid, 0 where it is compliant (whose
    restitution, if given, sets its damping instead)."""
    if getattr(train, f"{contact}_contact") != "rigid":
        return 0.0
    return float(getattr(train, f"{contact}_restitution"))
