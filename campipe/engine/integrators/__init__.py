"""The integrators, found by name: each is a small object behind one protocol
(:class:`~campipe.engine.integrators.base.Integrator`: check, prepare, run), registered
here. A new integrator is a module beside these and a :func:`register` call.

- ``modal-exact`` (:mod:`.modal_exact`): the default for rigid contacts;
- ``newmark-linear`` (:mod:`.newmark_linear`): the thesis's algorithm;
- ``compliant`` (:mod:`.compliant`): compliant contact laws.
"""

from __future__ import annotations

from campipe.engine.case import RunSettingsError
from campipe.engine.integrators.base import Integrator, RunLike
from campipe.engine.integrators.compliant import Compliant
from campipe.engine.integrators.modal_exact import ModalExact
from campipe.engine.integrators.newmark_linear import NewmarkLinear

__all__ = ["DEFAULT", "REGISTRY", "Integrator", "RunLike", "get", "names", "register"]

#: Every integrator by name.
REGISTRY: dict[str, Integrator] = {}
#: What ``default`` means for a case with rigid contacts (a compliant case takes the first
#: registered integrator of compliant contacts).
DEFAULT = "modal-exact"


def register(integrator: Integrator) -> Integrator:
    """Make an integrator available by its name (``run.integrator``)."""
    if integrator.name in REGISTRY or integrator.name == "default":
        raise ValueError(f"an integrator named {integrator.name!r} exists")
    REGISTRY[integrator.name] = integrator
    return integrator


def names(contacts: str | None = None) -> tuple[str, ...]:
    """The registered names (of the integrators of ``contacts``, if given)."""
    return tuple(n for n, i in REGISTRY.items() if contacts is None or i.contacts == contacts)


def get(name: str) -> Integrator:
    """The integrator of a resolved name; refuse an unknown one at ``run.integrator``."""
    integrator = REGISTRY.get(name)
    if integrator is None:
        known = ", ".join(("default", *REGISTRY))
        raise RunSettingsError.at(
            "run.integrator",
            f"unknown integrator {name!r}; known: {known}",
            found=name,
            expected=f"one of: {known}",
        )
    return integrator


for _builtin in (ModalExact(), NewmarkLinear(), Compliant()):
    register(_builtin)
