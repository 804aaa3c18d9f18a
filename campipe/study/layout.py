"""What goes into a batch file and into the archive: sizes, variables and attributes, all
built from the declarations in :mod:`campipe.study.variables`."""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Iterable, Mapping, Sequence
from importlib import metadata
from pathlib import Path

import numpy as np

import campipe
from campipe.io.archive import VariableSpec
from campipe.io.spec_yaml import SpecFileError, parse_spec_text
from campipe.study.expand import ResolvedCase, Study
from campipe.study.results import BatchData, numerics_fingerprint
from campipe.study.variables import (
    DOF_NAMES,
    DOF_UNITS,
    NO_SEAT,
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


#: The variable along ``case`` holding each case's id, in batch files and the archive: named
#: here only.
CASE_ID = "case"


def record_text(record: Iterable[str]) -> str:
    return " ".join(record) or "-"


def batch_key(case_ids: Iterable[str], record: Iterable[str]) -> str:
    """A batch file's key: the cases it holds and what it records, in this layout, by this
    engine."""
    text = json.dumps([LAYOUT_VERSION, numerics_fingerprint(), list(record), list(case_ids)])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _spec(name: str, var: Variable, coordinates: str | None = None) -> VariableSpec:
    attrs = var.attrs()
    if coordinates:
        attrs["coordinates"] = coordinates
    return VariableSpec(name, var.dims, var.dtype, attrs)


def _axes(record: Iterable[str]) -> list[str]:
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
        out.append(_spec(name, var, coords))
    return out


def batch_layout(data: BatchData, record: tuple[str, ...]):
    """(sizes, variables, arrays, attributes) of a batch file."""
    sizes = {
        "case": data.n_cases,
        "cam_angle": data.cam_angle.size,
        "revolution": data.n_revolutions,
        "event": data.n_events,
    }
    if "q" in record:
        sizes["dof"] = len(DOF_NAMES)
    specs = [_spec(n, VARIABLES[n]) for n in _axes(record)]
    specs.append(_spec(CASE_ID, VARIABLES[CASE_ID]))
    specs += data_specs(record, "")
    arrays = {
        **axis_arrays(data.cam_angle, data.n_revolutions),
        CASE_ID: data.case_ids,
        **data.arrays,
    }
    attrs = {
        "campipe_layout": LAYOUT_VERSION,
        "campipe_record": record_text(record),
        "campipe_numerics": data.numerics,
        "batch_key": data.key,
    }
    return sizes, specs, arrays, attrs


def coordinate_values(cases: Sequence[ResolvedCase], study: Study) -> dict[str, np.ndarray]:
    """Per-case coordinate arrays in archive units, in study order: ``case`` (the ids), then
    each case coordinate (no seat as :data:`~campipe.study.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {CASE_ID: np.array([c.case_id for c in cases], dtype=object)}
    return {**out, **key_columns(cases, case_coordinates(study.varied))}


def key_columns(
    cases: Sequence[ResolvedCase], coordinates: Mapping[str, tuple[str, Variable, float]]
) -> dict[str, np.ndarray]:
    """The case coordinates ``coordinates`` names (spec key → (name, variable, factor), as
    :func:`~campipe.study.variables.case_coordinates` gives them), each an array in archive
    units over ``cases`` (no seat as :data:`~campipe.study.variables.NO_SEAT`)."""
    out: dict[str, np.ndarray] = {}
    for key, (name, var, factor) in coordinates.items():
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
            if key == "speed":
                # rpm from rad/s: round away the conversion's last-digit noise (11000 rpm
                # stays 11000, so `--where "speed_rpm == 11000"` finds it)
                values = np.array([float(f"{v:.12g}") for v in values])
            if key == "seat":
                values = np.where(np.isnan(values), NO_SEAT, values)
            out[name] = values
    return out


def archive_layout(study: Study, n_events: int | None, cam_angle: np.ndarray, n_revolutions: int):
    """(sizes, variables, static arrays) of the study's archive; the static arrays are the
    axes and the per-case coordinates, the rest streams in from batch files. ``n_events``
    None makes ``event`` unlimited: the events are appended as the cases are written."""
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
    specs = [_spec(n, VARIABLES[n]) for n in _axes(study.record)]
    specs.append(_spec(CASE_ID, VARIABLES[CASE_ID]))
    values = coordinate_values(study.cases, study)
    for _key, (name, var, _) in coords.items():
        if "mode" in var.dims:
            sizes["mode"] = values[name].shape[1]
        specs.append(_spec(name, var))
    specs += data_specs(study.record, " ".join(coord_names))
    static = {**axis_arrays(cam_angle, n_revolutions), **values}
    static = {s.name: static[s.name] for s in specs if s.name in static}
    return sizes, specs, static


def study_attrs(study: Study) -> dict[str, object]:
    """Global attributes describing the study (provenance comes from campipe.io.archive)."""
    coords = case_coordinates(study.varied)
    axes = [
        {
            "key": a.key,
            "name": coords[a.key][0] if a.key in coords else a.key,
            "kind": a.kind,
            "size": a.size,
        }
        for a in study.axes
    ]
    spec = study.spec
    return {
        "title": f"campipe study {spec.name}",
        "study_name": spec.name,
        "description": spec.description,
        "spec": spec.text,
        "spec_overrides": json.dumps(spec.overrides, default=str),
        "study_axes": json.dumps(axes),
        "record": record_text(study.record),
        "revolutions": float(study.revolutions),
        "output_every_deg": float(np.round(np.degrees(study.output_every), 9)),
        "replay_where": spec.replay or "",
        "campipe_layout": LAYOUT_VERSION,
        "campipe_record": record_text(study.record),
        "campipe_numerics": numerics_fingerprint(),
        "study_key": study_key(study),
        "spec_key": spec_key(spec.text, spec.overrides, spec.directory),
    }


#: The modules that turn a spec's text into cases and their ids (beside the engine's, which
#: :func:`numerics_fingerprint` covers): a spec read by the same code gives the same study.
SPEC_SOURCES = (
    "study/spec.py",
    "study/fields.py",
    "study/expand.py",
    "study/limits.py",
    "study/layout.py",
    "study/variables.py",
    "study/where.py",
    "io/spec_yaml.py",
    "io/lift_table.py",
    "units.py",
    "errors.py",
)


@functools.cache
def _spec_code() -> str:
    root = Path(campipe.__file__).parent
    h = hashlib.sha256()
    for name in SPEC_SOURCES:
        h.update(name.encode() + b"\0" + (root / name).read_bytes())
    try:
        pint = metadata.version("pint")  # unit conversions
    except metadata.PackageNotFoundError:
        pint = "?"
    return f"{h.hexdigest()[:16]} pint=={pint}"


def referenced_files(raw: object, directory: Path) -> dict[str, Path]:
    """Files a spec's values name (lift tables), relative to its folder: every string value
    that is the path of a regular file, as written → its path, in order."""
    found: dict[str, Path] = {}

    def walk(v: object) -> None:
        if isinstance(v, dict):
            for item in v.values():
                walk(item)
        elif isinstance(v, list | tuple):
            for item in v:
                walk(item)
        elif isinstance(v, str) and 0 < len(v) < 4096 and "\n" not in v:
            path = directory / v
            try:
                if path.is_file():
                    found.setdefault(v, path)
            except (OSError, ValueError):
                pass

    walk(raw)
    return found


def spec_key(text: str, overrides: Mapping[str, object], directory: Path) -> str:
    """Equal for two runs that read the same spec text, overrides and referenced files
    (lift tables) with the same campipe: they expand to the same cases, so an archive that
    records this key (``spec_key``) and verifies is up to date without the spec being checked
    or expanded again (:func:`campipe.study.execute.finished`)."""
    h = hashlib.sha256()
    for part in (LAYOUT_VERSION, numerics_fingerprint(), _spec_code(), text):
        h.update(part.encode("utf-8", "surrogatepass") + b"\0")
    h.update(json.dumps(dict(overrides), sort_keys=True, default=str).encode() + b"\0")
    raw: object = None
    try:
        raw = parse_spec_text(text, "spec")
    except SpecFileError:
        pass
    for name, path in referenced_files([raw, dict(overrides)], directory).items():
        h.update(name.encode("utf-8", "surrogatepass") + b"\0")
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()[:16]


def study_key(study: Study) -> str:
    """Equal for two runs that would write the same archive (provenance aside)."""
    text = json.dumps(
        [
            LAYOUT_VERSION,
            numerics_fingerprint(),
            study.spec.text,
            study.spec.overrides,
            list(study.record),
            [c.case_id for c in study.cases],
        ],
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]
