"""Where a session stands: one enumeration, and the statuses whose streams are finished.

Kept apart from the ORM models so the command line can name the statuses without loading them.
"""

from __future__ import annotations

from enum import StrEnum


class SessionStatus(StrEnum):
    """Where a session stands. Its streams are finished (scorable) once complete or recovered."""

    RUNNING = "running"
    COMPLETE = "complete"
    RECOVERED = "recovered"
    FAILED = "failed"


SESSION_STATUSES = tuple(status.value for status in SessionStatus)
SCORABLE = (SessionStatus.COMPLETE, SessionStatus.RECOVERED)
"""Statuses whose streams are finished: what is scored, analysed, replayed and compared."""

SCRIPTED_DEVICE = "scripted"
"""A session recorded with this device followed a script, not a person's hand: synthetic data."""
