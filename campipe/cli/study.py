"""``campipe study``, ``campipe validate`` and ``campipe query``: run a spec into an archive,
check it (with the run's estimate), read an archive's cases."""

from __future__ import annotations

import sys

import click

from campipe.cli.base import (
    SET_HELP,
    Failure,
    archive_path,
    limit_options,
    limits_given,
    load_spec,
    parse_overrides,
    scheduler_options,
    units_option,
    verify_option,
)
from campipe.cli.onset import run_onset
from campipe.cli.plot import check_spec_plots, write_plots


@click.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(),
    help="Archive to write (default: <name>.nc beside the spec; with --parts, the folder "
    "<name>.parts).",
)
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@scheduler_options("", "for which the batches are sized")
@click.option(
    "--batch-size",
    type=click.IntRange(min=1),
    help="Cases per batch (default: about four batches per worker, 4 to 256 cases).",
)
@click.option(
    "--keep-parts",
    is_flag=True,
    help="Keep the batch files (<archive>.parts/) after writing the archive.",
)
@click.option(
    "--parts",
    is_flag=True,
    help="Write a parts archive: a folder of one compressed netCDF file per batch, each "
    "written by the worker that computed it, and an index (the way to run on a cluster: "
    "this process only keeps count). Read as one archive by query, plot, replay and "
    "campipe.open_study; campipe pack writes the single file.",
)
@click.option(
    "--parts-dir",
    type=click.Path(file_okay=False),
    help="Write the parts archive (--parts) into this folder, as <name>.parts: a path every "
    "worker of a cluster reaches and can write (a shared file system). Each worker is "
    "checked first; the study stops before computing if one cannot write there.",
)
@click.option(
    "--progress/--no-progress",
    default=True,
    show_default=True,
    help="Show a progress line on stderr.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the archive path that is not this study's archive (another "
    "study's archive, any other file); cases it shares by id are reused. Lets a rerun remove "
    "the cases its archive holds that the spec no longer makes (a narrower sweep, an edited "
    "key). Also lets the spec's plots and recording replace files campipe did not write "
    "(never the spec).",
)
@limit_options
def study(
    spec,
    output,
    sets,
    scheduler,
    workers,
    batch_size,
    keep_parts,
    parts,
    parts_dir,
    progress,
    overwrite,
    max_cases,
    max_steps,
    max_samples,
    max_events,
    max_archive_gb,
) -> None:
    """Run the study SPEC (YAML) into one netCDF archive.

    Rerunning the same command after an interruption computes only the cases whose batches
    were not stored; a finished archive that already holds the study (its checksums
    verified) is left as it is.
    """
    import shlex

    from campipe.study.run.execute import run_study
    from campipe.study.run.progress import Progress, logging_cleared
    from campipe.study.run.resume import finished
    from campipe.study.spec.limits import Limits

    limits = limits_given(max_cases, max_steps, max_samples, max_events, max_archive_gb)
    if parts_dir and output:
        raise click.UsageError(
            "give the parts archive's path (-o) or the folder it goes into (--parts-dir), not both"
        )
    parts = parts or bool(parts_dir)
    if limits == Limits() and not overwrite and not parts:
        # A finished study answers from its spec's text and its archive's checksums alone.
        done = finished(spec, parse_overrides(sets), output)
        if done is not None:
            click.echo(f"campipe study: {done.summary()}", err=True)
            _report_statuses(done)
            click.echo(str(done.archive))
            return
    loaded = load_spec(spec, sets, limits)
    check_spec_plots(loaded, spec)
    if parts_dir:
        from pathlib import Path

        output = str(Path(parts_dir) / f"{loaded.name}.parts")
    archive = archive_path(loaded, spec, output, parts)
    if loaded.spec.search == "onset":
        from campipe.engine.onset import DEFAULT_ONSET_TOLERANCE_RPM, RPM

        tolerance = DEFAULT_ONSET_TOLERANCE_RPM * RPM
        run_onset(
            loaded,
            spec,
            archive,
            tolerance,
            "table",
            True,
            workers,
            command="study",
            overwrite=overwrite,
        )
        return
    stderr = sys.stderr
    bars: list[Progress] = []

    def bar(total, done):
        bars.append(Progress(total, stderr.write, done=done, terminal=stderr.isatty()))
        return bars[-1]

    replay = None
    if loaded.spec.replay:
        from campipe.io.outputs import RECORDING, check_output
        from campipe.replay.live import StudyReplay, recording_path

        recording = check_output(
            recording_path(archive),
            "replay",
            RECORDING,
            overwrite=overwrite,
            inputs=[(spec, "the spec")],
        )
        if recording.is_symlink():  # allowed by --overwrite: the link, not its target
            recording.unlink()
        replay = StudyReplay(loaded, recording)
    words = ["campipe", "study", spec, *(["-o", output] if output else [])]
    words += [w for pair in sets for w in ("--set", pair)]
    words += ["--scheduler", scheduler] if scheduler != "threads" else []
    words += ["--parts"] if parts else []
    command = shlex.join(words)
    try:
        with logging_cleared(lambda: bars[-1] if bars else None):
            report = run_study(
                loaded,
                archive,
                scheduler=scheduler,
                workers=workers,
                batch_size=batch_size,
                progress=bar if progress else None,
                keep_parts=keep_parts,
                command=command,
                on_batch=replay if scheduler != "processes" else None,
                overwrite=overwrite,
                parts=parts,
                notice=lambda text: click.echo(f"campipe study: {text}", err=True),
            )
    finally:
        for b in bars:
            b.close()
    for note in report.notes:
        click.echo(f"campipe study: {note}", err=True)
    click.echo(f"campipe study: {report.summary()}", err=True)
    _report_statuses(report)
    if replay is not None:
        try:
            recorded = replay.finish(report.archive)
        except Exception as exc:  # the archive is complete: the recording is an extra
            raise Failure.of(
                f"the archive {report.archive} is complete, but the replay recording "
                f"{replay.path} failed ({type(exc).__name__}: {str(exc)[:300]}); "
                f"write it with campipe replay {report.archive} --where EXPR",
                isinstance(exc, ValueError),
            ) from None
        if recorded:
            click.echo(
                f"campipe study: replay {loaded.spec.replay!r} recorded in {recorded}", err=True
            )
    if loaded.spec.plots:
        write_plots(loaded, report.archive, overwrite)
    click.echo(str(report.archive))


#: What to do about a failed case's status, after ``campipe study`` names the cases.
STATUS_ADVICE = {
    "step_limit": "the run stopped at run.max_steps (a stiff contact with little damping "
    "takes steps without end): raise it (--max-steps) or damp the contact",
    "unbounded": "the motion left its physical bounds (docs/engine.md): a spring far too weak "
    "for the speed, or a defect to report with the case",
    "chatter": "contact events kept recurring at one instant: run it with "
    "run.integrator: newmark-linear",
    "nonfinite": "the run became non-finite: a defect to report with the case",
}


def _report_statuses(report) -> None:
    """Name the cases that failed or kept only part of their events, by case id."""
    failed = report.failures()
    if failed:
        shown = ", ".join(f"{cid} ({status})" for cid, status in list(failed.items())[:10])
        more = f" and {len(failed) - 10} more" if len(failed) > 10 else ""
        advice = "".join(
            f"; {status}: {STATUS_ADVICE[status]}"
            for status in dict.fromkeys(failed.values())
            if status in STATUS_ADVICE
        )
        click.echo(
            f"campipe study: {len(failed)} case{'s' if len(failed) != 1 else ''} failed: "
            f"{shown}{more}; their histories and metrics are NaN (status in the archive; "
            f"campipe query ARCHIVE --summary lists them){advice}",
            err=True,
        )
    truncated = report.truncated()
    if truncated:
        shown = ", ".join(truncated[:10]) + (
            f" and {len(truncated) - 10} more" if len(truncated) > 10 else ""
        )
        click.echo(
            f"campipe study: {len(truncated)} case{'s' if len(truncated) != 1 else ''} kept "
            f"only run.max_events events: {shown} (status events_truncated); raise "
            "run.max_events to keep them all",
            err=True,
        )


@click.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    help="Workers to estimate the run time for (default: the cores available).",
)
@click.option(
    "--estimate/--no-estimate",
    default=True,
    show_default=True,
    help="Time a short sample run to estimate the run time.",
)
@limit_options
def validate(
    spec,
    sets,
    workers,
    estimate,
    max_cases,
    max_steps,
    max_samples,
    max_events,
    max_archive_gb,
) -> None:
    """Check the study SPEC and print its case count, axes and estimated cost."""
    from campipe.study.run.sizing import count_batches, default_batch_size, default_workers
    from campipe.study.spec.expand import archive_bytes

    loaded = load_spec(
        spec, sets, limits_given(max_cases, max_steps, max_samples, max_events, max_archive_gb)
    )
    check_spec_plots(loaded, spec)
    workers = workers or default_workers()
    click.echo(validate_text(loaded, spec))
    from campipe.engine.settings import sample_count

    samples = sample_count(loaded.revolutions, loaded.output_every)
    size = default_batch_size(len(loaded.cases), workers, samples)
    click.echo(f"batches: {count_batches(loaded.cases, size)} of up to {size} cases")
    click.echo(memory_text(len(loaded.cases), workers, samples))
    if estimate:
        from campipe.study.run.estimate import engine_import_seconds, first_cases

        engine_import_seconds()  # timed, for the estimate's start-up, as a study pays it
        from campipe.engine.kernels import compile_first

        # compiled (and recorded as such) before the estimate's runs time them, as a study's
        firsts = {settings: c.case for settings, c in first_cases(loaded).items()}
        compile_first(firsts, lambda text: click.echo(f"campipe validate: {text}", err=True))
        click.echo(estimate_text(loaded, workers))
    click.echo(
        f"archive: about {archive_bytes(loaded) / 1e6:.3g} MB before compression "
        f"(events not counted)"
    )
    if loaded.spec.design is not None:
        from campipe.study.spec.design import section_text

        click.echo("\n".join(section_text(loaded.spec.design)))


def memory_text(n_cases: int, workers: int, samples: int) -> str:
    """``memory: ...``: the bound on what the batches in flight hold, with its basis."""
    from campipe.study.run.sizing import BYTES_PER_SAMPLE, IN_FLIGHT_PER_WORKER, in_flight_memory

    bound, batches, size = in_flight_memory(n_cases, workers, samples)
    return (
        f"memory: the batches in flight take at most about {bound / 1e6:.3g} MB, whatever the "
        f"study's size ({batches} batch{'es' if batches != 1 else ''} of up to {size} cases: "
        f"at most {IN_FLIGHT_PER_WORKER} a worker in flight, each case {samples} samples × "
        f"{BYTES_PER_SAMPLE} bytes), beside the process's own (imports, kernels, the "
        "study's cases); the bench measures it (docs/bench.md)"
    )


def estimate_text(loaded, workers: int) -> str:
    """``run time: about ...``: the estimate (campipe.study.run.estimate) with its parts, and the
    spec's replay recording (campipe.replay.live.time_replay)."""
    import dataclasses
    import tempfile

    from campipe.study.run.estimate import estimate

    e = estimate(loaded, workers)
    parts = [
        f"the engine {_seconds(e.engine)}",
        f"storing and writing the archive {_seconds(e.layer)}",
        f"loading the engine {_seconds(e.startup)}",
    ]
    replayed = ""
    if loaded.spec.replay:
        from campipe.replay.live import time_replay

        with tempfile.TemporaryDirectory(prefix="campipe-estimate-") as folder:
            count, each = time_replay(loaded, folder)
        if count is None:
            replayed = f"; and {_seconds(each)} for each case the replay selects"
        elif count:
            e = dataclasses.replace(e, replay=count * each, seconds=e.seconds + count * each)
            parts.append(
                f"the replay's {count} case{'s' if count != 1 else ''} {_seconds(e.replay)}"
            )
    n = len(loaded.cases)
    what = "the whole study" if e.sample >= n else f"{e.sample} of its {n} cases, scaled"
    timed = f"a run of {what}"
    if e.turns is not None:
        a, b = e.turns
        timed = (
            f"runs of {what} for {a} and for {b} of its {loaded.revolutions:g} turns, the "
            "turns beyond extrapolated"
        )
    return (
        f"run time: about {_seconds(e.seconds)} on {workers} "
        f"worker{'s' if workers != 1 else ''}: {', '.join(parts)} (timed on {timed}; "
        f"{e.simulated:.3g} s simulated; the process's own start not included){replayed}"
        f"{_step_cap(loaded)}"
    )


def _step_cap(loaded) -> str:
    """``; each compliant case stops at ...``: the run-time cap on an adaptive integration's
    steps, for a study with compliant cases (whose steps no spec-time bound covers)."""
    from campipe.study.spec.resolve import distinct_but_speed

    caps = {c.settings.max_steps for c in distinct_but_speed(loaded.cases)[0]
            if c.settings.method == "compliant"}  # fmt: skip
    if not caps:
        return ""
    return (
        f"; each compliant case stops at {max(caps):.3g} steps (run.max_steps, --max-steps), "
        "its status step_limit, the other cases unaffected"
    )


def _seconds(seconds: float) -> str:
    """An estimate's time: ``0.42 s``, ``12 s``, ``3 min 05 s``."""
    from campipe.study.run.progress import format_seconds

    return f"{seconds:.2g} s" if seconds < 10 else format_seconds(seconds)


def _listed(values: list[str]) -> str:
    """An axis's values: all of up to six, else the first … the last."""
    return ", ".join(values) if len(values) <= 6 else f"{values[0]} … {values[-1]}"


def validate_text(loaded, spec_path) -> str:
    """The checked study in words: cases, axes (values as the spec wrote them), run."""
    from campipe.constants import RPM
    from campipe.study.spec.coordinates import coordinate_values
    from campipe.study.spec.notes import case_notes
    from campipe.study.spec.resolve import distinct_but_speed
    from campipe.study.spec.variables import case_coordinates

    s = loaded.spec
    run = s.base["run"]
    first = loaded.cases[0]
    lines = [
        f"{spec_path}: valid; study {s.name!r}, {len(loaded.cases)} "
        f"case{'s' if len(loaded.cases) != 1 else ''}"
    ]
    coords = case_coordinates(loaded.varied)
    values = coordinate_values(distinct_but_speed(loaded.cases)[0], loaded)  # labels only
    lines.append("axes:" if loaded.axes else "axes: none (a single case)")
    for a in loaded.axes:
        listed = s.sweep.get(a.key) or s.zip.get(a.key)
        if a.key in ("profile", "defects"):
            shown = list(dict.fromkeys(values[a.key]))
        elif listed is not None:
            shown = [str(v) for v in listed]
        elif a.kind == "sample":  # the range as the spec wrote it
            low, high = s.sample.written[a.key]
            shown = [f"{s.sample.method} over {low} … {high}, seed {s.sample.seed}"]
        else:
            shown = [f"{len(s.cases)} entries"]
        text = _listed(shown)
        if a.key == "speed" and s.drive is not None:  # the engine's speeds beside the cam's
            engine = sorted({float(f"{c.case.speed / s.drive / RPM:.9g}") for c in loaded.cases})
            text += f" (the engine's {_listed([f'{v:g}' for v in engine])} rpm)"
        name = coords[a.key][0] if a.key in coords else a.key
        lines.append(f"  {name:<22} {a.kind:<7} {a.size:>4} values: {text}")
    step = first.settings.step
    dt = "chosen by the integrator" if step is None else f"{step * 1e6:.4g} µs"
    length = (
        f"until each case repeats (at most {run['max_revolutions']} revolutions, the last "
        f"{run['history_turns']} recorded)"
        if run["revolutions"] == "auto"
        else f"{run['revolutions']:g} revolutions"
    )
    lines.append(
        f"run: {length}, integrator "
        f"{first.settings.method}, dt {dt}, output every {run['output_every']}, "
        f"record: {', '.join(r for r in loaded.record if r != 'settling') or '-'}"
    )
    if s.replay:
        lines.append(f"replay: {s.replay!r} (logged to <archive stem>.rrd as the study runs)")
    lines += [f"{topic}: {note}" for topic, note in case_notes(loaded.cases, loaded.record)]
    return "\n".join(lines)


@click.command()
@click.argument("archive", type=click.Path(exists=True))
@click.option(
    "--where",
    help='Keep cases where EXPR holds, e.g. "speed_rpm > 9000 and seat is none" or '
    '"spring_preload > 150 lbf" (comparisons, and, or, not, parentheses; never run as '
    "Python).",
)
@click.option("--columns", help="Comma-separated columns (default: parameters and metrics).")
@click.option("--sort", help="Sort by these comma-separated columns; -col for descending.")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["table", "csv", "json"]),
    default="table",
    show_default=True,
    help="json: an object with the study's name, each column's units and the cases as row "
    'objects ({"study", "units", "cases"}).',
)
@click.option(
    "--summary",
    is_flag=True,
    help="Print the axes, the failed cases and, for a speed sweep, the separation onset "
    "speeds (of the cases --where selects).",
)
@units_option
@verify_option
def query(archive, where, columns, sort, fmt, summary, units, verify) -> None:
    """Print an archive's cases, one row per case, values in the units the spec was written
    in (or --units); headers name the units."""
    from campipe.study.query.display import display_units
    from campipe.study.query.tables import case_table, displayed, format_rows, select
    from campipe.study.query.tables import summary as summary_text

    if summary and fmt != "table":
        raise click.UsageError(
            f"--summary prints text; --format {fmt} takes the cases' rows (query without "
            "--summary, --columns and --where choosing them)"
        )
    with _open_archive(archive, verify, ("cam_angle",)) as ds:  # query reads no history
        if summary:
            click.echo(summary_text(ds, where, units))
            return
        table = case_table(ds)
        shown = display_units(table.units, ds.attrs, units)
    names = table.default if columns is None else _column_names(columns)
    rows = select(table, where, sort)
    click.echo(format_rows(displayed(table, shown), rows, names, fmt))


def _column_names(columns: str) -> list[str]:
    """``--columns``' names, each once in the order given; none is refused."""
    names = list(dict.fromkeys(c.strip() for c in columns.split(",") if c.strip()))
    if not names:
        raise click.BadParameter(
            f"found no column in {columns!r}; name them separated by commas, e.g. "
            "speed_rpm,max_cam_force, or leave --columns out for the defaults",
            param_hint="--columns",
        )
    return names


def _open_archive(path, verify: bool = True, unread_dims: tuple[str, ...] = ()):
    """An archive (a file, or a parts archive's folder) as an xarray Dataset, or the error
    naming why it cannot be read (``io.archive.unreadable_error``)."""
    from campipe.errors import CampipeError
    from campipe.io.archive import unreadable_error
    from campipe.study.archive.open import open_archive

    try:
        return open_archive(path, verify, unread_dims)
    except CampipeError:
        raise
    except Exception as exc:
        raise unreadable_error(path, exc) from None


@click.command()
@click.argument("archive", type=click.Path(exists=True, file_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="The netCDF file to write (default: the archive's name with .nc).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the output path that is not this study's archive (never the "
    "parts archive's own files).",
)
def pack(archive, output, overwrite) -> None:
    """Write the single netCDF archive of the parts archive ARCHIVE (campipe study --parts):
    the file campipe study writes without --parts, variable for variable."""
    from pathlib import Path

    from campipe.io.outputs import check_output, describe_netcdf
    from campipe.study.run.parts import pack as pack_parts
    from campipe.study.run.parts import pack_inputs, pack_kind

    archive = Path(archive)
    target = Path(output) if output else archive.with_suffix(".nc")
    check_output(
        target,
        "-o",
        pack_kind(archive),
        overwrite=overwrite,
        inputs=pack_inputs(archive),
        describe=describe_netcdf,
    )
    words = ["campipe", "pack", str(archive), "-o", str(target)]
    click.echo(str(pack_parts(archive, target, command=" ".join(words))))
