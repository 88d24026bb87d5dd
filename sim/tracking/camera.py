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

from sim.errors import TrackingError

DICTIONARY = "DICT_4X4_50"


def aruco_dictionary(name: str = DICTIONARY):
    import cv2

    if not hasattr(cv2.aruco, name):
        raise TrackingError(f"unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50, DICT_5X5_100)")
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
            if not isinstance(data, dict) or set(data) - {"matrix", "distortion", "size", "rms_px"}:
                raise ValueError("expected an object with matrix, distortion, size and rms_px")
            camera = cls(
                np.array(data["matrix"], dtype=np.float64).reshape(3, 3),
                np.array(data["distortion"], dtype=np.float64),
                _image_size(data["size"]),
                float(data["rms_px"] if data.get("rms_px") is not None else "nan"),
            )
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise TrackingError(f"camera calibration {path} is not readable: {error}") from None
        problem = camera.problem()
        if problem:
            raise TrackingError(f"camera calibration {path} is not a camera: {problem}; calibrate again")
        return camera

    def problem(self) -> str | None:
        """What makes this model impossible (None when it is a camera): a pinhole with positive focal
        lengths, its centre inside the image, OpenCV's 4, 5, 8, 12 or 14 finite distortion terms."""
        K, distortion = self.matrix, self.distortion
        width, height = self.size
        if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            return "the focal lengths must be finite and positive"
        if np.any(K[1:, 0] != 0) or K[2, 1] != 0 or K[2, 2] != 1:
            return "the intrinsic matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"
        if not (0 <= K[0, 2] < width and 0 <= K[1, 2] < height):
            centre = f"({K[0, 2]:.1f}, {K[1, 2]:.1f}) px"
            return f"the principal point {centre} lies outside the {width}x{height} image"
        if (
            distortion.ndim != 1
            or distortion.size not in (4, 5, 8, 12, 14)
            or not np.all(np.isfinite(distortion))
        ):
            return "the distortion must be 4, 5, 8, 12 or 14 finite numbers"
        if not (np.isnan(self.rms) or 0 <= self.rms < 1e3):
            return f"the reprojection error {self.rms} px is not a pixel error"
        return None


def _image_size(size) -> tuple[int, int]:
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(v, int) and 0 < v <= 16384 for v in size)
    ):
        raise ValueError(f"size must be [width, height] in pixels (1-16384), got {size!r}")
    return size[0], size[1]


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
        raise TrackingError(
            f"the ChArUco board was found in {len(object_points)} of {len(images)} images; calibration needs "
            "at least 3 views with the board seen at different angles"
        )
    # k3 is fixed at 0: with a dozen views it mostly fits noise at the image corners
    rms, matrix, distortion, _, _ = cv2.calibrateCamera(
        object_points, image_points, size, None, None, flags=cv2.CALIB_FIX_K3
    )
    return Camera(matrix, distortion.ravel(), size, float(rms))
