"""A case's histories as a table: one row per sample, one column per history
(``campipe export``).

The columns: ``case`` (the case's id), ``cam_angle`` (and ``crank_angle``, for a spec with a
drive), ``time``, then each history the
archive holds along ``(case, cam_angle)`` in its order (``q`` as ``q1`` … ``q7``), but those
NaN in every exported row (a chain's unused coordinates, its ``rocker_moment``), each in
the units of the chosen system (:mod:`campipe.study.query.display`; velocities and
accelerations per degree at each case's cam speed in ``mm-deg``). Several cases follow one
another, each over all its samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from campipe.errors import CampipeError, did_you_mean, excerpt
from campipe.study.query.display import display_units, to_display
from campipe.study.query.tables import case_table, select, without_noise
from campipe.units import degree_speed

#: Units as an export's header writes them.
SHORT_UNITS = {"degree": "deg", "1": ""}


class ExportError(CampipeError, ValueError):
    """Cases or histories that cannot be exported as asked (``key`` the option)."""


@dataclass
class HistoryTable:
    """Histories of some cases as columns of samples."""

    columns: dict[str, np.ndarray]  # name → (rows,) values, all of one length
    units: dict[str, str]  # name → units as shown ("" for none)
    study: str  # the study's name
    cases: list[str]  # the cases' ids, in the order their rows come
    left_out: list[str]  # histories NaN in every row (a chain's unused q, its rocker_moment)


def pick_cases(ds, ids: Sequence[str] = (), where: str | None = None) -> np.ndarray:
    """Rows of the archive's cases named by id (or a unique start of one), in the order
    given, then those ``where`` selects (each case once).

    Raises
    ------
    ExportError
        For an id no case has or several start with, or a selection of no case.
    """
    known = [str(c) for c in ds["case"].values]
    rows: list[int] = []
    for given in ids:
        text = str(given).strip()
        hits = [i for i, c in enumerate(known) if c == text] or [
            i for i, c in enumerate(known) if text and c.startswith(text)
        ]
        if len(hits) != 1:
            what = "no case" if not hits else f"{len(hits)} cases"
            raise ExportError.at(
                "--case",
                f"{what} of the archive's {len(known)} has the id {excerpt(text)}"
                f"{did_you_mean(text, known)}; campipe query ARCHIVE --columns case lists them",
                found=text,
                expected="a case id, or a start of one unique to it",
            )
        rows.append(hits[0])
    if where is not None:
        selected = select(case_table(ds), where).tolist()
        if not selected:
            raise ExportError.at("--where", f"{where!r} selects none of the archive's cases")
        rows += selected
    if not rows:
        raise ExportError.at(
            "--case",
            "no case named: give --case ID (repeatable) or --where EXPR",
            expected="a case",
        )
    return np.array(list(dict.fromkeys(rows)), dtype=np.int64)


def history_names(ds) -> list[str]:
    """The archive's histories: its variables along ``(case, cam_angle)`` (and ``dof``)."""
    return [
        name
        for name, v in ds.data_vars.items()
        if v.dims[:2] == ("case", "cam_angle") and v.ndim <= 3
    ]


def history_table(ds, rows: np.ndarray, system: str = "spec") -> HistoryTable:
    """The histories of the archive's cases ``rows`` (an ``xarray.Dataset`` as stored) as a
    table in the units of ``system`` (``spec``, ``si``, ``in-lbf`` or ``mm-deg``)."""
    names = history_names(ds)
    if not names:
        raise ExportError.at("ARCHIVE", "the archive holds no histories along cam_angle")
    stored = {n: str(ds[n].attrs.get("units", "")) for n in ["cam_angle", *names]}
    dof_units = _dof_units(ds) if "q" in names else {}
    stored.update(dof_units)
    shown = display_units(stored, ds.attrs, system, keys={})
    at = degree_speed(shown.values())  # the cam's, or the engine's per degree of crank angle
    speed = np.asarray(ds[at].values, float)[rows] if at in ds else None
    angle = np.asarray(ds["cam_angle"].values, float)
    samples = angle.size
    ids = [str(c) for c in np.asarray(ds["case"].values)[rows]]
    columns: dict[str, np.ndarray] = {
        "case": np.repeat(np.array(ids, dtype=object), samples),
        "cam_angle": np.tile(angle, rows.size),
    }
    units = {"case": "", "cam_angle": shown["cam_angle"]}
    left_out: list[str] = []
    if "crank_angle" in ds.variables:  # a drive's: the crank angle beside the cam's
        columns["crank_angle"] = np.tile(np.asarray(ds["crank_angle"].values, float), rows.size)
        units["crank_angle"] = str(ds["crank_angle"].attrs.get("units", "degree"))
    for name in ["time", *(n for n in names if n != "time")] if "time" in names else names:
        values = np.asarray(ds[name].values)[rows]
        parts = (
            [(dof, values[:, :, j], dof_units[dof]) for j, dof in enumerate(dof_units)]
            if values.ndim == 3  # q: a column per coordinate
            else [(name, values, stored[name])]
        )
        for column, part, unit in parts:
            if part.dtype.kind == "f" and np.isnan(part).all():
                left_out.append(column)
                continue
            columns[column] = _shown(part, unit, shown[column], speed)
            units[column] = shown[column]
    units = {n: SHORT_UNITS.get(u, u) for n, u in units.items()}
    return HistoryTable(columns, units, str(ds.attrs.get("study_name", "")), ids, left_out)


def _shown(values: np.ndarray, stored: str, shown: str, speed: np.ndarray | None) -> np.ndarray:
    """(cases, samples) stored values as one column in the shown units, without the
    conversion's noise, and a zero without its sign (a contact force out of contact is
    stored as -0.0, which a table would write as ``-0.0``)."""
    if values.dtype.kind != "f":
        return values.reshape(-1)
    if stored != shown:
        values = without_noise(to_display(values, stored, shown, speed))
    return values.reshape(-1) + 0.0


def _dof_units(ds) -> dict[str, str]:
    """``q1`` … ``q7`` → their stored units (``dof_units``: m or rad)."""
    dofs = [str(d) for d in ds["dof"].values]
    if "dof_units" in ds.variables:
        return dict(zip(dofs, (str(u) for u in ds["dof_units"].values), strict=True))
    return dict.fromkeys(dofs, "")
