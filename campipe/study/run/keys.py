"""What a run's results are known by: the key of a batch file, of a study and of a spec's
text, and the archive's attributes that record them (with the numerics' fingerprint,
:func:`~campipe.study.run.results.numerics_fingerprint`): results of another study, spec or
engine are never reused."""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Iterable, Mapping
from importlib import metadata
from pathlib import Path

import numpy as np

import campipe
from campipe.io.spec_yaml import SpecFileError, parse_spec_text
from campipe.study.archive.layout import LAYOUT_VERSION, record_text
from campipe.study.run.results import numerics_fingerprint
from campipe.study.spec.expand import Study
from campipe.study.spec.variables import case_coordinates


def batch_key(case_ids: Iterable[str], record: Iterable[str]) -> str:
    """A batch file's key: the cases it holds and what it records, in this layout, by this
    engine."""
    text = json.dumps([LAYOUT_VERSION, numerics_fingerprint(), list(record), list(case_ids)])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


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
        "revolutions": "auto" if study.settle else float(study.revolutions),
        **(
            {"history_turns": int(study.revolutions), "max_revolutions": study.max_revolutions}
            if study.settle
            else {}
        ),
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
    "study/spec/check.py",
    "study/spec/blocks.py",
    "study/spec/fields.py",
    "study/spec/expand.py",
    "study/spec/resolve.py",
    "study/spec/limits.py",
    "study/spec/variables.py",
    "study/archive/layout.py",
    "study/run/keys.py",
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
    or expanded again (:func:`campipe.study.run.resume.finished`)."""
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
