"""Where vascsim keeps its data: the one module that reads settings from the environment.

- ``VASCSIM_HOME`` (default ``~/.local/share/vascsim``): the data directory, holding
  ``catalog.sqlite`` (the embedded catalog), ``sessions/`` (one folder of streams per
  session) and ``reports/``.
- ``VASCSIM_DATABASE_URL`` (default ``sqlite:///$VASCSIM_HOME/catalog.sqlite``): a
  SQLAlchemy URL; ``postgresql://user@host/db`` selects the shared server mode.
- ``VASCSIM_CACHE_DIR`` (default ``$VASCSIM_HOME/cache``): precomputed tissue models.
- ``VASCSIM_SETTING_<NAME>``: a dashboard setting (``vascsim serve --help`` lists them).

It also sets, once, what a library reads from the environment itself: VTK's render-window class
when there is no display (:func:`prepare_rendering`).
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


def cache_dir(home: Path | None = None) -> Path:
    """Where precomputed tissue models are kept: ``VASCSIM_CACHE_DIR``, else ``home/cache``."""
    value = os.environ.get("VASCSIM_CACHE_DIR")
    return Path(value).expanduser() if value else (home or data_home()) / "cache"


SETTING_PREFIX = "VASCSIM_SETTING_"


def settings_from_environment() -> dict[str, str]:
    """``VASCSIM_SETTING_<NAME>=value`` pairs as {name (lower case): value}, unparsed: the front-end
    that declares the setting checks its name and value."""
    return {
        key[len(SETTING_PREFIX) :].lower(): value
        for key, value in os.environ.items()
        if key.startswith(SETTING_PREFIX) and len(key) > len(SETTING_PREFIX)
    }


def prepare_rendering() -> None:
    """Without a display (no ``DISPLAY`` or ``WAYLAND_DISPLAY``) tell VTK to render offscreen with EGL
    (``VTK_DEFAULT_OPENGL_WINDOW``, read when a render window is made): otherwise it tries X first and
    falls back with a warning. A choice made by the user's environment is kept."""
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


LRS_VARIABLES = {
    "endpoint": "VASCSIM_LRS_ENDPOINT",
    "key": "VASCSIM_LRS_KEY",
    "secret": "VASCSIM_LRS_SECRET",
    "home_page": "VASCSIM_LRS_HOME_PAGE",
}
"""Where `vascsim lrs push` finds its LRS when no option names it (a secret in the environment
stays out of the process list)."""


def lrs_setting(name: str) -> str | None:
    """The LRS setting ``name`` (endpoint, key, secret, home_page) from the environment, or None."""
    return os.environ.get(LRS_VARIABLES[name]) or None
