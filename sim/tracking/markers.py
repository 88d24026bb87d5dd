"""Printed ArUco markers on an instrument: one flat marker, or a cube of them that survives the wrist.

A :class:`MarkerBody` is a rigid set of square markers on an instrument, each placed by its centre and
its own axes in the **body frame** (metres), and the instrument tip's position in that frame. A single
flat marker (the bench-video importer's) is a body of one; the live device's default is a cube fixed on
the instrument's handle with markers on five faces, so that turning the wrist through 180 deg about
the shaft always leaves one or two faces in view.

Body frame of a cube: origin at the cube's centre, y along the instrument towards its back end (the
shaft leaves the cube's -y face, where no marker is), x and z across. Each marker's own frame is
ArUco's: x to the marker's right, y up, z out of the face; its corners are listed top-left, top-right,
bottom-right, bottom-left, the order ``cv2.aruco`` detects them in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError
from sim.tracking.camera import DICTIONARY


@dataclass(frozen=True)
class MarkerFace:
    """One marker of a body: its id, centre and right/up axes (unit vectors) in the body frame."""

    marker_id: int
    centre: tuple[float, float, float]
    right: tuple[float, float, float]
    up: tuple[float, float, float]

    def frame(self) -> NDArray[np.float64]:
        """3x3, columns the marker's x (right), y (up) and z (out of the face) in the body frame."""
        right, up = np.asarray(self.right, dtype=float), np.asarray(self.up, dtype=float)
        return np.column_stack([right, up, np.cross(right, up)])


@dataclass(frozen=True)
class MarkerBody:
    """A rigid set of markers (all of side ``side_m``, from ``dictionary``) and the instrument tip's
    position in the body frame (m)."""

    name: str
    faces: tuple[MarkerFace, ...]
    side_m: float
    tip_offset_m: tuple[float, float, float]
    dictionary: str = DICTIONARY
    cube_m: float = 0.0
    """The cube's edge (m) for a cube body, 0 for a flat marker."""

    def __post_init__(self) -> None:
        ids = [face.marker_id for face in self.faces]
        if not ids or len(set(ids)) != len(ids):
            raise TrackingError(f"instrument {self.name!r}: its markers need distinct ids, got {ids}")
        if not self.side_m > 0:
            raise TrackingError(f"instrument {self.name!r}: marker side {self.side_m} m is not positive")

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(face.marker_id for face in self.faces)

    def corners(self, marker_id: int) -> NDArray[np.float64]:
        """(4, 3) corners of one marker in the body frame, in ArUco's order."""
        face = self.faces[self.ids.index(marker_id)]
        return face_corners(face, self.side_m)

    @classmethod
    def flat(
        cls,
        marker_id: int = 7,
        side_m: float = 0.03,
        tip_offset_m: tuple[float, float, float] = (0.0, -0.06, -0.01),
        dictionary: str = DICTIONARY,
        name: str = "needle holder",
    ) -> MarkerBody:
        """One flat marker; the body frame is the marker's own."""
        face = MarkerFace(marker_id, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
        return cls(name, (face,), side_m, tip_offset_m, dictionary)

    @classmethod
    def cube(
        cls,
        name: str,
        first_id: int,
        cube_m: float = 0.03,
        side_m: float = 0.024,
        tip_offset_m: tuple[float, float, float] = (0.0, -0.12, 0.0),
        dictionary: str = DICTIONARY,
    ) -> MarkerBody:
        """A cube of edge ``cube_m`` with markers ``first_id`` .. ``first_id + 4`` on its faces +z, +x,
        -z, -x (around the shaft, each marker's up towards the back end) and +y (the back end)."""
        if side_m >= cube_m:
            raise TrackingError(
                f"instrument {name!r}: a {side_m * 1e3:.1f} mm marker does not fit on a "
                f"{cube_m * 1e3:.1f} mm cube face with a white margin; make the markers smaller"
            )
        h = cube_m / 2
        up = (0.0, 1.0, 0.0)
        faces = []
        for k, normal in enumerate([(0, 0, 1), (1, 0, 0), (0, 0, -1), (-1, 0, 0)]):
            n = np.asarray(normal, dtype=float)
            right = np.cross(up, n)
            faces.append(MarkerFace(first_id + k, tuple(h * n), tuple(right), up))
        faces.append(MarkerFace(first_id + 4, (0.0, h, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)))
        return cls(name, tuple(faces), side_m, tip_offset_m, dictionary, cube_m)

    def with_tip(self, tip_offset_m) -> MarkerBody:
        """The same markers with a measured tip offset (m, body frame), e.g. from pivot calibration."""
        return MarkerBody(
            self.name, self.faces, self.side_m, tuple(float(v) for v in tip_offset_m), self.dictionary,
            self.cube_m,
        )  # fmt: skip


def face_corners(face: MarkerFace, side_m: float) -> NDArray[np.float64]:
    """(4, 3) corners of a marker of side ``side_m`` on ``face``, body frame, ArUco's order."""
    h = side_m / 2
    local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    return local @ face.frame().T + np.asarray(face.centre, dtype=float)


NEEDLE_HOLDER = MarkerBody.cube("needle holder", first_id=10)
"""The default needle holder: a 30 mm cube, markers 10-14 (24 mm), the tip 120 mm down the shaft
(replace it by pivot calibration: ``vascsim instruments register``)."""
FORCEPS = MarkerBody.cube("forceps", first_id=20)
"""The default forceps: a 30 mm cube, markers 20-24."""
INSTRUMENTS = {"needle-holder": NEEDLE_HOLDER, "forceps": FORCEPS}
