"""campipe's exceptions share one base, :class:`CampipeError`.

An error names what went wrong as attributes, so a caller maps it without parsing its text:
``key`` (the spec key or parameter, e.g. ``run.dt``), ``found`` (the offending value, as
given), ``expected`` (what would be accepted) and ``reason`` (the message without the key, for
a caller that names the key its own way, such as a spec path). The message stays readable on
its own.
"""

from __future__ import annotations

import difflib
import reprlib
from collections.abc import Iterable
from typing import Self

#: Characters of a value an error message shows at most.
EXCERPT = 60

_repr = reprlib.Repr()
_repr.maxlevel = 3
_repr.maxstring = EXCERPT
_repr.maxother = EXCERPT
_repr.maxlong = 40
for _name in ("maxlist", "maxtuple", "maxdict", "maxset", "maxfrozenset", "maxdeque", "maxarray"):
    setattr(_repr, _name, 4)


def excerpt(value: object, limit: int = EXCERPT) -> str:
    """A short ``repr`` of ``value`` for a message: nested or long values are cut (``...``)
    without building their whole repr, so a huge or self-repeating value costs nothing."""
    try:
        text = _repr.repr(value)
    except (ValueError, RecursionError):  # an int beyond Python's digit limit, say
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


class CampipeError(Exception):
    """Base of campipe's errors.

    Parameters
    ----------
    message : str
        The whole message, readable on its own.
    key : str, optional
        The spec key, parameter or option the error is about.
    found : object, optional
        The value found there.
    expected : str, optional
        What would be accepted.
    reason : str, optional
        The message without its key (what :meth:`at` puts after ``"key: "``); defaults to
        the whole message.
    """

    def __init__(
        self,
        message: str,
        *,
        key: str | None = None,
        found: object = None,
        expected: str | None = None,
        reason: str | None = None,
    ) -> None:
        super().__init__(message)
        self.key = key
        self.found = found
        self.expected = expected
        self.reason = message if reason is None else reason

    @classmethod
    def at(
        cls, key: str, reason: str, *, found: object = None, expected: str | None = None
    ) -> Self:
        """The error ``"<key>: <reason>"``, with ``key`` and ``reason`` kept apart."""
        return cls(f"{key}: {reason}", key=key, found=found, expected=expected, reason=reason)


def did_you_mean(word: object, known: Iterable[str]) -> str:
    """``"; did you mean 'speed'?"`` for a near miss, else ``""``."""
    if not isinstance(word, str) or len(word) > 100:
        return ""
    close = difflib.get_close_matches(word, list(known), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
