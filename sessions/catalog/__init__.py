"""The catalog: every table, query and migration of the sessions' SQL database (SQLite by default,
PostgreSQL by URL), behind one object and one store.

- :mod:`~sessions.catalog.engine`: the :class:`Catalog` (engine, transactions, migrations, a new
  session's trial number) and the errors by type (``NotFound``, ``AlreadyExists``, ``WrongState``,
  ``Forbidden``), mapped to HTTP by the dashboard;
- :mod:`~sessions.catalog.models`: the tables; :mod:`~sessions.catalog.migrations`: Alembic's;
- :mod:`~sessions.catalog.store`: the :class:`~sessions.catalog.store.CatalogStore`, the domain API
  the front-ends read (:mod:`~sessions.catalog.admin`, :mod:`~sessions.catalog.listing`,
  :mod:`~sessions.catalog.views` with :mod:`~sessions.catalog.scope`, returning
  :mod:`~sessions.catalog.records`); :mod:`~sessions.catalog.accounts`: users, passwords, tokens.

Nothing outside this folder writes SQL (tests/test_layering.py holds the list still to move here).
"""

from __future__ import annotations

from sessions.catalog.engine import (
    AlreadyExists,
    Catalog,
    CatalogError,
    Forbidden,
    NotFound,
    WrongState,
    alembic_config,
    make_engine,
    metric_results,
    new_uid,
    now,
    stream_file,
)

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
