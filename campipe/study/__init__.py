"""Studies: a YAML spec expanded into cases, run in batches on dask, stored in one archive.

Layers, in the order a study passes through them:

- :mod:`~campipe.study.fields`: the spec's keys, declared once.
- :mod:`~campipe.study.spec`: checking a spec (key paths in every message).
- :mod:`~campipe.study.expand`: expansion (sweep, zip, cases, sample) and resolution of each
  case to engine inputs and a stable id.
- :mod:`~campipe.study.results`: one batch through the engine, as archive arrays.
- :mod:`~campipe.study.variables`, :mod:`~campipe.study.layout`: the archive's variables.
- :mod:`~campipe.study.execute`: batches on dask, resume, the archive.
- :mod:`~campipe.study.where`: the ``--where`` language.
- :mod:`~campipe.study.query`: tables, the summary and the replay selection.
- :mod:`~campipe.study.schema`: the JSON Schema of a spec.

File formats live in :mod:`campipe.io`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from campipe.io.spec_yaml import read_spec
from campipe.study.expand import ResolvedCase, Study, expand
from campipe.study.limits import Limits
from campipe.study.spec import Spec, SpecError, check_spec

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
        checked from the spec before any case is built.

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
    spec = check_spec(raw, text, path.parent, str(path), overrides, max_axis=limits.cases)
    spec.path = path
    return expand(spec, str(path), limits)
