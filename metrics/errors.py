"""The metrics engine's one error: what it was given (a stream, a table, a parameter) is unusable."""

from __future__ import annotations

from sim.errors import VascsimError


class MetricsError(VascsimError, ValueError):
    """A stream, table or parameter given to the metrics engine is unusable; the message names it."""


__all__ = ["MetricsError"]
