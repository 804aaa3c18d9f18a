"""rerun recordings of valve-train cases: the file format of ``campipe replay`` and a study's
``replay:``.

This module writes what it is given: each case as plain arrays and text
(:class:`CaseRecording`, built by :mod:`campipe.replay.record` from an archive's or a batch's
case). It selects nothing and computes nothing; rerun itself is imported where it is used,
so importing this module stays light.

One recording holds every selected case, each in its own entity subtree; a blueprint shows
each case on its own tab, the mechanism sketch beside the plots::

    cases/<case_id>/lift/{cam,follower,valve}   Scalars, lift [mm]
    cases/<case_id>/force/{cam,seat}            Scalars, contact force [N]
    cases/<case_id>/contact_state               Scalars, configuration 1–4 (thesis Table I)
    cases/<case_id>/events                      TextLog: separations and impacts
    cases/<case_id>/parameters                  TextDocument (markdown, static)
    cases/<case_id>/sketch/...                  LineStrips2D / Points2D [mm], moving
    cases/<case_id>/sketch/frame/...            LineStrips2D / Boxes2D [mm], static (ground)

Timelines (no others: the wall-clock ``log_time`` and ``log_tick`` are switched off, and
``send_columns`` adds none):

- ``cam_angle``: a *duration* timeline on which one second stands for one degree of cam
  angle (the viewer prints 270° as ``+270s``). rerun's sequence timelines take integers
  only, which would either round the events' angles to whole degrees or count in some
  fraction of a degree; a duration keeps nanosecond integers, so every archive angle (kept
  to 1e-9°) is placed exactly and the axis reads in degrees.
- ``time``: the time from the start of the run, a duration.

Every history is sent whole with ``send_columns``. The values are the archive's, converted
only in units: lifts m → mm (× 1000), forces in N as stored. A recording is deterministic for
the same archive and selection: its recording id is a hash of the study and the cases, and
nothing depends on the clock; only rerun's row and chunk ids (time-based) differ between two
writes, so files are compared by :func:`read_recording`, not byte by byte. (The blueprint is
rerun's own store beside the recording, with its own random ids and times.)
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from campipe.vocabulary import (
    CAM_IMPACT,
    CAM_SEPARATION,
    CHECK_VALVE_CLOSES,
    CHECK_VALVE_OPENS,
    PLUNGER_BOTTOMS,
    PLUNGER_TOPS,
    ROMAN,
    SEAT_IMPACT,
    SEAT_SEPARATION,
)

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

APPLICATION_ID = "campipe"
#: Timeline names.
CAM_ANGLE, TIME = "cam_angle", "time"
#: Nanoseconds per degree on the cam_angle timeline, per second on the time timeline.
NANOS = 1_000_000_000
#: Sketch and lift units: millimetres per metre.
MM = 1000.0

#: Series: archive name → (entity under the case, label, its default units, factor to them
#: from the archive's, colour); a recording's own units replace the defaults
#: (``CaseRecording.units``: ``campipe replay --units``).
SERIES: dict[str, tuple[str, str, str, float, tuple[int, int, int]]] = {
    "cam_lift": ("lift/cam", "cam lift", "mm", MM, (150, 150, 150)),
    "follower_lift": ("lift/follower", "follower lift", "mm", MM, (50, 110, 200)),
    "valve_lift": ("lift/valve", "valve lift", "mm", MM, (40, 160, 80)),
    "cam_force": ("force/cam", "cam contact force", "N", 1.0, (50, 110, 200)),
    "seat_force": ("force/seat", "seat contact force", "N", 1.0, (160, 90, 40)),
    "contact_state": (
        "contact_state",
        "contact state [1 I cam, 2 II free, 3 III cam+seat, 4 IV seat]",
        "",
        1.0,
        (60, 60, 60),
    ),
}
#: Event kinds (campipe.vocabulary) → (name, text-log level).
EVENT_KINDS = {
    CAM_SEPARATION: ("cam separation", "INFO"),
    CAM_IMPACT: ("cam impact", "WARN"),
    SEAT_SEPARATION: ("seat separation", "INFO"),
    SEAT_IMPACT: ("seat impact", "WARN"),
    CHECK_VALVE_OPENS: ("lash adjuster's check valve opens", "INFO"),
    CHECK_VALVE_CLOSES: ("lash adjuster's check valve closes", "INFO"),
    PLUNGER_BOTTOMS: ("lash adjuster's plunger bottoms out", "WARN"),
    PLUNGER_TOPS: ("lash adjuster's plunger fully out", "WARN"),
}
#: Sketch parts: name → colour.
PART_COLOURS = {
    "cam": (140, 140, 140),
    "pushrod": (50, 110, 200),
    "rocker": (230, 140, 30),
    "stem": (40, 160, 80),
    "head": (40, 160, 80),
    "spring": (150, 80, 190),
    "retainer": (90, 90, 90),
    "frame": (90, 90, 90),
    "seat": (120, 70, 40),
    "mass": (50, 110, 200),  # a chain's masses (mass_1 …) and links (link_1 …)
    "link": (150, 80, 190),
}
IN_CONTACT, OFF_CONTACT = (40, 180, 70), (220, 40, 40)


class Labelled(Protocol):
    """What a blueprint needs of a case: its id and a short name."""

    @property
    def case_id(self) -> str: ...

    @property
    def label(self) -> str: ...


@dataclass(frozen=True)
class SketchFrames:
    """The mechanism of one case as drawn at every sample, positions in metres."""

    moving: Mapping[str, np.ndarray]  # part → (n, k, 2) its line strip per sample [m]
    radii: Mapping[str, float]  # moving part → line radius [m]
    cam_outline: np.ndarray  # (n, k, 2) the turning cam's outline per sample [m]
    cam_mark: np.ndarray  # (n, 2, 2) a radius marking the cam's angle per sample [m]
    follower: np.ndarray  # (n, 2) the follower's contact point [m]
    on_cam: np.ndarray  # (n,) bool: the follower is on the cam
    frame: Mapping[str, np.ndarray]  # fixed part → (k, 2) line strip [m]
    note_at: tuple[float, float]  # where the magnification note stands [m]
    valve: np.ndarray | None = None  # (n, 2) the valve's seat point [m]; None: no seat
    seated: np.ndarray | None = None  # (n,) bool: the valve is on its seat
    seat: np.ndarray | None = None  # (blocks, 2, 2) the seat's boxes: min corner, size [m]


@dataclass(frozen=True)
class CaseRecording:
    """One case as a recording shows it: the archive's values (SI, angles in degrees), its
    parameters as a markdown document and the mechanism's sketch."""

    case_id: str  # the case's id: its entity subtree is cases/<case_id>
    label: str  # a short name, the blueprint tab's
    cam_angle: np.ndarray  # (n,) sample angles [degree]
    histories: Mapping[str, np.ndarray]  # "time" [s] and every SERIES name → (n,) values
    events: Mapping[str, np.ndarray]  # event variables as the archive holds them
    parameters: str  # markdown document
    sketch: SketchFrames
    #: SERIES name → (units shown, factor from the archive's units); missing: SERIES's own
    units: Mapping[str, tuple[str, float]] = field(default_factory=dict)

    def series(self, name: str) -> tuple[str, float]:
        """The label with units and the factor from archive values of a SERIES history."""
        _, words, units, factor, _ = SERIES[name]
        units, factor = self.units.get(name, (units, factor))
        return (f"{words} [{units}]" if units else words), factor


def case_path(case_id: str) -> str:
    """The entity subtree of a case."""
    return f"cases/{case_id}"


def nanos(values: np.ndarray) -> np.ndarray:
    """Degrees (or seconds) → the timeline's integer nanoseconds, rounded to nearest."""
    return np.round(np.asarray(values, dtype=float) * NANOS).astype(np.int64)


def _indexes(cam_angle: np.ndarray, time: np.ndarray) -> list:
    import rerun as rr

    return [
        rr.TimeColumn(CAM_ANGLE, duration=nanos(cam_angle).astype("timedelta64[ns]")),
        rr.TimeColumn(TIME, duration=nanos(time).astype("timedelta64[ns]")),
    ]


# -- the content of one case ---------------------------------------------------------------------


#: The events' velocity and impulse as the archive holds them: (units, factor).
EVENT_SI = {"event_velocity": ("m/s", 1.0), "event_impulse": ("N*s", 1.0)}


def event_text(
    kind: int,
    angle: float,
    time: float,
    velocity: float,
    impulse: float,
    before: int,
    after: int,
    units: Mapping[str, tuple[str, float]] = EVENT_SI,
) -> str:
    """One event as a text-log line, its velocity and impulse (archive values) in ``units``
    (name → (units, factor from the archive's))."""
    name = EVENT_KINDS.get(int(kind), (f"event {kind}", "INFO"))[0]
    (v_units, v_factor), (j_units, j_factor) = (
        units.get(n, EVENT_SI[n]) for n in ("event_velocity", "event_impulse")
    )
    text = (
        f"{name} at {angle:.4f}° (t = {time * 1e3:.4f} ms): velocity "
        f"{velocity * v_factor:.4g} {v_units}, "
        f"configuration {ROMAN.get(int(before), before)} → {ROMAN.get(int(after), after)}"
    )
    if int(kind) in (CAM_IMPACT, SEAT_IMPACT):
        text += f", impulse {impulse * j_factor:.4g} {j_units.replace('*', '·')}"
    return text


def log_case(rec: rr.RecordingStream, case: CaseRecording, magnification: float) -> None:
    """Log one case into ``rec``: series, events, parameters and the moving sketch."""
    import rerun as rr

    root = case_path(case.case_id)
    h = case.histories
    indexes = _indexes(case.cam_angle, h["time"])
    for name, (path, _, _, _, colour) in SERIES.items():
        label, factor = case.series(name)
        style = rr.SeriesLines(
            names=label,
            colors=[colour],
            interpolation_mode="StepAfter" if name == "contact_state" else None,
        )
        rec.log(f"{root}/{path}", style, static=True)
        values = np.asarray(h[name], dtype=float) * factor
        rec.send_columns(
            f"{root}/{path}", indexes=indexes, columns=rr.Scalars.columns(scalars=values)
        )
    log_events(rec, root, case.events, case.units)
    rec.log(
        f"{root}/parameters",
        rr.TextDocument(case.parameters, media_type=rr.MediaType.MARKDOWN),
        static=True,
    )
    log_sketch(rec, f"{root}/sketch", case.sketch, indexes, magnification)


def log_events(
    rec: rr.RecordingStream,
    root: str,
    ev: Mapping[str, np.ndarray],
    units: Mapping[str, tuple[str, float]] = EVENT_SI,
) -> None:
    """A case's events as a text log at their cam angles and times (velocity and impulse in
    ``units``, as :func:`event_text`)."""
    import rerun as rr

    if not ev["event_kind"].size:
        return
    rows = list(
        zip(
            ev["event_kind"],
            ev["event_cam_angle"],
            ev["event_time"],
            ev["event_velocity"],
            ev["event_impulse"],
            ev["event_from"],
            ev["event_to"],
            strict=True,
        )
    )
    texts = [event_text(k, a, t, v, j, b, c, units=units) for k, a, t, v, j, b, c in rows]
    levels = [EVENT_KINDS.get(int(k), ("", "INFO"))[1] for k in ev["event_kind"]]
    rec.send_columns(
        f"{root}/events",
        indexes=_indexes(ev["event_cam_angle"], ev["event_time"]),
        columns=rr.TextLog.columns(text=texts, level=levels),
    )


def _points(
    rec: rr.RecordingStream, path: str, indexes: list, where: np.ndarray, held: np.ndarray
) -> None:
    """A dot per sample [m], green while its contact holds, red while it does not."""
    import rerun as rr

    rec.log(path, rr.Points2D.from_fields(radii=[1.5]), static=True)
    rec.send_columns(
        path,
        indexes=indexes,
        columns=rr.Points2D.columns(
            positions=where * MM,
            colors=np.where(held[:, None], IN_CONTACT, OFF_CONTACT).astype(np.uint8),
        ),
    )


def log_sketch(
    rec: rr.RecordingStream, root: str, sketch: SketchFrames, indexes: list, magnification: float
) -> None:
    """The mechanism, moving with the samples, and its fixed frame."""
    import rerun as rr

    n = sketch.follower.shape[0]
    for name, strips in sketch.moving.items():
        rec.log(
            f"{root}/{name}",
            rr.LineStrips2D.from_fields(
                colors=[PART_COLOURS[name.split("_")[0]]], radii=[sketch.radii[name] * MM]
            ),
            static=True,
        )
        rec.send_columns(
            f"{root}/{name}",
            indexes=indexes,
            columns=rr.LineStrips2D.columns(strips=list(strips * MM)).partition(
                np.ones(n, dtype=np.int32)
            ),
        )
    outline, mark = sketch.cam_outline * MM, sketch.cam_mark * MM
    cam = [s for pair in zip(outline, mark, strict=True) for s in pair]
    rec.log(
        f"{root}/cam",
        rr.LineStrips2D.from_fields(
            colors=[PART_COLOURS["cam"], PART_COLOURS["frame"]], radii=[0.6, 0.4]
        ),
        static=True,
    )
    rec.send_columns(
        f"{root}/cam",
        indexes=indexes,
        columns=rr.LineStrips2D.columns(strips=cam).partition(np.full(n, 2, dtype=np.int32)),
    )
    _points(rec, f"{root}/follower", indexes, sketch.follower, sketch.on_cam)
    if sketch.seat is not None and sketch.valve is not None and sketch.seated is not None:
        _points(rec, f"{root}/valve", indexes, sketch.valve, sketch.seated)
        boxes = sketch.seat * MM
        rec.log(
            f"{root}/frame/seat",
            rr.Boxes2D(mins=boxes[:, 0], sizes=boxes[:, 1], colors=[PART_COLOURS["seat"]]),
            static=True,
        )
    for name, strip in sketch.frame.items():
        rec.log(
            f"{root}/frame/{name}",
            rr.LineStrips2D([strip * MM], colors=[PART_COLOURS["frame"]], radii=[0.5]),
            static=True,
        )
    x, y = sketch.note_at
    rec.log(
        f"{root}/frame/note",
        rr.Points2D(
            [[x * MM, y * MM]],
            radii=[0.01],
            labels=[f"deviation from rigid-body motion ×{magnification:g} [mm]"],
        ),
        static=True,
    )


# -- recordings --------------------------------------------------------------------------------


def case_view(
    case: Labelled, magnification: float, lift: str = "mm", force: str = "N"
) -> rrb.Container:
    """The sketch beside the plots (lifts in ``lift``, forces in ``force``), events and
    parameters of one case."""
    import rerun.blueprint as rrb

    root = case_path(case.case_id)
    return rrb.Horizontal(
        rrb.Spatial2DView(
            origin=f"{root}/sketch", name=f"mechanism [mm], deviations ×{magnification:g}"
        ),
        rrb.Vertical(
            rrb.TimeSeriesView(origin=f"{root}/lift", name=f"lift [{lift}]"),
            rrb.TimeSeriesView(origin=f"{root}/force", name=f"contact force [{force}]"),
            rrb.TimeSeriesView(origin=f"{root}/contact_state", name="contact state"),
            rrb.Tabs(
                rrb.TextLogView(origin=f"{root}/events", name="events"),
                rrb.TextDocumentView(origin=f"{root}/parameters", name="parameters"),
            ),
            row_shares=[3, 3, 1, 2],
        ),
        column_shares=[2, 3],
        name=case.label,
    )


def blueprint(
    cases: Sequence[Labelled],
    magnification: float,
    units: Mapping[str, tuple[str, float]] | None = None,
) -> rrb.Blueprint:
    """One tab per case (the first active), the time panel on ``cam_angle``; ``units`` as
    ``CaseRecording.units``."""
    import rerun.blueprint as rrb

    units = units or {}
    lift = units.get("valve_lift", ("mm", MM))[0]
    force = units.get("cam_force", ("N", 1.0))[0]
    views = [case_view(c, magnification, lift, force) for c in cases]
    layout = views[0] if len(views) == 1 else rrb.Tabs(*views, active_tab=0)
    return rrb.Blueprint(layout, rrb.TimePanel(timeline=CAM_ANGLE), collapse_panels=False)


def recording_id(key: str, case_ids: Sequence[str], magnification: float) -> str:
    """A recording id fixed by the study, the cases and the magnification."""
    text = "\n".join([key, f"{magnification!r}", *case_ids])
    return "campipe-" + hashlib.sha256(text.encode()).hexdigest()[:24]


def recording_stream(rid: str, name: str) -> rr.RecordingStream:
    """A recording of its own (not rerun's global one) with no wall-clock timelines."""
    import rerun as rr

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=rid, send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    rec.send_recording_name(name)
    return rec


def write_recording(
    cases: Sequence[CaseRecording],
    path: str | Path,
    *,
    study: str,
    key: str,
    magnification: float,
    progress: Callable[[int], object] | None = None,
) -> Path:
    """Write ``cases`` to one ``.rrd`` file, atomically (a temporary file renamed into place).

    Parameters
    ----------
    cases : sequence of CaseRecording
        At least one; each gets its subtree ``cases/<case_id>``.
    path : str or Path
        The recording to write.
    study : str
        The study's name, in the recording's name.
    key : str
        The study's key (the archive's ``study_key``), part of the recording id.
    magnification : float
        Factor on the sketch's deviations from the rigid-body motion [-], as drawn.
    progress : callable, optional
        Called with 1 after each case is logged.
    """
    if not cases:
        raise ValueError("no cases to record")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    rec = recording_stream(
        recording_id(key, [c.case_id for c in cases], magnification), f"{study} replay"
    )
    try:
        rec.save(tmp, default_blueprint=blueprint(cases, magnification, cases[0].units))
        for case in cases:
            log_case(rec, case, magnification)
            if progress is not None:
                progress(1)
        rec.flush()
        rec.disconnect()
        os.replace(tmp, path)
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    return path


def spawn_viewer(
    cases: Sequence[CaseRecording],
    *,
    study: str,
    key: str,
    magnification: float,
    progress: Callable[[int], object] | None = None,
) -> None:
    """Open the rerun viewer on ``cases`` (``progress`` called with 1 after each case)."""
    rec = recording_stream(
        recording_id(key, [c.case_id for c in cases], magnification), f"{study} replay"
    )
    rec.spawn(default_blueprint=blueprint(cases, magnification, cases[0].units if cases else None))
    for case in cases:
        log_case(rec, case, magnification)
        if progress is not None:
            progress(1)
    rec.flush()


# -- reading back --------------------------------------------------------------------------------


@dataclass
class RecordedEntity:
    """One entity of a recording as read back: timelines and components, rows in logging
    order (rerun's row ids left out)."""

    static: dict[str, list] = field(default_factory=dict)  # component → its static value
    times: dict[str, np.ndarray] = field(default_factory=dict)  # timeline → (rows,) [ns]
    columns: dict[str, list] = field(default_factory=dict)  # component → one value per row

    def scalars(self, component: str = "Scalars:scalars") -> np.ndarray:
        """(rows,) the one value each row holds."""
        return np.array([row[0] for row in self.columns[component]], dtype=float)


def read_recording(path: str | Path) -> dict[str, RecordedEntity]:
    """Entity path → its data, from the first recording store of an ``.rrd`` file
    (``rerun.chunk.RrdReader``)."""
    from rerun.chunk import RrdReader

    parts: dict[str, list] = {}
    for chunk in RrdReader(path).store().stream():
        rb = chunk.to_record_batch()
        entity = rb.schema.metadata[b"rerun:entity_path"].decode().lstrip("/")
        parts.setdefault(entity, []).append(rb)
    out: dict[str, RecordedEntity] = {}
    for entity, batches in sorted(parts.items()):
        e = RecordedEntity()
        rows: dict[tuple, list] = {}
        for rb in batches:
            kinds = {f.name: (f.metadata or {}).get(b"rerun:kind", b"").decode() for f in rb.schema}
            index = tuple(sorted(n for n, k in kinds.items() if k == "index"))
            data = [n for n, k in kinds.items() if k == "data"]
            if not index:
                for name in data:
                    e.static[name] = rb.column(name).to_pylist()[-1]
                continue
            ids = rb.column("rerun.controls.RowId").to_pylist()
            times = {n: np.asarray(rb.column(n).cast("int64")) for n in index}
            values = {n: rb.column(n).to_pylist() for n in data}
            rows.setdefault(index, []).extend(
                (
                    rid,
                    {n: int(t[i]) for n, t in times.items()},
                    {n: v[i] for n, v in values.items()},
                )
                for i, rid in enumerate(ids)
            )
        for index, items in rows.items():
            items.sort(key=lambda item: item[0])
            for name in index:
                e.times[name] = np.array([t[name] for _, t, _ in items], dtype=np.int64)
            names = dict.fromkeys(n for _, _, d in items for n in d)
            for name in names:
                e.columns[name] = [d.get(name) for _, _, d in items]
        out[entity] = e
    return out
