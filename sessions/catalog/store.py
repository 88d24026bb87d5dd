"""The catalog as a store with a domain API: each method runs its own transaction and returns plain
frozen values (:mod:`sessions.catalog.records`), never ORM rows, so a front-end (the CLI, the
dashboard's API and pages) states no rule of its own and two front-ends cannot disagree.

- :mod:`~sessions.catalog.admin`: accounts, sign-ins, station tokens, studies;
- :mod:`~sessions.catalog.listing`: studies, participants and sessions listed, what is scorable, the
  study table an analysis reads, deleting a session;
- :mod:`~sessions.catalog.views`: what one reader may see (:mod:`~sessions.catalog.scope`, the row-level
  rule), for the dashboard.

Errors are the catalog's, by type (:class:`sessions.catalog.NotFound`, ``AlreadyExists``,
``WrongState``, ``Forbidden``), with messages that name the input and carry no front-end's advice.
"""

from __future__ import annotations

from sessions.catalog.admin import Administration
from sessions.catalog.engine import Catalog
from sessions.catalog.listing import Listings
from sessions.catalog.records import (
    AnnotationRecord,
    FileRecord,
    ParticipantRecord,
    SessionFacts,
    SessionRecord,
    StationRecord,
    StudyRecord,
    StudySummary,
    UserRecord,
)
from sessions.catalog.scope import EVERYTHING, STAFF, Scope
from sessions.catalog.views import ScopedReads

__all__ = [
    "EVERYTHING",
    "STAFF",
    "AnnotationRecord",
    "CatalogStore",
    "FileRecord",
    "ParticipantRecord",
    "Scope",
    "SessionFacts",
    "SessionRecord",
    "StationRecord",
    "StudyRecord",
    "StudySummary",
    "UserRecord",
]


class CatalogStore(Administration, Listings, ScopedReads):
    """One catalog's store (see the module docstring)."""

    def __init__(self, catalog: Catalog) -> None:
        self.catalog = catalog
