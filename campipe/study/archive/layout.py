"""What goes into the archive (and a batch file): sizes, variables, axes and per-case
coordinates, all built from the declarations in :mod:`campipe.study.spec.variables`. What names
a run's results (the keys, the attributes that record them) is
:mod:`campipe.study.run.keys`'s."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from campipe.io.archive import VariableSpec
from campipe.model.coordinates import coordinates, translations
from campipe.model.levers import LEVERS
from campipe.study.spec.coordinates import CASE_ID, coordinate_values, padded
from campipe.study.spec.drive import CRANK_ANGLE_NAME
from campipe.study.spec.expand import Study
from campipe.study.spec.resolve import distinct_but_speed
from campipe.study.spec.variables import (
    DOF_NAMES,
    DOF_UNITS,
    VARIABLES,
    Variable,
    case_coordinates,
    data_variables,
)

#: Version of the file layout: batch files and archives of another layout are not reused.
#: 2: per-case ``status``; checksums of every variable (``campipe_checksums``); the engine's
#: fingerprint (``campipe_numerics``); the spec's file (``spec_file``).
#: 3: the case ids are the coordinate ``case`` of the ``case`` dimension (was ``case_id``);
#: no seat is ``seat = -inf`` (was NaN).
LAYOUT_VERSION = "campipe-archive-3"


def record_text(record: Iterable[str]) -> str:
    return " ".join(record) or "-"


def variable_spec(name: str, var: Variable, coordinates: str | None = None) -> VariableSpec:
    attrs = var.attrs()
    if coordinates:
        attrs["coordinates"] = coordinates
    return VariableSpec(name, var.dims, var.dtype, attrs)


def axis_names(record: Iterable[str]) -> list[str]:
    names = ["cam_angle", "revolution"]
    if "q" in record:
        names += ["dof", "dof_units"]
    return names


def axis_arrays(cam_angle: np.ndarray, n_revolutions: int) -> dict[str, np.ndarray]:
    return {
        "cam_angle": cam_angle,
        "revolution": np.arange(1, n_revolutions + 1, dtype=np.int32),
        "dof": np.array(DOF_NAMES, dtype=object),
        "dof_units": np.array(DOF_UNITS, dtype=object),
    }


def data_specs(record: Iterable[str], case_coords: str) -> list[VariableSpec]:
    out = []
    for name, var in data_variables(record).items():
        coords = (
            case_coords
            if "case" in var.dims
            else ("event_case" if name != "event_case" and "event" in var.dims else None)
        )
        out.append(variable_spec(name, var, coords))
    return out


#: What a run of automatic length's angles count from: its histories hold each case's last
#: recorded revolutions only (``recorded_revolution``).
FROM_RECORDED = {
    "cam_angle": "cam angle from the start of the case's first recorded revolution "
    "(recorded_revolution)",
    "event_cam_angle": "cam angle at the event, from the start of the case's first recorded "
    "revolution (recorded_revolution)",
    "measured": "revolution counted in the summary metrics (1: in the settled window), or "
    "not (0: before it, or not run)",
}


def _from_recorded(spec: VariableSpec) -> VariableSpec:
    if spec.name not in FROM_RECORDED:
        return spec
    return dataclasses.replace(spec, attrs={**spec.attrs, "long_name": FROM_RECORDED[spec.name]})


#: Long names of a lever layout's histories (docs/model.md, Lever layouts): its cam lift and
#: follower are the valve side's, its cam force the roller's on the cam.
LEVER_NAMES = {
    "cam_lift": "kinematic valve lift: the cam's lift through the lever at each cam angle "
    "(a lever layout's valve side; the cam's own lift is campipe model's --cam-lift)",
    "follower_lift": "the lever's pallet height in the kinematic valve lift's coordinate "
    "(valve side)",
    "cam_force": "the roller's normal force on the cam, compressive positive, zero out of contact",
}
#: Long names of a lumped chain's (lumped, direct-acting): its first mass rides the cam.
CHAIN_NAMES = {
    "follower_lift": "the chain's first mass (the follower on the cam, q1) height in the "
    "cam's lift coordinate",
}
#: Long names of every chain's member loads (a lever layout's too, built as a chain): the
#: thesis train's names are its members', which a chain does not have.
CHAIN_LOADS = {
    "pushrod_force": "force through the chain's link next to the cam (between its first mass "
    "and the next), compressive positive",
    "stem_force": "force through the chain's link next to the valve (between the valve and "
    "the mass before it), compressive positive",
    "spring_force": "valve spring force on the valve, compressive positive",
    "rocker_moment": "rocker arm bending moment at the pivot: the thesis train's elastic "
    "rocker's; NaN in a chain (a lever layout's lever is rigid)",
}


def _chain_q(train) -> dict[str, str]:
    """``q``'s long name and comment for a chain's coordinates (``coordinates``)."""
    used = [c for c in coordinates(train) if c.name != "unused"]
    return {
        "long_name": "the chain's coordinates, q1 the mass on the cam and q7 the valve "
        "(places the chain does not use hold NaN)",
        "comment": "; ".join(f"{c.symbol} {c.name}, positive {c.positive}" for c in used)
        + ": translations [m]; see dof_units",
    }


def _named_for_layout(specs: list[VariableSpec], trains: list) -> list[VariableSpec]:
    """The histories' long names for ``trains`` (the study's, one per kind of case) where
    all are of one kind: a lever layout's valve side (:data:`LEVER_NAMES`), a chain's
    follower (:data:`CHAIN_NAMES`); a chain's member loads (:data:`CHAIN_LOADS`) and
    coordinates (:func:`_chain_q`, where all have the same). The thesis's train's and a mix
    of kinds keep the thesis's."""
    if all(t.layout in LEVERS for t in trains):
        names = dict(LEVER_NAMES)
    elif all(t.chain and t.layout not in LEVERS for t in trains):
        names = dict(CHAIN_NAMES)
    else:
        return specs
    names.update(CHAIN_LOADS)
    q = _chain_q(trains[0])
    same_q = all(_chain_q(t) == q for t in trains)
    out = []
    for s in specs:
        if s.name in names:
            s = dataclasses.replace(s, attrs={**s.attrs, "long_name": names[s.name]})
        elif s.name == "q" and same_q:
            s = dataclasses.replace(s, attrs={**s.attrs, **q})
        out.append(s)
    return out


def study_trains(study: Study) -> list:
    """The study's trains, one per combination of its axes but a speed sweep's."""
    return [c.case.train for c in distinct_but_speed(study.cases)[0]]


def chain_dof_units(trains: list) -> np.ndarray | None:
    """``dof_units`` for ``trains`` (the study's, one per kind of case) where all are chains:
    every coordinate a translation [m] (None for the thesis's train or a mix: its units)."""
    if not all(t.chain for t in trains):
        return None
    return np.array(
        ["m" if t else "rad" for t in translations(trains[0])][: len(DOF_NAMES)], dtype=object
    )


def archive_layout(
    study: Study,
    n_events: int | None,
    cam_angle: np.ndarray,
    n_revolutions: int,
    trains: list | None = None,
):
    """(sizes, variables, static arrays) of the study's archive; the static arrays are the
    axes and the per-case coordinates, the rest streams in from batch files. ``n_events``
    None makes ``event`` unlimited: the events are appended as the cases are written.
    ``trains``: the study's (``study_trains``) where ``study`` holds only some of its cases."""
    coords = case_coordinates(study.varied)
    coord_names = [name for name, _, _ in coords.values()]
    sizes: dict[str, int | None] = {
        "case": len(study.cases),
        "cam_angle": cam_angle.size,
        "revolution": n_revolutions,
        "event": n_events,
    }
    if "q" in study.record:
        sizes["dof"] = len(DOF_NAMES)
    specs = [variable_spec(n, VARIABLES[n]) for n in axis_names(study.record)]
    specs.append(variable_spec(CASE_ID, VARIABLES[CASE_ID]))
    values = coordinate_values(study.cases, study)
    lists = [name for name, var, _ in coords.values() if "mode" in var.dims]
    if lists:  # one width for every list (masses, stiffnesses, damping_ratios): the longest
        sizes["mode"] = width = max(values[name].shape[1] for name in lists)
        values.update({name: padded(values[name], width) for name in lists})
    for _key, (name, var, _) in coords.items():
        specs.append(variable_spec(name, var))
    specs += data_specs(study.record, " ".join(coord_names))
    if study.settle:
        specs = [_from_recorded(s) for s in specs]
    trains = trains or study_trains(study)
    specs = _named_for_layout(specs, trains)
    static = {**axis_arrays(cam_angle, n_revolutions), **values}
    dof_units = chain_dof_units(trains)
    if dof_units is not None:
        static["dof_units"] = dof_units
    if study.spec.drive is not None:  # the crank angle beside the cam's
        specs = _with_crank_angle(specs, study.spec.drive, study.settle)
        static[CRANK_ANGLE_NAME] = np.asarray(cam_angle, float) / study.spec.drive
    static = {s.name: static[s.name] for s in specs if s.name in static}
    return sizes, specs, static


def _with_crank_angle(specs: list[VariableSpec], ratio: float, settle: bool) -> list[VariableSpec]:
    """The archive's variables with the coordinate ``crank_angle`` along ``cam_angle`` (the
    cam angle over the drive's ``ratio``), named in the ``coordinates`` of each variable along
    ``cam_angle``."""
    since = "the case's first recorded revolution" if settle else "the start of the run"
    crank = VariableSpec(
        CRANK_ANGLE_NAME,
        ("cam_angle",),
        "f8",
        {
            "long_name": f"crank angle from {since}: cam_angle / drive.cam_per_crank",
            "units": "degree",
            "cam_per_crank": float(ratio),
        },
    )
    out = []
    for spec in specs:
        if "cam_angle" in spec.dims and spec.name != "cam_angle":
            names = str(spec.attrs.get("coordinates", "")).split()
            attrs = {**spec.attrs, "coordinates": " ".join([*names, CRANK_ANGLE_NAME])}
            spec = dataclasses.replace(spec, attrs=attrs)
        out.append(spec)
        if spec.name == "cam_angle":
            out.append(crank)
    return out
