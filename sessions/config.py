"""Where vascsim keeps its data: ``VASCSIM_HOME`` and ``VASCSIM_DATABASE_URL``.

- ``VASCSIM_HOME`` (default ``~/.local/share/vascsim``): the data directory, holding
  ``catalog.sqlite`` (the embedded catalog), ``sessions/`` (one folder of streams per
  session) and ``reports/``.
- ``VASCSIM_DATABASE_URL`` (default ``sqlite:///$VASCSIM_HOME/catalog.sqlite``): a
  SQLAlchemy URL; ``postgresql://user@host/db`` selects the shared server mode.
"""

from __future__ import annotations

import os
from pathlib import Path


def data_home() -> Path:
    value = os.environ.get("VASCSIM_HOME")
    home = Path(value).expanduser() if value else Path.home() / ".local" / "share" / "vascsim"
    return home


def database_url(home: Path | None = None) -> str:
    url = os.environ.get("VASCSIM_DATABASE_URL")
    if url:
        return url
    return f"sqlite:///{(home or data_home()) / 'catalog.sqlite'}"
