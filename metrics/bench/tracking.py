"""Tracking the needle holder in bench-session video by the ArUco markers fixed on it.

Per frame, the instrument tip from the live camera device's own detector and pose
(:class:`sim.tracking.pose.BodyTracker`: one flat marker or a cube of them). Frames
without the marker are filled by interpolation
over short gaps; the path is then smoothed by a zero-phase low-pass filter and
becomes :class:`metrics.SessionStreams` with the tool position only (no force, no
needle state), so the motion metrics of the registry apply unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.signals.tracked import TRACKED_SMOOTHING_HZ, gap_lengths, tracked_path
from metrics.streams import SessionStreams
from sim.tracking.camera import Camera
from sim.tracking.markers import MarkerBody
from sim.tracking.pose import BodyTracker

SMOOTHING_HZ = TRACKED_SMOOTHING_HZ
MAX_GAP_S = 0.5
"""Gaps without the marker up to this long are interpolated; longer ones stop the import."""


@dataclass(frozen=True)
class TrackedPath:
    """time (n,) s; tip (n, 3) m in the camera frame, smoothed; raw_tip with NaN where the marker was
    not found; found (n,) bool; reprojection_px (n,) marker corner reprojection error."""

    time: NDArray[np.float64]
    tip: NDArray[np.float64]
    raw_tip: NDArray[np.float64]
    found: NDArray[np.bool_]
    reprojection_px: NDArray[np.float64]

    def to_streams(
        self, session_id: str, participant_id: str | None = None, label: str | None = None
    ) -> SessionStreams:
        return SessionStreams(
            session_id=session_id,
            time=self.time,
            tool_position=self.tip,
            participant_id=participant_id,
            label=label,
            attributes={"source": "bench-video", "marker_found_fraction": float(self.found.mean())},
        )


def track_frames(
    frames: Iterable[NDArray[np.uint8]],
    fps: float,
    camera: Camera,
    marker: MarkerBody | None = None,
    progress: Callable[[int], None] | None = None,
) -> TrackedPath:
    """Track every frame (BGR or grey) of a video shot at ``fps``."""
    tracker = BodyTracker(camera, marker or MarkerBody.flat())
    tips, errors = [], []
    for k, frame in enumerate(frames):
        pose = tracker.locate(frame)
        tips.append(np.full(3, np.nan) if pose is None else pose.tip)
        errors.append(np.nan if pose is None else pose.reprojection_px)
        if progress is not None:
            progress(k + 1)
    if len(tips) < 4:
        raise MetricsError(f"the video has {len(tips)} frames; tracking needs at least 4")
    raw = np.array(tips)
    time = np.arange(len(raw)) / float(fps)
    return TrackedPath(time, smooth_path(time, raw), raw, np.isfinite(raw[:, 0]), np.array(errors))


def smooth_path(time: NDArray[np.float64], raw: NDArray[np.float64], cutoff_hz: float = SMOOTHING_HZ):
    """Fill short gaps linearly, then a zero-phase 4th-order Butterworth low-pass at ``cutoff_hz``."""
    found = np.isfinite(raw[:, 0])
    if found.sum() < 4:
        raise MetricsError(f"the marker was found in {int(found.sum())} frames; tracking needs at least 4")
    gaps = gap_lengths(found, time)
    if gaps.max(initial=0.0) > MAX_GAP_S:
        raise MetricsError(
            f"the marker was lost for {gaps.max():.2f} s (more than {MAX_GAP_S} s); check lighting and that "
            "the marker faces the camera"
        )
    return tracked_path(time, raw, cutoff_hz)


TRACK_FILE = "track.parquet"


def save_track(path: TrackedPath, target) -> None:
    """The tracked path as Parquet: time, tip (smoothed), raw tip, found, reprojection error."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = {"time": path.time}
    for prefix, values in (("tip", path.tip), ("raw", path.raw_tip)):
        for k, axis in enumerate("xyz"):
            columns[f"{prefix}_{axis}"] = values[:, k]
    columns["found"] = path.found
    columns["reprojection_px"] = path.reprojection_px
    table = pa.table(columns)
    pq.write_table(table, target, compression="zstd")


def load_track(source) -> TrackedPath:
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(source)
        column = {name: table.column(name).to_numpy() for name in table.column_names}
        return TrackedPath(
            column["time"],
            np.column_stack([column["tip_x"], column["tip_y"], column["tip_z"]]),
            np.column_stack([column["raw_x"], column["raw_y"], column["raw_z"]]),
            column["found"].astype(bool),
            column["reprojection_px"],
        )
    except (OSError, KeyError, ValueError) as error:
        raise MetricsError(f"tracked path {source} is not readable: {error}") from None
