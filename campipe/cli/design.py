"""``campipe design``: the values of a spec's keys that meet its requirements best."""

from __future__ import annotations

import math

import click

from campipe.cli.base import SET_HELP, Failure, InputFailure, load_spec, scheduler_options


@click.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["table", "csv", "json"]),
    default="table",
    show_default=True,
    help="json: {study, units, cases: [row objects]} as campipe query's, the chosen design first.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="The netCDF file of the designs evaluated (default: <name>-design.nc beside SPEC).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that is not this spec's design file; never the spec.",
)
@scheduler_options(
    "Where the designs are computed, as campipe study's batches: ", "for which the estimate is made"
)
def design(spec, sets, fmt, output, overwrite, scheduler, workers) -> None:
    """The design SPEC's design: section asks for: the values of design.vary's keys, within
    their bounds, that meet design.require (the no-follow onset, metrics at stated speeds)
    with the least (minimize) or greatest (maximize) objective. One varied key that is the
    objective: a root search to its tolerance; else SciPy's optimisers (design.method).

    Prints the chosen design first, then every other design evaluated, with the margin on
    each requirement and the one that binds; writes them to a netCDF file campipe query and
    campipe plot read. Exit status 1 when no design meets the requirements (the closest is
    printed first, marked closest, with the requirement it fails).

    The designs of a batch (a root search's bounds and its scan, a global method's
    generation, a Pareto sample) are computed side by side on the scheduler, as campipe
    study's batches; an estimate and a progress line go to stderr."""
    from pathlib import Path

    from campipe.study.run.execute import check_scheduler
    from campipe.study.run.sizing import default_workers

    check_scheduler(scheduler)
    workers = workers or (1 if scheduler == "synchronous" else default_workers())
    loaded = load_spec(spec, sets)
    if loaded.spec.design is None:
        raise InputFailure(
            f"{spec}: design: missing; campipe design needs a design section, e.g. design: "
            "{vary: {model.spring_preload: {from: 80 lbf, to: 250 lbf}}, require: "
            "{onset_speed_rpm: {min: 9500 rpm}}, minimize: model.spring_preload}"
        )
    path = Path(output) if output else Path(spec).parent / f"{loaded.name}-design.nc"
    if loaded.spec.drive is not None:
        note = drive_note(loaded.spec.drive, loaded.spec.design)
        click.echo(f"campipe design: {note}", err=True)
    if any(r.key == "min_spring_clash_margin" for r in loaded.spec.design.require):
        from campipe.study.spec.notes import CLASH_RECORDS, travel_note

        # a chain's or a lever's clash margin against the thesis's assumed travel, as
        # campipe study notes it (a helper's finger met a 1 mm margin with 31 mm to spare)
        if travel := travel_note(loaded.cases, CLASH_RECORDS):
            click.echo(f"campipe design: {travel}", err=True)
    _run(loaded, spec, path, fmt, overwrite, scheduler, workers)


def drive_note(ratio: float, design) -> str:
    """What a design's speeds are in a spec with a drive: the cam's, as onset_speed_rpm's,
    with the engine's beside the spec's own onset bounds."""
    from campipe.study.spec.design import ONSET, bound_label

    bounds = [
        f"{bound_label(r, side)} is the engine's {value / ratio:g} rpm"
        if not r.engine_onset
        else f"{bound_label(r, side)} is the cam's {value:g} rpm"
        for r in design.require
        if r.key == ONSET
        for side, value in (("min", r.minimum), ("max", r.maximum))
        if not math.isnan(value)
    ]
    example = "; ".join(bounds) or f"the engine's 7000 rpm is the cam's {7000 * ratio:g} rpm"
    return (
        f"with drive (cam_per_crank {ratio:g}), design's speeds (the onset's bounds, each "
        f"metric's at:) are the cam's, as {ONSET}'s: {example} (onset_engine_speed_rpm and "
        "at_engine take the engine's)"
    )


def _kind(study_name: str, spec_file: str):
    from campipe.io.outputs import Kind, netcdf_attrs
    from campipe.study.design.output import DESIGN_FILE

    def ours(path) -> bool:
        attrs = netcdf_attrs(path)
        return (
            attrs is not None
            and attrs.get("campipe_file") == DESIGN_FILE
            and attrs.get("study_name") == study_name
            and str(attrs.get("spec_file", "")) in ("", spec_file)
        )

    return Kind("a design file of this spec", ours)


def _search(loaded, scheduler: str, workers: int):
    """The search on the scheduler, its estimate first, then campipe study's progress line on
    stderr (redrawn in a terminal, every 2 s elsewhere) counting designs against the most
    the search may take."""
    import sys

    from campipe.study.design.estimate import estimate_design
    from campipe.study.design.search import most_evaluations, run_design
    from campipe.study.run.progress import Progress
    from campipe.study.run.workers import task_map

    def estimate(evaluate) -> None:
        click.echo(f"campipe design: {estimate_design(evaluate, loaded, workers).text()}", err=True)
        progress.restart()  # the kernels compiled: the rate counts the designs' time only

    stderr = sys.stderr
    progress = Progress(
        most_evaluations(loaded.spec.design),
        stderr.write,
        terminal=stderr.isatty(),
        unit="designs at most",
        then="writing the file",
    )
    try:
        with task_map(scheduler, workers) as mapped:
            return run_design(
                loaded,
                notice=lambda text: click.echo(f"campipe design: {text}", err=True),
                on_evaluation=lambda _: progress.advance(1),
                mapped=mapped,
                before=estimate,
            )
    finally:
        progress.close()


def _run(loaded, spec_path, path, fmt, overwrite, scheduler, workers) -> None:
    import os
    from pathlib import Path

    import numpy as np

    from campipe.io.archive import provenance, write_file
    from campipe.io.lock import writing
    from campipe.io.outputs import check_output, describe_netcdf
    from campipe.study.design.output import (
        DESIGN_FILE,
        answer_binding,
        design_table,
        file_contents,
        shown_units,
        summary_lines,
        written_value,
    )
    from campipe.study.query.tables import displayed, format_rows
    from campipe.study.spec.design import ENGINE_ONSET, ONSET

    spec_file = os.path.relpath(Path(spec_path).resolve(), Path(path).parent.resolve())
    kind = _kind(loaded.name, spec_file)
    inputs = [(spec_path, "the spec")]
    check_output(path, "-o", kind, overwrite=overwrite, inputs=inputs, describe=describe_netcdf)
    path.parent.mkdir(parents=True, exist_ok=True)
    result = _search(loaded, scheduler, workers)
    table = design_table(result)
    sizes, variables, arrays, attrs = file_contents(result, table)
    with writing(path):
        check_output(path, "-o", kind, overwrite=overwrite, inputs=inputs,
                     describe=describe_netcdf)  # fmt: skip
        write_file(
            path,
            sizes,
            variables,
            arrays,
            {
                **attrs,
                **provenance(f"campipe design {spec_path}"),
                "campipe_file": DESIGN_FILE,
                "spec_file": spec_file,
            },
            loaded.compression,
        )
    from campipe.cli.onset import with_engine_speed

    # with a drive, the onset at the engine's speed beside the cam's, as campipe onset's
    shown = displayed(with_engine_speed(table, loaded.spec.drive), shown_units(result))
    click.echo(format_rows(shown, np.arange(shown.n), shown.default, fmt))
    lines = summary_lines(result)
    for line in lines:
        click.echo(line, err=True)
    binding = answer_binding(result)
    if result.feasible and not result.front and binding.startswith((ONSET, ENGINE_ONSET)):
        sets = " ".join(f"--set {v.key}='{written_value(result.best.x[j], v.units, v.written)}'"
                        for j, v in enumerate(result.design.vary))  # fmt: skip
        level = next(r.level for r in result.design.require if r.key == ONSET)
        if not math.isnan(level):
            sets += f" --level '{math.degrees(level):g} deg'"
        click.echo(
            f"where on the cam it loses contact at its onset (leaves_cam_at_deg: a ramp's "
            f"take-up or the nose): campipe onset {spec_path} {sets}",
            err=True,
        )
    click.echo(f"wrote {path}", err=True)
    if not result.feasible:
        raise Failure(lines[0])
