"""The kinematic valve lift a histories figure overlays on the dynamic one: the lift a rigid
train would give, the cam's lift times the rocker's geometric ratio
(:func:`campipe.model.lash_ratio`; 1 for a chain of masses, whose cam lift is its valve
side's, a lever layout's kinematic valve lift) less the lash at the valve (a rigid train
opens its valve once the cam has taken the lash up), never below the seat (the valve rests
there). With a hydraulic lash adjuster the lash is what its plunger leaves: a finger's cam
lift is already its raised pivot's (the dry lash is taken off), a chain's takes each turn's
extension (``hla_extension_by_rev``; without it recorded, no overlay: the lash is not known).

Each case's train is the archive's spec's ``model`` with the case's own model-parameter
columns; a case whose train cannot be built (a spec campipe cannot read again) has no
overlay, and the figure says nothing of it.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping

import numpy as np

from campipe.errors import CampipeError
from campipe.io.spec_yaml import SpecFileError, parse_spec_text
from campipe.model import PARAMETERS, lash_ratio, system_matrices, valve_train
from campipe.model.hla import adjuster, on_pivot
from campipe.model.seated import measured_side

log = logging.getLogger(__name__)


def rocker_ratios(
    attrs: Mapping[str, object], columns: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n,) each case's rocker ratio (valve-end travel per unit of follower travel) [-], its
    dry lash at the valve [m] and whether a lash adjuster lengthens its chain's link (its
    extension then takes lash up: :mod:`the module <campipe.plot.kinematics>`), NaN (False)
    where its train cannot be built; ``columns`` are the cases' per-case columns as stored."""
    try:
        raw = parse_spec_text(str(attrs.get("spec", "")), "the archive's spec")
    except SpecFileError:
        raw = {}
    model = raw.get("model") if isinstance(raw, Mapping) else None
    model = dict(model) if isinstance(model, Mapping) else {}
    preset = str(model.pop("preset", "thesis-1971"))
    scalars = [
        name
        for name, p in PARAMETERS.items()
        if name in columns and not (p.length or p.integer or p.choices)
    ]
    n = len(next(iter(columns.values()))) if columns else 0
    out = np.full((3, n), np.nan)
    for i in range(n):
        values = tuple((name, float(columns[name][i])) for name in scalars)
        out[:, i] = _ratio(preset, tuple(sorted(_spelled(model).items())), values)
    return out[0], out[1], out[2] == 1.0


def _spelled(model: Mapping[str, object]) -> dict[str, str]:
    """The spec's model values as hashable text (lists as their YAML text)."""
    return {str(k): repr(v) if isinstance(v, list | dict) else str(v) for k, v in model.items()}


@functools.lru_cache(maxsize=256)
def _ratio(preset: str, model: tuple, values: tuple) -> tuple[float, float, float]:
    """(the rocker ratio, the dry lash at the valve [m], 1 where a lash adjuster lengthens the
    chain's link else 0) of the train ``preset`` + ``model`` (spec text) + ``values`` (SI)."""
    import ast

    overrides: dict[str, object] = {}
    for name, text in model:
        try:
            overrides[name] = ast.literal_eval(text) if text[:1] in "[{" else text
        except (ValueError, SyntaxError):
            overrides[name] = text
    for name, value in values:
        units = PARAMETERS[name].units
        overrides[name] = f"{value!r} {units}".strip() if units else value
    try:
        train = valve_train(preset, overrides)
        # a chain's cam lift is its valve side's (a lever layout's kinematic valve lift)
        ratio = 1.0 if train.chain else float(lash_ratio(system_matrices(train)))
        at_valve = ratio if measured_side(train) == "cam" and not train.chain else 1.0
        in_link = adjuster(train) is not None and not on_pivot(train)
        lash = float(train.lash) if train.lash > 0.0 else 0.0  # NaN: none given
        return ratio, lash * at_valve, float(in_link)
    except (CampipeError, ValueError, ArithmeticError) as exc:
        log.info("no kinematic lift: the case's train cannot be built (%s)", exc)
        return float("nan"), float("nan"), 0.0


def kinematic_lift(
    cam_lift: np.ndarray, ratios: np.ndarray, seats: np.ndarray, lashes: np.ndarray | None = None
) -> np.ndarray:
    """(n, samples) the valve lift of a rigid train: ``ratios`` × ``cam_lift`` less each
    case's lash at the valve (``lashes``: (n,), or (n, samples) where a lash adjuster moves
    it; none: 0), at least each case's seat (``-inf``: none); all in one length unit."""
    lift = np.asarray(cam_lift, float) * np.asarray(ratios, float)[:, None]
    if lashes is not None:
        lash = np.asarray(lashes, float)
        lift = lift - (lash[:, None] if lash.ndim == 1 else lash)
    return np.maximum(lift, np.asarray(seats, float)[:, None])


def turn_extensions(ds, rows: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(len(rows), kept samples) each case's lash adjuster's extension [m] in the turn of each
    of the archive ``ds``'s kept samples (its ``hla_extension_by_rev``: at the turn's start;
    a run of automatic length's histories from its ``recorded_revolution``), NaN where it was
    not recorded."""
    out = np.full((len(rows), int(np.sum(keep))), np.nan)
    if "hla_extension_by_rev" not in ds.variables:
        return out
    by_rev = np.asarray(ds["hla_extension_by_rev"].values[rows], float)
    angle = np.asarray(ds["cam_angle"].values, float)[keep]
    turn = np.floor(angle / 360.0 + 1e-9).astype(np.int64)
    first = np.zeros(len(rows), np.int64)
    if "recorded_revolution" in ds.variables:
        first = np.asarray(ds["recorded_revolution"].values[rows], np.int64)
    at = np.clip(first[:, None] + turn[None, :], 0, by_rev.shape[1] - 1)
    return np.take_along_axis(by_rev, at, axis=1)
