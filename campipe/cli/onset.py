"""``campipe onset``: the speed where separation begins, for each design of a spec."""

from __future__ import annotations

import click
import numpy as np

from campipe.cli.base import SET_HELP, Failure, load_spec
from campipe.constants import DEFAULT_ONSET_LEVEL_DEG, DEFAULT_ONSET_TOLERANCE_RPM


@click.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option(
    "--tolerance",
    default=f"{DEFAULT_ONSET_TOLERANCE_RPM:g} rpm",
    show_default=True,
    metavar="SPEED",
    help="The onset's tolerance (the width of its final bracket).",
)
@click.option(
    "--level",
    default=f"{DEFAULT_ONSET_LEVEL_DEG:g} deg",
    show_default=True,
    metavar="ANGLE",
    help="With a seat, the no-follow a turn the onset reaches (0 deg: the first separation, "
    "a flight the engine keeps: over a nanometre). Without a seat the onset is the first "
    "separation.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["table", "csv", "json"]),
    default="table",
    show_default=True,
    help="json: {study, units, cases: [row objects]} as campipe query's (null: no onset in "
    "the range, or no seat).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="The netCDF file written (default: <name>-onset.nc beside SPEC).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that is not this spec's onset archive (another "
    "study's archive, any other file); never the spec.",
)
@click.option(
    "--check/--no-check",
    default=True,
    show_default=True,
    help="Run the time-domain engine 0.5 % below and above each onset (10 turns, the first "
    "2 left out): below it must stay under the level, above reach it (nearer, down to "
    "0.0625 %, where a window of no-follow is narrower).",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    help="Threads for the search (default: the cores available).",
)
def onset(spec, sets, tolerance, level, fmt, output, overwrite, check, workers) -> None:
    """The no-follow onset speed of every combination of SPEC's other axes, within its
    speed range, missing no window of no-follow in it: the root of the steady state's least
    cam force (with a seat, where its no-follow reaches --level a turn), checked by the
    time-domain engine either side. Exit status 1 when a check disagrees."""
    from pathlib import Path

    from campipe.units import QuantityError, parse_angular

    try:  # a bare number is refused: it would be read as rad/s, or rad
        tol = parse_angular(tolerance, "rad/s", "--tolerance", "rpm")
    except QuantityError as exc:
        raise click.BadParameter(exc.reason, param_hint="--tolerance") from None
    if not tol > 0:
        raise click.BadParameter(f"found {tolerance!r}, expected > 0 rpm", param_hint="--tolerance")
    try:
        angle = parse_angular(level, "rad", "--level", "deg")
    except QuantityError as exc:
        raise click.BadParameter(exc.reason, param_hint="--level") from None
    if not 0 <= angle < 2 * np.pi:  # no-follow a turn: at most the whole turn
        raise click.BadParameter(
            f"found {level!r}, expected ≥ 0 deg and below 360 deg (no-follow a turn)",
            param_hint="--level",
        )
    loaded = load_spec(spec, sets)
    path = Path(output) if output else Path(spec).parent / f"{loaded.name}-onset.nc"
    given = click.get_current_context().get_parameter_source("level")
    run_onset(loaded, spec, path, tol, fmt, check, workers, overwrite=overwrite, level=angle,
              level_given=given is click.core.ParameterSource.COMMANDLINE)  # fmt: skip


def run_onset(
    loaded,
    spec_path,
    path,
    tolerance,
    fmt,
    check,
    workers,
    command="onset",
    overwrite=False,
    level=None,
    level_given=False,
) -> None:
    """``campipe onset``'s work (and ``campipe study``'s for a spec with ``search``): the
    output checked by the output rule (``campipe.io.outputs``) before the search, and
    written under the lock ``campipe study`` holds on an archive."""
    from pathlib import Path

    from campipe.io.lock import writing

    path = Path(path)
    spec_file = onset_output(loaded, spec_path, path, overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        onset_output(loaded, spec_path, path, overwrite)  # another run may have written it
        _search_and_write(
            loaded, spec_path, path, spec_file, tolerance, fmt, check, workers, command, level,
            level_given,
        )  # fmt: skip


def onset_output(loaded, spec_path, path, overwrite) -> str:
    """Refuse an output the onset may not replace (the spec, another study's archive, a file
    campipe did not write for this spec's onset) unless ``overwrite``; returns the spec's path
    relative to the output's folder, which the file records."""
    import os
    from pathlib import Path

    from campipe.io.outputs import check_output, describe_netcdf, onset_kind

    spec_file = os.path.relpath(Path(spec_path).resolve(), Path(path).parent.resolve())
    check_output(
        path,
        "-o",
        onset_kind(loaded.name, spec_file),
        overwrite=overwrite,
        inputs=[(spec_path, "the spec")],
        describe=describe_netcdf,
    )
    return spec_file


def _search_and_write(
    loaded, spec_path, path, spec_file, tolerance, fmt, check, workers, command, level,
    level_given=False,
):  # fmt: skip
    from campipe.io.archive import provenance, write_file
    from campipe.io.outputs import ONSET_FILE
    from campipe.study.onset import file_contents, onset_study, summary_lines
    from campipe.study.query.display import display_units
    from campipe.study.query.tables import displayed, format_rows
    from campipe.study.run.sizing import default_workers

    result = onset_study(
        loaded,
        tolerance,
        **({} if level is None else {"level": level}),
        confirm=check,
        workers=workers or default_workers(),
        notice=lambda text: click.echo(f"campipe {command}: {text}", err=True),
    )
    sizes, variables, arrays, attrs = file_contents(result)
    write_file(
        path,
        sizes,
        variables,
        arrays,
        {
            **attrs,
            **provenance(f"campipe onset {spec_path}"),
            "campipe_file": ONSET_FILE,
            "spec_file": spec_file,
        },
        loaded.compression,
    )
    table = with_engine_speed(result.table, loaded.spec.drive)
    table = displayed(table, display_units(table.units, attrs))
    click.echo(format_rows(table, np.arange(table.n), table.default, fmt))
    if loaded.spec.drive is not None:
        click.echo(
            f"onset_speed_rpm is the cam's speed, onset_engine_speed_rpm the engine's "
            f"(the cam's / drive.cam_per_crank {loaded.spec.drive:g})",
            err=True,
        )
    for line in summary_lines(result):
        click.echo(line, err=True)
    if level_given and level and not (result.levels > 0).any():
        click.echo(
            "--level applies to a train with a seat, and no combination has one: each onset "
            "is the first separation",
            err=True,
        )
    click.echo(f"wrote {path}", err=True)
    if result.disagreements.size:
        raise Failure(summary_lines(result)[-1])


def with_engine_speed(table, drive: float | None):
    """The onset table (a CaseTable) with, for a spec with a drive, the onset at the
    engine's speed beside the cam's (``onset_engine_speed_rpm``, after ``onset_speed_rpm``)."""
    from campipe.study.query.tables import CaseTable

    if drive is None or "onset_speed_rpm" not in table.columns:
        return table
    columns, units, default = {}, {}, []
    for name, values in table.columns.items():
        columns[name], units[name] = values, table.units[name]
        if name == "onset_speed_rpm":
            columns["onset_engine_speed_rpm"] = np.asarray(values, float) / drive
            units["onset_engine_speed_rpm"] = table.units[name]
    for name in table.default:
        default.append(name)
        if name == "onset_speed_rpm":
            default.append("onset_engine_speed_rpm")
    return CaseTable(columns, units, default, table.n, table.study)
