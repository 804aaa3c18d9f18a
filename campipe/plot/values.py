"""A value a figure's option gives (``--limit``, ``--level``) as a value of a column in the
units it is shown in: a number as it is, a quantity converted, a length per degree only
against a column shown per degree of the same angle."""

from __future__ import annotations

from typing import Any

from campipe.study.spec.plots import PlotError
from campipe.units import (
    QuantityError,
    convert,
    degree_speed,
    per_degree,
    read_quantity,
    written_per_degree,
)


def shown_value(value: str | float, view: Any, name: str, key: str) -> float:
    """A value of the column ``name`` of ``view`` (a ``figures.View``: its ``shown.units``)
    in its shown units: a number as it is, a quantity (``1 deg``, ``0.5 m/s``, ``0.2
    mm/deg``) converted; a PlotError naming ``key`` otherwise (a length per degree against a
    column shown per second, or the other way: the one is a different value of the other at
    each speed)."""
    if isinstance(value, int | float):
        return float(value)
    try:
        return float(value)
    except ValueError:
        pass
    shown = view.shown.units.get(name) or ""
    if written_per_degree(str(value)) or per_degree(shown)[1]:
        return _per_degree_value(str(value).strip(), shown, name, key)
    try:
        q = read_quantity(str(value), key)
        return convert(float(q.magnitude), str(q.units), shown)
    except Exception as exc:  # QuantityError, or pint's for units of another dimension
        reason = exc.reason if isinstance(exc, QuantityError) else "not of its kind"
        raise PlotError.at(
            key, f"cannot read {value!r} as a value of {name} [{shown}] ({reason})"
        ) from None


def _per_degree_value(value: str, shown: str, name: str, key: str) -> float:
    """``value`` (a number and its units) as a value of ``name`` shown in ``shown``, one of
    the units a length per degree (``units.per_degree``): the other must be too, of the same
    power and angle (the cam's, or the crank's)."""
    number, given = written_per_degree(value) or ("", "")
    (length, power), (to_length, to_power) = per_degree(given), per_degree(shown)
    same = power and power == to_power and degree_speed([given]) == degree_speed([shown])
    try:
        if same:
            return float(number) * convert(1.0, length, to_length)
    except Exception:  # pint's, not a length; float's
        pass
    raise PlotError.at(
        key,
        f"cannot draw {value!r} on {name} [{shown}]: write it in {shown} (a value per "
        "degree is a different one per second at each speed), or choose --units to match",
    )
