"""Which compiled kernels a run calls, and whether numba would have to compile them first.

numba compiles a kernel on its first call and keeps it in its cache (``cache=True``, in the
folder :mod:`campipe.kernel_cache` gives it): a later process loads it in a fraction of a
second, but the first run of a campipe version on a machine (or of a new clone or venv of it)
compiles them first, for tens of seconds. A caller that wants to say so on the terminal (the
CLI) asks :func:`uncompiled` before running; the engine itself prints nothing. numba offers no
public way to ask whether its cache holds a kernel: campipe records it itself once it has
compiled them (``kernel_cache.mark_compiled``, beside numba's cache). Only the kernels of the
run's integrator and start are named, and only those are compiled: a modal-exact study never
compiles newmark-linear.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from numba import types

from campipe import kernel_cache
from campipe.engine import batch, contact, exact, integrators, steady
from campipe.engine.plunger import carried
from campipe.engine.settings import Case, RunSettings

log = logging.getLogger(__name__)


def kernels(settings: RunSettings) -> dict[str, object]:
    """The compiled kernels (numba dispatchers) a run with ``settings`` calls, by name; each
    takes the helpers it calls with it (inlined, or compiled and cached along)."""
    own = integrators.get(settings.method).kernels()
    out: dict[str, object] = {}
    if settings.start == "quasi-static" or "quasi-static state" in own:
        out["quasi-static state"] = contact.quasi_static_batch
    if settings.start == "quasi-static":
        out["cam lift"] = batch.cam_at
    else:
        out["periodic start"] = steady.periodic_starts
    out.update(own)
    return out


def search_kernels() -> dict[str, object]:
    """The compiled kernels the onset's search calls (``onset.onset_speeds``), by name."""
    return {"steady extremes": steady.steady_extremes}


def _missing(named: Mapping[str, Any]) -> list[str]:
    """The names of ``named``'s kernels neither loaded in this process nor recorded as
    compiled into numba's cache (``kernel_cache.compiled_marker``)."""
    return [
        name
        for name, kernel in named.items()
        if not kernel.signatures and not kernel_cache.compiled_marker(name).exists()
    ]


def uncompiled(settings: RunSettings) -> list[str]:
    """Names of the kernels a run with ``settings`` would compile before it runs: ``[]``
    when every one is loaded or was compiled into numba's cache before."""
    return _missing(kernels(settings))


def compile_notice(settings: Iterable[RunSettings], search: bool = False) -> str | None:
    """A line saying which kernels runs with these settings (and, with ``search``, the
    onset's search) would compile first, or None when all are loaded or cached: for a
    caller to show before the wait."""
    missing: dict[str, None] = {}
    found = [_missing(search_kernels())] if search else []
    found += [uncompiled(one) for one in dict.fromkeys(settings)]
    for names in found:
        missing.update(dict.fromkeys(names))
    if not missing:
        return None
    return (
        f"compiling {', '.join(missing)} with numba, once for this campipe install on this "
        "machine (tens of seconds); later runs load them from numba's cache in a fraction of "
        "a second"
    )


def _start_kernels(
    case: Case, settings: RunSettings, search: bool = False, kernel_types: tuple | None = None
) -> None:
    if kernel_types is not None:  # modal-exact's
        for helper, signature in exact.ahead_signatures(kernel_types).items():
            helper.compile(signature)
    batch.start_states([case], settings)
    if search:
        from campipe.engine import periodic

        periodic.steady_extremes([case])


def _second_process(connection, case: Case, settings: RunSettings, search: bool) -> None:
    """The second process of a first run: imports the engine, waits for modal-exact's types
    (or None), compiles the helpers ahead and the start's kernels, reports, and ends at once
    (``os._exit``: everything it compiled is in the kernel cache by then, and a process that
    has compiled tears down its numba for a few tenths of a second, which the first would
    wait for)."""
    try:
        _start_kernels(case, settings, search, connection.recv())
        connection.send(None)
    except BaseException as exc:  # the first process logs it; the run compiles what is missing
        connection.send(f"{type(exc).__name__}: {exc}")
    finally:
        connection.close()
        os._exit(0)


def compile_kernels(case: Case, settings: RunSettings, search: bool = False) -> bool:
    """Compile (or load) every kernel a run with ``settings`` calls, the periodic start's
    and the integrator's at once: the start's in a second process, while this one compiles
    the integrator: modal-exact for the types of its arguments (``batch.integrator_types``,
    no kernel run), newmark-linear through a short quasi-static run. numba compiles one
    kernel at a time in a process, so the two cost the time of the longer on two cores, not
    their sum; both land in the kernel cache, from which the study's own run then loads
    them. The second process, started first, imports the engine while this one finds
    modal-exact's types; given them, it first compiles modal-exact helpers that this one
    then loads (``exact.ahead_signatures``), so that the two end together. With ``search``
    the second process also compiles the onset's search (``search_kernels``).

    Both processes use numba's public interface only: ``Dispatcher.compile`` and calls,
    each kernel written to numba's cache by its own ``cache=True`` (the second process
    inherits ``NUMBA_CACHE_DIR``). True when every kernel was compiled (or loaded); False
    when something failed, logged: the run then compiles what is missing itself."""
    short = dataclasses.replace(settings, revolutions=0.01, warmup=0)
    if settings.start != "periodic" and not search:
        batch.run_batch([case], short, full_state=False, on_failure="record")
        return True
    import multiprocessing

    try:
        spawn = multiprocessing.get_context("spawn")
        ours, theirs = spawn.Pipe()
        second = spawn.Process(
            target=_second_process, args=(theirs, case, settings, search), daemon=True
        )
        second.start()  # it imports the engine while this one goes on
        theirs.close()  # its end is its own now: should it die, our end reads EOFError
    except OSError as exc:  # no second process: compile in turn, in this one
        log.debug("compiling in one process: %s", exc)
        second = None
    try:
        # Found here (no kernel run) and handed over: the second process then compiles the
        # helpers ahead.
        kernel_types = None
        if settings.method == "modal-exact":
            kernel_types = batch.integrator_types([case], settings, False)
            if carried(case, settings.integrator):  # the kernel with a plunger's code
                kernel_types = (*kernel_types[:-1], types.Array(types.int64, 1, "C"))
        handed = False
        if second is not None:
            try:
                ours.send(kernel_types)
                handed = True
            except OSError as exc:  # it is gone (it could not start): its share is ours
                log.debug("the second process is gone: %s", exc)
        if not handed:
            _start_kernels(case, settings, search, kernel_types)
        if kernel_types is not None:
            exact.modal_exact_batch.compile(kernel_types)
        else:
            quasi_static = dataclasses.replace(short, start="quasi-static")
            batch.run_batch([case], quasi_static, full_state=False, on_failure="record")
        if handed and (failed := ours.recv()) is not None:
            log.debug("the second process failed: %s", failed)
            return False
        return True
    except Exception as exc:  # the run itself compiles whatever is still missing
        log.debug("compiling ahead failed: %s", exc)
        return False
    except BaseException:  # an interrupt: the second process stops too
        if second is not None:
            second.terminate()
        raise
    finally:
        if second is not None:
            ours.close()
            second.join()


def compile_first(
    firsts: Mapping[RunSettings, Case],
    notice: Callable[[str], None] | None,
    search: bool = False,
) -> None:
    """Before runs with each of these settings (a case of each given), and with ``search``
    the onset's search: say on ``notice`` which kernels numba compiles (nothing when all are
    cached), and compile them here (:func:`compile_kernels`, the start's and the
    integrator's in two processes at once), so that the runs, on any number of workers, load
    them from the cache; then record them as compiled (``kernel_cache.mark_compiled``), so
    that the next run says nothing."""
    text = compile_notice(firsts, search=search)
    if text is None:
        return
    if notice is not None:
        notice(text)
    for settings, case in firsts.items():
        if compile_kernels(case, settings, search=search):
            names = [*kernels(settings), *(search_kernels() if search else ())]
            kernel_cache.mark_compiled(names)


def record_loaded(named: Mapping[str, Any]) -> None:
    """Record as compiled (``kernel_cache.mark_compiled``) those of ``named``'s kernels this
    process has loaded or compiled (and numba then cached): for a caller that ran them
    without :func:`compile_first` compiling them ahead (the onset's search without the
    check)."""
    kernel_cache.mark_compiled(name for name, kernel in named.items() if kernel.signatures)
