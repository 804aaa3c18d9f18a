"""``campipe bench``: speed against error."""

from __future__ import annotations

import sys

import click


@click.command()
@click.option(
    "--quick",
    is_flag=True,
    help="Small ladders, 1.5 cam turns per scene, scaling up to 256 cases (< 1 min).",
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
    help="Measure throughput and the engine's time against cases and workers.",
)
@click.option(
    "--cluster/--no-cluster",
    default=None,
    help="Run a study with --parts on a local dask cluster of 1, 2 and 4 worker processes: "
    "cases per second against the client's CPU per case [default: with --scaling].",
)
@click.option(
    "--suite/--no-suite",
    default=True,
    show_default=True,
    help="Run the scenes: references, integrators, peers, fidelity.",
)
@click.option(
    "--previous",
    "previous",
    default=None,
    type=click.Path(dir_okay=False),
    help="The previous run's bench.json to compare with [default: the output folder's].",
)
@click.option(
    "--plot/--no-plot",
    default=True,
    show_default=True,
    help="Write bench.png (needs matplotlib: pip install 'campipe[plot]').",
)
def bench(quick, output, scenes, scaling, cluster, suite, previous, plot) -> None:
    """Speed against error: the suite of scenes, every integrator and fidelity, peers, scaling.

    Ends with the verdict: each goal with its measured figure (reached, not reached or not
    shown), every timed figure more than 10 % slower than the previous run's on the same
    machine (each timed once more first, and named only if slower again; kept beside the new
    ones in bench.json), each reference cross-check (agree or disagree, and why). Exit status
    1 when a cross-check disagrees.
    """
    from pathlib import Path

    from campipe.bench import verdict
    from campipe.bench.report import FILES, with_previous, write_report
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
            progress=say,
            with_cluster=cluster,
        )
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    # Read before the report overwrites it.
    result = with_previous(result, previous or Path(output) / FILES["json"])
    if result.regressions:
        from campipe.bench import gate
        from campipe.bench.retime import retimer

        say(f"timing again the {len(result.regressions)} figures more than 10 % slower")
        result = gate.confirm(result, retimer(result))
    paths = write_report(result, output, with_plot=plot)
    for path in paths.values():
        click.echo(str(path))
    click.echo(verdict.text(result))
    if not verdict.all_agree(result):
        sys.exit(1)
