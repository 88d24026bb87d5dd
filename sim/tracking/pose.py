"""An instrument's pose in one camera frame, from the markers of its body that are in view.

Per frame: ArUco detection with sub-pixel corner refinement (first in a window around the last
sighting, then over the whole image), then the body's pose:

- **one marker seen**: ``cv2.solvePnP`` with IPPE for squares. A square seen nearly face-on has two
  poses that fit about equally (mirror images); a clearly better fit decides, otherwise the one
  continuing the last frame's rotation does;
- **two or more seen**: that single-marker pose of the largest marker in the image starts a
  Levenberg-Marquardt refinement over every corner of every seen marker at once, which is both more
  accurate (more points, wider baseline) and free of the mirror ambiguity.

The instrument tip is the body pose applied to the body's tip offset. Everything is in the camera
frame (x right, y down, z along the optical axis), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.tracking.camera import Camera, aruco_dictionary
from sim.tracking.markers import MarkerBody

AMBIGUOUS_FIT_RATIO = 0.5
"""IPPE's two poses count as equally good when the better reprojection error is over half the other's."""
MIN_FACING = 0.5
"""A face turned further than ~70 deg from the camera (cosine below this) is left out of a pose that
other faces can give: its corners are foreshortened to a few pixels and blurred."""
SEARCH_MARGIN = 1.5
"""The window searched first spans the last sighting plus this many times its size on each side."""


@dataclass(frozen=True)
class BodyPose:
    """The body's rotation (camera <- body) and translation (m), the tip (m), the corners' RMS
    reprojection error (px) and how many of the body's markers were used."""

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    tip: NDArray[np.float64]
    reprojection_px: float
    markers_seen: int


def marker_detector(dictionary: str):
    """An ArUco detector with sub-pixel corner refinement (the settings the tracker's accuracy needs)."""
    import cv2

    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    parameters.cornerRefinementWinSize = 9  # half-window (px): 5 left 0.35 mm depth bias, 9 0.29 mm
    parameters.cornerRefinementMaxIterations = 50
    parameters.cornerRefinementMinAccuracy = 0.01
    return cv2.aruco.ArucoDetector(aruco_dictionary(dictionary), parameters)


def grey_of(frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
    import cv2

    return frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)


class BodyTracker:
    """Finds one instrument's markers in successive frames and returns its pose in each."""

    def __init__(self, camera: Camera, body: MarkerBody) -> None:
        self.camera = camera
        self.body = body
        self._detector = marker_detector(body.dictionary)
        self._ids = set(body.ids)
        self._previous_rotation: NDArray[np.float64] | None = None
        self._roi: tuple[int, int, int, int] | None = None

    def reset(self) -> None:
        """Forget the last sighting (after the instrument was lost for a while)."""
        self._previous_rotation, self._roi = None, None

    def detect(self, grey: NDArray[np.uint8]) -> dict[int, NDArray[np.float64]]:
        """This body's markers in the image: id -> (4, 2) corners (px), the last sighting's window first."""
        if self._roi is not None:
            x0, y0, x1, y1 = self._roi
            found = self._find(grey[y0:y1, x0:x1])
            if found:
                return {k: v + np.array([x0, y0]) for k, v in found.items()}
        return self._find(grey)

    def _find(self, grey: NDArray[np.uint8]) -> dict[int, NDArray[np.float64]]:
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None:
            return {}
        return {
            int(i): c.reshape(4, 2).astype(np.float64)
            for i, c in zip(ids.ravel(), corners, strict=True)
            if int(i) in self._ids
        }

    def locate(self, frame: NDArray[np.uint8]) -> BodyPose | None:
        """The body's pose in ``frame`` (BGR or grey), or None when none of its markers is in view."""
        grey = grey_of(frame)
        seen = self.detect(grey)
        if not seen:
            self._roi = None
            return None
        points = np.concatenate(list(seen.values()))
        margin = SEARCH_MARGIN * float(np.ptp(points, axis=0).max())
        low = np.maximum(points.min(axis=0) - margin, 0).astype(int)
        high = np.minimum(points.max(axis=0) + margin, [grey.shape[1], grey.shape[0]]).astype(int)
        self._roi = (int(low[0]), int(low[1]), int(high[0]), int(high[1]))
        pose = self._solve(seen)
        if pose is not None:
            self._previous_rotation = pose.rotation
        return pose

    def _solve(self, seen: dict[int, NDArray[np.float64]]) -> BodyPose | None:
        import cv2

        matrix, distortion = self.camera.matrix, self.camera.distortion
        largest = max(seen, key=lambda k: _area(seen[k]))
        single = self._single_marker(largest, seen[largest])
        if single is None:
            return None
        rotation, translation, error = single
        if len(seen) > 1:
            # a face seen at a grazing angle has foreshortened, blurred corners: leave it out
            facing = {k: v for k, v in seen.items() if self._facing(k, rotation, translation) >= MIN_FACING}
            seen = facing if facing else {largest: seen[largest]}
        if len(seen) > 1:
            object_points = np.concatenate([self.body.corners(k) for k in seen])
            image_points = np.concatenate(list(seen.values()))
            guess_r = cv2.Rodrigues(rotation)[0]
            guess_t = translation.reshape(3, 1).copy()
            ok, r, t = cv2.solvePnP(
                object_points, image_points, matrix, distortion, guess_r, guess_t, True,
                flags=cv2.SOLVEPNP_ITERATIVE,
            )  # fmt: skip
            if ok:
                rotation, translation = cv2.Rodrigues(r)[0], t.ravel()
                projected, _ = cv2.projectPoints(object_points, r, t, matrix, distortion)
                error = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - image_points) ** 2, 1))))
        tip = rotation @ np.asarray(self.body.tip_offset_m, dtype=np.float64) + translation
        return BodyPose(rotation, translation, tip, error, len(seen))

    def _facing(self, marker_id: int, rotation, translation) -> float:
        """Cosine of the angle between a face's outward normal and the direction to the camera."""
        face = self.body.faces[self.body.ids.index(marker_id)]
        normal = rotation @ face.frame()[:, 2]
        centre = rotation @ np.asarray(face.centre) + translation
        return float(-np.dot(normal, centre) / np.linalg.norm(centre))

    def _single_marker(
        self, marker_id: int, corners: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float] | None:
        """The body pose from one marker (IPPE, the mirror ambiguity settled as the module says)."""
        import cv2

        h = self.body.side_m / 2
        square = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        count, rotations, translations, errors = cv2.solvePnPGeneric(
            square, corners, self.camera.matrix, self.camera.distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        if count == 0:
            return None
        face = self.body.faces[self.body.ids.index(marker_id)]
        to_body = face.frame()  # body <- marker
        centre = np.asarray(face.centre, dtype=np.float64)
        choices = []
        for r, t in zip(rotations, translations, strict=True):
            camera_from_body = cv2.Rodrigues(r)[0] @ to_body.T
            choices.append((camera_from_body, t.ravel() - camera_from_body @ centre))
        residuals = np.ravel(errors)
        best = int(np.argmin(residuals))
        if self._previous_rotation is not None and count > 1:
            ordered = np.sort(residuals)
            if ordered[0] > AMBIGUOUS_FIT_RATIO * ordered[1]:
                best = int(np.argmin([np.linalg.norm(R - self._previous_rotation) for R, _ in choices]))
        rotation, translation = choices[best]
        return rotation, translation, float(residuals[best])


def _area(corners: NDArray[np.float64]) -> float:
    x, y = corners[:, 0], corners[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))
