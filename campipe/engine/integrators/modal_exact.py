"""modal-exact: the default for rigid contacts. Exact between contact events (each
configuration's closed form over a cam piece), the events located by a bracketed root
search to the run's tolerance (``campipe.engine.exact``)."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

from campipe.engine.case import Case
from campipe.engine.integrators.base import RunLike


class ModalExact:
    name = "modal-exact"
    description = "exact between contact events, events located to run.tolerance"
    contacts = "rigid"
    default_step: float | None = None
    fixed_step = False
    unbounded_advice: str | None = None
    fills_outputs = True

    def check(self, cases: Sequence[Case], run: RunLike) -> None:
        """It runs every rigid case (refined members, restitution, form closure)."""

    def stability_limit(self, case: Case) -> tuple[float, int]:
        return math.inf, 0

    def kernels(self) -> dict[str, Any]:
        from campipe.engine import exact

        return {"modal-exact": exact.modal_exact_batch}

    def prepare(self, batch: Any, run: RunLike) -> Any:
        return batch.modal_trains, batch.packed, batch.runs

    def run(self, prepared: Any, cases: Any, out: Any) -> None:
        _engine()[0].modal_exact_batch(*arguments(prepared, cases, out))


@functools.cache
def _engine():
    """The modules of the compiled kernel and its arguments, imported when first run (not
    with the registry: a spec is checked without numba) and held (an import statement in
    each call costs a one-case run a microsecond)."""
    from campipe.engine import closed_form, exact, kernel_call

    return exact, closed_form, kernel_call


def arguments(prepared: Any, cases: Any, out: Any) -> tuple:
    """The kernel's arguments for a batch starting as ``cases`` says, with fresh work
    arrays: its named structures as plain tuples (``campipe.engine.kernel_call``)."""
    _, closed_form, kernel_call = _engine()
    modal_trains, packed, runs = prepared
    n_q = modal_trains.load.shape[1]
    args = kernel_call.plain(
        cases, modal_trains, packed, runs, out, closed_form.make_workspace(n_q),
        closed_form.make_state(),
    )  # fmt: skip
    return (*args, carried_plungers(runs))


def carried_plungers(runs: Any) -> Any:
    """The kernel's last argument: the batch's plunger coordinates if a case carries one
    (``plunger_modes``), else None, for which numba compiles a kernel without the plunger's
    code (a second specialisation, compiled only when such a batch first runs)."""
    coords = runs.plunger_coord
    if coords.size == 1:  # (a one-case call: no reduction)
        return coords if coords[0] >= 0 else None
    return coords if coords.size and int(coords.max()) >= 0 else None
