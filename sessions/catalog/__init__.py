"""The catalog: every table, query and migration of the sessions' SQL database (SQLite by default,
PostgreSQL by URL), behind one object and one store.

- :mod:`~sessions.catalog.engine`: the :class:`Catalog` (engine, transactions, migrations, a new
  session's trial number); :mod:`~sessions.catalog.errors`: the errors by type (``NotFound``,
  ``AlreadyExists``, ``WrongState``, ``Forbidden``), mapped to HTTP by the dashboard;
  :mod:`~sessions.catalog.groups`: the closed vocabulary of groups a participant is stored under;
- :mod:`~sessions.catalog.models`: the tables; :mod:`~sessions.catalog.migrations`: Alembic's;
- :mod:`~sessions.catalog.store`: the :class:`~sessions.catalog.store.CatalogStore`, the domain API
  the front-ends read (:mod:`~sessions.catalog.admin`, :mod:`~sessions.catalog.listing`,
  :mod:`~sessions.catalog.views` with :mod:`~sessions.catalog.scope`, returning
  :mod:`~sessions.catalog.records`); :mod:`~sessions.catalog.accounts`: users, passwords, tokens;
- the queries the domain modules run inside their own transactions: :mod:`~sessions.catalog.lookups`,
  :mod:`~sessions.catalog.results`, :mod:`~sessions.catalog.standards`.

Nothing outside this folder writes SQL (tests/test_layering.py holds the list still to move here).
"""

from __future__ import annotations

from sessions.catalog.engine import (
    Catalog,
    alembic_config,
    make_engine,
    metric_results,
    new_uid,
    now,
    stream_file,
)
from sessions.catalog.errors import AlreadyExists, CatalogError, Forbidden, NotFound, WrongState

__all__ = [
    "AlreadyExists",
    "Catalog",
    "CatalogError",
    "Forbidden",
    "NotFound",
    "WrongState",
    "alembic_config",
    "make_engine",
    "metric_results",
    "new_uid",
    "now",
    "stream_file",
]
