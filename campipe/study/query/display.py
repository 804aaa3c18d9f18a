"""Units a designer reads: which units each archive value is shown in, and how it reads.

The archive stores SI (with ``speed_rpm`` in rpm and angles in degrees); ``campipe query``,
``campipe plot`` and ``campipe export`` show values in one of five unit systems (``--units``):

- ``spec`` (the default): each value the spec wrote with units in the units it wrote
  (``seat: [none, 0.1 in]`` shows in, ``spring_preload: 151 lbf`` in lbf), and every other
  value in the system the spec writes its lengths and forces in (in-lbf for a spec that writes
  ``in`` or ``lbf``; for one that writes ``mm``, lengths in mm, stiffnesses in N/mm and
  stresses in MPa, velocities in m/s; else SI);
- ``si``: the archive's own units;
- ``in-lbf``: inches, pounds-force and seconds (the thesis's units), rpm and degrees;
- ``mm-deg``: the designer's: lift in mm, velocity in mm/deg and acceleration in mm/deg² of
  cam angle (each case's at its cam speed), forces in N, stresses in MPa, rpm and degrees;
- ``mm-degca``: the same per degree of crank angle (``mm/degCA``, each case's at its engine
  speed: an archive of a spec with a drive), angles still the cam's.

The systems but ``spec`` are :data:`campipe.units.UNIT_SYSTEMS`.

No seat (``-inf`` in the archive, :data:`~campipe.study.spec.variables.NO_SEAT`) reads ``none``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping

import numpy as np

from campipe.errors import CampipeError, excerpt
from campipe.io.spec_yaml import SpecFileError, parse_spec_text
from campipe.study.spec.plots import SYSTEMS
from campipe.study.spec.variables import NONE_WORD, STANDARD_COORDINATES
from campipe.units import UNIT_SYSTEMS, convert, convert_values

#: Stored (SI) units → their in-lbf counterparts (units not listed stay as stored).
IN_LBF = UNIT_SYSTEMS["in-lbf"]
#: Units that mark a spec as written in inches and pounds.
_IN_LBF_WORDS = {"in", "inch", "inches", "lbf", "lb", "ft", "foot", "feet", "thou", "mil"}
#: Units that mark a spec as written in millimetres (where none marks it in inches), and what
#: its other values show in: lengths, stiffnesses and stresses as a millimetre spec writes
#: them, velocities (a seating velocity) and accelerations in SI as the trade quotes them.
_MM_WORDS = {"mm", "millimeter", "millimeters", "millimetre", "millimetres"}
SPEC_MM = {"m": "mm", "N/m": "N/mm", "Pa": "MPa"}
_WRITTEN = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(?P<units>\S.*?)\s*$")


class UnitsError(CampipeError, ValueError):
    """A ``--units`` choice that is not a unit system (``key`` ``--units``)."""


def check_system(system: str) -> str:
    if system not in SYSTEMS:
        raise UnitsError.at(
            "--units", f"found {excerpt(system)}, expected one of: {', '.join(SYSTEMS)}"
        )
    return system


def written_units(attrs: Mapping[str, object]) -> dict[str, str]:
    """Spec key → the units its values were written in (the first value with units), from
    the archive's ``spec`` and ``spec_overrides`` attributes; {} if they cannot be read."""
    import json

    try:
        raw = parse_spec_text(str(attrs.get("spec", "")), "the archive's spec")
        overrides = json.loads(str(attrs.get("spec_overrides") or "{}"))
    except (SpecFileError, ValueError):
        return {}
    out: dict[str, str] = {}
    if isinstance(overrides, dict):
        for key, value in overrides.items():
            for k in _axis_key(str(key)):
                _note(out, k, value)
    if not isinstance(raw, Mapping):
        return out
    for block in ("sweep", "zip"):
        for key, values in _mapping(raw.get(block)).items():
            _note(out, str(key), values)
            for item in _blocks(values):  # a sweep of whole blocks: {kind: harmonic, lift: 1 in}
                for k, v in _leaves({key: item}):
                    _note(out, k, v)
    sample = _mapping(raw.get("sample"))
    for key, values in _mapping(sample.get("ranges")).items():
        _note(out, str(key), values)
    for key, values in _mapping(_mapping(raw.get("design")).get("vary")).items():
        _note(out, str(key), values)  # campipe design's varied keys
    for entry in [raw, *(e for e in raw.get("cases") or [] if isinstance(e, Mapping))]:
        for key, value in _leaves(entry):
            _note(out, key, value)
    return out


def _axis_key(key: str) -> list[str]:
    """``sweep.model.spring_preload`` → ``model.spring_preload`` (an override's key)."""
    for block in ("sweep.", "zip.", "sample.ranges."):
        if key.startswith(block):
            return [key[len(block) :]]
    return [key]


def _blocks(values: object) -> Iterable[Mapping]:
    """The mappings in a sweep's list of values, at any depth (a list of defect lists)."""
    for v in values if isinstance(values, list) else []:
        if isinstance(v, Mapping):
            yield v
        elif isinstance(v, list):
            yield from _blocks(v)


def _mapping(value: object) -> Mapping:
    return value if isinstance(value, Mapping) else {}


def _leaves(entry: Mapping, prefix: str = "") -> Iterable[tuple[str, object]]:
    for k, v in entry.items():
        if k in ("sweep", "zip", "sample", "cases", "replay", "plots"):
            continue
        if isinstance(v, Mapping) and k in ("model", "profile", "run"):
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def _note(out: dict[str, str], key: str, value: object) -> None:
    """Record the units of the first value of ``value`` (a quantity, a list of them, a range
    ``{from, to}``) written with units."""
    if key in out:
        return
    if isinstance(value, Mapping):
        value = [value.get("from"), value.get("to")]
    for v in value if isinstance(value, list) else [value]:
        if isinstance(v, str):
            m = _WRITTEN.match(v)
            if m is not None:
                out[key] = m["units"]
                return


def spec_system(written: Mapping[str, str]) -> str:
    """``in-lbf`` for a spec that writes any length or force in inches or pounds, else ``mm``
    for one that writes a length in millimetres, else ``si``."""
    words = {w for units in written.values() for w in re.findall(r"[A-Za-z]+", units)}
    return "in-lbf" if words & _IN_LBF_WORDS else "mm" if words & _MM_WORDS else "si"


def _spec_fallback(written: Mapping[str, str]) -> dict[str, str]:
    """Stored units → those of the system the spec writes in (:func:`spec_system`)."""
    system = spec_system(written)
    return SPEC_MM if system == "mm" else UNIT_SYSTEMS[system]


def display_units(
    stored: Mapping[str, str],
    attrs: Mapping[str, object],
    system: str = "spec",
    keys: Mapping[str, str] | None = None,
) -> dict[str, str]:
    """Column or variable name → the units to show it in.

    Parameters
    ----------
    stored : mapping
        Name → its stored units (pint spelling; "" for none).
    attrs : mapping
        The archive's global attributes (its spec, for ``system="spec"``).
    system : str
        One of :data:`SYSTEMS`.
    keys : mapping, optional
        Name → the spec key it holds (default: the standard coordinates, the study's axes and
        model parameters by their own name).
    """
    check_system(system)
    if system == "si":
        return dict(stored)
    written = written_units(attrs) if system == "spec" else {}
    fallback = _spec_fallback(written) if system == "spec" else UNIT_SYSTEMS[system]
    names_to_keys = dict(keys) if keys is not None else column_keys(attrs)
    out = {}
    for name, units in stored.items():
        key = names_to_keys.get(name, f"model.{name}")
        shown = written.get(key)
        if shown is not None and units and _convertible(units, shown):
            out[name] = shown
        else:
            out[name] = fallback.get(units, units)
    return out


def column_keys(attrs: Mapping[str, object]) -> dict[str, str]:
    """Archive name → spec key: the standard coordinates and the study's axes."""
    import json

    out = {name: key for key, (name, _) in STANDARD_COORDINATES.items()}
    try:
        axes = json.loads(str(attrs.get("study_axes", "[]")))
    except ValueError:
        axes = []
    for a in axes if isinstance(axes, list) else []:
        if isinstance(a, dict) and "name" in a and "key" in a:
            out[str(a["name"])] = str(a["key"])
    return out


def _convertible(stored: str, shown: str) -> bool:
    try:
        convert(1.0, stored, shown)
    except Exception:  # pint's DimensionalityError, an unknown unit
        return False
    return True


def factor(stored: str, shown: str) -> float:
    """Multiply a stored value by this to show it (every unit here is a pure scale)."""
    if not stored or stored == shown:
        return 1.0
    return convert(1.0, stored, shown)


def to_display(
    values: np.ndarray, stored: str, shown: str, cam_speed_rpm: np.ndarray | None = None
) -> np.ndarray:
    """``values`` (stored units) in ``shown`` units; text and no-seat values pass through.
    Per-degree units (``mm/deg``, ``mm/deg^2``) need ``cam_speed_rpm``, each row's cam speed
    [rpm] along the first axis (:func:`campipe.units.convert_values`)."""
    return convert_values(values, stored, shown, cam_speed_rpm)


def format_value(value: object, digits: int = 6) -> str:
    """A value as a table shows it: ``none`` for no seat, ``nan``, ``%g`` numbers, text."""
    if isinstance(value, float | np.floating):
        v = float(value)
        if v == -math.inf:
            return NONE_WORD
        return f"{v:.{digits}g}"
    if isinstance(value, np.integer):
        return str(int(value))
    return str(value)


def label(name: str, units: str) -> str:
    """An axis or column label: ``seat [in]``, or ``cam_impacts`` without units."""
    return f"{name} [{units}]" if units and units != "1" else name
