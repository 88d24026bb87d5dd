"""An instrument's pose in one camera frame, from the markers of its body that are in view.

Per frame: ArUco detection (first in a window around the last sighting, then over the whole image),
each marker's corners refined as the meeting points of its fitted edges (:func:`refined_corners`),
then the body's pose:

- **one marker seen**: ``cv2.solvePnP`` with IPPE for squares. A square seen nearly face-on has two
  poses that fit about equally (mirror images); a clearly better fit decides, otherwise the one
  continuing the last frame's rotation does;
- **two or more seen**: that single-marker pose of the largest marker in the image starts a
  Levenberg-Marquardt refinement over every corner of every seen marker at once, which is both more
  accurate (more points, wider baseline) and free of the mirror ambiguity;
- then, in both cases, when a marker facing the camera is seen small (under :data:`EDGES_BELOW_PX`),
  the pose is refined on every black-white cell edge of the facing markers (:mod:`sim.tracking.edges`):
  a marker seen alone and small is where the corners alone leave the tilt, and so the tip's depth,
  uncertain.

The instrument tip is the body pose applied to the body's tip offset. Everything is in the camera
frame (x right, y down, z along the optical axis), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.tracking.camera import Camera, aruco_dictionary
from sim.tracking.edges import refine_on_edges
from sim.tracking.markers import MarkerBody

AMBIGUOUS_FIT_RATIO = 0.5
"""IPPE's two poses count as equally good when the better reprojection error is over half the other's."""
MIN_FACING = 0.35
"""A face turned further than ~70 deg from the camera (cosine below this) is left out of a pose that
other faces can give: its corners are foreshortened to a few pixels and blurred."""
MAX_REFINE_TURN_DEG = 5.0
MAX_REFINE_SHIFT_M = 0.01
"""An edge refinement (:mod:`sim.tracking.edges`) that turns the body further or moves it further than
this from its corners' pose is not trusted: the corners' pose is kept (the single-marker tilt it mends is
a fraction of a degree, its depth a few mm)."""
EDGES_BELOW_PX = 64.0
"""The pose is refined on the markers' cell edges when a facing marker is seen smaller than this
(px across): at 640x480 the cube's 24 mm markers are 46 px at 30 cm and the edges take the tip from
1.28 to 0.93 mm RMS; at 1280x720 they are 92 px, the corners alone give 0.43 mm and the edges 0.39 mm
for 1-2 ms more a frame (benchmarks/camera.py)."""
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


EDGE_SAMPLES = 48
"""Points located along each of a marker's four outer edges."""
EDGE_END_FRACTION = 0.08
"""The points keep this fraction of the side away from each corner (where two edges blur together)."""
EDGE_REACH_PX = 3.0
"""How far across the detector's edge the true one is looked for (px; less on a marker seen small or
at a slant, so the search never reaches the cube's own edge beyond the white margin)."""
MAX_CORNER_SHIFT = 0.25
"""A refined corner further than this fraction of the marker's shortest side (and over 2 px) from the
detector's is not trusted: the detector's are kept. (The detector's own corner can be 4 px out on a
marker seen at a slant, 20 px across; the edges put it back within 0.4 px.)"""


def refined_corners(grey: NDArray[np.uint8], quad: NDArray[np.float64]) -> NDArray[np.float64]:
    """A marker's corners as the intersections of straight lines fitted to its four outer edges.

    ``cv2.cornerSubPix`` (the detector's refinement) is made for the saddle corners of a chessboard; on
    the L-shaped outer corner of a black square it is pulled inwards by the blur, so a marker looks
    smaller and further away (0.55 mm of depth bias at 30 cm on 92-pixel markers). Edges are located
    without that bias: across each side at :data:`EDGE_SAMPLES` points, the edge is the centroid of the
    intensity gradient; a total-least-squares line through them, and adjacent lines meet at a corner.
    With this the tip of the synthetic wrist video came within 0.39 mm RMS of the truth (0.90 mm with
    the detector's corners)."""
    import cv2

    image = grey.astype(np.float32)
    lines = []
    for k in range(4):
        start, end = quad[k], quad[(k + 1) % 4]
        along = end - start
        length = float(np.linalg.norm(along))
        if length < 8.0:
            return quad
        unit = along / length
        across = np.array([-unit[1], unit[0]])
        # the white margin round a cube's marker is an eighth of its side: the search stays inside it
        height = abs(float(np.dot(quad[(k + 2) % 4] - start, across)))
        reach = min(EDGE_REACH_PX, 0.08 * height)
        offsets = np.linspace(-reach, reach, 25)
        fractions = np.linspace(EDGE_END_FRACTION, 1 - EDGE_END_FRACTION, EDGE_SAMPLES)
        base = start + fractions[:, None] * along
        points = base[:, None, :] + offsets[None, :, None] * across
        profile = cv2.remap(
            image, points[..., 0].astype(np.float32), points[..., 1].astype(np.float32), cv2.INTER_LINEAR
        )
        gradient = np.abs(np.diff(profile, axis=1))
        gradient = np.maximum(gradient - 0.2 * gradient.max(axis=1, keepdims=True), 0.0)
        weight = gradient.sum(axis=1)
        if np.any(weight <= 0):
            return quad
        middle = (offsets[:-1] + offsets[1:]) / 2
        edge = base + ((gradient * middle).sum(axis=1) / weight)[:, None] * across
        centre = edge.mean(axis=0)
        direction = np.linalg.svd(edge - centre)[2][0]
        normal = np.array([-direction[1], direction[0]])
        lines.append((normal, float(normal @ centre)))
    refined = np.empty_like(quad)
    for k in range(4):
        (n1, d1), (n2, d2) = lines[k - 1], lines[k]
        system = np.array([n1, n2])
        if abs(np.linalg.det(system)) < 1e-6:
            return quad
        refined[k] = np.linalg.solve(system, [d1, d2])
    shortest = float(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1).min())
    if np.linalg.norm(refined - quad, axis=1).max() > max(2.0, MAX_CORNER_SHIFT * shortest):
        return quad
    return refined


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
            int(i): refined_corners(grey, c.reshape(4, 2).astype(np.float64))
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
        pose = self._solve(seen, grey)
        if pose is not None:
            self._previous_rotation = pose.rotation
        return pose

    def _solve(
        self, seen: dict[int, NDArray[np.float64]], grey: NDArray[np.uint8] | None = None
    ) -> BodyPose | None:
        """The body pose from the corners of the markers seen, refined on the cell edges of those facing
        the camera when the image is given."""
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
                rotation, translation, error = cv2.Rodrigues(r)[0], t.ravel(), None
        facing = [k for k in seen if self._facing(k, rotation, translation) >= MIN_FACING]
        small = facing and min(np.sqrt(_area(seen[k])) for k in facing) < EDGES_BELOW_PX
        if small and grey is not None:
            refined = refine_on_edges(grey, self.camera, self.body, facing, rotation, translation)
            if refined is not None and _near(refined, (rotation, translation)):
                (rotation, translation), error = refined, None
        if error is None:  # the pose moved from IPPE's: the corners' error under the one returned
            error = self._corner_error(seen, rotation, translation)
        tip = rotation @ np.asarray(self.body.tip_offset_m, dtype=np.float64) + translation
        return BodyPose(rotation, translation, tip, error, len(seen))

    def _corner_error(self, seen: dict[int, NDArray[np.float64]], rotation, translation) -> float:
        """The seen corners' RMS reprojection error (px) under a body pose."""
        import cv2

        object_points = np.concatenate([self.body.corners(k) for k in seen])
        image_points = np.concatenate(list(seen.values()))
        projected, _ = cv2.projectPoints(
            object_points, cv2.Rodrigues(rotation)[0], translation, self.camera.matrix, self.camera.distortion
        )
        return float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - image_points) ** 2, 1))))

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


def _near(refined, start) -> bool:
    """Whether an edge refinement stayed within :data:`MAX_REFINE_TURN_DEG` and :data:`MAX_REFINE_SHIFT_M`
    of the corners' pose (a face seen small and at a slant can pull it to a far, wrong minimum)."""
    (rotation, translation), (start_rotation, start_translation) = refined, start
    cosine = np.clip((np.trace(rotation @ start_rotation.T) - 1) / 2, -1.0, 1.0)
    return bool(
        np.all(np.isfinite(translation))
        and np.degrees(np.arccos(cosine)) <= MAX_REFINE_TURN_DEG
        and np.linalg.norm(translation - start_translation) <= MAX_REFINE_SHIFT_M
    )


def _area(corners: NDArray[np.float64]) -> float:
    x, y = corners[:, 0], corners[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))
