"""From replay cases to rerun recordings: what each case shows, and ``campipe replay``.

:func:`recording_case` turns a :class:`~campipe.replay.cases.ReplayCase` into the plain
arrays and text a recording holds (:class:`campipe.io.rerun_replay.CaseRecording`): the
parameters document and the mechanism's sketch at every sample. :func:`replay_archive` is
``campipe replay``: it opens an archive, selects its cases and writes them (or opens the
viewer). The file format itself is :mod:`campipe.io.rerun_replay`'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from campipe.io.archive import ArchiveDamagedError, unreadable_error
from campipe.io.outputs import RECORDING, check_output
from campipe.io.rerun_replay import (
    EVENT_SI,
    MM,
    SERIES,
    CaseRecording,
    SketchFrames,
    spawn_viewer,
    write_recording,
)
from campipe.model import PARAMETERS
from campipe.replay import chain_sketch, sketch
from campipe.replay.cases import ReplayCase, ReplayError, archive_cases, select_rows
from campipe.study.archive.open import open_archive
from campipe.study.query.display import display_units
from campipe.study.run.progress import Progress
from campipe.units import convert, convert_values, degree_speed, per_degree

#: Line radii of the sketch's parts drawn with no width of their own [m].
HEAD_RADIUS = SPRING_RADIUS = 0.0005
RETAINER_RADIUS = 0.001


def _value(value: object) -> str:
    if isinstance(value, tuple):
        return ", ".join(_value(v) for v in value)
    if isinstance(value, float):
        return "none" if math.isnan(value) or value == -math.inf else f"{value:.10g}"
    return str(value)


def case_geometry(case: ReplayCase) -> sketch.Geometry:
    return sketch.Geometry.from_train(case.train)


def _base_radius(case: ReplayCase) -> float:
    """The drawn cam's base-circle radius [m] (a drawing choice)."""
    return chain_sketch.BASE_RADIUS if case.train.chain else case_geometry(case).base_radius


def parameters_document(
    case: ReplayCase, magnification: float, units: Mapping[str, tuple[str, float]] | None = None
) -> str:
    """The case as a markdown document: its columns, its model, how to read the replay (the
    series and events in ``units``, :func:`series_units`'s)."""
    defaults = {
        "valve_lift": "mm",
        "cam_force": "N",
        "event_velocity": "m/s",
        "event_impulse": "N*s",
    }
    shown = {name: (units or {}).get(name, (d, 1.0))[0] for name, d in defaults.items()}
    lines = [
        f"# {case.label}",
        "",
        f"Study `{case.study}`, case `{case.case_id}`.",
        "",
        "## Case (as the archive holds it)",
        "",
        "| column | value | units |",
        "|---|---|---|",
    ]
    lines += [
        f"| {name} | {_value(value)} | {units} |" for name, (value, units) in case.columns.items()
    ]
    lines += ["", "## Valve train", "", "| parameter | value | units |", "|---|---|---|"]
    for name, p in PARAMETERS.items():
        lines.append(f"| {name} | {_value(getattr(case.train, name))} | {p.units} |")
    lines += [
        "",
        "## Reading the replay",
        "",
        "- Timeline `cam_angle`: one second of this duration timeline stands for one degree "
        "(270° reads `+270s`). Timeline `time`: the time from the start of the run.",
        f"- Plots: lifts in {shown['valve_lift']}, contact forces in {shown['cam_force']}, "
        "compressive positive and zero out of contact; contact state 1 I cam contact, 2 II "
        "free, 3 III cam and seat, 4 IV seat only (thesis Table I).",
        f"- Sketch, in mm: the rigid train the cam (and the seat) would carry, at true scale, "
        f"plus **×{magnification:g}** the computed deviation from it: the gap at the cam "
        "while the follower is off it, the valve's bounce off its seat, and the elastic "
        + (
            "deflection of the links (a chain of masses: boxes joined by springs, from the "
            "cam's mass up to the valve and its spring). "
            if case.train.chain
            else "deflection of pushrod, rocker and valve stem. "
        )
        + "A contact that holds is drawn at its "
        f"true place. Cam base-circle radius {_base_radius(case) * MM:g} mm "
        "(a drawing choice). The follower's dot is green on the cam, red off it; the valve's "
        "green on its seat, red off it.",
        "- Events: separations and impacts at their cam angles, with the closing velocity "
        f"(impacts) or velocity jump in {shown['event_velocity']} and the impulse delivered "
        f"(impacts) in {shown['event_impulse']}.",
    ]
    return "\n".join(lines)


def turn_profile(case: ReplayCase) -> tuple[np.ndarray, np.ndarray]:
    """The cam's lift over one turn from the archive's samples: (angles [rad], lift [m])."""
    phi = np.mod(case.cam_angle, 360.0)
    phi, first = np.unique(np.round(phi, 9), return_index=True)
    return np.radians(phi), case.histories["cam_lift"][first]


def sketch_frames(case: ReplayCase, magnification: float) -> SketchFrames:
    """The mechanism at every sample, moving with q (deviations magnified), the cam turning:
    the thesis's train as :mod:`~campipe.replay.sketch` draws it, a chain of masses as boxes
    and springs (:mod:`~campipe.replay.chain_sketch`)."""
    if case.q is None:
        raise ReplayError(f"case {case.case_id}: no q to draw the mechanism from")
    if case.train.chain:
        return chain_frames(case, magnification)
    geom = case_geometry(case)
    state = np.asarray(case.histories["contact_state"])
    qd = sketch.displayed_coordinates(
        case.q, case.histories["cam_lift"], state, geom, magnification, case.seat_q7
    )
    angle = np.radians(case.cam_angle)
    phi, lift = turn_profile(case)
    frame = sketch.fixed_parts(geom, case.seat_q7)
    seat = frame.pop("seat", None)
    return SketchFrames(
        moving=sketch.moving_parts(qd, geom),
        radii={
            "pushrod": geom.pushrod_radius,
            "rocker": geom.rocker_radius,
            "stem": geom.stem_radius,
            "head": HEAD_RADIUS,
            "spring": SPRING_RADIUS,
            "retainer": RETAINER_RADIUS,
        },
        cam_outline=sketch.cam_outline(phi, lift, angle, geom),
        cam_mark=sketch.cam_mark(angle, geom),
        follower=sketch.follower_position(qd, geom),
        on_cam=np.isin(state, sketch.CAM_CONTACT),
        frame=frame,
        note_at=(-geom.pushrod_arm, geom.pushrod_arm * 0.6),
        valve=None if seat is None else sketch.valve_position(qd, geom),
        seated=None if seat is None else np.isin(state, sketch.SEAT_CONTACT),
        seat=seat,
    )


def chain_frames(case: ReplayCase, magnification: float) -> SketchFrames:
    """A chain of masses at every sample: boxes joined by springs on the turning cam."""
    assert case.q is not None
    state = np.asarray(case.histories["contact_state"])
    xd = chain_sketch.displayed_displacements(
        case.q, case.histories["cam_lift"], state, case.train, magnification, case.seat_q7
    )
    angle = np.radians(case.cam_angle)
    phi, lift = turn_profile(case)
    geom = chain_sketch.cam_geometry()
    frame = chain_sketch.fixed_parts(xd.shape[1], case.seat_q7)
    seat = frame.pop("seat", None)
    moving = chain_sketch.moving_parts(xd)
    return SketchFrames(
        moving=moving,
        radii={
            name: RETAINER_RADIUS if name.startswith("mass") else SPRING_RADIUS for name in moving
        },  # fmt: skip
        cam_outline=sketch.cam_outline(phi, lift, angle, geom),
        cam_mark=sketch.cam_mark(angle, geom),
        follower=chain_sketch.follower_position(xd),
        on_cam=np.isin(state, sketch.CAM_CONTACT),
        frame=frame,
        note_at=(-3 * chain_sketch.HALF_WIDTH, chain_sketch.spring_plate(xd.shape[1])),
        valve=None if seat is None else chain_sketch.valve_position(xd),
        seated=None if seat is None else np.isin(state, sketch.SEAT_CONTACT),
        seat=seat,
    )


#: The events' values the recording's text log gives, in the archive's units.
EVENT_VALUES = {name: units for name, (units, _) in EVENT_SI.items()}


def series_units(
    stored: Mapping[str, str], attrs: Mapping[str, object], system: str
) -> dict[str, tuple[str, float]]:
    """The recording's series (``rerun_replay.SERIES``) stored in ``stored`` units, and its
    events' values (:data:`EVENT_VALUES`), shown in the unit system ``system`` as query and
    plot show them (``display_units``, the spec read from ``attrs``, an archive's
    attributes): name → (units, factor); a factor NaN for a value per degree, which
    :func:`recording_case` takes at the case's speed."""
    stored = {**stored, **EVENT_VALUES}
    shown = display_units(stored, attrs, system)
    return {
        name: (
            shown[name],
            math.nan if per_degree(shown[name])[1] else convert(1.0, u, shown[name]),
        )
        for name, u in stored.items()
    }


def archive_series_units(ds, system: str) -> dict[str, tuple[str, float]]:
    """:func:`series_units` of an archive's series."""
    stored = {
        name: str(ds[name].attrs.get("units", ""))
        for name in SERIES
        if name in ds.variables and ds[name].attrs.get("units", "") not in ("", "1")
    }
    return series_units(stored, ds.attrs, system)


def recording_case(
    case: ReplayCase,
    magnification: float = sketch.DEFAULT_MAGNIFICATION,
    units: Mapping[str, tuple[str, float]] | None = None,
) -> CaseRecording:
    """What a recording shows of ``case``: its archive values (series and events in
    ``units``, as :func:`series_units`; default mm, N and SI), parameters and sketch."""
    units = dict(units or {})
    for name, (shown, factor) in units.items():
        if math.isnan(factor):  # per degree: at the case's speed (the cam's, or the engine's)
            speed = case.columns.get(degree_speed([shown]), (None, ""))[0]
            one = convert_values(np.ones(1), EVENT_VALUES[name], shown, speed)
            units[name] = (shown, float(one[0]))
    return CaseRecording(
        case_id=case.case_id,
        label=case.label,
        cam_angle=case.cam_angle,
        histories=case.histories,
        events=case.events,
        parameters=parameters_document(case, magnification, units),
        sketch=sketch_frames(case, magnification),
        units=units,
    )


def default_output(archive: str | Path) -> Path:
    """``campipe replay``'s recording when ``-o`` is not given: ``<archive stem>.replay.rrd``
    beside the archive (the study's own recording is ``<archive stem>.rrd``)."""
    return Path(archive).with_suffix(".replay.rrd")


def check_recording(archive: Path, attrs: dict, output: str | Path | None, overwrite: bool) -> Path:
    """The recording's path (``output`` or :func:`default_output`), refused by the output rule
    where it would replace the archive, its spec or a file that is not a recording."""
    spec = str(attrs.get("spec_file") or "")
    return check_output(
        output or default_output(archive),
        "-o",
        RECORDING,
        overwrite=overwrite,
        inputs=[
            (archive, "the archive replayed"),
            (archive.parent / spec if spec else None, "the archive's spec"),
        ],
    )


def replay_archive(
    archive: str | Path,
    *,
    case_ids: Sequence[str] = (),
    where: str | None = None,
    output: str | Path | None = None,
    spawn: bool = False,
    magnification: float = sketch.DEFAULT_MAGNIFICATION,
    progress: Callable[[int, str], Progress] | None = None,
    overwrite: bool = False,
    verify: bool = True,
    units: str = "spec",
) -> tuple[Path | None, list[ReplayCase]]:
    """Replay an archive's cases chosen by id or by a ``--where`` expression.

    Writes one recording (``output``, default :func:`default_output`) or, with ``spawn``,
    opens the viewer instead. Nothing is written when the selection fails. ``progress(total,
    unit)`` makes a progress line for each step over the cases (sketching them, logging
    them), as ``campipe replay`` shows. The recording follows the output rule
    (``campipe.io.outputs``): it never replaces the archive or its spec, and replaces a file
    that is not a recording only with ``overwrite``. ``verify``: check the archive against
    its checksums first (``open_archive``; a damaged one raises ArchiveDamagedError).
    ``units``: the unit system of the lifts and forces plotted (as ``campipe query`` and
    ``plot``: spec, si, in-lbf, mm-deg); the sketch is drawn in mm.

    Returns
    -------
    (path or None, cases)
        The recording written (None when spawned) and the cases it holds.

    Raises
    ------
    ReplayError
        For a missing or unreadable archive, an unknown case id, a selection of no case,
        or q that can be neither read nor computed again.
    campipe.study.where.QueryError
        For a ``--where`` expression the query language refuses.
    """
    archive = Path(archive)
    if not archive.exists():
        raise ReplayError(f"{archive}: no such archive", key=str(archive))
    try:
        ds = open_archive(archive, verify)  # a file, or a parts archive's folder
    except ArchiveDamagedError:
        raise
    except (OSError, ValueError, RuntimeError, AttributeError) as exc:  # netCDF4: an attribute
        raise unreadable_error(archive, exc) from None  # as query and plot: not netCDF is 2
    with ds:
        if not spawn:
            check_recording(archive, ds.attrs, output, overwrite)
        try:
            rows = select_rows(ds, case_ids, where)
        except ReplayError as exc:
            raise ReplayError(f"{archive}: {exc}", key=exc.key, found=exc.found) from None
        cases = archive_cases(ds, rows, directories=[archive.parent, Path.cwd()])
        key = str(ds.attrs.get("study_key", ""))
        shown = archive_series_units(ds, units)
    bar = progress(len(cases), "cases sketched") if progress else None
    contents = []
    for c in cases:
        contents.append(recording_case(c, magnification, shown))
        if bar is not None:
            bar.advance(1)
    if bar is not None:
        bar.close()
    study = cases[0].study if cases else ""
    bar = progress(len(cases), "cases logged") if progress else None
    try:
        if spawn:
            spawn_viewer(
                contents,
                study=study,
                key=key,
                magnification=magnification,
                progress=bar.advance if bar else None,
            )
            return None, cases
        path = write_recording(
            contents,
            output or default_output(archive),
            study=study,
            key=key,
            magnification=magnification,
            progress=bar.advance if bar else None,
        )
    finally:
        if bar is not None:
            bar.close()
    return path, cases
