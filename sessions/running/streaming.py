"""A station streaming its sessions to a central recorder (``--stream-to``): every batch the local
recording makes durable is spooled and sent (recorder.remote.station.StationUploader), and the window's
newest frame goes to the dashboard's live page (recorder.remote.station.ViewSender).

The local recording is the session of record: a central recorder that is down, slow or refusing never
stops or fails a trainee's trial. What it has not acknowledged stays in the station's spool
(``home/spool/<session>``) and the next streamed session sends it first.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from recorder.remote.protocol import CLOSING_STATUSES
from recorder.remote.station import StationUploader, ViewSender
from recorder.schema import RecorderError
from sessions.catalog import Catalog
from sessions.catalog.errors import CatalogError
from sessions.catalog.lookups import session_with_uid
from sessions.running.live import live_view_path
from sessions.status import SessionStatus

STATION_TOKEN_VARIABLE = "VASCSIM_STATION_TOKEN"
"""The environment variable holding this station's ingest token (issued on the dashboard's
Administration page; never on a command line, where other users of the machine can read it)."""
DRAIN_TIMEOUT_S = 20.0
"""How long a finished session waits for the central recorder to acknowledge what is left."""
log = logging.getLogger("vascsim.streaming")


@dataclass(frozen=True)
class StreamTarget:
    """The central recorder a station streams to: its ingest address and this station's token."""

    url: str
    token: str
    drain_timeout_s: float = DRAIN_TIMEOUT_S

    @classmethod
    def from_environment(cls, url: str) -> StreamTarget:
        """The target at ``url`` (``http(s)://host[:port]/ingest``, the dashboard's ingest) with the
        token in :data:`STATION_TOKEN_VARIABLE`; CatalogError naming what is missing."""
        if not url.startswith(("http://", "https://")):
            raise CatalogError(f"stream address {url!r} must start with http:// or https://")
        token = os.environ.get(STATION_TOKEN_VARIABLE, "").strip()
        if not token:
            raise CatalogError(
                f"streaming to {url} needs this station's token in {STATION_TOKEN_VARIABLE} "
                "(issued on the dashboard's Administration page)"
            )
        return cls(url.rstrip("/"), token)


def spool_root(home: Path) -> Path:
    return home / "spool"


class StreamedSession:
    """One session's stream: its header, every batch (``submit`` is the writer's mirror), the window's
    view while it runs, and the close once the recording is finished."""

    def __init__(self, target: StreamTarget, home: Path, uid: str, header: dict) -> None:
        self.target, self.home, self.uid = target, home, uid
        self.spool = spool_root(home) / uid
        self.uploader = StationUploader(target.url, target.token, uid, self.spool)
        self.uploader.set_header(header)
        self.views = ViewSender(target.url, target.token, uid, live_view_path(home, uid))

    @property
    def submit(self):
        return self.uploader.submit

    def start(self) -> None:
        self.uploader.start()
        self.views.start()

    def finish(self, status: str) -> str | None:
        """Close the stream once the recording is closed; None when the central recorder holds all
        of it, else a line saying what stays in the spool (the trial itself is kept locally)."""
        self.views.stop()
        try:
            self.uploader.finish(status)
            self.uploader.stop(timeout=self.target.drain_timeout_s)
        except RecorderError as error:
            if self.uploader.error is not None:  # refused: the refusal names what and why
                return str(error)
            return (
                f"central recorder {self.target.url} did not take {self.uploader.pending} item(s) of "
                f"session {self.uid} within {self.target.drain_timeout_s:g} s"
            )
        finally:
            self.uploader.close()
        shutil.rmtree(self.spool, ignore_errors=True)
        return None


def catalog_status(catalog: Catalog) -> Callable[[str], str | None]:
    """``status_of`` for :func:`send_leftovers` from this station's catalog."""

    def status_of(uid: str) -> str | None:
        with catalog.session() as orm:
            row = session_with_uid(orm, uid)
            return None if row is None else str(row.status)

    return status_of


def send_leftovers(
    target: StreamTarget, home: Path, status_of: Callable[[str], str | None], timeout: float = 2.0
) -> list[str]:
    """Send what earlier streamed sessions left in this station's spool (the link was down when they
    ended, or the station crashed during them); a spool the central recorder now holds entirely is
    removed. Returns a line per session still left (kept for the next try).

    ``status_of(uid)``: the session's status in this station's catalog (None when it has none). A
    session still ``running`` here is left alone: it is recording now, or a crash left it and it has
    not been recovered. One that ended without asking the central recorder to close its copy (the
    station crashed, the session was recovered or failed here since) is closed there with that
    status, so the central copy stops showing as recording; it holds what the station had sent."""
    root = spool_root(home)
    left = []
    for spool in sorted(root.iterdir()) if root.is_dir() else []:
        status = status_of(spool.name)
        if status == SessionStatus.RUNNING:
            left.append(f"session {spool.name} is still recording here, or a crash left it unrecovered")
            continue
        uploader = StationUploader(target.url, target.token, spool.name, spool, timeout=timeout)
        try:
            if status is not None and not (spool / "close.json").exists():
                uploader.finish(status if status in CLOSING_STATUSES else SessionStatus.FAILED)
            uploader.send_pending()
        except RecorderError as error:
            left.append(str(error))
            continue
        finally:
            uploader.close()
        if uploader.pending:
            left.append(f"session {spool.name}: {uploader.pending} item(s) not yet sent to {target.url}")
        else:
            shutil.rmtree(spool, ignore_errors=True)
    return left
