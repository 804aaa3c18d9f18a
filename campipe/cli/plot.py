"""``campipe plot``: the figures of an archive, and those a spec asks for when its study ends."""

from __future__ import annotations

import click

from campipe.cli.base import Failure, InputFailure, SpecRefused, units_option, verify_option

#: The plot kinds (campipe.study.spec.plots.KINDS, repeated so --help needs no import of the study
#: layer; tests/integration/test_plot.py checks they agree).
PLOT_KINDS = ("histories", "metric", "map", "events", "pareto", "spectrum")


@click.command()
@click.argument("kind", type=click.Choice(PLOT_KINDS))
@click.argument("archive", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="File to write: PNG, SVG or PDF by its suffix (default: <archive stem>-KIND.png "
    "beside the archive).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that is not a figure of its format (never the "
    "archive or its spec).",
)
@click.option("--where", help="Draw the cases where EXPR holds (the language of query --where).")
@units_option
@click.option(
    "--x",
    "x",
    metavar="COLUMN",
    help="metric, map: the column along x (default: the speed where it varies, "
    "engine_speed_rpm for an archive with a drive, else speed_rpm; else the first numeric "
    "column that varies); pareto: the first objective's.",
)
@click.option(
    "--y",
    "y",
    metavar="COLUMN",
    help="metric: the value drawn (default: separation_deg_per_rev); map: the column along y; "
    "pareto: the second objective's.",
)
@click.option(
    "--z", "z", metavar="COLUMN", help="map: the value coloured (default: separation_deg_per_rev)."
)
@click.option(
    "--level",
    metavar="VALUE",
    help="map: draw the contour at this value of z, a number in its shown units or a quantity "
    "such as '1 deg'.",
)
@click.option(
    "--turn",
    metavar="N|last|all",
    help="histories, events: show one cam turn (1, 2, ... or last; default all).",
)
@click.option(
    "--angle",
    type=click.Choice(["cam", "crank"]),
    help="histories, events: draw against the cam angle (default) or the crank angle (an "
    "archive whose spec gives a drive).",
)
@click.option(
    "--range",
    "span",
    metavar="LO:HI",
    help="histories, events: show the angles LO to HI [deg of the angle drawn], e.g. 60:120 "
    "(with --turn, of that turn).",
)
@click.option(
    "--limit",
    "limits",
    multiple=True,
    metavar="VALUE",
    help="metric: draw a limit line at this value of y, a number in its shown units or a "
    "quantity such as '0.5 m/s'. Repeatable.",
)
@verify_option
def plot(
    kind,
    archive,
    output,
    overwrite,
    where,
    units,
    x,
    y,
    z,
    level,
    turn,
    angle,
    span,
    limits,
    verify,
) -> None:
    """Draw a figure of ARCHIVE.

    \b
    histories  valve lift (the seat hatched), velocity, acceleration, cam and follower
               lift, contact forces against cam (or crank) angle, the cases overlaid (at
               most 10), events marked
    metric     a per-case value (--y) against a swept column (--x), a line per
               combination of the other varied keys
    map        a per-case value (--z) over two columns (--x, --y), its contour at --level
    events     each case's separations, landings and seatings on a cam angle × case chart
    pareto     a campipe design file's two objectives (--x, --y), its Pareto front
    spectrum   the order spectrum of a history (--y; valve acceleration) over the last turn
    """
    from campipe.plot import plot_archive
    from campipe.study.spec.plots import PlotError, check_plot

    options = {"kind": kind, "where": where, "units": units, "output": output}
    options.update({"x": x, "y": y, "z": z, "level": level, "turn": turn})
    options.update({"angle": angle, "range": span, "limit": list(limits) or None})
    given = {k: v for k, v in options.items() if v is not None}
    try:
        request = check_plot(given)
    except PlotError as exc:
        raise InputFailure(f"--{exc.key}: {exc.reason}") from None
    path, _ = plot_archive(archive, request, output, overwrite=overwrite, verify=verify)
    click.echo(str(path))


#: The map's z when a request names none (campipe.plot.figures.cell_map's).
DEFAULT_Z = "separation_deg_per_rev"


def check_spec_plots(loaded, source: str = "spec") -> None:
    """Refuse, before anything runs, a spec's ``plots:`` options that drawing would refuse
    once the archive is written: a ``turn`` past the turns the histories cover, a map's
    ``level`` in units of another dimension than its z's. ``campipe validate`` and
    ``campipe study`` call it; a SpecRefused naming each ``plots[i].<key>``, as the spec's
    other problems (``source`` the spec's file)."""
    import math

    from campipe.study.spec.check import SpecError
    from campipe.study.spec.fields import SpecProblem
    from campipe.units import QuantityError, convert, read_quantity

    turns = max(int(math.ceil(float(loaded.revolutions) - 1e-9)), 1)
    units = _column_units(loaded)
    problems = []
    for i, request in enumerate(loaded.spec.plots):
        turn = request.turn
        if isinstance(turn, int) and turn > turns:
            problems.append(SpecProblem(
                f"plots[{i}].turn",
                f"found {turn}, but the study's histories cover {turns} "
                f"turn{'s' if turns != 1 else ''} (run.revolutions); expected 1 to {turns}, "
                "last or all",
            ))  # fmt: skip
        level = request.level
        zname = request.z or DEFAULT_Z
        if request.kind != "map" or not isinstance(level, str) or units.get(zname) is None:
            continue
        try:
            float(level)
            continue  # a number: in z's shown units
        except ValueError:
            pass
        try:
            q = read_quantity(level, f"plots[{i}].level")
        except QuantityError as exc:
            why = exc.reason
        else:
            try:
                convert(1.0, str(q.units), str(units[zname]))
                continue
            except Exception:  # pint's DimensionalityError: another dimension
                why = (
                    f"{q.units:~} is not of its dimension: write it in {units[zname]}, or as a "
                    "number in the units shown"
                )
        problems.append(SpecProblem(f"plots[{i}].level", f"cannot read {level!r} as a level "
                                    f"of {zname} [{units[zname]}]: {why}"))  # fmt: skip
    if problems:
        raise SpecRefused(str(SpecError(problems, source)))


def _column_units(loaded) -> dict[str, str | None]:
    """The SI units of the archive's columns a plot may name: its variables (metrics
    included) and its per-case coordinates."""
    from campipe.study.spec.variables import case_coordinates, data_variables

    out = {name: var.units for name, var in data_variables(loaded.record).items()}
    for name, var, _ in case_coordinates(loaded.varied).values():
        out[name] = var.units
    return out


def write_plots(loaded, archive, overwrite=False) -> None:
    """The spec's ``plots:``, each written beside the finished archive, inside its folder
    (the output rule, ``campipe.io.outputs``)."""
    from collections import Counter

    from campipe.plot import plot_archive

    seen: Counter[str] = Counter()
    for i, request in enumerate(loaded.spec.plots):
        output = (
            archive.parent / request.output
            if request.output
            else request.default_output(archive, seen[request.kind])
        )
        seen[request.kind] += 1
        try:
            path, _ = plot_archive(
                archive,
                request,
                output,
                overwrite=overwrite,
                key=f"plots[{i}].output" if request.output else f"plots[{i}]",
                inside=archive.parent,
            )
        except Exception as exc:  # the archive is complete: a figure is an extra
            raise Failure.of(
                f"the archive {archive} is complete, but plots[{i}] ({request.kind}) failed: "
                f"{str(exc)[:300]}; draw it with campipe plot {request.kind} {archive}",
                isinstance(exc, ValueError),
            ) from None
        click.echo(f"campipe study: plots[{i}] ({request.kind}) written to {path}", err=True)
