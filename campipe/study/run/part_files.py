"""A batch as a part of a parts archive (:mod:`campipe.io.parts`): one compressed CF netCDF
file with the single-file archive's variables and attributes for the batch's cases, written
atomically (with its checksums) by the worker that computed it.

The client builds a :class:`PartLayout` once (the study's variables, axes and attributes);
a worker lays each of its batches out with it, the case coordinates computed there from the
batch's cases, so the client's work per case is only to keep count.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from campipe.engine.settings import output_angles
from campipe.io.archive import NetCDFWriter, VariableSpec, provenance, write_error
from campipe.io.parts import checksum_digest, part_name
from campipe.study.archive.layout import archive_layout, study_trains
from campipe.study.run.keys import study_attrs
from campipe.study.run.results import BatchData, BatchPlan, cam_angle_degrees
from campipe.study.spec.coordinates import CASE_ID, key_columns, padded
from campipe.study.spec.expand import Study
from campipe.study.spec.variables import Variable, case_coordinates


@dataclass(frozen=True)
class PartLayout:
    """What every part of a study's parts archive shares (sent with each batch's task)."""

    sizes: Mapping[str, int | None]  # the archive's dimensions; case and event per part
    specs: tuple[VariableSpec, ...]  # its variables, in the single-file archive's order
    axes: Mapping[str, np.ndarray]  # cam_angle, revolution (dof, dof_units)
    coordinates: Mapping[str, tuple[str, Variable, float]]  # case_coordinates(study.varied)
    attrs: Mapping[str, object]  # the archive's global attributes
    compression: str  # run.compression


def part_layout(study: Study, command: str, spec: str) -> PartLayout:
    """The layout of ``study``'s parts: the single-file archive's (``archive_layout``)."""
    cam_angle = cam_angle_degrees(output_angles(study.cases[0].settings))
    # Laid out on the first case: the case coordinates of the rest are the workers' to
    # compute (all of them here took 10 µs a case), but for a list's longest length.
    first = dataclasses.replace(study, cases=study.cases[:1])
    sizes, specs, static = archive_layout(
        first, None, cam_angle, study.n_revolutions, study_trains(study)
    )
    sizes = {**sizes, "case": len(study.cases)}
    if "mode" in sizes:
        lists = [k for k, (_, v, _) in case_coordinates(study.varied).items() if "mode" in v.dims]
        widths = (np.asarray(c.values[k]).size for c in study.cases for k in lists)
        sizes["mode"] = max(widths)
    names = {s.name for s in specs if "case" not in s.dims and "event" not in s.dims}
    attrs = {**study_attrs(study), "spec_file": spec, **provenance(command)}
    return PartLayout(
        sizes,
        tuple(specs),
        {k: v for k, v in static.items() if k in names},
        case_coordinates(study.varied),
        attrs,
        study.compression,
    )


def part_arrays(data: BatchData, plan: BatchPlan, layout: PartLayout) -> dict[str, np.ndarray]:
    """Every variable of a batch's part: the axes, the case ids and coordinates of its cases
    (a list per case, such as ``damping_ratios``, padded with NaN to the study's width) and
    its data."""
    coords = key_columns(plan.cases, layout.coordinates)
    width = layout.sizes.get("mode")
    for name, values in coords.items():
        if values.ndim == 2 and width is not None and values.shape[1] < width:
            coords[name] = padded(values, int(width))
    return {**layout.axes, CASE_ID: data.case_ids, **coords, **data.arrays}


def store_part(
    data: BatchData, plan: BatchPlan, directory: Path, layout: PartLayout
) -> tuple[Path, str]:
    """Write a batch's part atomically into the parts archive ``directory``; returns its path
    and the index's checksum of it (:func:`campipe.io.parts.checksum_digest`)."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(directory, exc) from None
    arrays = part_arrays(data, plan, layout)
    sizes = {**layout.sizes, "case": data.n_cases, "event": None}
    attrs = {**layout.attrs, "campipe_numerics": data.numerics, "batch_key": data.key}
    path = directory / part_name(data.key)
    with NetCDFWriter(path, sizes, layout.specs, attrs, layout.compression) as w:
        for v in layout.specs:
            if v.dims[:1] == ("event",):
                w.append(v.name, arrays[v.name])
            else:
                w.write(v.name, arrays[v.name])
        w.commit()
    return path, checksum_digest(w.checksum_text)
