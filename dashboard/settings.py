"""The dashboard's settings, declared once: (name, default, help), passed to ``create_app``.

Each can be set as ``vascsim serve --setting NAME=VALUE`` or in the environment as
``VASCSIM_SETTING_NAME`` (read by :mod:`sessions.config`); :func:`parse_settings` checks both.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

from sessions.catalog import CatalogError


class SettingError(CatalogError):
    """A setting that is not declared, or a value of the wrong kind; the message names it."""


def _setting(default, help_text: str):
    return field(default=default, metadata={"help": help_text})


@dataclass(frozen=True)
class DashboardSettings:
    """Where the data is and how the web application behaves (each field listed by `vascsim serve --help`)."""

    home: Path
    database_url: str
    host: str = _setting("127.0.0.1", "address to bind; anything but localhost exposes the dashboard")
    port: int = _setting(8000, "TCP port")
    secure_cookies: bool = _setting(False, "mark cookies Secure (set when served behind HTTPS)")
    login_lifetime_s: float = _setting(8 * 3600.0, "how long a sign-in lasts, in seconds")
    login_attempts: int = _setting(
        5, "failed sign-ins per user name and address in the window (4x per name, 10x per address)"
    )
    login_window_s: float = _setting(300.0, "the rate-limit window for failed sign-ins, in seconds")
    live_poll_s: float = _setting(0.2, "how often the live view reads a running station's journal, seconds")
    live_rate_hz: float = _setting(50.0, "samples per second sent to a live view (decimated)")
    header_timeout_s: float = _setting(
        10.0, "a request's headers must arrive within this, seconds (else 408)"
    )
    body_timeout_s: float = _setting(
        10.0, "a request's body must arrive within this plus 1 s per body_min_rate bytes (else 408)"
    )
    body_min_rate: float = _setting(500.0, "bytes per second a slow body must keep up, after body_timeout_s")
    max_connections: int = _setting(256, "connections served at once, WebSockets included (more: 503)")

    @property
    def ingest_root(self) -> Path:
        """Where remote stations' streams land (one folder per station and session)."""
        return self.home / "ingest"


def documented_settings() -> list[tuple[str, object, str]]:
    """(name, default, help) of every setting with a default."""
    return [
        (f.name, f.default, f.metadata["help"]) for f in fields(DashboardSettings) if "help" in f.metadata
    ]


KIND_NAMES = {int: "a whole number", float: "a number", bool: "true or false"}


def parse_settings(given: dict[str, str], source: str) -> dict[str, object]:
    """Declared settings from text values ({name: text}), each converted to its declared type;
    an unknown name or a bad value is a :class:`SettingError` naming it and ``source``."""
    declared = {f.name: f for f in fields(DashboardSettings) if "help" in f.metadata}
    parsed: dict[str, object] = {}
    for name, text in given.items():
        if name not in declared:
            raise SettingError(f"{source}: unknown setting {name!r}; settings: {', '.join(declared)}")
        kind = type(declared[name].default)
        try:
            if kind is bool:
                if text.lower() not in ("1", "0", "true", "false", "yes", "no", "on", "off"):
                    raise ValueError(text)
                value: object = text.lower() in ("1", "true", "yes", "on")
            else:
                value = kind(text)
        except ValueError:
            kind_name = KIND_NAMES.get(kind, kind.__name__)
            raise SettingError(f"{source}: setting {name} must be {kind_name}; got {text!r}") from None
        if isinstance(value, int | float) and not isinstance(value, bool) and not value > 0:
            raise SettingError(f"{source}: setting {name} must be positive; got {text!r}")
        parsed[name] = value
    return parsed
