"""The ``campipe`` command line (click). I/O only: every number comes from the numerics layer.

Each command imports what it uses when it runs (``campipe --help`` loads click, the model's
parameter table and NumPy, nothing else): dask, xarray, netCDF4, pint, SciPy, numba and
rerun load only in the commands that need them.

The group and what the commands share are :mod:`~campipe.cli.base`'s; one module per family
of commands: :mod:`~campipe.cli.study` (study, validate, query, pack), :mod:`~campipe.cli.export`,
:mod:`~campipe.cli.plot`, :mod:`~campipe.cli.onset`, :mod:`~campipe.cli.design`,
:mod:`~campipe.cli.replay`, :mod:`~campipe.cli.model` (model, init, schema) and
:mod:`~campipe.cli.bench`.
"""

import os
import signal
import sys


def _interrupted_early(signum, frame) -> None:
    """Ctrl-C while the command line loads (before ``main`` maps it to a message): a line,
    exit status 130, no traceback of an import."""
    sys.stderr.write("campipe: interrupted (Ctrl-C) while starting; nothing was done\n")
    os._exit(128 + signal.SIGINT)


def _terminated_early(signum, frame) -> None:
    """SIGTERM (a batch system's time limit, ``kill``) while the command line loads: a line,
    exit status 143, as for Ctrl-C."""
    sys.stderr.write("campipe: terminated (SIGTERM) while starting; nothing was done\n")
    os._exit(128 + signal.SIGTERM)


# Only in campipe's own process (its console script, python -m campipe: read from the
# interpreter's own arguments, which a spawned worker process does not share even where it
# copies sys.argv), and where the signal is Python's (Ctrl-C not ignored, as in a background
# job; SIGTERM at its default): a program that imports the command line keeps its handlers.
# main() puts Python's Ctrl-C back, and makes SIGTERM end the command as Ctrl-C does.
if os.path.basename(sys.orig_argv[1] if len(sys.orig_argv) > 1 else "") == "campipe" or (
    sys.orig_argv[1:3] == ["-m", "campipe"]
):
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupted_early)
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _terminated_early)

from campipe.cli import bench, design, export, model, onset, plot, replay, study  # noqa: E402
from campipe.cli.base import main  # noqa: E402

__all__ = ["main"]

for _command in (
    bench.bench,
    export.export,
    design.design,
    model.init,
    model.model,
    model.schema,
    onset.onset,
    study.pack,
    plot.plot,
    study.query,
    replay.replay,
    study.study,
    study.validate,
):
    main.add_command(_command)
