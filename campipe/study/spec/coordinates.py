"""Each case's coordinates as the archive stores them: its id (the coordinate ``case``) and the
values of the standard and varied keys (:func:`~campipe.study.spec.variables.case_coordinates`)
in archive units, from the resolved cases alone."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from campipe.study.spec.drive import engine_speed
from campipe.study.spec.expand import Study
from campipe.study.spec.fields import ENGINE_SPEED
from campipe.study.spec.resolve import ResolvedCase
from campipe.study.spec.variables import NO_SEAT, Variable, case_coordinates

#: The variable along ``case`` holding each case's id, in batch files and the archive: named
#: here only.
CASE_ID = "case"


def padded(values: np.ndarray, width: int) -> np.ndarray:
    """(n, m) lists (a list per case: masses, damping_ratios) as (n, width), width ≥ m: NaN
    beyond each list, as a column of lists of different lengths is stored."""
    out = np.full((values.shape[0], width), np.nan)
    out[:, : values.shape[1]] = values
    return out


def coordinate_values(cases: Sequence[ResolvedCase], study: Study) -> dict[str, np.ndarray]:
    """Per-case coordinate arrays in archive units, in study order: ``case`` (the ids), then
    each case coordinate (no seat as :data:`~campipe.study.spec.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {CASE_ID: np.array([c.case_id for c in cases], dtype=object)}
    return {**out, **key_columns(cases, case_coordinates(study.varied))}


def key_columns(
    cases: Sequence[ResolvedCase], coordinates: Mapping[str, tuple[str, Variable, float]]
) -> dict[str, np.ndarray]:
    """The case coordinates ``coordinates`` names (spec key → (name, variable, factor), as
    :func:`~campipe.study.spec.variables.case_coordinates` gives them), each an array in archive
    units over ``cases`` (no seat as :data:`~campipe.study.spec.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {}
    for key, (name, var, factor) in coordinates.items():
        if key == ENGINE_SPEED.key:  # a drive's: the cam's speed over its ratio
            raw: list = [engine_speed(c.values) for c in cases]
        else:
            raw = [c.values[key] for c in cases]
        if var.dtype == "str":
            out[name] = np.array([str(v) for v in raw], dtype=object)
        elif var.dtype.startswith("i"):
            out[name] = np.array(raw, dtype=var.dtype)
        elif "mode" in var.dims:
            # a list per case (damping_ratios), as long as the longest, NaN beyond a shorter
            lists = [np.asarray(v, dtype=float) for v in raw]
            values = np.full((len(lists), max(v.size for v in lists)), np.nan)
            for i, v in enumerate(lists):
                values[i, : v.size] = v
            out[name] = values * factor
        else:
            values = np.array(raw, dtype=float) * factor
            if key in ("speed", "engine_speed"):
                # rpm from rad/s: round away the conversion's last-digit noise (11000 rpm
                # stays 11000, so `--where "speed_rpm == 11000"` finds it)
                values = np.array([float(f"{v:.12g}") for v in values])
            if key == "seat":
                values = np.where(np.isnan(values), NO_SEAT, values)
            out[name] = values
    return out
