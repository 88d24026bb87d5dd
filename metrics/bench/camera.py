"""Camera model and ChArUco calibration (OpenCV contrib's aruco module).

A calibration is the intrinsic matrix K (pixels), the distortion coefficients and the
image size, saved as JSON. It comes from several views of a ChArUco board: every
detected chessboard corner, refined to sub-pixel accuracy by the board detector, is
matched to its known board position, and ``cv2.calibrateCamera`` fits the model.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError

DICTIONARY = "DICT_4X4_50"


def aruco_dictionary(name: str = DICTIONARY):
    import cv2

    if not hasattr(cv2.aruco, name):
        raise MetricsError(f"unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50, DICT_5X5_100)")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares (columns, rows), square and marker side (m), dictionary."""

    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.03
    marker_m: float = 0.022
    dictionary: str = DICTIONARY

    def board(self):
        import cv2

        return cv2.aruco.CharucoBoard(
            self.squares, self.square_m, self.marker_m, aruco_dictionary(self.dictionary)
        )


@dataclass(frozen=True)
class Camera:
    """Pinhole camera with OpenCV's distortion model. matrix: (3, 3) K in pixels; distortion: (k1, k2, p1,
    p2, k3); size: (width, height) pixels; rms: reprojection error of the calibration (pixels)."""

    matrix: NDArray[np.float64]
    distortion: NDArray[np.float64]
    size: tuple[int, int]
    rms: float = float("nan")

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(
            json.dumps(
                {
                    "matrix": np.asarray(self.matrix).tolist(),
                    "distortion": np.asarray(self.distortion).ravel().tolist(),
                    "size": list(self.size),
                    "rms_px": self.rms,
                },
                indent=2,
            )
        )
        return path

    @classmethod
    def load(cls, path: str | Path) -> Camera:
        path = Path(path)
        try:
            data = json.loads(path.read_text())
            return cls(
                np.array(data["matrix"], dtype=np.float64).reshape(3, 3),
                np.array(data["distortion"], dtype=np.float64),
                (int(data["size"][0]), int(data["size"][1])),
                float(data.get("rms_px", float("nan"))),
            )
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise MetricsError(f"camera calibration {path} is not readable: {error}") from None


def calibrate_charuco(
    images: list[NDArray[np.uint8]], board: BoardSpec | None = None, min_corners: int = 6
) -> Camera:
    """Calibrate from views of a ChArUco board (BGR or grey images of one size)."""
    import cv2

    board = board or BoardSpec()
    charuco = board.board()
    detector = cv2.aruco.CharucoDetector(charuco)
    object_points, image_points = [], []
    size = None
    for image in images:
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        size = (grey.shape[1], grey.shape[0])
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < min_corners:
            continue
        found_object, found_image = charuco.matchImagePoints(corners, ids)
        object_points.append(found_object.astype(np.float32))
        image_points.append(found_image.astype(np.float32))
    if len(object_points) < 3:
        raise MetricsError(
            f"the ChArUco board was found in {len(object_points)} of {len(images)} images; calibration needs "
            "at least 3 views with the board seen at different angles"
        )
    # k3 is fixed at 0: with a dozen views it mostly fits noise at the image corners
    rms, matrix, distortion, _, _ = cv2.calibrateCamera(
        object_points, image_points, size, None, None, flags=cv2.CALIB_FIX_K3
    )
    return Camera(matrix, distortion.ravel(), size, float(rms))
