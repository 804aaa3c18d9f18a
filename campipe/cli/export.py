"""``campipe export``: a case's histories as a table (CSV, Parquet or MATLAB)."""

from __future__ import annotations

import click

from campipe.cli.base import units_option, verify_option


@click.command()
@click.argument("archive", type=click.Path(exists=True))
@click.option(
    "--case",
    "cases",
    multiple=True,
    metavar="ID",
    help="A case to export, by its id or a start of it unique to it. Repeatable.",
)
@click.option("--where", help="Export the cases where EXPR holds (the language of query --where).")
@units_option
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["csv", "parquet", "mat"]),
    help="csv, parquet (needs pyarrow) or mat (MATLAB, through SciPy); default: by the "
    "output's suffix (.csv, .parquet, .mat).",
)
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="File to write.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that campipe export did not write (never the "
    "archive or its spec).",
)
@verify_option
def export(archive, cases, where, units, fmt, output, overwrite, verify) -> None:
    """Write the histories of cases of ARCHIVE as a table: one row per sample, one column
    per history (case, cam_angle, time, valve_lift, valve_velocity, ..., q1 ... q7), each
    header naming its units (valve_velocity [mm/deg])."""
    from pathlib import Path

    from campipe.cli.study import _open_archive
    from campipe.io.outputs import check_output
    from campipe.io.table_file import export_kind, format_of, pyarrow_parquet, write_table
    from campipe.study.query.export import history_table, pick_cases

    fmt = format_of(output, fmt)
    if fmt == "parquet":
        pyarrow_parquet()
    archive = Path(archive)
    with _open_archive(archive, verify) as ds:
        spec = str(ds.attrs.get("spec_file") or "")
        check_output(
            output,
            "-o",
            export_kind(fmt),
            overwrite=overwrite,
            inputs=[
                (archive, "the archive exported"),
                (archive.parent / spec if spec else None, "the archive's spec"),
            ],
        )
        table = history_table(ds, pick_cases(ds, cases, where), units)
    path = write_table(output, fmt, table.columns, table.units, table.study)
    n = len(table.cases)
    rows = len(next(iter(table.columns.values())))
    click.echo(f"campipe export: {n} case{'s' if n != 1 else ''}, {rows} rows", err=True)
    if table.left_out:
        click.echo(
            f"campipe export: left out, NaN in every row exported (not of this layout): "
            f"{', '.join(table.left_out)}",
            err=True,
        )
    click.echo(str(path))
