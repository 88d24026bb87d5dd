"""The metrics engine's one error: what it was given (a stream, a table, a parameter) is unusable."""

from __future__ import annotations

from sim.errors import VascsimError


class MetricsError(VascsimError, ValueError):
    """A stream, table or parameter given to the metrics engine is unusable; the message names it."""


class GroupsMissing(MetricsError):
    """A comparison of two groups was asked of a table that lacks one or both: ``absent`` names them
    (so a front-end can say which group has no data yet)."""

    def __init__(self, message: str, absent: list[str]) -> None:
        super().__init__(message)
        self.absent = list(absent)


__all__ = ["GroupsMissing", "MetricsError"]
