"""Durable session recording: schemas, a non-blocking writer, crash recovery, a checked reader."""

from recorder.reader import Session, list_sessions, open_session
from recorder.schema import COLUMN, SAMPLE_COLUMNS, SCHEMA_VERSION, RecorderError
from recorder.writer import SessionWriter, recover

__all__ = [
    "COLUMN",
    "SAMPLE_COLUMNS",
    "SCHEMA_VERSION",
    "RecorderError",
    "Session",
    "SessionWriter",
    "list_sessions",
    "open_session",
    "recover",
]
