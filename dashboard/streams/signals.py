"""A recorded session's plotted signals, its replay video, and its files, read from the data directory."""

from __future__ import annotations

import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from dashboard.errors import DashboardError, not_found
from metrics.replay.reference import SIGNALS, signal_of
from metrics.session.events import readable_events
from metrics.signals.tissue import with_tissue_fields
from metrics.streams import from_recorded
from recorder import open_session
from recorder.writer import SAMPLES_FILE
from sessions.config import cache_dir
from sessions.tasks import session_tissue

MAX_POINTS = 2000
"""Plotted points per signal: each is the largest value of its time bin, so no peak is lost."""
VIDEO_SUFFIXES = ("-vs.mp4", ".mp4", "-vs.webm", ".webm")
CACHED_SESSIONS = 32


def inside(home: Path, path: Path) -> Path:
    """``path`` resolved, refused unless it lies inside the data directory ``home``."""
    resolved = path.resolve()
    if not resolved.is_relative_to(home.resolve()):
        raise DashboardError(403, f"{path.name!r} lies outside the data directory")
    return resolved


def binned_peaks(
    time: np.ndarray, values: np.ndarray, points: int = MAX_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """(bin start times, largest finite value per bin; NaN for bins without one)."""
    size = max(1, int(np.ceil(values.size / points)))
    count = values.size // size * size
    if count == 0:
        return time[:0], values[:0]
    blocks = values[:count].reshape(-1, size)
    finite = np.isfinite(blocks)
    peaks = np.where(finite.any(axis=1), np.max(np.where(finite, blocks, -np.inf), axis=1), np.nan)
    return time[:count:size], peaks


class SignalCache:
    """Plot data per session directory, recomputed when its samples file changes."""

    def __init__(self, home: Path) -> None:
        self.home = home
        self._held: OrderedDict[tuple, dict] = OrderedDict()
        self._lock = threading.Lock()

    def signals(self, directory: str) -> dict:
        folder = inside(self.home, Path(directory))
        samples = folder / SAMPLES_FILE
        if not samples.exists():
            raise not_found("recorded samples of this session")
        key = (str(folder), samples.stat().st_mtime_ns)
        with self._lock:
            if key in self._held:
                return self._held[key]
        data = self._compute(folder)
        with self._lock:
            self._held[key] = data
            while len(self._held) > CACHED_SESSIONS:
                self._held.popitem(last=False)
        return data

    def _compute(self, folder: Path) -> dict:
        streams = from_recorded(open_session(folder))
        tissue = session_tissue(streams, cache_dir(self.home))
        if tissue is not None:
            streams = with_tissue_fields(streams, tissue)
        out: dict = {"duration_s": float(streams.duration), "signals": {}, "events": []}
        for name, (label, factor) in SIGNALS.items():
            values = signal_of(streams, name)
            if values is None:
                continue
            times, peaks = binned_peaks(streams.time, values * factor)
            out["signals"][name] = {
                "label": label,
                "time": [round(float(t), 4) for t in times],
                "values": [None if not np.isfinite(v) else round(float(v), 5) for v in peaks],
            }
        out["events"] = readable_events(streams.events)
        return out


def replay_video(home: Path, uid: str) -> Path | None:
    """The session's rendered replay (``vascsim replay``'s default paths), the expert comparison first."""
    for suffix in VIDEO_SUFFIXES:
        path = home / "replays" / f"{uid}{suffix}"
        if path.is_file():
            return inside(home, path)
    return None


def session_file(home: Path, directory: str, name: str, catalogued: set[str]) -> Path:
    """A stream file of a session: only names the catalog lists, only inside the data directory."""
    if name not in catalogued or "/" in name or "\\" in name or name.startswith("."):
        raise not_found(f"file {name!r} of this session")
    path = inside(home, Path(directory) / name)
    if not path.is_file():
        raise not_found(f"file {name!r} of this session")
    return path
