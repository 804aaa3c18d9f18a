"""Reading an archive as a grid: :func:`open_study`.

An archive holds its cases along one dimension, ``case``, in the order the spec expands them
(:mod:`campipe.study.spec.expand`): for each ``cases`` entry, the ``sweep`` grid (first key
outermost), then the ``zip`` rows, then the ``sample`` points. Where the sweep is a full grid
whose values are plain labels (numbers without NaN, or text), :func:`open_study` turns its
axes into dimensions of their own; what is not a grid (the zip rows, the case entries, the
samples) stays along ``case``.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from campipe.io.archive import ArchiveDamagedError, ArchiveFileError, check
from campipe.io.parts import INDEX, PartsIndexError, part_checksum, read_index
from campipe.io.watch import watched
from campipe.study.archive.layout import LAYOUT_VERSION
from campipe.units import (
    ENGINE_SPEED,
    convert_values,
    degree_speed,
    no_speed,
    per_degree,
    system_units,
)

log = logging.getLogger(__name__)
#: The name the rest of the study (zip rows, case entries, samples) goes by while the sweep
#: is unstacked; it is ``case`` again afterwards.
_REST = "_rest"


def sweep_axes(attrs: Mapping[str, object]) -> list[tuple[str, int]]:
    """(archive name, size) of each sweep axis, outermost first (``study_axes``)."""
    try:
        axes = json.loads(str(attrs.get("study_axes", "[]")))
    except ValueError:
        return []
    return [(str(a["name"]), int(a["size"])) for a in axes if a.get("kind") == "sweep"]


def open_study(path: str | Path, units: str = "si", verify: bool = True, **open_kwargs):
    """Open a study's archive with its sweep's axes as dimensions, where the study is a grid.

    Parameters
    ----------
    path : str or Path
        The archive (``campipe study`` writes it): one netCDF file, or a parts archive's
        folder (``campipe study --parts``), read as one dataset (:func:`open_archive`).
    units : str
        The unit system of the values (:data:`campipe.units.UNIT_SYSTEMS`): ``si``, as stored
        (the default); ``in-lbf``; or ``mm-deg`` (lift mm, velocity mm/deg and acceleration
        mm/deg² of cam angle at each case's cam speed, force N, stress MPa). Each converted
        variable's ``units`` attribute names its new units (:func:`in_units`).
    verify : bool
        Check every variable against the checksums stored when the archive was written
        before returning it (:func:`open_archive`); False skips that read of the archive.
    **open_kwargs
        Passed to :func:`xarray.open_dataset` (e.g. ``chunks={}`` to read lazily with dask).

    Returns
    -------
    xarray.Dataset
        For a sweep, each swept key a dimension (named as its archive coordinate,
        ``speed_rpm``, ``seat``, ``spring_preload``, …) with its values in the spec's order,
        and the case ids in the coordinate ``case_id`` over them. What the study varies
        otherwise (zip rows, case entries, samples) stays along ``case``. Events keep their
        dimension ``event``, each with its case's id (``event_case_id``) instead of its row.
        A study that is not a full grid of plain values (no sweep, a swept vector such as
        ``damping_ratios``, a sweep with NaN such as ``run.dt: [default, ...]``, repeated
        labels) is returned as stored, one case per row of ``case``.
    """
    system = system_units(units, "units")
    ds = open_archive(path, verify, **open_kwargs)
    try:
        if system:
            ds = in_units(ds, units)
        grid = as_grid(ds)
    except Exception:
        ds.close()
        raise
    if grid is None:
        return ds
    grid.set_close(ds.close)  # the grid's close closes the file (else it stays open)
    return grid


def in_units(ds, units: str):
    """The archive ``ds`` (an ``xarray.Dataset`` along ``case``, as stored) with every
    variable whose units the system ``units`` lists converted
    (:data:`campipe.units.UNIT_SYSTEMS`), its ``units`` attribute the new units. Per-degree
    units take each case's cam speed (``speed_rpm``; an event's, its case's); lazy (dask)
    variables stay lazy."""
    system = system_units(units, "units")
    at = degree_speed(system.values())  # the cam's, or the engine's per degree of crank angle
    if at == ENGINE_SPEED and at not in ds.variables:
        raise no_speed(system["m/s"])  # an archive without a drive: no engine speed
    speeds = {}  # dimension → that speed [rpm] along it
    if at in ds.variables and ds[at].dims == ("case",):
        speeds["case"] = ds[at].variable
        if "event_case" in ds.variables:
            rows = ds["event_case"].values
            speeds["event"] = type(speeds["case"])("event", ds[at].values[rows])
    out = ds.copy()
    for name, var in ds.variables.items():
        stored = str(var.attrs.get("units", ""))
        shown = system.get(stored)
        if shown is None or var.dtype.kind != "f" or name in ds.dims:
            continue
        power = per_degree(shown)[1]
        at_1rpm = float(convert_values(1.0, stored, shown, 1.0))
        if not power:
            new = var * at_1rpm
        else:
            dim = next((d for d in var.dims if d in speeds), None)
            if dim is None:
                continue  # no cam speed along it: left as stored
            new = var * (at_1rpm / speeds[dim] ** power)
        new.attrs = {**var.attrs, "units": shown}
        new.encoding = dict(var.encoding)
        if name in ds.coords:
            out = out.assign_coords({name: new})
        else:
            out[name] = new
    return out


def open_archive(
    path: str | Path, verify: bool = True, unread_dims: tuple[str, ...] = (), **open_kwargs
):
    """An archive as stored, one case per row of ``case`` in the study's order: a netCDF
    file (:func:`xarray.open_dataset`), or a parts archive's folder, its parts read as one
    dataset (:func:`open_parts`).

    With ``verify`` (the default), every variable and the global attributes are first
    checked against the checksums stored when the file (each part) was written, reading it
    once: a damaged archive raises :class:`~campipe.io.archive.ArchiveDamagedError` naming
    the variables that differ. A reader that never reads the variables along some dimensions
    names them in ``unread_dims`` (``campipe query``: ``("cam_angle",)``, the histories),
    and those are left unchecked. Archives store each chunk's Fletcher-32 as well, which HDF5
    checks on any read, verified or not.

    Raises
    ------
    campipe.io.archive.ArchiveFileError
        For a path that is neither a regular file nor a folder (a pipe, a device: opening
        one would wait on it), a netCDF file campipe did not write, or a damaged archive
        (its subclass ArchiveDamagedError).
    """

    path = Path(path)
    if path.is_dir():
        return open_parts(path, verify, unread_dims, **open_kwargs)
    if path.exists() and not path.is_file():
        raise ArchiveFileError.at(
            str(path), "not a regular file; an archive is a netCDF file or a parts folder"
        )
    if verify:
        check(path, layout=LAYOUT_VERSION, skip_dims=unread_dims)
    ds = _open_dataset(path, **open_kwargs)
    if "case" not in ds.variables and "campipe_layout" not in ds.attrs:
        ds.close()
        raise ArchiveFileError.at(
            str(path),
            "not a campipe archive (netCDF without a case variable or a campipe_layout "
            "attribute); campipe study writes one",
        )
    return ds


@watched
def _open_dataset(path: str | Path, **open_kwargs):
    """:func:`xarray.open_dataset`, watched (:mod:`campipe.io.watch`): a damaged file whose
    metadata sends HDF5 round a loop is given up, not waited on for ever."""
    import xarray as xr

    return xr.open_dataset(path, **open_kwargs)


def open_parts(
    path: str | Path, verify: bool = True, unread_dims: tuple[str, ...] = (), **open_kwargs
):
    """A parts archive (:mod:`campipe.io.parts`) as one dataset, the single-file archive's:
    its parts' variables along ``case`` and along ``event`` concatenated in the index's
    order, the cases put in the study's order (``event_case`` their rows again), the
    index's global attributes.

    Raises
    ------
    campipe.io.parts.PartsIndexError
        If the folder holds no readable index (not a parts archive, or a run not finished).
    """

    path = Path(path)
    index = read_index(path)
    if verify:
        for p in index["parts"]:
            _check_part(path, p, unread_dims)
    parts = [_open_dataset(path / str(p["file"]), **open_kwargs) for p in index["parts"]]
    try:
        ds = _combine(path, parts, [str(c) for c in index["case"]])
    except Exception:
        for p in parts:
            p.close()
        raise
    ds.attrs = dict(index["attrs"])

    def close() -> None:
        for p in parts:
            p.close()

    ds.set_close(close)
    return ds


def _check_part(archive: Path, entry: Mapping[str, object], unread_dims: tuple[str, ...]) -> None:
    """A part the index names: the same file (its stored checksums those the index
    recorded) and undamaged (:func:`~campipe.io.archive.check`)."""
    part = archive / str(entry["file"])
    recorded = entry.get("checksum")
    if recorded is not None and part.is_file() and part_checksum(part) != recorded:
        raise ArchiveDamagedError.at(
            str(part),
            f"not the part {INDEX} names (its checksums differ from those the index "
            "recorded: replaced or damaged); run the study again to write it anew, or read "
            "it as it is with --no-verify",
            found=["checksums"],
            expected=str(recorded),
        )
    check(part, layout=LAYOUT_VERSION, skip_dims=unread_dims)


def _combine(path: Path, parts: list, ids: list[str]):
    """Parts (xarray Datasets) as one: per-case variables concatenated along ``case``,
    events along ``event`` (each part's ``event_count`` their ragged lengths), then the
    cases ``ids`` picked in that order (the first part holding each)."""
    import pandas as pd
    import xarray as xr

    if not parts:
        raise PartsIndexError.at(str(path), "its index names no part")

    def concat(datasets, dim):
        return xr.concat(
            datasets, dim, data_vars="minimal", coords="minimal", compat="override", join="exact"
        )

    cases = concat([p.drop_dims("event") for p in parts], "case")
    events = concat(
        [p.drop_vars([n for n in p.variables if "event" not in p[n].dims]) for p in parts],
        "event",
    )
    held = pd.Index(cases["case"].values)
    first = np.flatnonzero(~held.duplicated())  # a case two parts hold: the first's
    rows = held[first].get_indexer(ids)
    if (rows < 0).any():
        missing = ids[int(np.argmax(rows < 0))]
        raise PartsIndexError.at(str(path), f"case {missing} is in no part its index names")
    rows = first[rows]
    counts = cases["event_count"].values.astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    if not np.array_equal(rows, np.arange(len(ids))) or starts[-1] != events.sizes["event"]:
        taken = counts[rows]
        offsets = np.repeat(starts[rows] - np.concatenate([[0], np.cumsum(taken)[:-1]]), taken)
        cases = cases.isel(case=rows)
        events = events.isel(event=np.arange(int(taken.sum())) + offsets)
        counts = taken
    event_case = events["event_case"]
    values = np.repeat(np.arange(len(ids), dtype=event_case.dtype), counts)
    events = events.assign_coords(
        event_case=xr.Variable("event", values, event_case.attrs, event_case.encoding)
    )
    return xr.merge([cases, events], compat="override", join="exact", combine_attrs="override")


def as_grid(ds):
    """The archive (an ``xarray.Dataset``) with its sweep axes as dimensions, or None when
    the study is not a full grid of plain values (see :func:`open_study`)."""
    import pandas as pd
    import xarray as xr

    n = ds.sizes.get("case", 0)
    axes = sweep_axes(ds.attrs)
    if not axes or n == 0 or "case" not in ds.variables:
        return None
    names = [name for name, _ in axes]
    sizes = [size for _, size in axes]
    sweep = int(np.prod(sizes, dtype=np.int64))
    if n % sweep or any(name not in ds.coords or ds[name].dims != ("case",) for name in names):
        log.info("not a grid: the sweep's axes are not per-case coordinates of %d cases", n)
        return None
    inner = _inner_length(ds.attrs, n // sweep)
    index = np.arange(n)
    rest = (index // (sweep * inner)) * inner + index % inner
    values = [ds[name].values for name in names]
    for name, v, size in zip(names, values, sizes, strict=True):
        if len(pd.unique(v)) != size or (v.dtype.kind == "f" and np.isnan(v).any()):
            log.info("not a grid: %s does not take %d distinct plain values", name, size)
            return None
    levels = [*values, rest] if n > sweep else values
    level_names = [*names, _REST] if n > sweep else names
    multi = pd.MultiIndex.from_arrays(levels, names=level_names)
    if not multi.is_unique:
        log.info("not a grid: two cases share one point of the sweep")
        return None
    ids = ds["case"].values
    flat = ds.drop_vars(["case", *names])
    if "event_case" in flat.variables:
        rows = flat["event_case"].values
        flat = flat.drop_vars("event_case").assign_coords(
            event_case_id=("event", ids[rows] if rows.size else np.array([], dtype=ids.dtype))
        )
        flat["event_case_id"].attrs["long_name"] = "case id of the event's case"
    flat = flat.assign_coords(case_id=("case", ids))
    flat["case_id"].attrs.update(ds["case"].attrs)
    coords = xr.Coordinates.from_pandas_multiindex(multi, "case")
    grid = flat.assign_coords(coords).unstack("case")
    order = {name: pd.unique(v) for name, v in zip(names, values, strict=True)}
    grid = grid.reindex(order)
    for name in names:
        grid[name].attrs.update(ds[name].attrs)
    if n > sweep:
        grid = grid.drop_vars(_REST).rename_dims({_REST: "case"})
    return grid.transpose(*names, *(["case"] if n > sweep else []), ...)


def _inner_length(attrs: Mapping[str, object], rest: int) -> int:
    """The zip rows × samples of the study (the rest of a case entry after its sweep):
    the archive's ``rest`` cases per sweep point, divided by its case entries."""
    try:
        axes = json.loads(str(attrs.get("study_axes", "[]")))
    except ValueError:
        return rest
    entries = next((int(a["size"]) for a in axes if a.get("kind") == "cases"), 1)
    return rest // entries if entries and rest % entries == 0 else rest
