"""One pint registry for the whole package, and the parsing of quantities with units.

Specs and ``--set`` write quantities as strings with units (``"9 in"``, ``"245 lbf/in"``,
``"9524 rpm"``); the numerics work in SI floats. A quantity is a decimal number followed by
units (names joined by ``*``, ``/``, small integer powers ``**2`` and parentheses): the text
is checked against that grammar before pint reads the units, so no arithmetic is evaluated
(``9**9**9 rpm`` is refused at once instead of computing a number with 369 million digits).

A text ``<number> <units>`` is read as the number times its units' factor, as pint converts
it (:func:`_by_factor`): the values of a range are not read through pint one by one. Each
units' factor, each other text read and each conversion are kept for later processes
(``campipe.disk_cache``, keyed by pint's version and this module's source): a run whose
units were all read before never imports pint (0.1 s). A refusal is never kept.
"""

from __future__ import annotations

import atexit
import functools
import json
import logging
import math
import re
import sys
import threading
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from campipe.errors import CampipeError, excerpt

if TYPE_CHECKING:
    import pint

log = logging.getLogger(__name__)

#: Values kept for later processes, at most (those found last).
KEEP_VALUES = 2048

_hide_dask = False  # import pint without dask (pint_without_dask)
_lock = threading.Lock()
_known: dict[str, float] | None = None  # values found by this process or kept by others
_found: dict[str, float] = {}  # values this process found, to keep at exit


def pint_without_dask() -> None:
    """Have pint, when this process first needs it, imported without its dask support. pint
    imports dask, when it is installed, to wrap dask arrays in quantities: 90 ms of every
    command that reads a quantity, for nothing campipe does. For the command line, whose
    process is the command's own (dask itself stays importable)."""
    global _hide_dask
    _hide_dask = True


def _pint():
    """The pint module, imported on first use (see :func:`pint_without_dask`)."""
    if _hide_dask and "pint" not in sys.modules and "dask" not in sys.modules:
        sys.modules["dask"] = None  # type: ignore[assignment]  # find_spec("dask") is None
        try:
            import pint
        finally:
            del sys.modules["dask"]
    import pint

    return pint


#: Spellings of the trade pint does not know: a speed written ``9000 rev/min`` or
#: ``9000 r/min`` (ISO 80000's r/min) is the ``9000 rpm`` pint reads.
TRADE_ALIASES = ("@alias revolution = rev = r",)


@functools.cache
def registry() -> pint.UnitRegistry:
    """The package's one pint registry, made on first use (``campipe --help`` never pays
    for it). Its parsed definitions are kept in pint's own cache folder (pint's
    ``cache_folder=":auto:"``, a per-user folder): reading them back takes a fifth of the
    time parsing them does (0.03 s against 0.13 s), and a cache that cannot be read or
    written is passed over."""
    pint = _pint()
    try:
        reg = pint.UnitRegistry(cache_folder=":auto:")
    except Exception as exc:  # a damaged or unwritable cache: parse the definitions
        log.debug("pint's definition cache is not usable (%s): parsing the definitions", exc)
        reg = pint.UnitRegistry()
    for alias in TRADE_ALIASES:
        reg.define(alias)
    return reg


class QuantityError(CampipeError, ValueError):
    """A quantity that is missing its units, has the wrong dimension, or does not parse; its
    ``key`` is the key the value came from, ``found`` the value as given, ``expected`` the
    units it must convert to."""


def parse_quantity(text: object, units: str, key: str, example_units: str | None = None) -> float:
    """Parse ``text`` as a quantity and return its magnitude in ``units``.

    Parameters
    ----------
    text : object
        A quantity with units, such as ``"9 in"``. A bare number is accepted only where
        ``units`` is dimensionless; anything else is refused with a QuantityError.
    units : str
        The units to convert to (pint spelling), ``""`` for dimensionless.
    key : str
        The key the value came from, named in any error.
    example_units : str, optional
        Units to suggest in error messages (defaults to ``units``).

    Raises
    ------
    QuantityError
        With the key, what was found and what is expected.
    """
    if isinstance(text, str):
        return _parse_text(text, units, key, example_units)
    return _parse(text, units, key, example_units)


@functools.lru_cache(maxsize=8192)
def _parse_text(text: str, units: str, key: str, example_units: str | None) -> float:
    """A quantity's text read once a process, or by an earlier one (:func:`_kept`): every
    case of a grid repeats its preset's and its base's values (a refusal is raised again each
    time, never kept); or by its units' factor (:func:`_by_factor`)."""

    def parse(text: str) -> float:
        return _kept(("quantity", text, units), lambda: _parse(text, units, key, example_units))

    return _by_factor(text, parse)


def _sweep_hint(text: object, key: str) -> str:
    """A list where one value goes: how a spec varies it."""
    if not isinstance(text, list):
        return ""
    return f"; to vary it, list its values under sweep: {{{key}: [...]}}"


def _parse(text: object, units: str, key: str, example_units: str | None) -> float:
    """:func:`parse_quantity`, uncached."""
    if not units and isinstance(text, (int, float)) and not isinstance(text, bool):
        # a bare number where none are wanted: no units to read
        expected = f"a quantity in {example_units}" if example_units else "a number"
        return _finite(float(text), text, key, expected)
    ureg = registry()
    pint = _pint()
    target = ureg.Unit(units) if units else ureg.dimensionless
    dimensionless = target.dimensionless
    example = example_units or _example_unit(target)
    expected = f"a quantity in {example}" if example else "a number"
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        such = f"a quantity such as '1 {example}'" if example else "a number"
        raise QuantityError.at(
            key,
            f"expected {such}, found {excerpt(text)}{_sweep_hint(text, key)}",
            found=text,
            expected=expected,
        )
    if isinstance(text, (int, float)):
        if dimensionless:
            return _finite(float(text), text, key, expected)
        raise QuantityError.at(
            key,
            f"found the bare number {excerpt(text)}; write it with units, "
            f"e.g. '{excerpt(text, 30)} {example}'",
            found=text,
            expected=expected,
        )
    q = _read(text, key, example)
    if not isinstance(q, pint.Quantity):
        q = ureg.Quantity(float(q), "")
    if q.dimensionless and not dimensionless:
        raise QuantityError.at(
            key,
            f"found {excerpt(text)} without units; write it with units, "
            f"e.g. '{text.strip()} {example}'",
            found=text,
            expected=expected,
        )
    try:
        value = float(q.to(target).magnitude)
    except pint.DimensionalityError:
        raise QuantityError.at(
            key,
            f"found {excerpt(text)} [{q.dimensionality}], expected a quantity convertible "
            f"to {example}{_also_si(example, target)} [{target.dimensionality}]",
            found=text,
            expected=expected,
        ) from None
    return _finite(value, text, key, expected)


def _also_si(example: str, target) -> str:
    """The SI units (``target``) after an example in others: " or N/m"; "" otherwise."""
    si = "" if target.dimensionless else f"{target:~C}"
    return f" or {si}" if si and si != example else ""


def _finite(value: float, text: object, key: str, expected: str) -> float:
    if not math.isfinite(value):
        raise QuantityError.at(
            key,
            f"found {excerpt(text)}, beyond the range of a float in SI units",
            found=text,
            expected=expected,
        )
    return value


#: Longest quantity text read [characters].
MAX_QUANTITY_LENGTH = 100
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d{1,4})?"
_QUANTITY = re.compile(rf"^\s*(?P<number>{_NUMBER})?\s*(?P<units>.*?)\s*$", re.DOTALL)
#: Units: names, * and /, powers of at most two digits, parentheses, spaces.
_UNIT_TOKENS = re.compile(
    r"\s+|[A-Za-z_\u00b0\u00b5\u03bc\u03a9][A-Za-z0-9_\u00b0\u00b5\u03bc\u03a9]*"
    r"|(?:\*\*|\^)\s*[-+]?\d{1,2}(?:\.\d{1,3})?|[*/()]"
)


def _read(text: str, key: str, example: str) -> pint.Quantity | float:
    """``text`` as a Quantity (or a plain number), or a QuantityError naming the key and
    suggesting ``example`` units. Only ``<number> <units>`` is read (see the module)."""

    def refuse(why: str) -> QuantityError:
        return QuantityError.at(
            key,
            f"cannot read {excerpt(text)} as a quantity ({why}); "
            f"write a number and a unit, e.g. '1 {example}'",
            found=text,
            expected=f"a quantity in {example}",
        )

    if len(text) > MAX_QUANTITY_LENGTH:
        raise refuse(f"{len(text)} characters, expected at most {MAX_QUANTITY_LENGTH}")
    m = _QUANTITY.match(text)
    if m is None or m["number"] is None:
        raise refuse("it does not start with a number")
    number = float(m["number"])
    if not math.isfinite(number):
        raise refuse("the number is beyond the range of a float")
    units = m["units"]
    if not units:
        return number
    tokens = [t for t in _UNIT_TOKENS.findall(units) if not t.isspace()]
    powers = [t[0] in "*^" and len(t) > 1 and t != "*" for t in tokens]
    if (
        "".join(_UNIT_TOKENS.findall(units)) != units
        or any(a and b for a, b in zip(powers, powers[1:], strict=False))
        or units.count("(") > 2
    ):
        raise refuse("units are names joined by *, / and small powers such as **2")
    try:
        ureg = registry()
        unit = ureg.parse_units(units)
        q = ureg.Quantity(number, unit)
        q.to_base_units()  # a unit whose size overflows is refused here, once
    except Exception as exc:  # pint raises several unrelated types on bad text
        raise refuse(excerpt(str(exc), 120)) from None
    return q


def read_quantity(text: str, key: str) -> pint.Quantity:
    """``text`` (``"150 lbf"``, ``"0.1 in"``) as a pint Quantity with units, read by the
    grammar above (nothing evaluated); a QuantityError naming ``key`` otherwise."""
    registry()
    pint = _pint()
    q = _read(text, key, "in")
    if not isinstance(q, pint.Quantity) or q.unitless:
        raise QuantityError.at(
            key,
            f"found {excerpt(text)} without units; write a number and a unit, e.g. '1 in'",
            found=text,
            expected="a quantity with units",
        )
    return q


def written_units(value: object) -> str:
    """The units a quantity's text was written in, as written (``"6.5 mm"``: ``"mm"``); ""
    for a bare number, text that starts with no number, or anything else. Nothing is read
    through pint."""
    if not isinstance(value, str) or len(value) > MAX_QUANTITY_LENGTH:
        return ""
    m = _QUANTITY.match(value)
    return m["units"] if m is not None and m["number"] is not None else ""


def is_unit(name: str) -> bool:
    """``name`` alone is a unit pint knows (``in``, ``lbf``, ``rpm``), not a prefix or text."""
    try:
        registry().parse_units(name)
    except Exception:  # pint raises several unrelated types on text that is not a unit
        return False
    return True


def names_an_angle(q: pint.Quantity) -> bool:
    """The quantity's units hold exactly one angle (``deg``, ``rpm``, ``rad/s``): pint takes
    the radian as dimensionless, so ``150 Hz`` would otherwise pass for an angular speed."""
    return dict(q.to_base_units().unit_items()).get("radian") == 1


def _example_unit(unit: pint.Unit) -> str:
    return f"{unit:~}" if not unit.dimensionless else ""


def convert(value: float, from_units: str, to_units: str) -> float:
    """Convert a float between two pint unit spellings."""
    return _kept(
        ("convert", f"{type(value).__name__} {value!r}", from_units, to_units),
        lambda: float(registry().Quantity(value, from_units).to(to_units).magnitude),
    )


def parse_angular(text: object, units: str, key: str, example_units: str) -> float:
    """Parse an angle or an angular speed, whose units must name an angle.

    pint treats the radian as dimensionless, so :func:`parse_quantity` alone would take a bare
    ``268`` as radians and ``1 Hz`` as 1 rad/s. Here the quantity's base units must hold
    exactly one radian: ``"268 deg"``, ``"9000 rpm"``, ``"2 rad/s"``.

    Parameters
    ----------
    text : str, float or int
        The quantity, such as ``"268 deg"``.
    units : str
        ``"rad"`` or an angle per something, such as ``"rad/s"``.
    key : str
        The key the value came from, named in any error.
    example_units : str
        Units to suggest in errors (``"deg"``, ``"rpm"``).

    Raises
    ------
    QuantityError
        With the key, what was found and what is expected.
    """
    expected = f"a quantity in {example_units}"
    if isinstance(text, bool) or not isinstance(text, str):
        if isinstance(text, (int, float)):
            raise QuantityError.at(
                key,
                f"found the bare number {excerpt(text)}; write it with units, "
                f"e.g. '{excerpt(text, 30)} {example_units}'",
                found=text,
                expected=expected,
            )
        raise QuantityError.at(
            key,
            f"expected a quantity such as '1 {example_units}', found {excerpt(text)}"
            + _sweep_hint(text, key),
            found=text,
            expected=expected,
        )

    def parse(text: str) -> float:
        return _kept(("angular", text, units), lambda: _angular(text, units, key, example_units))

    return _by_factor(text, parse)


def _angular(text: str, units: str, key: str, example_units: str) -> float:
    """:func:`parse_angular` of a text, uncached."""
    expected = f"a quantity in {example_units}"
    registry()
    pint = _pint()
    q = _read(text, key, example_units)
    if not isinstance(q, pint.Quantity) or dict(q.to_base_units().unit_items()).get("radian") != 1:
        read = f" (read as {q.units:~P})" if isinstance(q, pint.Quantity) else ""
        raise QuantityError.at(
            key,
            f"found {excerpt(text)}{read}, expected a quantity whose units name an angle, "
            f"such as '1 {example_units}'",
            found=text,
            expected=expected,
        )
    try:
        value = float(q.to(units).magnitude)
    except pint.DimensionalityError:
        raise QuantityError.at(
            key,
            f"found {excerpt(text)}, expected a quantity convertible to {example_units}, "
            f"such as '1 {example_units}'",
            found=text,
            expected=expected,
        ) from None
    return _finite(value, text, key, expected)


def _by_factor(text: str, parse: Callable[[str], float]) -> float:
    """``parse(text)`` of a ``<number> <units>`` text as the number times ``parse("1
    <units>")``, when ``parse("0 <units>")`` is 0 (no offset, such as degC's): what pint
    computes, bit for bit (a quantity's conversion is its magnitude times one factor of its
    units), without reading each value of a range (``6000.5 rpm``, ``6001 rpm``, …) through
    pint or keeping it (:func:`_kept`). Any other text, or units ``parse`` refuses, is
    ``parse(text)`` itself, whose errors name the text."""
    m = _QUANTITY.match(text)
    if m is None or m["number"] is None or not m["units"] or len(text) > MAX_QUANTITY_LENGTH:
        return parse(text)
    number = float(m["number"])
    if not math.isfinite(number):
        return parse(text)
    try:
        factor = parse(f"1 {m['units']}")
        offset = parse(f"0 {m['units']}")
    except QuantityError:
        return parse(text)
    value = number * factor
    if offset != 0.0 or not math.isfinite(value):
        return parse(text)
    return value


def _kept(what: tuple[str, ...], compute: Callable[[], float]) -> float:
    """``compute()``, the value of ``what`` (the function and its arguments), or the value
    this process or an earlier one found for it (kept at exit, :func:`_keep_found`); an error
    is raised, never kept."""
    key = json.dumps(what)
    known = _known_values()
    value = known.get(key)
    if value is None:
        value = compute()
        with _lock:
            if not _found:
                atexit.register(_keep_found)
            known[key] = _found[key] = value
    return value


def _known_values() -> dict[str, float]:
    global _known
    with _lock:
        if _known is None:
            _known = _read_kept()
        return _known


@functools.cache
def _store_key() -> str | None:
    """What the values depend on: pint's version and this module's source; None where pint's
    version is unknown (nothing is then kept)."""
    from importlib import metadata

    from campipe.sources import source_digest

    try:
        version = metadata.version("pint")
    except metadata.PackageNotFoundError:
        return None
    return f"pint {version}; " + source_digest(["units.py"])


def _read_kept() -> dict[str, float]:
    """The values earlier processes kept; none if their file is missing or damaged."""
    from campipe import disk_cache

    key = _store_key()
    content = None if key is None else disk_cache.read("quantities", key)
    try:
        values = json.loads(content) if content else {}
    except ValueError:
        return {}
    if not isinstance(values, dict) or not all(type(v) is float for v in values.values()):
        return {}
    return values


def _keep_found() -> None:
    """Keep the values this process found, with those kept before (the :data:`KEEP_VALUES`
    found last)."""
    from campipe import disk_cache

    key = _store_key()
    with _lock:
        found = dict(_found)
        _found.clear()
    if key is None or not found:
        return
    values = _read_kept()
    for k in found:
        values.pop(k, None)
    values.update(found)
    values = dict(list(values.items())[-KEEP_VALUES:])
    disk_cache.write("quantities", key, json.dumps(values).encode())


# -- unit systems ------------------------------------------------------------------------------

#: The unit systems a value is shown in (``--units``, ``open_study(path, units=...)``):
#: stored (SI) units → the system's (units not listed stay as stored). ``spec`` (the units the
#: spec wrote, :mod:`campipe.study.query.display`) is read from an archive's spec, not listed.
UNIT_SYSTEMS: dict[str, dict[str, str]] = {
    "si": {},
    # the thesis's units: inches, pounds-force and seconds
    "in-lbf": {
        "Pa": "psi",  # (a contact pressure)
        "m": "in",
        "N": "lbf",
        "m/s": "in/s",
        "m/s^2": "in/s^2",
        "N*m": "lbf*in",
        "N*s": "lbf*s",
        "N/m": "lbf/in",
        "kg": "lbf*s^2/in",
    },
    # the designer's: lift in mm, velocity and acceleration per degree of cam angle (at each
    # case's cam speed), forces in N, stresses in MPa
    "mm-deg": {
        "m": "mm",
        "m/s": "mm/deg",
        "m/s^2": "mm/deg^2",
        "N/m": "N/mm",
        "Pa": "MPa",
    },
    # the same per degree of crank angle (degCA, at each case's engine speed: a spec with a
    # drive); angles stay the cam's
    "mm-degca": {
        "m": "mm",
        "m/s": "mm/degCA",
        "m/s^2": "mm/degCA^2",
        "N/m": "N/mm",
        "Pa": "MPa",
    },
}
#: Degrees of cam angle a second at 1 rpm (a turn a minute): 360/60.
DEG_PER_S_PER_RPM = 6.0
_PER_DEGREE = re.compile(r"^(?P<length>[A-Za-z]+)/deg(?P<crank>CA)?(?:\^(?P<power>[12]))?$")
#: The speed column a value shown per degree is converted at: the cam's, or for units per
#: degree of crank angle (``mm/degCA``) the engine's.
CAM_SPEED, ENGINE_SPEED = "speed_rpm", "engine_speed_rpm"


class UnitSystemError(CampipeError, ValueError):
    """A unit system that is not one (``key`` the option naming it)."""


def system_units(system: str, key: str = "units") -> dict[str, str]:
    """Stored units → the units of ``system`` (one of :data:`UNIT_SYSTEMS`)."""
    if system not in UNIT_SYSTEMS:
        raise UnitSystemError.at(
            key,
            f"found {excerpt(system)}, expected one of: {', '.join(UNIT_SYSTEMS)}",
            found=system,
            expected=", ".join(UNIT_SYSTEMS),
        )
    return UNIT_SYSTEMS[system]


def per_degree(units: str) -> tuple[str, int]:
    """``mm/deg`` → (``mm``, 1), ``mm/deg^2`` → (``mm``, 2), other units → (units, 0): a
    length per degree of cam angle (or per degree squared), which a velocity [length/s] or an
    acceleration [length/s²] becomes only at a cam speed; ``mm/degCA`` the same per degree
    of crank angle, at the engine's speed (:func:`degree_speed`)."""
    m = _per_degree_match(units)
    if m is None:
        return units, 0
    return m["length"], int(m["power"] or 1)


def written_per_degree(text: str) -> tuple[str, str] | None:
    """A quantity as written whose units are a length per degree (``0.2 mm/deg``,
    ``5e-4 mm/deg**2``, ``0.1 mm/degCA``) as (its number, its units as :func:`per_degree`
    reads them: ``mm/deg^2``); None for any other text. Pint knows no ``degCA``, and a value
    per degree converts to one per second only at a speed: such a quantity is kept as
    written."""
    number, _, written = str(text).strip().partition(" ")
    units = written.replace("**", "^").replace(" ", "")
    return (number, units) if per_degree(units)[1] else None


def _per_degree_match(units: str) -> re.Match[str] | None:
    return _PER_DEGREE.match(str(units).replace("**", "^").replace(" ", ""))


def degree_speed(units: Iterable[str]) -> str:
    """The speed column [rpm] values shown in ``units`` are converted at: the engine's
    (``engine_speed_rpm``) when one of them is per degree of crank angle, else the cam's."""
    crank = any((m := _per_degree_match(u)) is not None and m["crank"] for u in units)
    return ENGINE_SPEED if crank else CAM_SPEED


def no_speed(to_units: str) -> UnitSystemError:
    """The refusal of ``to_units`` (per degree) for values without the speed it is converted
    at (:func:`degree_speed`): the engine's needs a drive, named as the fix."""
    if degree_speed([to_units]) == ENGINE_SPEED:
        return UnitSystemError.at(
            "units",
            f"{to_units} needs each case's engine speed (engine_speed_rpm), which an archive "
            "has from a spec with a drive (drive: {cam_per_crank: 0.5}); without one use "
            "mm-deg, per degree of cam angle",
            found=to_units,
            expected="an engine speed",
        )
    return UnitSystemError.at(
        "units",
        f"{to_units} needs each case's cam speed (speed_rpm)",
        found=to_units,
        expected="a cam speed",
    )


def convert_values(values, from_units: str, to_units: str, cam_speed_rpm=None):
    """``values`` (an array in ``from_units``) in ``to_units``.

    A velocity or an acceleration shown per degree of cam angle (``mm/deg``, ``mm/deg^2``)
    depends on the cam's speed: v [m/s] is v·1000/(ω·180/π) mm/deg with ω the cam speed
    [rad/s], a [m/s²] is a·1000/(ω·180/π)² mm/deg².

    Parameters
    ----------
    values : array_like
        Floats in ``from_units`` (other kinds, such as text, are returned as they are).
    from_units, to_units : str
        Pint spellings (``""`` for none: the values are returned as they are).
    cam_speed_rpm : array_like, optional
        The cam speed [rpm] of each value along the first axis of ``values`` (or one speed);
        needed only for per-degree units; for units per degree of crank angle (``mm/degCA``)
        the engine's (:func:`degree_speed` names which).

    Raises
    ------
    UnitSystemError
        For per-degree units without a cam speed, or from units that are not a length per
        second (squared, for ``/deg^2``).
    """
    import numpy as np

    values = np.asarray(values)
    if values.dtype.kind != "f" or not from_units or not to_units or from_units == to_units:
        return values
    length, power = per_degree(to_units)
    if not power:
        return values * convert(1.0, from_units, to_units)
    if cam_speed_rpm is None:
        raise no_speed(to_units)
    per_second = f"{length}/s" if power == 1 else f"{length}/s^2"
    try:
        scale = convert(1.0, from_units, per_second)
    except Exception:  # pint's DimensionalityError: not a length per second
        raise UnitSystemError.at(
            "units",
            f"cannot show {from_units} in {to_units}: not a {per_second}",
            found=from_units,
            expected=per_second,
        ) from None
    speed = np.asarray(cam_speed_rpm, dtype=float)
    if speed.ndim:
        speed = speed.reshape(speed.shape + (1,) * (values.ndim - 1))
    return values * scale / (speed * DEG_PER_S_PER_RPM) ** power
