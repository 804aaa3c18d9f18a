"""The cases a replay shows: selected from an archive or a running study's batch, with the
coordinates q they need for the sketch.

A :class:`ReplayCase` holds one case's histories and events exactly as the archive stores
them (SI, angles in degrees), its per-case columns (what ``campipe query`` prints) and its
valve train. Both ways in give the same case:

- from an archive (:func:`archive_cases`): rows chosen by case id or by a ``--where``
  expression (:func:`select_rows`, the study layer's safe parser);
- from a batch as a study runs (:func:`batch_cases`): its rows that the spec's ``replay:``
  selection matches.

An archive that did not record ``q`` (``run.record: [q]``) still replays: the archive keeps
the spec's text and ``--set`` overrides, so :func:`rebuild_cases` expands the spec again and
finds each case by its id (the SHA-256 of its canonical parameters: a rebuilt case with the
same id has the same inputs), and :func:`regain_q` runs those cases through the engine again.
The engine is deterministic, so the rerun reproduces the archive's histories; a difference
(another campipe version) is reported, and the plots keep the archive's values.
"""

from __future__ import annotations

import json
import logging
import math
import shlex
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from campipe.engine import RunSettings, run_batch
from campipe.errors import CampipeError, did_you_mean
from campipe.io.spec_yaml import SpecFileError, parse_spec_text
from campipe.model import PARAMETERS, ModelParameterError, ValveTrain, valve_train
from campipe.model.parameters import Parameter
from campipe.study.query.tables import case_table, replay_mask, select
from campipe.study.run.results import BatchData, BatchPlan
from campipe.study.spec.check import SpecError, check_spec
from campipe.study.spec.coordinates import coordinate_values
from campipe.study.spec.expand import Study, expand
from campipe.study.spec.resolve import ResolvedCase
from campipe.study.spec.variables import VARIABLES, case_coordinates, data_variables
from campipe.vocabulary import N_COORDINATES

log = logging.getLogger(__name__)

#: Histories along cam_angle a replay shows (archive names).
HISTORIES = (
    "time",
    "cam_lift",
    "follower_lift",
    "valve_lift",
    "cam_force",
    "seat_force",
    "contact_state",
)
#: Event variables a replay shows (archive names).
EVENT_FIELDS = (
    "event_time",
    "event_cam_angle",
    "event_kind",
    "event_from",
    "event_to",
    "event_velocity",
    "event_impulse",
)
#: Largest difference [m] between a rerun's valve lift and the archive's still called equal.
RERUN_TOLERANCE = 1e-12


class ReplayError(CampipeError, ValueError):
    """A replay that cannot be made: no such case, an empty selection (``key`` the option,
    ``--case`` or ``--where``), no way to get q."""


@dataclass
class ReplayCase:
    """One case to replay: the archive's values (SI, angles in degrees), q and its train."""

    case_id: str  # the case's id
    study: str  # the study's name
    cam_angle: np.ndarray  # (n,) sample angles [degree]
    histories: dict[str, np.ndarray]  # HISTORIES → (n,) archive values (time [s], lifts [m], ...)
    q: np.ndarray | None  # (n, 7) coordinates [m, rad]; None until computed again
    events: dict[str, np.ndarray]  # EVENT_FIELDS → (n_events,) archive values
    columns: dict[str, tuple[Any, str]]  # per-case column → (value, units) as in the archive
    train: ValveTrain  # the case's valve train [SI]

    @property
    def seat(self) -> float:
        """Seat position as a valve lift [m]; NaN: no seat (the engine's and the sketch's
        word for it: the archive's is -inf)."""
        value = float(self.columns.get("seat", (math.nan, "m"))[0])
        return value if math.isfinite(value) else math.nan

    @property
    def valve_reference(self) -> float:
        """q7 of the valve at zero valve lift (cam on its base circle, no seat) [m]."""
        if self.q is None:
            raise ReplayError(f"case {self.case_id}: no q, so no valve reference")
        return float(np.median(self.q[:, 6] - self.histories["valve_lift"]))

    @property
    def seat_q7(self) -> float:
        """q7 of the valve on its seat [m]; NaN: no seat."""
        return self.valve_reference + self.seat if not math.isnan(self.seat) else math.nan

    @property
    def label(self) -> str:
        """A short name: speed, seat and the case id's first digits."""
        parts = []
        speed = self.columns.get("speed_rpm")
        if speed is not None:
            parts.append(f"{float(speed[0]):.6g} rpm")
        parts.append("no seat" if math.isnan(self.seat) else f"seat {self.seat * 1e3:.4g} mm")
        return f"{', '.join(parts)} ({self.case_id[:8]})"


# -- selection ---------------------------------------------------------------------------------


def select_rows(ds, case_ids: Sequence[str] = (), where: str | None = None) -> np.ndarray:
    """Rows of an archive (an ``xarray.Dataset``) by case id, or where an expression holds.

    Parameters
    ----------
    ds : xarray.Dataset
        An archive.
    case_ids : sequence of str
        Case ids, in the order to show them.
    where : str, optional
        A ``--where`` expression (:mod:`campipe.study.where`; never evaluated as Python).

    Raises
    ------
    ReplayError
        For an unknown case id, or an expression that selects no case.
    campipe.study.where.QueryError
        For an expression the query language refuses.
    """
    if "case" not in ds.variables:
        layout = ds.attrs.get("campipe_layout")
        raise ReplayError(
            f"an archive of another layout ({layout}): rerun its study with --overwrite"
            if layout
            else "not a campipe archive (no case coordinate)"
        )
    table = case_table(ds)
    ids = [str(i) for i in table.columns["case"]]
    if case_ids:
        picked = []
        for cid in case_ids:
            if cid not in ids:
                raise ReplayError(
                    f"--case {cid}: no such case among the archive's {len(ids)} "
                    f"cases{did_you_mean(cid, ids)} (campipe query ARCHIVE "
                    "--columns case lists them)",
                    key="--case",
                    found=cid,
                    expected="a case id of the archive",
                )
            picked.append(ids.index(cid))
        return np.array(list(dict.fromkeys(picked)), dtype=np.int64)
    rows = select(table, where)
    if rows.size == 0:
        raise ReplayError(
            f"--where {where!r} selects none of the archive's {len(ids)} cases; nothing written",
            key="--where",
            found=where,
        )
    return rows


def _cell(value: object) -> object:
    if isinstance(value, np.ndarray):
        return tuple(_cell(v) for v in value)
    if isinstance(value, np.generic):
        return value.item()
    return value


# -- from an archive ---------------------------------------------------------------------------


def archive_cases(
    ds,
    rows: Iterable[int],
    *,
    resolved: Mapping[str, ResolvedCase] | None = None,
    directories: Sequence[Path] = (),
) -> list[ReplayCase]:
    """The archive's rows as replay cases.

    Parameters
    ----------
    ds : xarray.Dataset
        An archive.
    rows : iterable of int
        Rows along ``case``, in the order to show them.
    resolved : mapping, optional
        Case id → :class:`~campipe.study.ResolvedCase`, for a caller that has the study
        (otherwise the cases are rebuilt from the archive's spec when needed).
    directories : sequence of Path
        Where to look for files the spec names (lift tables), first match wins.

    Raises
    ------
    ReplayError
        If the archive lacks ``q`` and its cases cannot be rebuilt to compute it again.
    """
    rows = [int(r) for r in rows]
    table = case_table(ds)
    ids = [str(table.columns["case"][r]) for r in rows]
    cam_angle = np.asarray(ds["cam_angle"].values, dtype=float)
    counts = np.asarray(ds["event_count"].values, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    has_q = "q" in ds.variables
    if resolved is None:
        try:
            resolved = rebuild_cases(ds.attrs, directories)
        except ReplayError as exc:
            if not has_q:
                raise ReplayError(
                    f"{exc}; the archive holds no q (run.record: [q]) to draw "
                    "the mechanism from, so its cases must be rebuilt: keep the "
                    "files the spec names beside the archive, or add run.record:"
                    " [q] to the spec and run the study again"
                ) from None
            log.warning(
                "%s; the sketch takes the train from the spec's model and the case's columns", exc
            )
            resolved = {}
    missing = [cid for cid in ids if cid not in resolved]
    if missing and not has_q:
        raise ReplayError(
            f"cases {', '.join(missing[:3])} are not among the cases the "
            "archive's spec expands to (was it written by another campipe "
            "version?); add run.record: [q] to the spec and run the study again"
        )
    out = []
    for r, cid in zip(rows, ids, strict=True):
        columns = {
            name: (_cell(table.columns[name][r]), table.units[name]) for name in table.columns
        }
        histories = {name: np.asarray(ds[name][r].values) for name in HISTORIES}
        span = slice(int(starts[r]), int(starts[r + 1]))
        events = {name: np.asarray(ds[name][span].values) for name in EVENT_FIELDS}
        rc = resolved.get(cid)
        train = rc.case.train if rc is not None else _train_from_columns(ds.attrs, columns)
        q = np.asarray(ds["q"][r].values, dtype=float) if has_q else None
        out.append(
            ReplayCase(
                cid,
                str(ds.attrs.get("study_name", "")),
                cam_angle,
                histories,
                q,
                events,
                columns,
                train,
            )
        )
    if not has_q:
        fill_q(out, [resolved[c.case_id] for c in out])
    return out


def rebuild_cases(
    attrs: Mapping[str, object], directories: Sequence[Path] = ()
) -> dict[str, ResolvedCase]:
    """Case id → :class:`~campipe.study.ResolvedCase`: the archive's spec (``spec``,
    ``spec_overrides``) expanded again.

    Files the spec names (lift tables) are looked for in ``directories`` and beside the
    spec the archive's ``history`` ran, first match wins.

    Raises
    ------
    ReplayError
        If the spec is missing or does not expand.
    """
    text = attrs.get("spec")
    if not isinstance(text, str) or not text:
        raise ReplayError("the archive keeps no spec to rebuild its cases from")
    try:
        overrides = json.loads(str(attrs.get("spec_overrides") or "{}"))
        raw = parse_spec_text(text, "the archive's spec")
    except (json.JSONDecodeError, SpecFileError) as exc:
        raise ReplayError(f"cannot read the archive's spec ({exc})") from None
    problem = "no directory to look in"
    for directory in [*directories, *_history_directories(attrs)]:
        try:
            spec = check_spec(raw, text, directory, "the archive's spec", overrides)
            return {c.case_id: c for c in expand(spec, "the archive's spec").cases}
        except SpecError as exc:
            problem = str(exc).replace("\n", " ")
    raise ReplayError(f"cannot rebuild the cases from the archive's spec ({problem})")


def _history_directories(attrs: Mapping[str, object]) -> list[Path]:
    """The spec's folder as the ``history`` command line named it (``campipe study SPEC``)."""
    command = str(attrs.get("history", "")).split(" ", 1)[-1]
    try:
        words = shlex.split(command)
    except ValueError:
        return []
    if len(words) >= 3 and words[:2] == ["campipe", "study"]:
        return [Path(words[2]).parent]
    return []


def _train_from_columns(
    attrs: Mapping[str, object], columns: Mapping[str, tuple[Any, str]]
) -> ValveTrain:
    """The valve train from the spec's ``model`` and the case's model-parameter columns:
    the sketch's lengths when the cases cannot be rebuilt (q was recorded)."""
    try:
        raw = parse_spec_text(str(attrs.get("spec", "")), "the archive's spec")
    except SpecFileError:
        raw = {}
    model = dict(raw.get("model") or {}) if isinstance(raw, Mapping) else {}
    preset = str(model.pop("preset", "thesis-1971"))
    for name, p in PARAMETERS.items():
        if name in columns:
            value, units = columns[name]
            model[name] = _column_value(p, value, units)
    try:
        return valve_train(preset, model)
    except ModelParameterError as exc:
        raise ReplayError(f"cannot build the case's valve train ({exc})") from None


def _column_value(p: Parameter, value: Any, units: str) -> object:
    """A model parameter's archive column value as a spec value."""
    if p.length:
        return [float(v) for v in value if v == v]  # NaN pads a shorter case's list
    if p.integer:
        return int(value)
    if p.choices:
        return str(value)
    if not p.units:
        return float(value)
    return f"{float(value)!r} {units}".strip()


def regain_q(resolved: Sequence[ResolvedCase]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Run resolved cases through the engine again (one batch per run-settings group):
    each case's (q1 … q7 [m, rad], valve lift [m]) at the output angles (a refined member's
    internal coordinates are not drawn)."""
    groups: dict[RunSettings, list[int]] = {}
    for i, rc in enumerate(resolved):
        groups.setdefault(rc.settings, []).append(i)
    out: list = [None] * len(resolved)
    for settings, idx in groups.items():
        result = run_batch([resolved[i].case for i in idx], settings)
        for k, i in enumerate(idx):
            out[i] = (result.q[k, :, :N_COORDINATES], result.valve_lift[k])
    return out


def fill_q(cases: Sequence[ReplayCase], resolved: Sequence[ResolvedCase]) -> None:
    """Give cases without q the q of an engine rerun; warn where the rerun's valve lift
    differs from the case's."""
    log.info("q not recorded: running %d case(s) through the engine again", len(cases))
    for case, (q, valve_lift) in zip(cases, regain_q(resolved), strict=True):
        diff = float(np.max(np.abs(valve_lift - case.histories["valve_lift"]), initial=0.0))
        if diff > RERUN_TOLERANCE:
            log.warning(
                "case %s: the engine's rerun differs from the archive by up to %.3g m "
                "of valve lift (another campipe version?); the sketch follows the "
                "rerun, the plots the archive",
                case.case_id,
                diff,
            )
        case.q = q


# -- from a running study ----------------------------------------------------------------------


def batch_columns(
    study: Study, plan: BatchPlan, data: BatchData
) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """A batch's per-case columns and their units, as the archive will hold them."""
    columns = coordinate_values(list(plan.cases), study)
    units = {"case": ""}
    for name, var, _ in case_coordinates(study.varied).values():
        units[name] = var.units or ""
    for name, var in data_variables(study.record).items():
        if var.dims == ("case",):
            columns[name] = np.asarray(data.arrays[name])
            units[name] = VARIABLES[name].units or ""
    return columns, units


def batch_cases(study: Study, plan: BatchPlan, data: BatchData) -> list[ReplayCase]:
    """The cases of a computed batch that the spec's ``replay: {where: ...}`` selects
    (:func:`campipe.study.query.tables.replay_mask`), as replay cases (q computed again for a study
    that does not record it).

    Parameters
    ----------
    study : campipe.study.Study
    plan : campipe.study.run.results.BatchPlan
    data : campipe.study.run.results.BatchData
        The batch's archive arrays, as stored.
    """
    rows = np.flatnonzero(replay_mask(study, plan, data))
    if rows.size == 0:
        return []
    columns, units = batch_columns(study, plan, data)
    arrays = data.arrays
    counts = np.asarray(arrays["event_count"], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    out = []
    for r in rows:
        span = slice(int(starts[r]), int(starts[r + 1]))
        out.append(
            ReplayCase(
                case_id=str(data.case_ids[r]),
                study=study.name,
                cam_angle=np.asarray(data.cam_angle, dtype=float),
                histories={name: np.asarray(arrays[name][r]) for name in HISTORIES},
                q=np.asarray(arrays["q"][r], dtype=float) if "q" in arrays else None,
                events={name: np.asarray(arrays[name][span]) for name in EVENT_FIELDS},
                columns={name: (_cell(columns[name][r]), units[name]) for name in columns},
                train=plan.cases[r].case.train,
            )
        )
    if "q" not in arrays:
        fill_q(out, [plan.cases[r] for r in rows])
    return out
