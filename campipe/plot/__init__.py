"""Figures of an archive: ``campipe plot KIND ARCHIVE`` and a spec's ``plots:`` list.

- :mod:`~campipe.plot.figures`: each kind as a matplotlib Figure, built from an archive (an
  ``xarray.Dataset``) and a :class:`~campipe.study.spec.plots.PlotRequest`; pure, nothing written;
- :mod:`~campipe.plot.style`: lines and markers that read in grey, labels with units.

matplotlib is imported by these modules only, so ``campipe --help`` and the other commands
never load it.
"""

from __future__ import annotations

import os
from pathlib import Path

from campipe.io.archive import ArchiveDamagedError, unreadable_error
from campipe.io.outputs import FIGURE, check_output
from campipe.study.archive.open import open_archive
from campipe.study.spec.plots import PlotRequest


def plot_archive(
    archive: str | Path,
    request: PlotRequest,
    output: str | Path | None = None,
    *,
    overwrite: bool = False,
    key: str = "-o",
    inside: str | Path | None = None,
    verify: bool = True,
):
    """Draw ``request`` from the archive at ``archive`` and write it to ``output`` (default
    ``request.output`` relative to the archive's folder, else
    :meth:`~campipe.study.spec.plots.PlotRequest.default_output`); the format follows the suffix.

    The figure follows the output rule (``campipe.io.outputs``), checked before drawing: it
    never replaces the archive or its spec, replaces a file that is not a figure of its
    format only with ``overwrite``, and stays inside the folder ``inside`` when given (a
    spec's ``plots[].output``); ``key`` names the option or spec key in the refusal.
    ``verify``: check the archive against its checksums first (``open_archive``).

    Returns
    -------
    (Path, matplotlib.figure.Figure)
        The file written and the figure.
    """
    from campipe.plot.figures import figure
    from campipe.plot.pareto import pareto_figure
    from campipe.plot.spectrum import spectrum_figure

    archive = Path(archive)
    if output is None:
        output = (
            archive.parent / request.output if request.output else request.default_output(archive)
        )
    try:
        ds = open_archive(archive, verify)  # a file, or a parts archive's folder
    except ArchiveDamagedError:
        raise
    except Exception as exc:
        raise unreadable_error(archive, exc) from None
    with ds:
        spec = str(ds.attrs.get("spec_file") or "")
        check_output(
            output,
            key,
            FIGURE,
            overwrite=overwrite,
            inside=inside,
            inputs=[
                (archive, "the archive drawn"),
                (archive.parent / spec if spec else None, "the archive's spec"),
            ],
        )
        draw = {"spectrum": spectrum_figure, "pareto": pareto_figure}.get(request.kind, figure)
        fig = draw(ds, request)
    return write(fig, output), fig


def write(fig, path: str | Path) -> Path:
    """Write a figure; PNG, SVG or PDF by the suffix of ``path``."""
    from campipe.study.spec.plots import FORMATS, PlotError

    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise PlotError.at(
            "-o", f"{path}: expected a file ending in {', '.join(FORMATS)} (the suffix chooses)"
        )
    # at a temporary name, renamed into place: a link at the path is replaced, not followed
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fig.savefig(tmp, dpi=120, format=path.suffix.lower()[1:])
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
