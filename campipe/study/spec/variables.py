"""The archive's variables, declared once: dimensions, type, units, long name, role.

Every netCDF attribute of an archive comes from here (:func:`layout`); the per-case
coordinates come from the spec's key table (:mod:`campipe.study.spec.fields`) and the member loads
from the engine's :data:`~campipe.engine.MEMBER_LOADS`. Units are pint spellings that UDUNITS
also reads; the archive is SI except ``speed_rpm`` [rpm] and angles [degree].

Dimensions: ``case`` (its coordinate ``case`` holds the case ids); ``cam_angle`` (0 …
360·revolutions at ``run.output_every``); ``revolution``; ``dof`` (q1–q7, when ``run.record``
holds ``q``; a refined member's internal coordinates are not stored); ``mode`` (for a varied
``damping_ratios``, as long as the longest list, NaN beyond
a shorter one); ``event`` (all cases' events, case by case: a CF contiguous ragged array counted
by ``event_count``, with ``event_case`` naming each event's case).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from campipe.engine import MEMBER_LOADS, SPRING_HISTORIES
from campipe.model import COORDINATES, PARAMETERS
from campipe.study.spec.fields import CASE_FIELDS, Field, varied_fields
from campipe.units import convert
from campipe.vocabulary import CONTACT_FLAGS, EVENT_FLAGS, STATUS_FLAGS


@dataclass(frozen=True)
class Variable:
    """One archive variable's declaration."""

    dims: tuple[str, ...]  # netCDF dimensions
    dtype: str  # numpy dtype ("f8", "i1", "i4", "i8") or "str"
    long_name: str  # CF long_name
    units: str | None = None  # CF units (pint spelling); None for words, flags and counts
    role: str = "history"  # "axis", "parameter", "history", "metric", "count", "status",
    #                        "event"
    record: str | None = None  # the run.record item that stores it (None: always stored)
    extra: tuple[tuple[str, object], ...] = ()  # further CF attributes

    def attrs(self) -> dict[str, object]:
        out: dict[str, object] = {"long_name": self.long_name}
        if self.units is not None:
            out["units"] = self.units
        out.update(dict(self.extra))
        return out


CASE = ("case",)
HISTORY = ("case", "cam_angle")
PER_REV = ("case", "revolution")

#: The metrics: (summary name, per-revolution name, dtype per revolution, long name, units,
#: how the summary reads the measured revolutions: "mean" per revolution or "max").
PER_REVOLUTION_METRICS = (
    (
        "separation_deg_per_rev",
        "separation_deg",
        "f8",
        "no-follow: cam angle in configuration II (follower off the cam, valve off its seat)",
        "degree",
        "mean",
    ),
    (
        "seated_off_cam_deg_per_rev",
        "seated_off_cam_deg",
        "f8",
        "cam angle in configuration IV (valve seated, follower off the cam: the lash)",
        "degree",
        "mean",
    ),
    ("cam_impacts", "cam_impacts_by_rev", "i4", "cam impacts", None, "mean"),
    ("seat_impacts", "seat_impacts_by_rev", "i4", "valve seat impacts", None, "mean"),
    (
        "max_cam_impact_velocity",
        "max_cam_impact_velocity_by_rev",
        "f8",
        "largest closing velocity at a cam impact",
        "m/s",
        "max",
    ),
    (
        "max_seating_velocity",
        "max_seating_velocity_by_rev",
        "f8",
        "largest closing velocity at a seat impact",
        "m/s",
        "max",
    ),
    (
        "max_cam_force",
        "max_cam_force_by_rev",
        "f8",
        "largest compressive cam force between impacts",
        "N",
        "max",
    ),
    (
        "max_seat_force",
        "max_seat_force_by_rev",
        "f8",
        "largest compressive seat force between impacts",
        "N",
        "max",
    ),
)


#: Metrics stored when ``run.record`` holds ``contact_pressure``: the peak Hertz pressure of
#: the largest contact force (``campipe.model.contact_laws``; NaN where the contact's geometry
#: does not give it), as PER_REVOLUTION_METRICS.
CONTACT_PRESSURE_METRICS = (
    (
        "max_cam_pressure",
        "max_cam_pressure_by_rev",
        "f8",
        "peak Hertz pressure at the cam contact",
        "Pa",
        "max",
    ),
    (
        "max_seat_pressure",
        "max_seat_pressure_by_rev",
        "f8",
        "peak Hertz pressure at the valve seat contact",
        "Pa",
        "max",
    ),
)
#: The spring's metrics, stored with ``run.record: [spring]`` (as PER_REVOLUTION_METRICS;
#: "min": the summary is the least over the measured revolutions). Read from the histories
#: at the output angles (``run.output_every``), which must resolve the spring's surge.
SPRING_METRICS = (
    (
        "max_spring_force",
        "max_spring_force_by_rev",
        "f8",
        "largest compressive force along the valve spring (any element) at the output angles",
        "N",
        "max",
    ),
    (
        "min_spring_clash_margin",
        "min_spring_clash_margin_by_rev",
        "f8",
        "least valve spring coil-clash margin at the output angles",
        "m",
        "min",
    ),
)
#: The record item that stores the spring's histories and metrics.
SPRING_RECORD = "spring"


def _metric_variables(
    summary, per_rev, dtype, long_name, units, how, record=None
) -> dict[str, Variable]:
    """A metric's two variables: per revolution, and its summary over the measured ones."""
    reads = {"mean": "per revolution, mean over", "max": "largest in", "min": "least in"}[how]
    return {
        summary: Variable(
            CASE,
            "f8",
            f"{long_name}, {reads} the measured revolutions",
            units,
            role="metric",
            record=record,
        ),
        per_rev: Variable(
            PER_REV,
            dtype,
            f"{long_name}, per revolution",
            units,
            role="per_revolution",
            record=record,
        ),
    }


#: Variables every archive holds (member loads and q only when run.record asks).
VARIABLES: dict[str, Variable] = {
    "cam_angle": Variable(
        ("cam_angle",), "f8", "cam angle from the start of the run", "degree", role="axis"
    ),
    "revolution": Variable(("revolution",), "i4", "cam revolution, counted from 1", role="axis"),
    "dof": Variable(
        ("dof",), "str", "generalised coordinate (thesis q1-q7)", role="axis", record="q"
    ),
    "dof_units": Variable(
        ("dof",), "str", "units of each generalised coordinate", role="axis", record="q"
    ),
    "case": Variable(
        CASE,
        "str",
        "case id: first 16 hex digits of the SHA-256 of the case's canonical parameters",
        role="axis",
    ),
    "time": Variable(HISTORY, "f8", "time from the start of the run", "s"),
    "cam_lift": Variable(HISTORY, "f8", "cam lift", "m"),
    "follower_lift": Variable(
        HISTORY, "f8", "pushrod foot height in the cam's lift coordinate", "m"
    ),
    "valve_lift": Variable(
        HISTORY, "f8", "valve opening from its base-circle static position", "m"
    ),
    "cam_force": Variable(
        HISTORY, "f8", "cam contact force, compressive positive, zero out of contact", "N"
    ),
    "seat_force": Variable(
        HISTORY, "f8", "valve seat contact force, compressive positive, zero out of contact", "N"
    ),
    "contact_state": Variable(
        HISTORY, "i1", "contact configuration (thesis Table I)", extra=CONTACT_FLAGS
    ),
    "q": Variable(
        ("case", "cam_angle", "dof"),
        "f8",
        "generalised coordinates q1-q7 (thesis order and signs)",
        record="q",
        extra=(
            (
                "comment",
                "q1, q2, q4, q7 are translations [m]; q3, q5, q6 are "
                "rotations [rad]; see dof_units",
            ),
        ),
    ),
    "valve_velocity": Variable(HISTORY, "f8", "valve opening velocity", "m/s"),
    "valve_acceleration": Variable(HISTORY, "f8", "valve opening acceleration", "m/s^2"),
    "measured": Variable(
        PER_REV,
        "i1",
        "revolution counted in the summary metrics (1), or a warm-up revolution (0)",
        role="per_revolution",
        extra=(("flag_values", [0, 1]), ("flag_meanings", "warm_up measured")),
    ),
    **{
        name: var
        for metric in PER_REVOLUTION_METRICS
        for name, var in _metric_variables(*metric).items()
    },
    **{
        name: var
        for metric in CONTACT_PRESSURE_METRICS
        for name, var in _metric_variables(*metric, record="contact_pressure").items()
    },
    "steps": Variable(CASE, "i8", "integration steps taken", role="count"),
    "status": Variable(
        CASE,
        "i1",
        "status of the case's run: ok; nonfinite and chatter failed (histories and metrics "
        "NaN); events_truncated kept only run.max_events events",
        role="status",
        extra=STATUS_FLAGS,
    ),
    "event_count": Variable(
        CASE,
        "i4",
        "number of events of each case",
        role="count",
        extra=(("sample_dimension", "event"),),
    ),
    "event_case": Variable(("event",), "i4", "index of the event's case along case", role="event"),
    "event_time": Variable(("event",), "f8", "time of the event", "s", role="event"),
    "event_cam_angle": Variable(("event",), "f8", "cam angle at the event", "degree", role="event"),
    "event_kind": Variable(("event",), "i1", "kind of event", role="event", extra=EVENT_FLAGS),
    "event_from": Variable(
        ("event",),
        "i1",
        "contact configuration before the event",
        role="event",
        extra=CONTACT_FLAGS,
    ),
    "event_to": Variable(
        ("event",), "i1", "contact configuration after the event", role="event", extra=CONTACT_FLAGS
    ),
    "event_velocity": Variable(
        ("event",), "f8", "velocity jump or closing velocity at the event", "m/s", role="event"
    ),
    "event_impulse": Variable(
        ("event",), "f8", "impulse delivered at an impact", "N*s", role="event"
    ),
    **{
        name: Variable(HISTORY, "f8", long_name, units.replace(" ", "*"), record=name)
        for name, (long_name, units) in MEMBER_LOADS.items()
    },
    **{
        name: Variable(HISTORY, "f8", long_name, units, record=name)
        for name, (long_name, units) in SPRING_HISTORIES.items()
    },
    **{
        name: var
        for metric in SPRING_METRICS
        for name, var in _metric_variables(*metric, record=SPRING_RECORD).items()
    },
}

#: Record items that store more than one variable (``spring``: its force on the rocker, its
#: histories and its metrics, which are recorded under the item's own name).
RECORD_GROUPS = {
    "member_loads": tuple(MEMBER_LOADS),
    SPRING_RECORD: ("spring_force", *SPRING_HISTORIES, SPRING_RECORD),
}
#: dof coordinate values and units.
DOF_NAMES = tuple(c.symbol for c in COORDINATES)
DOF_UNITS = tuple("m" if c.kind == "translation" else "rad" for c in COORDINATES)
#: Provenance attributes that legitimately differ between two runs of the same study (the
#: spec's path is relative to the archive's folder; the checksums cover all the others, so
#: they differ too).
VOLATILE_ATTRS = ("date_created", "host", "history", "spec_file", "campipe_checksums")


def recorded(record: Iterable[str]) -> set[str]:
    """Names of the optional variables ``run.record`` stores."""
    out: set[str] = set()
    for item in record:
        out.update(RECORD_GROUPS.get(item, (item,)))
    return out


def data_variables(record: Iterable[str]) -> dict[str, Variable]:
    """The variables a batch computes: all but the axes and per-case coordinates."""
    wanted = recorded(record)
    return {
        name: v
        for name, v in VARIABLES.items()
        if v.role not in ("axis", "parameter") and (v.record is None or v.record in wanted)
    }


def coordinate_field(key: str) -> Field:
    """The spec key behind a per-case coordinate."""
    return CASE_FIELDS.get(key) or varied_fields()[key]


#: The archive's ``seat`` of a case without a seat: the seat engages at valve lift ``seat``,
#: so no seat is a seat infinitely far below, never reached. A real value (unlike NaN, which
#: groupby, pivot tables and unstack drop), ordered below every seat; shown as ``none``.
NO_SEAT = -math.inf
#: How ``NO_SEAT`` is shown and written in ``--where``.
NONE_WORD = "none"

#: Standard per-case coordinates: spec key → archive variable.
STANDARD_COORDINATES: dict[str, tuple[str, Variable]] = {
    "speed": ("speed_rpm", Variable(CASE, "f8", "cam speed", "rpm", role="parameter")),
    "seat": (
        "seat",
        Variable(
            CASE,
            "f8",
            "valve seat position as a valve lift",
            "m",
            role="parameter",
            extra=(
                (
                    "comment",
                    "-inf: no seat (a seat infinitely below the valve, never reached); "
                    "campipe shows it as none",
                ),
            ),
        ),
    ),
    "profile": ("profile", Variable(CASE, "str", "cam profile", role="parameter")),
    "defects": ("defects", Variable(CASE, "str", "defects applied to the cam", role="parameter")),
    "closure": (
        "closure",
        Variable(CASE, "str", "closure: force (spring) or form (second cam)", role="parameter"),
    ),
    "run.integrator": ("integrator", Variable(CASE, "str", "integrator", role="parameter")),
    "run.dt": (
        "dt",
        Variable(
            CASE,
            "f8",
            "time step (largest step of an integrator that "
            "sizes its own; NaN: the integrator's choice)",
            "s",
            role="parameter",
        ),
    ),
}


def case_coordinates(varied: Iterable[str]) -> dict[str, tuple[str, Variable, float]]:
    """Per-case coordinates: spec key → (archive name, variable, factor from SI).

    The standard ones first, then one for each varied key, named by its field's
    ``archive_name`` (model parameters by their own name).
    """
    out: dict[str, tuple[str, Variable, float]] = {}
    for key, (name, var) in STANDARD_COORDINATES.items():
        field = coordinate_field(key) if key in CASE_FIELDS else None
        factor = 1.0
        if field is not None and var.units and field.units and var.units != field.units:
            factor = convert(1.0, field.units, var.units)
        out[key] = (name, var, factor)
    for key in varied:
        if key in out:
            continue
        f = coordinate_field(key)
        name = f.archive_name or key.replace(".", "_")
        p = PARAMETERS.get(key.removeprefix("model.")) if key.startswith("model.") else None
        if f.kind in ("choice", "text") or (p is not None and p.choices):
            var = Variable(CASE, "str", f.description, role="parameter")
            out[key] = (name, var, 1.0)
            continue
        if f.kind == "integer" or (p is not None and p.integer):
            out[key] = (name, Variable(CASE, "i8", f.description, role="parameter"), 1.0)
            continue
        units = f.archive_units if f.archive_units is not None else f.units
        dims: tuple[str, ...] = CASE
        if p is not None and p.length:
            dims = ("case", "mode")
        var = Variable(dims, "f8", f.description, units or "1", role="parameter")
        factor = convert(1.0, f.units, units) if f.units and units and units != f.units else 1.0
        out[key] = (name, var, factor)
    return out
