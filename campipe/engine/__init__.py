"""The engine: contact configurations, integrators over batches of cases, member loads."""

from campipe.engine.batch import (
    INTEGRATORS,
    BatchResult,
    Case,
    IntegrationError,
    RunSettings,
    StabilityError,
    run_batch,
    stability_limit,
)
from campipe.engine.loads import MEMBER_LOADS, member_loads

__all__ = [
    "INTEGRATORS",
    "MEMBER_LOADS",
    "BatchResult",
    "Case",
    "IntegrationError",
    "RunSettings",
    "StabilityError",
    "member_loads",
    "run_batch",
    "stability_limit",
]
