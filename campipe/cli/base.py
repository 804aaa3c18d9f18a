"""The ``campipe`` group and what its commands share: errors mapped to messages and exit
statuses (:func:`failure`), ``--set`` overrides, a spec loaded and refused, the limit and
unit options."""

from __future__ import annotations

import atexit
import functools
import gc
import logging
import os
import sys

import click

from campipe import __version__
from campipe.errors import CampipeError
from campipe.memory import reuse_freed_memory
from campipe.units import pint_without_dask


def parse_overrides(pairs: tuple[str, ...]) -> dict[str, object]:
    """``("spring_rate=260 lbf/in", …)`` → ``{"spring_rate": "260 lbf/in"}``, values as YAML."""
    from campipe.io.spec_yaml import SpecFileError, parse_value

    out: dict[str, object] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise click.BadParameter(
                f"{pair!r}: write NAME=VALUE, e.g. spring_rate='260 lbf/in'", param_hint="--set"
            )
        try:
            out[key] = parse_value(text, key)
        except SpecFileError as exc:
            raise click.BadParameter(str(exc), param_hint="--set") from None
    return out


#: Longest line of an error message shown: a message quoting a huge value stays readable.
MAX_MESSAGE_LINE = 1000


class Failure(CampipeError, click.ClickException):
    """A CampipeError or a system error as the command's message: one line or a few naming
    the cause and what to do. Exit status 2 for the user's input (the error is a
    ValueError: a spec, an option, a path), 1 for the environment (a RuntimeError or
    OSError: a full or read-only disk, a busy archive, a scheduler or worker gone)."""

    exit_code = 1

    def __init__(self, message: str) -> None:
        lines = [
            line if len(line) <= MAX_MESSAGE_LINE else line[: MAX_MESSAGE_LINE - 3] + "..."
            for line in message.splitlines()[:60]
        ]
        super().__init__("\n".join(lines))

    def show(self, file=None) -> None:
        click.echo(f"Error: {self.format_message()}", err=True)

    @staticmethod
    def of(message: str, user_input: bool) -> Failure:
        """An InputFailure (exit status 2) or an environment Failure (1)."""
        return InputFailure(message) if user_input else Failure(message)


class InputFailure(Failure):
    """A Failure caused by the user's input: exit status 2."""

    exit_code = 2


def failure(exc: BaseException) -> Failure | None:
    """The Failure for an exception a user can act on, or None for a defect (left to raise
    with its traceback)."""
    if isinstance(exc, CampipeError):
        return Failure.of(str(exc), isinstance(exc, ValueError))
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return Failure(f"{where}{exc.strerror or exc}")
    if isinstance(exc, MemoryError):
        return Failure("out of memory; run a smaller study, or on a larger machine")
    from campipe.io.archive import missing_filter

    if (plugin := missing_filter(exc)) is not None:
        return Failure(f"cannot read the archive ({exc}): {plugin}")
    if isinstance(exc, RuntimeError) and "NetCDF: HDF error" in str(exc):
        return Failure(
            f"cannot read the archive ({exc}): a part of it is damaged (a chunk whose "
            "Fletcher-32 checksum differs, or the file's structure); read it without "
            "--no-verify to name the variables, or run the study again to write it anew"
        )
    return None


class Interrupted(Failure):
    """Ctrl-C (SIGINT): exit status 130, as a shell reports it."""

    exit_code = 128 + 2


class Terminated(KeyboardInterrupt):
    """SIGTERM in a running command (a batch system's time limit, ``kill``): raised as Ctrl-C
    is, so that what a run does on Ctrl-C (its lock released, its batches kept) it does on
    this too; the command ends with status 143 (:class:`TerminatedFailure`)."""


class TerminatedFailure(Failure):
    """SIGTERM: exit status 143, as a shell reports it."""

    exit_code = 128 + 15


#: What an interrupted command leaves, by command.
AFTER_INTERRUPT = {
    "study": "the batches finished are kept: rerun the same command to resume",
    "onset": "nothing was written; rerun the same command to search again",
}


class CampipeGroup(click.Group):
    """The ``campipe`` group: maps errors to messages and exit statuses (:func:`failure`),
    and Ctrl-C to a line saying what stays (not click's bare "Aborted!")."""

    def invoke(self, ctx: click.Context):
        from campipe.io.watch import ReadStalled, stuck

        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as exc:
            name = ctx.invoked_subcommand or ""
            after = f"; {AFTER_INTERRUPT[name]}" if name in AFTER_INTERRUPT else ""
            if reading := stuck():
                after += f" (while reading {reading[0]}: if it never ended, the file is damaged)"
            if isinstance(exc, Terminated):
                raise TerminatedFailure(f"campipe {name}: terminated (SIGTERM){after}") from None
            raise Interrupted(f"campipe {name}: interrupted (Ctrl-C){after}") from None
        except ReadStalled as exc:
            raise Failure(str(exc)) from None
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except BrokenPipeError:
            raise  # a reader such as `head` closed stdout: click's main exits quietly
        except Exception as exc:
            mapped = failure(exc)
            if mapped is None:
                raise
            raise mapped from None

    def main(self, *args, **kwargs):
        """click's ``main``; after a read left inside HDF5 (:func:`campipe.io.watch.stuck`)
        the process ends at once with the command's status: the interpreter's own exit would
        tear the library down under that read (a segmentation fault)."""
        from campipe.io.watch import stuck

        try:
            return super().main(*args, **kwargs)
        except SystemExit as exc:
            if stuck():
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(exc.code if isinstance(exc.code, int) else 1)
            raise


@click.group(cls=CampipeGroup)
@click.version_option(version=__version__, package_name="campipe")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """campipe: parametric studies of cam-driven valve-train dynamics."""
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)])
    _restore_interrupt()
    _exit_without_collecting()
    reuse_freed_memory()  # this process is the command's own (campipe.memory)


def _restore_interrupt() -> None:
    """Python's own Ctrl-C (KeyboardInterrupt, which :class:`CampipeGroup` maps) in place of
    the handler ``campipe.cli`` sets while it loads, and SIGTERM raising :class:`Terminated`
    (mapped likewise) in place of its."""
    import signal

    if getattr(signal.getsignal(signal.SIGINT), "__name__", "") == "_interrupted_early":
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if getattr(signal.getsignal(signal.SIGTERM), "__name__", "") == "_terminated_early":
        signal.signal(signal.SIGTERM, _terminate)


def _terminate(signum, frame) -> None:
    """SIGTERM in a running command: :class:`Terminated`, raised where the command is."""
    raise Terminated()


@functools.cache
def _exit_without_collecting() -> None:
    """At exit, leave the objects still alive to the operating system (``gc.freeze``, once
    the exit handlers registered since have run) instead of the interpreter's last garbage
    collections: once a kernel has run, those go through numba's object graph, 0.15 s of a
    one-case study. Exit handlers still run; a command closes its files before it returns."""
    atexit.register(gc.freeze)


# -- studies ----------------------------------------------------------------------------------


class SpecRefused(CampipeError, click.ClickException):
    """A spec refused before anything runs (exit status 2, like a usage error)."""

    exit_code = 2

    def show(self, file=None) -> None:
        click.echo(self.format_message(), err=True)


def load_spec(spec_path, sets, limits=None):
    from campipe.io.spec_yaml import SpecFileError
    from campipe.study import SpecError, load_study

    pint_without_dask()  # this process is the command's own
    overrides = parse_overrides(sets)
    try:
        return load_study(spec_path, overrides, limits)
    except (SpecFileError, SpecError) as exc:
        raise SpecRefused(str(exc)) from None


#: The defaults of campipe.study.spec.limits.Limits, repeated here so --help needs no import of
#: the engine (tests/integration/test_fuzz.py checks they agree).
DEFAULT_LIMITS = {
    "cases": 100_000,
    "steps": 1e9,
    "samples": 100_000,
    "events": 100_000,
    "archive_gb": 20.0,
}


def limit_options(command):
    """``--max-cases`` … ``--max-archive-gb``: the limits a spec is checked against."""
    d = DEFAULT_LIMITS
    options = [
        click.option(
            "--max-archive-gb",
            type=click.FloatRange(min=0, min_open=True),
            default=d["archive_gb"],
            show_default=True,
            help="Largest archive before compression [GB].",
        ),
        click.option(
            "--max-events",
            type=click.IntRange(min=1),
            default=d["events"],
            show_default=True,
            help="Largest run.max_events (events kept per case).",
        ),
        click.option(
            "--max-samples",
            type=click.IntRange(min=2),
            default=d["samples"],
            show_default=True,
            help="Most stored samples per case (revolutions × 360° / output_every).",
        ),
        click.option(
            "--max-steps",
            type=click.FloatRange(min=1),
            default=d["steps"],
            show_default=True,
            help="Most integration steps per case (the slowest speed with the smallest step).",
        ),
        click.option(
            "--max-cases",
            type=click.IntRange(min=1),
            default=d["cases"],
            show_default=True,
            help="Most cases in the study (counted from the axes' lengths).",
        ),
    ]
    for option in options:
        command = option(command)
    return command


def limits_given(max_cases, max_steps, max_samples, max_events, max_archive_gb):
    from campipe.study.spec.limits import Limits

    return Limits(max_cases, max_steps, max_samples, max_events, max_archive_gb * 1e9)


def archive_path(study, spec_path, output, parts: bool = False):
    """``-o``, or the default archive beside the spec: ``<name>.nc``, or the folder
    ``<name>.parts`` for a parts archive."""
    from pathlib import Path

    if output:
        return Path(output)
    return Path(spec_path).parent / f"{study.name}{'.parts' if parts else '.nc'}"


SET_HELP = (
    "Override a spec key before checking it, value as YAML: --set run.revolutions=1, "
    "--set sweep.speed='[9000 rpm, 9524 rpm]'. Repeatable."
)


#: The unit systems of --units (campipe.study.spec.plots.SYSTEMS, repeated so --help needs no
#: import of the study layer; tests/integration/test_plot.py checks they agree).
UNIT_SYSTEMS = ("spec", "si", "in-lbf", "mm-deg", "mm-degca")


def scheduler_options(where: str, workers_for: str):
    """``--scheduler`` and ``--workers``: where a command's computations run (``where``
    begins the scheduler's help) and what a cluster's worker threads are counted for."""

    def decorate(command):
        command = click.option(
            "--workers",
            type=click.IntRange(min=1),
            help="Threads or processes of a local scheduler (default: the cores available); "
            f"on a dask cluster, its worker threads, {workers_for}.",
        )(command)
        return click.option(
            "--scheduler",
            default="threads",
            show_default=True,
            help=f"{where}threads, synchronous, processes, or a dask.distributed scheduler "
            "address such as tcp://127.0.0.1:8786 (or 127.0.0.1:8786).",
        )(command)

    return decorate


def verify_option(command):
    """``--no-verify``: read an archive without first checking it against its checksums."""
    return click.option(
        "--verify/--no-verify",
        default=True,
        show_default=True,
        help="Check every variable of the archive against the checksums stored when it was "
        "written before reading it (one more read of the archive); a damaged one is refused, "
        "its variables named. --no-verify skips that check (HDF5 still checks each chunk it "
        "reads of archives written since campipe 0.1's Fletcher-32).",
    )(command)


def units_option(command):
    """``--units spec|si|in-lbf|mm-deg|mm-degca``: the units values are shown in."""
    return click.option(
        "--units",
        type=click.Choice(UNIT_SYSTEMS),
        default="spec",
        show_default=True,
        help="Show values in the units the spec wrote them in, with the rest in the spec's "
        "system (spec), in SI as stored (si), in inches, pounds-force and seconds (in-lbf), "
        "or in mm, mm/deg and mm/deg^2 of cam angle at each case's cam speed, N and MPa "
        "(mm-deg), or the same per degree of crank angle at each case's engine speed "
        "(mm-degca: mm/degCA, a spec with a drive; angles stay the cam's).",
    )(command)
