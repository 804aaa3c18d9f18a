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
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from campipe.engine import MEMBER_LOADS, SPRING_HISTORIES
from campipe.engine.metrics import READS, Metric, archived_metrics
from campipe.model import COORDINATES, PARAMETERS
from campipe.study.spec.fields import CASE_FIELDS, Field, varied_fields
from campipe.units import convert
from campipe.vocabulary import CONTACT_FLAGS, EVENT_FLAGS, STATUS_FLAGS

#: The recorded history of the cam's normal force (``run.record``).
CAM_NORMAL_FORCE = "cam_normal_force"


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
    also: str | None = None  # a second run.record item it needs beside ``record`` (None: none)
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

#: The record item that stores the spring's histories and metrics.
SPRING_RECORD = "spring"
#: The record item of a run of automatic length (``run.revolutions: auto``): how each case
#: settled. Not a spec's to name: the study adds it.
SETTLING_RECORD = "settling"


def metric_variables(metric: Metric) -> dict[str, Variable]:
    """A metric's variables (``campipe.engine.metrics``): per revolution, its summary over the
    measured ones and, for a mean in a run of automatic length, that mean's uncertainty."""
    reads = READS[metric.summary_of_turns]
    out = {
        metric.summary: Variable(
            CASE,
            "f8",
            f"{metric.description}, {reads} the measured revolutions",
            metric.units,
            role="metric",
            record=metric.record,
        ),
        metric.per_rev: Variable(
            PER_REV,
            metric.dtype,
            f"{metric.description}, per revolution",
            metric.units,
            role="per_revolution",
            record=metric.record,
        ),
    }
    if metric.uncertainty is not None:
        out[metric.uncertainty] = uncertainty_variable(metric)
    return out


def uncertainty_variable(metric: Metric) -> Variable:
    """A mean metric's uncertainty (``<summary>_uncertainty``): the standard error of its
    window mean by batch means (:func:`campipe.engine.metrics.batch_means_error`) for a case
    whose response never repeats, NaN for one that settled. Stored by a run of automatic
    length only (as ``period_turns`` is)."""
    return Variable(
        CASE,
        "f8",
        f"{metric.description}: standard error of the window mean by batch means of "
        f"{metric.summary} (NaN where the response repeats: its mean is exact to "
        "run.settle_tolerance)",
        metric.units,
        role="uncertainty",
        record=SETTLING_RECORD,
        also=metric.record,
    )


#: Variables every archive holds (member loads and q only when run.record asks), but the
#: metrics' (``VARIABLES`` has them all).
_BEFORE_METRICS: dict[str, Variable] = {
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
        HISTORY,
        "f8",
        "valve opening from its base-circle static position, or from its seat in a train with lash",
        "m",
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
}
_AFTER_METRICS: dict[str, Variable] = {
    "steps": Variable(CASE, "i8", "integration steps taken", role="count"),
    "period_turns": Variable(
        CASE,
        "i4",
        "turns after which the settled response repeats (1: every turn); 0: it did not repeat "
        "within run.max_revolutions, and its metrics are statistics over its window",
        role="count",
        record=SETTLING_RECORD,
    ),
    "settled_revolution": Variable(
        CASE,
        "i4",
        "first revolution (from 1) of the window the summary metrics are taken over: whole "
        "periods of the settled response, or the run's second half if it did not repeat",
        role="count",
        record=SETTLING_RECORD,
    ),
    "revolutions_run": Variable(
        CASE, "i4", "revolutions integrated", role="count", record=SETTLING_RECORD
    ),
    "recorded_revolution": Variable(
        CASE,
        "i4",
        "first revolution (from 1) of the stored histories and events (the run's last "
        "run.history_turns)",
        role="count",
        record=SETTLING_RECORD,
    ),
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
    CAM_NORMAL_FORCE: Variable(
        HISTORY,
        "f8",
        "roller's normal force on the cam: the cam force (a lever layout's the valve side's "
        "force at the pallet times its lever ratio, as cam_force is)",
        "N",
        record=CAM_NORMAL_FORCE,
    ),
}


class _Variables(Mapping[str, Variable]):
    """Every archive variable by name: the fixed ones and, after ``measured``, two per
    archived metric of the metrics table as it is when read (a metric registered at run time
    included)."""

    def __init__(self) -> None:
        self._rows: tuple[int, ...] = ()
        self._table: dict[str, Variable] = {}

    def _all(self) -> dict[str, Variable]:
        rows = archived_metrics()
        if tuple(map(id, rows)) != self._rows:
            metric_vars = {n: v for m in rows for n, v in metric_variables(m).items()}
            self._table = {**_BEFORE_METRICS, **metric_vars, **_AFTER_METRICS}
            self._rows = tuple(map(id, rows))
        return self._table

    def __getitem__(self, name: str) -> Variable:
        return self._all()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


VARIABLES: Mapping[str, Variable] = _Variables()

#: Record items that store more than one variable (``member_loads``: the histories and the
#: least force through the joints that only push; ``spring``: its force on the rocker, its
#: histories and its metrics; the metrics are recorded under the item's own name).
RECORD_GROUPS = {
    "member_loads": (*MEMBER_LOADS, "member_loads"),
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
        if v.role not in ("axis", "parameter")
        and (v.record is None or v.record in wanted)
        and (v.also is None or v.also in wanted)
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
