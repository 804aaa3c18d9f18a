"""The kinematic valve lift a histories figure overlays on the dynamic one: the lift a rigid
train would give, the cam's lift times the rocker's geometric ratio
(:func:`campipe.model.lash_ratio`; 1 for a chain of masses, whose cam lift is its valve
side's, a lever layout's kinematic valve lift), never below the seat (the valve rests there).

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

log = logging.getLogger(__name__)


def rocker_ratios(attrs: Mapping[str, object], columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """(n,) each case's rocker ratio (valve-end travel per unit of follower travel) [-], NaN
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
    out = np.full(n, np.nan)
    for i in range(n):
        values = tuple((name, float(columns[name][i])) for name in scalars)
        out[i] = _ratio(preset, tuple(sorted(_spelled(model).items())), values)
    return out


def _spelled(model: Mapping[str, object]) -> dict[str, str]:
    """The spec's model values as hashable text (lists as their YAML text)."""
    return {str(k): repr(v) if isinstance(v, list | dict) else str(v) for k, v in model.items()}


@functools.lru_cache(maxsize=256)
def _ratio(preset: str, model: tuple, values: tuple) -> float:
    """The rocker ratio of the train ``preset`` + ``model`` (spec text) + ``values`` (SI)."""
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
        return 1.0 if train.chain else float(lash_ratio(system_matrices(train)))
    except (CampipeError, ValueError, ArithmeticError) as exc:
        log.info("no kinematic lift: the case's train cannot be built (%s)", exc)
        return float("nan")


def kinematic_lift(cam_lift: np.ndarray, ratios: np.ndarray, seats: np.ndarray) -> np.ndarray:
    """(n, samples) the valve lift of a rigid train: ``ratios`` × ``cam_lift``, at least each
    case's seat (``-inf``: none); all in one length unit."""
    lift = np.asarray(cam_lift, float) * np.asarray(ratios, float)[:, None]
    return np.maximum(lift, np.asarray(seats, float)[:, None])
