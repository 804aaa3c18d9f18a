"""The ``campipe`` command line (click). I/O only: every number comes from the numerics layer.

Each command imports what it uses when it runs (``campipe --help`` loads click, the model's
parameter table and NumPy, nothing else): dask, xarray, netCDF4, pint, SciPy, numba and
rerun load only in the commands that need them.
"""

from __future__ import annotations

import atexit
import functools
import gc
import json
import logging
import math
import sys

import click
import numpy as np

from campipe import __version__
from campipe.constants import INCH, LBF_IN, RPM
from campipe.errors import CampipeError
from campipe.model import (
    ELEMENTS,
    PARAMETERS,
    PRESETS,
    Coordinate,
    ModelParameterError,
    coordinates,
    modal_damping_ratios,
    newmark_linear_stability_limit,
    system_matrices,
    to_display_units,
    translations,
    valve_train,
)
from campipe.model.assembly import CONVERGENCE_ELEMENTS, frequency_convergence, observed_orders
from campipe.units import convert, pint_without_dask
from campipe.vocabulary import CONFIGURATIONS, ROMAN

#: The parameters ``campipe model --convergence`` refines.
REFINEMENTS = tuple(f"{member}_elements" for member in ELEMENTS)


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
    return None


class CampipeGroup(click.Group):
    """The ``campipe`` group: maps errors to messages and exit statuses (:func:`failure`)."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except Exception as exc:
            mapped = failure(exc)
            if mapped is None:
                raise
            raise mapped from None


@click.group(cls=CampipeGroup)
@click.version_option(version=__version__, package_name="campipe")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """campipe: parametric studies of cam-driven valve-train dynamics."""
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)])
    _exit_without_collecting()


@functools.cache
def _exit_without_collecting() -> None:
    """At exit, leave the objects still alive to the operating system (``gc.freeze``, once
    the exit handlers registered since have run) instead of the interpreter's last garbage
    collections: once a kernel has run, those go through numba's object graph, 0.15 s of a
    one-case study. Exit handlers still run; a command closes its files before it returns."""
    atexit.register(gc.freeze)


@main.command()
@click.option(
    "--preset",
    default="thesis-1971",
    show_default=True,
    type=click.Choice(sorted(PRESETS)),
    help="Named parameter set.",
)
@click.option(
    "--set",
    "sets",
    multiple=True,
    metavar="NAME=VALUE",
    help="Override a model parameter, with units: --set spring_rate='260 lbf/in'. "
    "Repeatable. Names: " + ", ".join(PARAMETERS),
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (SI units).")
@click.option(
    "--convergence",
    type=click.Choice(REFINEMENTS),
    metavar="NAME",
    help="Instead, show how the lowest natural frequencies converge as the parameter NAME "
    f"(one of: {', '.join(REFINEMENTS)}) divides its member into "
    + ", ".join(map(str, CONVERGENCE_ELEMENTS))
    + " elements.",
)
@click.option(
    "--modes",
    default=6,
    show_default=True,
    type=click.IntRange(1, 64),
    help="Modes shown with --convergence.",
)
def model(
    preset: str, sets: tuple[str, ...], as_json: bool, convergence: str | None, modes: int
) -> None:
    """Print the model's matrices, natural frequencies, mode shapes and stability limits."""
    pint_without_dask()  # this process is the command's own
    overrides = parse_overrides(sets)
    try:
        train = valve_train(preset, overrides)
    except ModelParameterError as exc:
        raise click.UsageError(str(exc)) from None
    if convergence is not None:
        report = convergence_report(train, convergence, modes)
        if as_json:
            click.echo(json.dumps({"preset": preset, **report}, indent=1))
        else:
            click.echo(convergence_text(report, preset, overrides))
        return
    sm = system_matrices(train)
    limits = {
        ROMAN[c]: newmark_linear_stability_limit(sm.mass, sm.stiffness, c) for c in CONFIGURATIONS
    }
    if as_json:
        click.echo(json.dumps(model_report(train, sm, limits, preset), indent=1))
    else:
        click.echo(model_text(train, sm, limits, preset, overrides))


def _json_value(value: object) -> object:
    """NaN (a parameter given as none) as JSON's null."""
    return None if isinstance(value, float) and math.isnan(value) else value


def model_report(train, sm, limits, preset) -> dict[str, object]:
    """The JSON form of ``campipe model``: SI units throughout."""
    return {
        "preset": preset,
        "parameters": {
            name: {"value": _json_value(getattr(train, name)), "units": p.units or "1"}
            for name, p in PARAMETERS.items()
        },
        "coordinates": [
            {
                "symbol": c.symbol,
                "name": c.name,
                "kind": c.kind,
                "positive": c.positive,
                "units": "m" if c.kind == "translation" else "rad",
            }
            for c in coordinates(train)
        ],
        "natural_frequencies": sm.frequencies.tolist(),
        "natural_frequencies_rpm": (sm.frequencies / RPM).tolist(),
        "modal_damping_ratios": modal_damping_ratios(sm.damping, sm.modes, sm.frequencies).tolist(),
        "mass_matrix": sm.mass.tolist(),
        "stiffness_matrix": sm.stiffness.tolist(),
        "damping_matrix": sm.damping.tolist(),
        "mode_shapes": sm.modes.tolist(),
        "stability_limit_s": limits,
        "units": {
            "natural_frequencies": "rad/s",
            "modal_damping_ratios": "1, (Φᵀ C Φ)ⱼⱼ / (2ωⱼ)",
            "mass_matrix": "kg (translation pairs), kg·m (mixed), kg·m² (rotation pairs)",
            "stiffness_matrix": "N/m (translation pairs), N (mixed), N·m (rotation pairs)",
            "damping_matrix": "N·s/m (translation pairs), N·s (mixed), N·m·s (rotation pairs)",
            "mode_shapes": "mass-normalised (Φᵀ M Φ = I, SI)",
            "stability_limit_s": "s",
        },
    }


def _matrix_text(a: np.ndarray, scale: float, coords: tuple[Coordinate, ...]) -> list[str]:
    head = "      " + "".join(f"{c.symbol:>9}" for c in coords)
    rows = [head]
    for c, row in zip(coords, a / scale, strict=True):
        rows.append(f"  {c.symbol:<4}" + "".join(f"{v:9.2f}" for v in row))
    return rows


def _parameter_text(p, value) -> str:
    if p.length:
        return ", ".join(f"{x:g}" for x in value)
    if p.allow_none and isinstance(value, float) and math.isnan(value):
        return "none"
    if p.choices or p.integer or not p.units:
        return f"{value:g}" if isinstance(value, float) else str(value)
    return f"{convert(value, p.units, p.thesis_units):g} {p.thesis_units}"


def model_text(train, sm, limits, preset, overrides) -> str:
    """The human form of ``campipe model``, in the thesis's units and layout."""
    lines = [
        f"campipe model: preset {preset}"
        + (f", overrides {', '.join(overrides)}" if overrides else "")
    ]
    lines.append("")
    lines.append("Parameters (thesis units)")
    for name, p in PARAMETERS.items():
        lines.append(f"  {name:<30} {_parameter_text(p, getattr(train, name))}")
    coords = coordinates(train)
    trans = translations(train)
    lines.append("")
    lines.append("Coordinates (thesis order and signs; refined members' internal nodes after q7)")
    for c in coords:
        lines.append(f"  {c.symbol:<4} {c.name:<30} {c.kind:<11} positive {c.positive}")
    rot = "rows/cols with a rotation carry rad: ×in per translation index"
    blocks = [
        ("Mass matrix [M] (Figure 11)", sm.mass, 1e-5, "lbf·s²/in", "×1e-5"),
        ("Stiffness matrix [K] (Figure 12)", sm.stiffness, 1e5, "lbf/in", "×1e5"),
        (
            f"Damping matrix [C] ({train.damping_kind}; Figure 13: modal)",
            sm.damping,
            1e-2,
            "lbf·s/in",
            "×1e-2",
        ),
    ]
    for title, a, scale, unit, tag in blocks:
        lines.append("")
        lines.append(f"{title}  {tag} {unit} ({rot})")
        lines += _matrix_text(to_display_units(a, INCH, LBF_IN, trans), scale, coords)
    lines.append("")
    lines.append("Natural frequencies (Figure 14), each mode's damping ratio (Φᵀ C Φ)ⱼⱼ / (2ωⱼ)")
    lines.append(f"  {'mode':>4} {'rad/s':>14} {'rpm':>14} {'ζ':>6}")
    zeta = modal_damping_ratios(sm.damping, sm.modes, sm.frequencies)
    for i, (w, z) in enumerate(zip(sm.frequencies, zeta, strict=True), 1):
        lines.append(f"  {i:>4} {w:14.1f} {w / RPM:14.1f} {z:6.3f}")
    lines.append("")
    lines.append(
        "Mode shapes (Figure 14), one column a mode, scaled to a largest translation of 1"
        " (rotations in rad/in)"
    )
    shapes = sm.modes / np.where(trans, INCH, 1.0)[:, None]
    shapes = shapes / np.abs(shapes[trans]).max(axis=0)
    lines.append("      " + "".join(f"{'mode ' + str(j):>9}" for j in range(1, len(coords) + 1)))
    for c, row in zip(coords, shapes, strict=True):
        lines.append(f"  {c.symbol:<4}" + "".join(f"{v:9.3f}" for v in row))
    lines.append("")
    lines.append("Stability limit of newmark-linear (Δt < √12/ω_max of the held configuration)")
    for name, dt in limits.items():
        lines.append(f"  {name:<4} {dt * 1e6:8.4f} µs")
    return "\n".join(lines)


def convergence_report(train, parameter: str, n_modes: int) -> dict[str, object]:
    """The natural frequencies as ``parameter`` (``spring_elements`` …) refines its member:
    the JSON form of ``campipe model --convergence`` (SI)."""
    member = parameter.removesuffix("_elements")
    freqs, roundoff = frequency_convergence(train, member, CONVERGENCE_ELEMENTS, n_modes)
    orders = observed_orders(freqs, roundoff, CONVERGENCE_ELEMENTS)

    def listed(a: np.ndarray) -> list:
        return (
            [None if np.isnan(v) else float(v) for v in a]
            if a.ndim == 1
            else [listed(row) for row in a]
        )

    return {
        "parameter": parameter,
        "elements": list(CONVERGENCE_ELEMENTS),
        "natural_frequencies": listed(freqs),
        "roundoff": listed(roundoff),
        "observed_orders": listed(orders),
        "units": {"natural_frequencies": "rad/s", "roundoff": "rad/s", "observed_orders": "1"},
    }


def convergence_text(report: dict, preset: str, overrides) -> str:
    """The human form of ``campipe model --convergence``."""
    parameter = report["parameter"]
    freqs = np.array(report["natural_frequencies"], dtype=float)
    orders = np.array(report["observed_orders"], dtype=float)
    counts = report["elements"]
    member = parameter.removesuffix("_elements").replace("_", " ")
    lines = [
        f"campipe model --convergence {parameter}: preset {preset}"
        + (f", overrides {', '.join(overrides)}" if overrides else ""),
        "",
        f"Lowest natural frequencies [rad/s] with the {member} divided into n equal elements.",
        "New internal modes (a spring's surge) enter as n grows: a column is one mode once it "
        "settles.",
        "",
        f"  {'n':>6}" + "".join(f"{'mode ' + str(j):>14}" for j in range(1, freqs.shape[1] + 1)),
    ]
    for n, row in zip(counts, freqs, strict=True):
        lines.append(f"  {n:>6}" + "".join(f"{v:14.7g}" if v == v else f"{'':>14}" for v in row))
    lines.append(
        f"  {'order':>6}" + "".join(f"{v:14.2f}" if v == v else f"{'-':>14}" for v in orders)
    )
    lines += [
        "",
        f"order: the observed order in 1/n from n = {', '.join(map(str, counts[-3:]))} "
        "(consistent mass: 2 for a bar, 4 for a beam);",
        "'-' where the column has not settled into one mode or has converged to the "
        "eigensolver's round-off.",
    ]
    return "\n".join(lines)


# -- studies ----------------------------------------------------------------------------------


class SpecRefused(CampipeError, click.ClickException):
    """A spec refused before anything runs (exit status 2, like a usage error)."""

    exit_code = 2

    def show(self, file=None) -> None:
        click.echo(self.format_message(), err=True)


def _load(spec_path, sets, limits=None):
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


def _limits(max_cases, max_steps, max_samples, max_events, max_archive_gb):
    from campipe.study.spec.limits import Limits

    return Limits(max_cases, max_steps, max_samples, max_events, max_archive_gb * 1e9)


def _archive_path(study, spec_path, output):
    from pathlib import Path

    return Path(output) if output else Path(spec_path).parent / f"{study.name}.nc"


_SET_HELP = (
    "Override a spec key before checking it, value as YAML: --set run.revolutions=1, "
    "--set sweep.speed='[9000 rpm, 9524 rpm]'. Repeatable."
)


@main.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="Archive to write (default: <name>.nc beside the spec).",
)
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option(
    "--scheduler",
    default="threads",
    show_default=True,
    help="threads, synchronous, processes, or a dask.distributed scheduler address "
    "such as tcp://127.0.0.1:8786.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    help="Threads or processes of a local scheduler (default: the cores available).",
)
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
    "--progress/--no-progress",
    default=True,
    show_default=True,
    help="Show a progress line on stderr.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace a file at the archive path that is not this study's archive (another "
    "study's archive, any other file); cases it shares by id are reused.",
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

    limits = _limits(max_cases, max_steps, max_samples, max_events, max_archive_gb)
    if limits == Limits() and not overwrite:
        # A finished study answers from its spec's text and its archive's checksums alone.
        done = finished(spec, parse_overrides(sets), output)
        if done is not None:
            click.echo(f"campipe study: {done.summary()}", err=True)
            _report_statuses(done)
            click.echo(str(done.archive))
            return
    loaded = _load(spec, sets, limits)
    archive = _archive_path(loaded, spec, output)
    if loaded.spec.search == "onset":
        from campipe.engine.periodic import DEFAULT_ONSET_TOLERANCE_RPM, RPM

        tolerance = DEFAULT_ONSET_TOLERANCE_RPM * RPM
        _onset(loaded, spec, archive, tolerance, "table", True, workers, command="study")
        return
    stderr = sys.stderr
    bars: list[Progress] = []

    def bar(total, done):
        bars.append(Progress(total, stderr.write, done=done, terminal=stderr.isatty()))
        return bars[-1]

    replay = None
    if loaded.spec.replay:
        from campipe.replay.live import StudyReplay, recording_path

        replay = StudyReplay(loaded, recording_path(archive))
    words = ["campipe", "study", spec, *(["-o", output] if output else [])]
    words += [w for pair in sets for w in ("--set", pair)]
    words += ["--scheduler", scheduler] if scheduler != "threads" else []
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
        _write_plots(loaded, report.archive)
    click.echo(str(report.archive))


def _report_statuses(report) -> None:
    """Name the cases that failed or kept only part of their events, by case id."""
    failed = report.failures()
    if failed:
        shown = ", ".join(f"{cid} ({status})" for cid, status in list(failed.items())[:10])
        more = f" and {len(failed) - 10} more" if len(failed) > 10 else ""
        click.echo(
            f"campipe study: {len(failed)} case{'s' if len(failed) != 1 else ''} failed: "
            f"{shown}{more}; their histories and metrics are NaN (status in the archive; "
            "campipe query ARCHIVE --summary lists them)",
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


@main.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
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
    from campipe.study.run.batches import count_batches, default_batch_size, default_workers
    from campipe.study.run.estimate import archive_bytes

    loaded = _load(
        spec, sets, _limits(max_cases, max_steps, max_samples, max_events, max_archive_gb)
    )
    workers = workers or default_workers()
    click.echo(validate_text(loaded, spec))
    from campipe.engine.settings import sample_count

    samples = sample_count(loaded.revolutions, loaded.output_every)
    size = default_batch_size(len(loaded.cases), workers, samples)
    click.echo(f"batches: {count_batches(loaded.cases, size)} of up to {size} cases")
    if estimate:
        from campipe.engine.kernels import compile_notice
        from campipe.study.spec.resolve import distinct_but_speed

        text = compile_notice(c.settings for c in distinct_but_speed(loaded.cases)[0])
        if text:
            click.echo(f"campipe validate: {text}", err=True)
        click.echo(estimate_text(loaded, workers))
    click.echo(
        f"archive: about {archive_bytes(loaded) / 1e6:.3g} MB before compression "
        f"(events not counted)"
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
    timed = "the whole study" if e.sample >= n else f"{e.sample} of its {n} cases, scaled"
    return (
        f"run time: about {_seconds(e.seconds)} on {workers} "
        f"worker{'s' if workers != 1 else ''}: {', '.join(parts)} (timed on a run of {timed}; "
        f"{e.simulated:.3g} s simulated; the process's own start not included){replayed}"
    )


def _seconds(seconds: float) -> str:
    """An estimate's time: ``0.42 s``, ``12 s``, ``3 min 05 s``."""
    from campipe.study.run.progress import format_seconds

    return f"{seconds:.2g} s" if seconds < 10 else format_seconds(seconds)


def validate_text(loaded, spec_path) -> str:
    """The checked study in words: cases, axes (values as the spec wrote them), run."""
    from campipe.study.archive.layout import coordinate_values
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
        elif a.kind == "sample":
            lo, hi = s.sample.ranges[a.key]
            units = coords[a.key][1].units if a.key in coords else ""
            factor = coords[a.key][2] if a.key in coords else 1.0
            shown = [
                f"{s.sample.method} over {lo * factor:.6g} … {hi * factor:.6g} {units}, "
                f"seed {s.sample.seed}"
            ]
        else:
            shown = [f"{len(s.cases)} entries"]
        text = ", ".join(shown) if len(shown) <= 6 else f"{shown[0]} … {shown[-1]}"
        name = coords[a.key][0] if a.key in coords else a.key
        lines.append(f"  {name:<22} {a.kind:<7} {a.size:>4} values: {text}")
    step = first.settings.step
    dt = "chosen by the integrator" if step is None else f"{step * 1e6:.4g} µs"
    lines.append(
        f"run: {run['revolutions']:g} revolutions, integrator "
        f"{first.settings.method}, dt {dt}, output every {run['output_every']}, "
        f"record: {', '.join(loaded.record) or '-'}"
    )
    if s.replay:
        lines.append(f"replay: {s.replay!r} (logged to <archive stem>.rrd as the study runs)")
    return "\n".join(lines)


#: The unit systems of --units (campipe.study.spec.plots.SYSTEMS, repeated so --help needs no
#: import of the study layer; tests/integration/test_plot.py checks they agree).
UNIT_SYSTEMS = ("spec", "si", "in-lbf")


def units_option(command):
    """``--units spec|si|in-lbf``: the units values are shown in."""
    return click.option(
        "--units",
        type=click.Choice(UNIT_SYSTEMS),
        default="spec",
        show_default=True,
        help="Show values in the units the spec wrote them in, with the rest in the spec's "
        "system (spec), in SI as stored (si), or in inches, pounds-force and seconds (in-lbf).",
    )(command)


@main.command()
@click.argument("archive", type=click.Path(exists=True, dir_okay=False))
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
    help="json: an array of row objects.",
)
@click.option(
    "--summary",
    is_flag=True,
    help="Print the axes, the failed cases and, for a speed sweep, the separation onset "
    "speeds (of the cases --where selects).",
)
@units_option
def query(archive, where, columns, sort, fmt, summary, units) -> None:
    """Print an archive's cases, one row per case, values in the units the spec was written
    in (or --units); headers name the units."""
    from campipe.study.query.display import display_units
    from campipe.study.query.tables import case_table, displayed, format_rows, select
    from campipe.study.query.tables import summary as summary_text

    with _open_archive(archive) as ds:
        if summary:
            click.echo(summary_text(ds, where, units))
            return
        table = case_table(ds)
        shown = display_units(table.units, ds.attrs, units)
    names = [c.strip() for c in columns.split(",") if c.strip()] if columns else table.default
    rows = select(table, where, sort)
    click.echo(format_rows(displayed(table, shown), rows, names, fmt))


def _open_archive(path):
    """An archive as an xarray Dataset, or a Failure naming why it cannot be read."""
    import xarray as xr

    from campipe.io.archive import unreadable

    try:
        return xr.open_dataset(path)
    except Exception as exc:
        raise Failure(f"{path}: {unreadable(exc)}") from None


# -- starting without the repository -----------------------------------------------------------


def packaged_specs() -> dict[str, bytes]:
    """The example specs shipped in the package (``campipe/specs/``): file name → content."""
    from importlib import resources

    folder = resources.files("campipe") / "specs"
    return {
        entry.name: entry.read_bytes()
        for entry in sorted(folder.iterdir(), key=lambda e: e.name)
        if entry.name.endswith((".yaml", ".md"))
    }


@main.command()
@click.argument("directory", default="studies", type=click.Path(file_okay=False))
@click.option("--force", is_flag=True, help="Replace files of the same names in DIRECTORY.")
def init(directory, force) -> None:
    """Write the example specs into DIRECTORY (default: studies): the quickstart, the
    separation map and the thesis's runs, with a README; then run one with campipe study."""
    from pathlib import Path

    folder = Path(directory)
    specs = packaged_specs()
    existing = [name for name in specs if (folder / name).exists()]
    if existing and not force:
        raise InputFailure(
            f"{folder / existing[0]}: exists (and {len(existing) - 1} more of the example "
            "files); choose another folder, or replace them with --force"
            if len(existing) > 1
            else f"{folder / existing[0]}: exists; choose another folder, or replace it "
            "with --force"
        )
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name, content in specs.items():
            (folder / name).write_bytes(content)
    except OSError as exc:
        raise Failure(f"{exc.filename or folder}: cannot write ({exc.strerror or exc})") from None
    for name in specs:
        click.echo(str(folder / name))
    click.echo(
        f"campipe init: {len(specs)} files in {folder}; next: campipe study "
        f"{folder / 'quickstart.yaml'}",
        err=True,
    )


@main.command()
@click.argument("which", default="study", type=click.Choice(["study", "model"]))
def schema(which) -> None:
    """Print the JSON Schema of a study spec (or of its model: block), for an editor's YAML
    checking: campipe schema > study.schema.json."""
    if which == "model":
        from campipe.model.schema import model_schema

        click.echo(json.dumps(model_schema(), indent=2, ensure_ascii=False))
        return
    from campipe.study.spec.schema import schema_text

    click.echo(schema_text(), nl=False)


# -- plots ------------------------------------------------------------------------------------

#: The plot kinds (campipe.study.spec.plots.KINDS, repeated so --help needs no import of the study
#: layer; tests/integration/test_plot.py checks they agree).
PLOT_KINDS = ("histories", "metric", "map", "events")


@main.command()
@click.argument("kind", type=click.Choice(PLOT_KINDS))
@click.argument("archive", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="File to write: PNG, SVG or PDF by its suffix (default: <archive stem>-KIND.png "
    "beside the archive).",
)
@click.option("--where", help="Draw the cases where EXPR holds (the language of query --where).")
@units_option
@click.option(
    "--x", "x", metavar="COLUMN", help="metric, map: the column along x (default: speed_rpm)."
)
@click.option(
    "--y",
    "y",
    metavar="COLUMN",
    help="metric: the value drawn (default: separation_deg_per_rev); map: the column along y.",
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
def plot(kind, archive, output, where, units, x, y, z, level, turn) -> None:
    """Draw a figure of ARCHIVE.

    \b
    histories  valve lift, velocity, acceleration, cam and follower lift, contact forces
               against cam angle, the cases overlaid (at most 10), events marked
    metric     a per-case value (--y) against a swept column (--x), a line per
               combination of the other varied keys
    map        a per-case value (--z) over two columns (--x, --y), its contour at --level
    events     each case's separations, landings and seatings on a cam angle × case chart
    """
    from campipe.plot import plot_archive
    from campipe.study.spec.plots import PlotError, check_plot

    options = {"kind": kind, "where": where, "units": units, "output": output}
    options.update({"x": x, "y": y, "z": z, "level": level, "turn": turn})
    given = {k: v for k, v in options.items() if v is not None}
    try:
        request = check_plot(given)
    except PlotError as exc:
        raise InputFailure(f"--{exc.key}: {exc.reason}") from None
    path, _ = plot_archive(archive, request, output)
    click.echo(str(path))


def _write_plots(loaded, archive) -> None:
    """The spec's ``plots:``, each written beside the finished archive."""
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
            path, _ = plot_archive(archive, request, output)
        except Exception as exc:  # the archive is complete: a figure is an extra
            raise Failure.of(
                f"the archive {archive} is complete, but plots[{i}] ({request.kind}) failed: "
                f"{str(exc)[:300]}; draw it with campipe plot {request.kind} {archive}",
                isinstance(exc, ValueError),
            ) from None
        click.echo(f"campipe study: plots[{i}] ({request.kind}) written to {path}", err=True)


# -- onset ------------------------------------------------------------------------------------


@main.command()
@click.argument("spec", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option(
    "--tolerance",
    default="0.1 rpm",
    show_default=True,
    metavar="SPEED",
    help="The onset's tolerance (the width of its final bracket).",
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
    "--check/--no-check",
    default=True,
    show_default=True,
    help="Run the time-domain engine 0.5 % below and above each onset.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    help="Threads for the search (default: the cores available).",
)
def onset(spec, sets, tolerance, fmt, output, check, workers) -> None:
    """The no-follow onset speed of every combination of SPEC's other axes, within its
    speed range: the root of the steady state's least cam force, checked by the time-domain
    engine either side. Exit status 1 when a check disagrees."""
    from pathlib import Path

    from campipe.units import QuantityError, parse_quantity

    try:
        tol = parse_quantity(tolerance, "rad/s", "--tolerance", "rpm")
    except QuantityError as exc:
        raise click.BadParameter(str(exc), param_hint="--tolerance") from None
    loaded = _load(spec, sets)
    path = Path(output) if output else Path(spec).parent / f"{loaded.name}-onset.nc"
    _onset(loaded, spec, path, tol, fmt, check, workers)


def _onset(loaded, spec_path, path, tolerance, fmt, check, workers, command="onset") -> None:
    """``campipe onset``'s work (and ``campipe study``'s for a spec with ``search``)."""
    from campipe.io.archive import provenance, write_file
    from campipe.study.onset import file_contents, onset_study, summary_lines
    from campipe.study.query.display import display_units
    from campipe.study.query.tables import displayed, format_rows
    from campipe.study.run.batches import default_workers

    result = onset_study(
        loaded,
        tolerance,
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
        {**attrs, **provenance(f"campipe onset {spec_path}")},
        loaded.compression,
    )
    table = displayed(result.table, display_units(result.table.units, attrs))
    click.echo(format_rows(table, np.arange(table.n), table.default, fmt))
    for line in summary_lines(result):
        click.echo(line, err=True)
    click.echo(f"wrote {path}", err=True)
    if result.disagreements.size:
        raise Failure(summary_lines(result)[-1])


# -- replay -----------------------------------------------------------------------------------


@main.command()
@click.argument("archive", type=click.Path(dir_okay=False))
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
@click.option("--spawn", is_flag=True, help="Open the rerun viewer instead of writing a file.")
@click.option(
    "--magnify",
    type=click.FloatRange(min=1.0),
    default=10.0,
    show_default=True,
    help="Factor on the sketch's deviations from the rigid-body motion.",
)
def replay(archive, case_ids, where, output, spawn, magnify) -> None:
    """Write a rerun recording of cases of ARCHIVE: lift, force and contact plots, events,
    parameters and the moving mechanism, on the timelines cam_angle and time. All cases go
    into one recording, each in its own cases/<case_id> subtree and blueprint tab."""
    from campipe.replay.cases import ReplayError
    from campipe.replay.record import replay_archive
    from campipe.study.run.progress import Progress
    from campipe.study.where import QueryError

    if bool(case_ids) == (where is not None):
        raise click.UsageError("give --case ID (repeatable) or --where EXPR, one of the two")
    if spawn and output:
        raise click.UsageError("-o and --spawn exclude each other")
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
        )
    except QueryError as exc:
        raise click.UsageError(str(exc)) from None
    except ReplayError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(
        f"campipe replay: {len(cases)} case{'s' if len(cases) != 1 else ''} ("
        + ", ".join(c.case_id for c in cases)
        + ")",
        err=True,
    )
    if path is not None:
        click.echo(str(path))


# -- bench ------------------------------------------------------------------------------------


@main.command()
@click.option(
    "--quick",
    is_flag=True,
    help="Small ladders, one cam turn per scene, scaling up to 256 cases (< 1 min).",
)
@click.option(
    "-o",
    "--output",
    "output",
    default="bench-results",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Folder for bench.md/.csv/.json/.png.",
)
@click.option(
    "--scene",
    "scenes",
    multiple=True,
    metavar="NAME",
    help="Run only this scene of the suite (repeatable).",
)
@click.option(
    "--scaling/--no-scaling",
    default=True,
    show_default=True,
    help="Measure throughput, time against cases and workers, archive size.",
)
@click.option(
    "--suite/--no-suite",
    default=True,
    show_default=True,
    help="Run the scenes: references, integrators, peers, fidelity.",
)
@click.option(
    "--study/--no-study",
    "study_section",
    default=True,
    show_default=True,
    help="Time campipe study end to end against the engine: start-up, 1 to 10000 cases, "
    "the client's ceiling, local worker processes, validate's estimates.",
)
@click.option(
    "--plot/--no-plot",
    default=True,
    show_default=True,
    help="Write bench.png (needs matplotlib: pip install 'campipe[plot]').",
)
def bench(quick, output, scenes, scaling, suite, study_section, plot) -> None:
    """Speed against error: the suite of scenes, every integrator and fidelity, peers, scaling.

    Ends with the verdict: each goal with its measured figure (reached, not reached or not
    shown), each reference cross-check (agree or disagree, and why). Exit status 1 when a
    cross-check disagrees.
    """
    from campipe.bench import verdict
    from campipe.bench.report import write_report
    from campipe.bench.run import run_bench

    if plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise click.UsageError(
                "--plot needs matplotlib: pip install 'campipe[plot]', or pass --no-plot"
            ) from None
    stderr = sys.stderr

    def say(text: str) -> None:
        stderr.write(f"campipe bench: {text}\n")

    try:
        result = run_bench(
            quick,
            scenes or None,
            with_scaling=scaling,
            with_suite=suite,
            with_study=study_section,
            progress=say,
        )
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    paths = write_report(result, output, with_plot=plot)
    for path in paths.values():
        click.echo(str(path))
    click.echo(verdict.text(result))
    if not verdict.all_agree(result):
        sys.exit(1)
