"""The engine: contact configurations, integrators over batches of cases, member loads."""

from campipe.engine.batch import (
    DEFAULT_INTEGRATOR,
    DEFAULT_STEPS,
    FIDELITIES,
    INTEGRATORS,
    BatchResult,
    Case,
    CaseError,
    IntegrationError,
    RunSettings,
    RunSettingsError,
    StabilityError,
    check_run,
    resolve_integrator,
    run_batch,
    stability_limit,
    start_states,
)
from campipe.engine.loads import MEMBER_LOADS, member_loads

__all__ = [
    "DEFAULT_INTEGRATOR",
    "DEFAULT_STEPS",
    "FIDELITIES",
    "INTEGRATORS",
    "MEMBER_LOADS",
    "BatchResult",
    "Case",
    "CaseError",
    "IntegrationError",
    "RunSettings",
    "RunSettingsError",
    "StabilityError",
    "check_run",
    "member_loads",
    "resolve_integrator",
    "run_batch",
    "stability_limit",
    "start_states",
]
