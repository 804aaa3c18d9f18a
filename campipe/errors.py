"""campipe's exceptions share one base, :class:`CampipeError`.

An error names what went wrong as attributes, so a caller maps it without parsing its text:
``key`` (the spec key or parameter, e.g. ``run.dt``), ``found`` (the offending value, as
given) and ``expected`` (what would be accepted). The message stays readable on its own.
"""

from __future__ import annotations


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
    """

    def __init__(
        self,
        message: str,
        *,
        key: str | None = None,
        found: object = None,
        expected: str | None = None,
    ) -> None:
        super().__init__(message)
        self.key = key
        self.found = found
        self.expected = expected
