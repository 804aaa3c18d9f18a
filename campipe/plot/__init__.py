"""Figures of an archive: ``campipe plot KIND ARCHIVE`` and a spec's ``plots:`` list.

- :mod:`~campipe.plot.figures`: each kind as a matplotlib Figure, built from an archive (an
  ``xarray.Dataset``) and a :class:`~campipe.study.spec.plots.PlotRequest`; pure, nothing written;
- :mod:`~campipe.plot.style`: lines and markers that read in grey, labels with units.

matplotlib is imported by these modules only, so ``campipe --help`` and the other commands
never load it.
"""

from __future__ import annotations

from pathlib import Path

from campipe.io.archive import ArchiveFileError, unreadable
from campipe.study.archive.open import open_archive
from campipe.study.spec.plots import PlotRequest


def plot_archive(archive: str | Path, request: PlotRequest, output: str | Path | None = None):
    """Draw ``request`` from the archive at ``archive`` and write it to ``output`` (default
    ``request.output`` relative to the archive's folder, else
    :meth:`~campipe.study.spec.plots.PlotRequest.default_output`); the format follows the suffix.

    Returns
    -------
    (Path, matplotlib.figure.Figure)
        The file written and the figure.
    """
    from campipe.plot.figures import figure

    archive = Path(archive)
    if output is None:
        output = (
            archive.parent / request.output if request.output else request.default_output(archive)
        )
    try:
        ds = open_archive(archive)  # a file, or a parts archive's folder
    except Exception as exc:
        raise ArchiveFileError.at(str(archive), unreadable(exc)) from None
    with ds:
        fig = figure(ds, request)
    return write(fig, output), fig


def write(fig, path: str | Path) -> Path:
    """Write a figure; PNG, SVG or PDF by the suffix of ``path``."""
    from campipe.study.spec.plots import FORMATS, PlotError

    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise PlotError.at(
            "-o", f"{path}: expected a file ending in {', '.join(FORMATS)} (the suffix chooses)"
        )
    fig.savefig(path, dpi=120)
    return path
