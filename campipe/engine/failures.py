"""What a batch's failed cases do to its run (``batch.run_batch``): raise naming them, or
record them with NaN histories and metrics; and a warning for a case whose events outran
the rows kept.

Pure numerics and messages: arrays in, no files, no printing (the warning is logged).
"""

from __future__ import annotations

import logging

import numpy as np

from campipe.engine.settings import (
    LIFT_BOUND,
    SPEED_BOUND,
    IntegrationError,
    RunSettings,
)
from campipe.vocabulary import (
    CHATTER,
    EVENTS_TRUNCATED,
    FAILURES,
    NONFINITE,
    STEP_LIMIT,
    UNBOUNDED,
)

log = logging.getLogger(__name__)


def raise_or_blank(
    out, settings: RunSettings, on_failure, check_stability_limit, integrator
) -> None:
    """Raise for the failed cases (``on_failure`` "raise"), warn of truncated events, and
    set a failed case's histories and metrics NaN."""
    status, n_events = out.status, out.n_events
    if on_failure == "raise":
        for code, what in failure_texts(settings, check_stability_limit, integrator).items():
            bad = np.flatnonzero(status == code)
            if bad.size:
                raise IntegrationError(f"cases {bad.tolist()}{what}", found=bad.tolist())
    for i in np.flatnonzero(status == EVENTS_TRUNCATED):
        log.warning(
            "case %d: %d events, only the first %d kept (raise run.max_events)",
            i,
            n_events[i],
            settings.max_events,
        )
    failed = np.flatnonzero(np.isin(status, FAILURES))
    for array in (out.q, out.v, out.acc, out.force, out.cam, out.per_rev):
        array[failed] = np.nan


def failure_texts(settings: RunSettings, check_stability_limit, integrator) -> dict[int, str]:
    """What ``raise_or_blank`` says after "cases [...]" of each failed status, in the order it
    looks for them."""

    def how(stepped: bool) -> str:
        return f"{settings.method}, step {settings.step:g} s" if stepped else settings.method

    defect = "this is a defect: please report it with the case"
    # (a train bouncing off its cam far past its onset can gain more than one throw's height)
    thrown = (
        "a train whose spring is far too weak for the speed can truly be thrown that far "
        "(its onset far below: campipe onset)"
    )
    unstable = (
        "the step is beyond the stability limit (the run was asked not to check it)"
        if not check_stability_limit
        else defect
    )
    return {
        NONFINITE: f" became non-finite ({how(bool(settings.step))}); {unstable}",
        CHATTER: ": contact events kept recurring at one instant (chatter); integrate them "
        "with newmark-linear",
        UNBOUNDED: f": the motion left its physical bounds "
        f"({how(integrator.fixed_step)}): a valve lift beyond "
        f"{LIFT_BOUND:g}× the larger of the full lift and the height the cam's fastest valve "
        f"speed throws it against its spring, or a speed beyond {SPEED_BOUND:g}× the cam's; "
        + (integrator.unbounded_advice or f"{thrown}; otherwise {defect}"),
        STEP_LIMIT: f": stopped at run.max_steps ({settings.max_steps:.6g} steps; a stiff "
        "contact without damping): raise --max-steps, or damp the contact",
    }
