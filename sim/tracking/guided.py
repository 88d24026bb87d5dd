"""Calibrating a camera live: which views of the ChArUco board are still missing, then the fit.

A good calibration needs the board seen square-on and tilted each way (the tilts are what pin the
focal length down), filling much of the image. :class:`CalibrationViews` watches the frames, finds
the board in each, sorts it by how it is tilted (a rough pose from a nominal focal length is enough
to tell), keeps the best few views of each kind, and says which kinds are still missing, so the
person holding the board is guided view by view. When every kind has enough views it calibrates
(:func:`sim.tracking.camera.calibrate_charuco`) and refuses a poor fit.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError
from sim.tracking.camera import BoardSpec, Camera, calibrate_charuco

KINDS = ("square-on", "tilted left", "tilted right", "tilted up", "tilted down")
VIEWS_PER_KIND = 3
TILT_DEG = 15.0
"""A board turned more than this about a side axis counts as tilted that way."""
MIN_CORNERS = 12
MIN_SPACING_S = 0.3
"""Frames kept for one kind are at least this far apart (consecutive frames are near copies)."""
MAX_RMS_PX = 1.0
"""A calibration whose reprojection error exceeds 1 px is refused (a sharp board gives 0.1-0.5 px)."""


class CalibrationViews:
    """Collects board views by kind (see the module docstring)."""

    def __init__(self, board: BoardSpec | None = None) -> None:
        import cv2

        self.board = board or BoardSpec()
        self._charuco = self.board.board()
        self._detector = cv2.aruco.CharucoDetector(self._charuco)
        self.views: dict[str, list[tuple[float, int, NDArray[np.uint8]]]] = {kind: [] for kind in KINDS}
        self.size: tuple[int, int] | None = None
        self.last_corners: NDArray[np.float32] | None = None  # (n, 1, 2) px: the board in the last frame

    def offer(self, time: float, frame: NDArray[np.uint8]) -> str | None:
        """Look at one frame (grey); returns the kind of view it was kept as, or None."""
        import cv2

        self.size = (frame.shape[1], frame.shape[0])
        corners, ids, _, _ = self._detector.detectBoard(frame)
        self.last_corners = corners if ids is not None else None
        if ids is None or len(ids) < MIN_CORNERS:
            return None
        object_points, image_points = self._charuco.matchImagePoints(corners, ids)
        width, height = self.size
        nominal = np.array([[0.9 * width, 0, width / 2], [0, 0.9 * width, height / 2], [0, 0, 1.0]])
        ok, rotation, _ = cv2.solvePnP(object_points, image_points, nominal, None)
        if not ok:
            return None
        kind = _kind(cv2.Rodrigues(rotation)[0])
        kept = self.views[kind]
        if kept and time - kept[-1][0] < MIN_SPACING_S:
            return None
        kept.append((time, len(ids), frame.copy()))
        kept.sort(key=lambda view: -view[1])  # the views with most corners first
        del kept[VIEWS_PER_KIND:]
        return kind

    def counts(self) -> dict[str, int]:
        """Views kept so far, by kind."""
        return {kind: len(kept) for kind, kept in self.views.items()}

    def missing(self) -> list[str]:
        """The kinds of view that still need more (each needs :data:`VIEWS_PER_KIND`)."""
        return [kind for kind in KINDS if len(self.views[kind]) < VIEWS_PER_KIND]

    def calibrate(self) -> Camera:
        """The camera from the views kept; refuses when a kind is missing or the fit is poor."""
        missing = self.missing()
        if missing:
            raise TrackingError(
                f"the board still has to be shown {', '.join(missing)}; hold it in view, turned that way"
            )
        frames = [frame for kind in KINDS for _, _, frame in self.views[kind]]
        camera = calibrate_charuco(frames, self.board)
        if not camera.rms <= MAX_RMS_PX:
            raise TrackingError(
                f"the calibration's reprojection error is {camera.rms:.2f} px (at most {MAX_RMS_PX:.1f} px): "
                "hold the board flat and still, in focus and in even light, and calibrate again"
            )
        return camera


def _kind(rotation: NDArray[np.float64]) -> str:
    """Which way the board's normal turns from the optical axis (camera frame: x right, y down)."""
    normal = rotation[:, 2]  # the board's z axis, into the board, in the camera frame
    left_right = math.degrees(math.atan2(normal[0], normal[2]))
    up_down = math.degrees(math.atan2(normal[1], normal[2]))
    if max(abs(left_right), abs(up_down)) < TILT_DEG:
        return "square-on"
    if abs(left_right) >= abs(up_down):
        return "tilted right" if left_right > 0 else "tilted left"
    return "tilted down" if up_down > 0 else "tilted up"


DEVICE_FROM_BOARD = np.diag([1.0, -1.0, -1.0])
"""A board lying on the table, its first row away from the trainee: its x is the trainee's right, its y
(down the rows) points at the trainee, its z into the table; the device frame's x is the right, y away
from the trainee (up the screen), z up from the table (out of the screen)."""
MIN_TABLE_CORNERS = 12


def table_registration(frame: NDArray[np.uint8], camera: Camera, board: BoardSpec | None = None):
    """The rotation from the camera's axes into the device frame (``device_from_camera``), from one
    view of the board lying flat on the table, its first row away from the trainee; and the board's
    reprojection error (px). Refuses a frame where too little of the board is seen."""
    import cv2

    board = board or BoardSpec()
    charuco = board.board()
    corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco).detectBoard(frame)
    if ids is None or len(ids) < MIN_TABLE_CORNERS:
        seen = 0 if ids is None else len(ids)
        raise TrackingError(
            f"the board was seen with {seen} corners (at least {MIN_TABLE_CORNERS} needed): lay it flat on "
            "the table in the camera's view, in good light"
        )
    object_points, image_points = charuco.matchImagePoints(corners, ids)
    ok, rotation, translation = cv2.solvePnP(object_points, image_points, camera.matrix, camera.distortion)
    if not ok:
        raise TrackingError("the board's pose could not be solved: show more of it to the camera")
    projected, _ = cv2.projectPoints(object_points, rotation, translation, camera.matrix, camera.distortion)
    error = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - image_points.reshape(-1, 2)) ** 2, 1))))
    if error > MAX_RMS_PX:
        raise TrackingError(
            f"the board on the table fits its pose to {error:.2f} px (at most {MAX_RMS_PX:.1f} px): lay it "
            "flat and still, in focus, and check the camera's calibration"
        )
    camera_from_board = cv2.Rodrigues(rotation)[0]
    return DEVICE_FROM_BOARD @ camera_from_board.T, error
