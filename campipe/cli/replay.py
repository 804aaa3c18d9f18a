"""``campipe replay``: cases of an archive as a rerun recording."""

from __future__ import annotations

import os
import sys

import click

from campipe.cli.base import InputFailure, units_option, verify_option


@click.command()
@click.argument("archive", type=click.Path())
@click.option(
    "--case",
    "case_ids",
    multiple=True,
    metavar="ID",
    help="Replay the case with this case id (the archive's case coordinate; repeatable).",
)
@click.option(
    "--where",
    help="Replay the cases where EXPR holds (the language of campipe "
    "query --where; never run as Python).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="Recording to write (default: <archive stem>.replay.rrd beside it).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that is not a rerun recording (never the archive "
    "or its spec).",
)
@click.option("--spawn", is_flag=True, help="Open the rerun viewer instead of writing a file.")
@click.option(
    "--magnify",
    type=click.FloatRange(min=1.0),
    default=10.0,
    show_default=True,
    help="Factor on the sketch's deviations from the rigid-body motion.",
)
@verify_option
@units_option
def replay(archive, case_ids, where, output, overwrite, spawn, magnify, verify, units) -> None:
    """Write a rerun recording of cases of ARCHIVE: lift, force and contact plots (in the
    units query and plot show, --units), events, parameters and the moving mechanism (in mm),
    on the timelines cam_angle and time. All cases go into one recording, each in its own
    cases/<case_id> subtree and blueprint tab."""
    from campipe.replay.cases import ReplayError
    from campipe.replay.record import replay_archive
    from campipe.study.run.progress import Progress
    from campipe.study.where import QueryError

    if bool(case_ids) == (where is not None):
        raise click.UsageError("give --case ID (repeatable) or --where EXPR, one of the two")
    if spawn and output:
        raise click.UsageError("-o and --spawn exclude each other")
    if output and not os.path.isdir(os.path.dirname(os.path.abspath(output))):
        raise InputFailure(
            f"-o {output}: its folder {os.path.dirname(os.path.abspath(output))} does not "
            "exist; create it, or write the recording elsewhere"
        )
    stderr = sys.stderr

    def bar(total: int, unit: str) -> Progress:
        return Progress(total, stderr.write, terminal=stderr.isatty(), unit=unit, then="")

    try:
        path, cases = replay_archive(
            archive,
            case_ids=case_ids,
            where=where,
            output=output,
            spawn=spawn,
            magnification=magnify,
            progress=bar,
            overwrite=overwrite,
            verify=verify,
            units=units,
        )
    except QueryError as exc:
        raise click.UsageError(str(exc)) from None
    except ReplayError as exc:  # the input's: a missing archive, an unknown case, none chosen
        raise InputFailure(str(exc)) from None
    click.echo(
        f"campipe replay: {len(cases)} case{'s' if len(cases) != 1 else ''} ("
        + ", ".join(c.case_id for c in cases)
        + ")",
        err=True,
    )
    if path is not None:
        click.echo(str(path))
