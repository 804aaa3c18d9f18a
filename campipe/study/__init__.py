"""Studies: a YAML spec expanded into cases, run in batches on dask, stored in one archive.

The packages, in the order a study passes through them, each importing only those before it:

- :mod:`~campipe.study.spec`: the spec's keys (``fields``), checking (``check``, ``blocks``),
  expansion and each case resolved to engine inputs and a stable id (``expand``,
  ``resolve``), the limits, the variables a study records and each case's coordinates,
  plot requests, the JSON Schema.
- :mod:`~campipe.study.archive`: the archive's layout, and an archive read as a grid.
- :mod:`~campipe.study.run`: one batch through the engine (``results``), batch sizes, batches
  on dask, batch files and resume, the archive's assembly, the progress line, the estimate.
- :mod:`~campipe.study.query`: tables, ``--where`` selections, the summary, units shown.

:mod:`~campipe.study.where` (the ``--where`` language) lies below them all: a spec's
``replay.where`` and plots are written in it. :mod:`~campipe.study.onset` (``campipe onset``)
lies above them all. File formats live in :mod:`campipe.io`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from campipe.io.spec_yaml import read_spec
from campipe.study.spec.check import Spec, SpecError, check_spec
from campipe.study.spec.expand import Study, expand
from campipe.study.spec.limits import Limits
from campipe.study.spec.resolve import ResolvedCase

__all__ = [
    "Limits",
    "ResolvedCase",
    "Spec",
    "SpecError",
    "Study",
    "check_spec",
    "expand",
    "load_study",
]


def load_study(
    path: str | Path,
    overrides: Mapping[str, object] | None = None,
    limits: Limits | None = None,
) -> Study:
    """Read, check and expand a spec file.

    Parameters
    ----------
    path : str or Path
        The spec (YAML).
    overrides : mapping, optional
        Dotted key → value applied over the spec first, e.g. ``{"run.revolutions": 1}``.
    limits : Limits, optional
        Bounds on cases, steps, samples, events and archive size (default: ``Limits()``),
        checked from the spec before any case is built; a ``steps`` other than the default
        is also each case's ``run.max_steps``, the cap of an adaptive integration at run time.

    Raises
    ------
    campipe.io.spec_yaml.SpecFileError
        For a file that is not plain YAML data.
    SpecError
        For any problem in the spec, each with its key path.
    """
    path = Path(path)
    raw, text = read_spec(path)
    limits = limits or Limits()
    if limits.steps != Limits().steps:  # --max-steps: also the run's cap (run.max_steps)
        overrides = {**(overrides or {}), "run.max_steps": math.ceil(limits.steps)}
    spec = check_spec(raw, text, path.parent, str(path), overrides, max_axis=limits.cases)
    spec.path = path
    return expand(spec, str(path), limits)
