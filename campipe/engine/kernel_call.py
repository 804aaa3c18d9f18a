"""How the batch's named structures cross into the compiled kernels of a run: as plain tuples.

A kernel takes a few named structures (``common.Cases``, ``closed_form.ModalTrains``, …), some
ninety arrays in all for modal-exact. Calling it, numba types and unboxes each argument: a
named tuple costs it about twice a plain tuple of the same arrays (a constant 0.6 µs a tuple
and 0.07 µs an array against 0.035 µs), 9 µs of modal-exact's call against 4.5 µs, and a
one-case run calls two such kernels (the periodic start's and the run's). So the run's kernels
(``exact.modal_exact_batch``, ``steady.periodic_starts``) take each structure as the plain
tuple of its fields (:func:`plain`) and name them again on their first line
(:func:`run_structures`, :func:`start_structures`): compiled, naming them costs nothing, and
the kernels' bodies, their helpers and the helpers' types are those of the named tuples
(``exact.ahead_signatures`` compiles them ahead from :func:`named_types`).
"""

from __future__ import annotations

from numba import njit, types

from campipe.engine.closed_form import ExactRuns, ModalTrains, Workspace
from campipe.engine.common import Cases, Outputs
from campipe.profiles.packed import PackedProfiles

#: The named structures ``exact.modal_exact_batch`` takes first, in order (then its state
#: record); ``steady.periodic_starts`` takes them but the outputs.
RUN_STRUCTURES = (Cases, ModalTrains, PackedProfiles, ExactRuns, Outputs, Workspace)


def plain(*arguments) -> tuple:
    """A kernel's ``arguments``, each named tuple as the plain tuple of its fields (arrays and
    anything else as they are)."""
    return tuple([tuple(a) if isinstance(a, tuple) else a for a in arguments])


def named_types(kernel_types: tuple) -> tuple:
    """The numba types of ``exact.modal_exact_batch``'s arguments as its body sees them (the
    named tuples), from those it is called with (``batch.integrator_types``: plain tuples)."""
    named = [
        types.BaseTuple.from_types(t.types, cls)
        for t, cls in zip(kernel_types, RUN_STRUCTURES, strict=False)
    ]
    return (*named, *kernel_types[len(named) :])


@njit(inline="always")
def run_structures(cases, trains, profiles, runs, out, ws):
    """``exact.modal_exact_batch``'s structures named again, from their plain tuples."""
    return (
        Cases(*cases),
        ModalTrains(*trains),
        PackedProfiles(*profiles),
        ExactRuns(*runs),
        Outputs(*out),
        Workspace(*ws),
    )


@njit(inline="always")
def start_structures(cases, trains, profiles, runs, ws):
    """``steady.periodic_starts``' structures named again, from their plain tuples."""
    return (
        Cases(*cases),
        ModalTrains(*trains),
        PackedProfiles(*profiles),
        ExactRuns(*runs),
        Workspace(*ws),
    )
