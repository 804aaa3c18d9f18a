"""The engine: contact configurations, integrators over batches of cases, member loads."""

from campipe.engine.batch import (
    DEFAULT_INTEGRATOR,
    INTEGRATORS,
    BatchResult,
    Case,
    IntegrationError,
    RunSettings,
    StabilityError,
    resolve_integrator,
    run_batch,
    stability_limit,
)
from campipe.engine.loads import MEMBER_LOADS, member_loads

__all__ = [
    "DEFAULT_INTEGRATOR",
    "INTEGRATORS",
    "MEMBER_LOADS",
    "BatchResult",
    "Case",
    "IntegrationError",
    "RunSettings",
    "StabilityError",
    "member_loads",
    "resolve_integrator",
    "run_batch",
    "stability_limit",
]
