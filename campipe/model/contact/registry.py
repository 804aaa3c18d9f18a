"""Contact laws by name (as xarray's backends): a spec's ``cam_contact`` / ``seat_contact``
names a class here, and :func:`contact_law` builds it from a train. A new law is a new file
registered here, not a branch in the integrator."""

from __future__ import annotations

from campipe.errors import did_you_mean
from campipe.model.contact.base import ContactLaw
from campipe.model.contact.hertz import Hertz
from campipe.model.contact.kelvin_voigt import KelvinVoigt
from campipe.model.contact.rigid import Rigid
from campipe.model.parameters import ModelParameterError, ValveTrain

#: Law name → class.
LAWS: dict[str, type[ContactLaw]] = {}


def register_law(law: type[ContactLaw]) -> type[ContactLaw]:
    """Make ``law`` found by its ``name``; returns it (so it decorates a class). A name is
    registered once."""
    if law.name in LAWS and LAWS[law.name] is not law:
        raise ValueError(f"contact law {law.name!r} is registered already ({LAWS[law.name]})")
    LAWS[law.name] = law
    return law


for _law in (Rigid, KelvinVoigt, Hertz):
    register_law(_law)


def law_class(name: str, key: str = "contact") -> type[ContactLaw]:
    """The class registered as ``name``; ``key`` is named in the error for an unknown one."""
    if name not in LAWS:
        raise ModelParameterError.at(
            key,
            f"unknown contact law {name!r}{did_you_mean(name, LAWS)}; known: " + ", ".join(LAWS),
            found=name,
            expected="one of " + ", ".join(LAWS),
        )
    return LAWS[name]


def contact_law(train: ValveTrain, contact: str) -> ContactLaw:
    """The law of ``contact`` ("cam" or "seat") of a train (checked by ``valve_train``)."""
    key = f"{contact}_contact"
    return law_class(getattr(train, key), key).from_train(train, contact)
