"""What an integrator is to the engine: one small protocol (check, prepare, run), found by
name in the registry (:mod:`campipe.engine.integrators`), never by if/elif.

An integrator module holds no numba at import: it names its compiled kernel and loads it in
:meth:`Integrator.prepare` or :meth:`Integrator.run`, so that checking a run (a spec, a study
plan) costs no compiled code.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol

import numpy as np

from campipe.engine.case import Case


class CarriedPlungers(NamedTuple):
    """The lash adjusters whose plunger an integrator carries as a state (``engine.plunger``):
    each turn's extension at its start, leak-down and pump-up (``BatchResult.lash_adjuster``,
    NaN for a case without one) and each sample's extension where it lengthens a chain's
    link (``BatchResult.extension``, NaN elsewhere)."""

    table: np.ndarray  # (n, n_rev, 3) [m]
    extension: np.ndarray  # (n, n_out) [m]


class RunLike(Protocol):
    """The run settings an integrator reads (``campipe.engine.RunSettings``)."""

    @property
    def integrator(self) -> str: ...  # as the run names it ("default" or a registered name)

    @property
    def revolutions(self) -> float | None: ...  # cam turns (None: until settled)

    @property
    def recorded_revolutions(self) -> float: ...  # cam turns the histories cover

    @property
    def output_every(self) -> float: ...  # output spacing [rad]

    @property
    def tolerance(self) -> float: ...  # event-time tolerance [s]

    @property
    def step(self) -> float | None: ...  # the step [s] (an event-driven one's cap), or None

    @property
    def method(self) -> str: ...  # the integrator's resolved name

    @property
    def max_steps(self) -> int: ...  # the most steps of one case (adaptive integrators)


class Integrator(Protocol):
    """An integrator of a batch of cases."""

    name: str  # the name a spec gives (``run.integrator``)
    description: str  # one line for the docs and the refusals
    contacts: str  # the contacts it integrates: "rigid" (held, impacts) or "compliant"
    default_step: float | None  # its step when a run names none [s]; None: it sizes its own
    #: it advances on a grid of its step: a periodic start falls on a whole number of steps
    fixed_step: bool
    #: what a case out of its physical bounds means for it (None: a defect, to be reported)
    unbounded_advice: str | None
    #: its kernel writes every output sample of every case (a failed case is blanked after
    #: it): the run's histories are handed to it uncleared (``common.make_outputs``)
    fills_outputs: bool

    def check(self, cases: Sequence[Case], run: RunLike) -> None:
        """Refuse what it cannot run (``RunSettingsError`` at ``run.integrator``, or a
        ``CaseError``), before anything is compiled."""
        ...

    def stability_limit(self, case: Case) -> tuple[float, int]:
        """Its largest stable step for a case [s] and the configuration that sets it
        (``inf`` and 0 for an integrator without a limit)."""
        ...

    def kernels(self) -> dict[str, Any]:
        """Its compiled kernels (numba dispatchers) by the name a first run's notice gives
        them, loading them (``campipe.engine.kernels``); none for one that compiles none."""
        ...

    def prepare(self, batch: Any, run: RunLike) -> Any:
        """What its kernel takes beside the cases and the outputs, from a prepared batch
        (``campipe.engine.batch.PreparedBatch``)."""
        ...

    def run(self, prepared: Any, cases: Any, out: Any) -> CarriedPlungers | None:
        """Advance every case from its start (``common.Cases``) and fill ``out``
        (``common.Outputs``) in place; return the lash adjusters whose plunger it carries as
        a state (only the compliant integrator's, ``engine.plunger``), else None."""
        ...
