"""The engine: contact configurations, integrators over batches of cases, member loads.

Names load on first use (PEP 562): a run's settings, cases and limits
(:mod:`~campipe.engine.settings`) cost no numba; ``run_batch`` and the results load the
compiled kernels' module (:mod:`~campipe.engine.batch`) when first asked for.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from campipe import kernel_cache

# numba's cache folder, set before the engine's modules import numba
kernel_cache.configure()

if TYPE_CHECKING:
    from campipe.engine.batch import BatchResult, initial_state, run_batch, start_states
    from campipe.engine.loads import (
        MEMBER_LOADS,
        SPRING_HISTORIES,
        member_loads,
        per_turn,
        spring_histories,
    )
    from campipe.engine.periodic import run_at_fidelity
    from campipe.engine.settings import (
        DEFAULT_INTEGRATOR,
        DEFAULT_STEPS,
        FIDELITIES,
        INTEGRATORS,
        Case,
        CaseError,
        IntegrationError,
        RunSettings,
        RunSettingsError,
        StabilityError,
        check_run,
        resolve_integrator,
        stability_limit,
    )

#: Where each public name lives.
_MODULES = {
    "campipe.engine.settings": (
        "DEFAULT_INTEGRATOR",
        "DEFAULT_STEPS",
        "FIDELITIES",
        "INTEGRATORS",
        "Case",
        "CaseError",
        "IntegrationError",
        "RunSettings",
        "RunSettingsError",
        "StabilityError",
        "check_run",
        "resolve_integrator",
        "stability_limit",
    ),
    "campipe.engine.batch": ("BatchResult", "initial_state", "run_batch", "start_states"),
    "campipe.engine.periodic": ("run_at_fidelity",),
    "campipe.engine.loads": (
        "MEMBER_LOADS",
        "SPRING_HISTORIES",
        "member_loads",
        "per_turn",
        "spring_histories",
    ),
}
_WHERE = {name: module for module, names in _MODULES.items() for name in names}

__all__ = [
    "BatchResult",
    "Case",
    "CaseError",
    "DEFAULT_INTEGRATOR",
    "DEFAULT_STEPS",
    "FIDELITIES",
    "INTEGRATORS",
    "IntegrationError",
    "MEMBER_LOADS",
    "RunSettings",
    "RunSettingsError",
    "SPRING_HISTORIES",
    "StabilityError",
    "check_run",
    "initial_state",
    "member_loads",
    "per_turn",
    "resolve_integrator",
    "run_at_fidelity",
    "run_batch",
    "spring_histories",
    "stability_limit",
    "start_states",
]


def __getattr__(name: str) -> object:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_WHERE})
