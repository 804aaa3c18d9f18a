"""The ``campipe`` command line (click). I/O only: every number comes from the numerics layer.

Each command imports what it uses when it runs (``campipe --help`` loads click, the model's
parameter table and NumPy, nothing else): dask, xarray, netCDF4, pint, SciPy, numba and
rerun load only in the commands that need them.

The group and what the commands share are :mod:`~campipe.cli.base`'s; one module per family
of commands: :mod:`~campipe.cli.study` (study, validate, query, pack), :mod:`~campipe.cli.export`,
:mod:`~campipe.cli.plot`, :mod:`~campipe.cli.onset`, :mod:`~campipe.cli.design`,
:mod:`~campipe.cli.replay`, :mod:`~campipe.cli.model` (model, init, schema) and
:mod:`~campipe.cli.bench`.
"""

from campipe.cli import bench, design, export, model, onset, plot, replay, study
from campipe.cli.base import main

__all__ = ["main"]

for _command in (
    bench.bench,
    export.export,
    design.design,
    model.init,
    model.model,
    model.schema,
    onset.onset,
    study.pack,
    plot.plot,
    study.query,
    replay.replay,
    study.study,
    study.validate,
):
    main.add_command(_command)
