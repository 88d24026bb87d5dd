"""Tracking the needle holder in bench-session video by an ArUco marker fixed on it.

Per frame: ArUco detection with sub-pixel corner refinement, the marker's pose by
``cv2.solvePnP`` (IPPE for squares: of its two solutions the one nearer the previous
frame's rotation), the instrument tip from the marker pose and the tip's measured
offset in the marker frame. Frames without the marker are filled by interpolation
over short gaps; the path is then smoothed by a zero-phase low-pass filter and
becomes :class:`metrics.SessionStreams` with the tool position only (no force, no
needle state), so the motion metrics of the registry apply unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from metrics.bench.camera import DICTIONARY, Camera, aruco_dictionary
from metrics.errors import MetricsError
from metrics.streams import SessionStreams

SMOOTHING_HZ = 3.0
"""Low-pass cut-off for the tracked path. At 30 frames/s a marker's pose noise (~0.5 mm per frame at
30 cm) dominates above ~3 Hz, where deliberate suturing hand motion has little power; at 6 Hz the
jerk-based smoothness (LDLJ) of a tracked path was 10 % off its ground truth, at 3 Hz 1.7 %."""
AMBIGUOUS_FIT_RATIO = 0.5
"""IPPE's two poses count as equally good when the better reprojection error is over half the other's."""
MAX_GAP_S = 0.5
"""Gaps without the marker up to this long are interpolated; longer ones stop the import."""


@dataclass(frozen=True)
class ToolMarker:
    """The marker on the needle holder: id, side (m), dictionary, and the instrument tip's position in
    the marker frame (m; marker centre at the origin, x right, y up, z out of the marker)."""

    marker_id: int = 7
    side_m: float = 0.03
    tip_offset_m: tuple[float, float, float] = (0.0, -0.06, -0.01)
    dictionary: str = DICTIONARY

    def corners(self) -> NDArray[np.float64]:
        """(4, 3) marker corners in the marker frame, in ArUco's order (top-left, clockwise)."""
        h = self.side_m / 2
        return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


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


class MarkerTracker:
    """Finds one marker in frames and returns the tool tip (camera frame, m) for each."""

    def __init__(self, camera: Camera, marker: ToolMarker | None = None) -> None:
        import cv2

        self.camera = camera
        self.marker = marker or ToolMarker()
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        parameters.cornerRefinementWinSize = 9  # half-window (px): 5 left 0.35 mm depth bias, 9 0.29 mm
        parameters.cornerRefinementMaxIterations = 50
        parameters.cornerRefinementMinAccuracy = 0.01
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(self.marker.dictionary), parameters)
        self._object = self.marker.corners().astype(np.float64)
        self._offset = np.asarray(self.marker.tip_offset_m, dtype=np.float64)
        self._previous_rotation: NDArray[np.float64] | None = None
        self._roi: tuple[int, int, int, int] | None = None

    def _detect(self, grey: NDArray[np.uint8]) -> NDArray[np.float64] | None:
        """(4, 2) image corners of the marker, searching near the last sighting first."""
        if self._roi is not None:
            x0, y0, x1, y1 = self._roi
            corners = self._find(grey[y0:y1, x0:x1])
            if corners is not None:
                return corners + np.array([x0, y0])
        return self._find(grey)

    def _find(self, grey: NDArray[np.uint8]) -> NDArray[np.float64] | None:
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None:
            return None
        hits = np.flatnonzero(ids.ravel() == self.marker.marker_id)
        if hits.size == 0:
            return None
        return corners[int(hits[0])].reshape(4, 2).astype(np.float64)

    def locate(self, frame: NDArray[np.uint8]) -> tuple[NDArray[np.float64] | None, float]:
        """The tool tip (3,) in the camera frame (m) and the reprojection error (px), or (None, nan)."""
        import cv2

        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        corners = self._detect(grey)
        if corners is None:
            self._roi = None
            return None, float("nan")
        margin = 1.5 * float(np.ptp(corners, axis=0).max())
        low = np.maximum(corners.min(axis=0) - margin, 0).astype(int)
        high = np.minimum(corners.max(axis=0) + margin, [grey.shape[1], grey.shape[0]]).astype(int)
        self._roi = (int(low[0]), int(low[1]), int(high[0]), int(high[1]))
        count, rotations, translations, errors = cv2.solvePnPGeneric(
            self._object, corners, self.camera.matrix, self.camera.distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        if count == 0:
            return None, float("nan")
        choices = [cv2.Rodrigues(r)[0] for r in rotations]
        residuals = np.ravel(errors)
        best = int(np.argmin(residuals))
        if self._previous_rotation is not None and count > 1:
            # The two IPPE solutions mirror each other. A clearly better fit decides; when both fit about
            # equally (a marker seen nearly face-on) the one continuing the last frame's rotation does.
            ordered = np.sort(residuals)
            if ordered[0] > AMBIGUOUS_FIT_RATIO * ordered[1]:
                best = int(np.argmin([np.linalg.norm(R - self._previous_rotation) for R in choices]))
        rotation = choices[best]
        self._previous_rotation = rotation
        tip = rotation @ self._offset + translations[best].ravel()
        return tip, float(residuals[best])


def track_frames(
    frames: Iterable[NDArray[np.uint8]],
    fps: float,
    camera: Camera,
    marker: ToolMarker | None = None,
    progress: Callable[[int], None] | None = None,
) -> TrackedPath:
    """Track every frame (BGR or grey) of a video shot at ``fps``."""
    tracker = MarkerTracker(camera, marker)
    tips, errors = [], []
    for k, frame in enumerate(frames):
        tip, error = tracker.locate(frame)
        tips.append(np.full(3, np.nan) if tip is None else tip)
        errors.append(error)
        if progress is not None:
            progress(k + 1)
    if len(tips) < 4:
        raise MetricsError(f"the video has {len(tips)} frames; tracking needs at least 4")
    raw = np.array(tips)
    time = np.arange(len(raw)) / float(fps)
    return TrackedPath(time, smooth_path(time, raw), raw, np.isfinite(raw[:, 0]), np.array(errors))


def smooth_path(time: NDArray[np.float64], raw: NDArray[np.float64], cutoff_hz: float = SMOOTHING_HZ):
    """Fill short gaps linearly, then a zero-phase 4th-order Butterworth low-pass at ``cutoff_hz``."""
    from scipy.signal import butter, sosfiltfilt

    found = np.isfinite(raw[:, 0])
    if found.sum() < 4:
        raise MetricsError(f"the marker was found in {int(found.sum())} frames; tracking needs at least 4")
    gaps = _gap_lengths(found, time)
    if gaps.max(initial=0.0) > MAX_GAP_S:
        raise MetricsError(
            f"the marker was lost for {gaps.max():.2f} s (more than {MAX_GAP_S} s); check lighting and that "
            "the marker faces the camera"
        )
    filled = np.column_stack([np.interp(time, time[found], raw[found, k]) for k in range(3)])
    rate = 1.0 / float(np.median(np.diff(time)))
    if cutoff_hz >= rate / 2:
        return filled
    sos = butter(4, cutoff_hz, fs=rate, output="sos")
    return sosfiltfilt(sos, filled, axis=0)


def _gap_lengths(found: NDArray[np.bool_], time: NDArray[np.float64]) -> NDArray[np.float64]:
    edges = np.diff(np.r_[0, (~found).astype(int), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    step = float(np.median(np.diff(time)))
    return (stops - starts) * step


def read_video(path) -> tuple[Iterable[NDArray[np.uint8]], float, int]:
    """Frames (grey uint8) of a video file through PyAV, its frame rate and frame count (0 if unknown)."""
    import av

    try:
        container = av.open(str(path))
    except (av.FFmpegError, OSError) as error:
        raise MetricsError(f"video {path} cannot be opened: {error}") from None
    stream = container.streams.video[0]
    stream.thread_type = "AUTO"
    fps = float(stream.average_rate or stream.guessed_rate or 0) or 30.0

    def frames():
        with container:
            for frame in container.decode(stream):
                yield frame.to_ndarray(format="gray")

    return frames(), fps, int(stream.frames or 0)


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
