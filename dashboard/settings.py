"""The dashboard's settings, declared once: (name, default, help), passed to ``create_app``."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path


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
    login_attempts: int = _setting(5, "failed sign-ins allowed per user name and address in the window")
    login_window_s: float = _setting(300.0, "the rate-limit window for failed sign-ins, in seconds")
    live_poll_s: float = _setting(0.2, "how often the live view reads a running station's journal, seconds")
    live_rate_hz: float = _setting(50.0, "samples per second sent to a live view (decimated)")

    @property
    def ingest_root(self) -> Path:
        """Where remote stations' streams land (one folder per station and session)."""
        return self.home / "ingest"


def documented_settings() -> list[tuple[str, object, str]]:
    """(name, default, help) of every setting with a default."""
    return [
        (f.name, f.default, f.metadata["help"]) for f in fields(DashboardSettings) if "help" in f.metadata
    ]
