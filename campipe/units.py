"""One pint registry for the whole package, and the parsing of quantities with units.

Specs and ``--set`` write quantities as strings with units (``"9 in"``, ``"245 lbf/in"``,
``"9524 rpm"``); the numerics work in SI floats. Parsing goes through pint's own parser, which
never evaluates Python code.
"""

from __future__ import annotations

import pint

from campipe.errors import CampipeError

ureg: pint.UnitRegistry = pint.UnitRegistry()
Q_ = ureg.Quantity


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
    target = ureg.Unit(units) if units else ureg.dimensionless
    dimensionless = target.dimensionless
    example = example_units or _example_unit(target)
    expected = f"a quantity in {example}" if example else "a number"
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise QuantityError.at(
            key,
            f"expected a quantity such as '1 {example}', found {text!r}",
            found=text,
            expected=expected,
        )
    if isinstance(text, (int, float)):
        if dimensionless:
            return float(text)
        raise QuantityError.at(
            key,
            f"found the bare number {text!r}; write it with units, e.g. '{text} {example}'",
            found=text,
            expected=expected,
        )
    q = _read(text, key, example)
    if not isinstance(q, pint.Quantity):
        q = Q_(float(q), "")
    if q.dimensionless and not dimensionless:
        raise QuantityError.at(
            key,
            f"found {text!r} without units; write it with units, e.g. '{text.strip()} {example}'",
            found=text,
            expected=expected,
        )
    try:
        return float(q.to(target).magnitude)
    except pint.DimensionalityError:
        raise QuantityError.at(
            key,
            f"found {text!r} [{q.dimensionality}], expected a quantity convertible "
            f"to {example} [{target.dimensionality}]",
            found=text,
            expected=expected,
        ) from None


def _read(text: str, key: str, example: str) -> pint.Quantity | float:
    """``text`` as pint reads it (a Quantity, or a plain number), or a QuantityError naming the
    key and suggesting ``example`` units."""
    try:
        return ureg.Quantity(text.strip())
    except Exception as exc:  # pint raises several unrelated types on bad text
        raise QuantityError.at(
            key,
            f"cannot read {text!r} as a quantity ({exc}); "
            f"write a number and a unit, e.g. '1 {example}'",
            found=text,
            expected=f"a quantity in {example}",
        ) from None


def _example_unit(unit: pint.Unit) -> str:
    return f"{unit:~}" if not unit.dimensionless else ""


def convert(value: float, from_units: str, to_units: str) -> float:
    """Convert a float between two pint unit spellings."""
    return float(Q_(value, from_units).to(to_units).magnitude)


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
                f"found the bare number {text!r}; write it with units, "
                f"e.g. '{text} {example_units}'",
                found=text,
                expected=expected,
            )
        raise QuantityError.at(
            key,
            f"expected a quantity such as '1 {example_units}', found {text!r}",
            found=text,
            expected=expected,
        )
    q = _read(text, key, example_units)
    if not isinstance(q, pint.Quantity) or dict(q.to_base_units().unit_items()).get("radian") != 1:
        raise QuantityError.at(
            key,
            f"found {text!r}, expected a quantity whose units name an angle, "
            f"such as '1 {example_units}'",
            found=text,
            expected=expected,
        )
    try:
        return float(q.to(units).magnitude)
    except pint.DimensionalityError:
        raise QuantityError.at(
            key,
            f"found {text!r}, expected a quantity convertible to {example_units}, "
            f"such as '1 {example_units}'",
            found=text,
            expected=expected,
        ) from None
