"""campipe's exceptions share one base, :class:`CampipeError`.

An error names what went wrong as attributes, so a caller maps it without parsing its text:
``key`` (the spec key or parameter, e.g. ``run.dt``), ``found`` (the offending value, as
given), ``expected`` (what would be accepted) and ``reason`` (the message without the key, for
a caller that names the key its own way, such as a spec path). The message stays readable on
its own.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Self


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
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
