"""Durable session recording: schemas, a non-blocking writer, crash recovery, a checked reader.

The names below load when first used (PEP 562): a process that needs one submodule (the catalog
checksums files with :mod:`recorder.layout`) does not import the reader, the writer and the scene.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_WHERE = {
    "Session": "recorder.reader",
    "list_sessions": "recorder.reader",
    "open_session": "recorder.reader",
    "COLUMN": "recorder.schema",
    "SAMPLE_COLUMNS": "recorder.schema",
    "SCHEMA_VERSION": "recorder.schema",
    "RecorderError": "recorder.schema",
    "SessionWriter": "recorder.writer",
    "recover": "recorder.writer",
}

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

if TYPE_CHECKING:
    from recorder.reader import Session, list_sessions, open_session
    from recorder.schema import COLUMN, SAMPLE_COLUMNS, SCHEMA_VERSION, RecorderError
    from recorder.writer import SessionWriter, recover


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'recorder' has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name]), name)
