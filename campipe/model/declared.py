"""One model parameter's declaration (:class:`Parameter`): its name, units, bounds and
default, declared once and read by the spec, the schema, ``campipe model --set`` and the
archive (:data:`campipe.model.parameters.PARAMETERS` holds them all); and the error a
parameter raises (:class:`ModelParameterError`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from campipe.errors import CampipeError


class ModelParameterError(CampipeError, ValueError):
    """A model parameter that is unknown, badly typed or out of range; ``key`` is the key path
    named in the message (``model.spring_rate``, ``damping_ratios[1]``)."""


@dataclass(frozen=True)
class Parameter:
    """Metadata of one model parameter, declared once."""

    name: str  # key in specs, --set and the archive
    long_name: str  # CF long_name
    units: str  # SI units of the numerics and the archive (pint spelling)
    thesis_units: str  # units the thesis preset is written in (pint spelling)
    minimum: float  # smallest allowed value in SI (exclusive when exclusive_minimum)
    exclusive_minimum: bool = True
    length: int = 0  # 0 for a scalar, else a list of one value or more (the thesis: this many)
    integer: bool = False  # a whole number (a count)
    choices: tuple[str, ...] = ()  # the words a choice takes (units then "")
    default: object = None  # the value (spec form) where neither preset nor override gives one
    maximum: float = math.inf  # largest allowed value (counts: the matrices stay small)
    allow_none: bool = False  # "none" (or null) accepted, meaning absent: NaN in SI
    min_length: int = 1  # fewest values of a list (0: an empty list, "not given")

    @property
    def continuous(self) -> bool:
        """A scalar number or quantity: what a range {from, to, num} or a sample may vary."""
        return not (self.length or self.integer or self.choices)
