"""Suture needles as polylines in the needle holder's frame, and their pose in the world.

A curved needle is a circular arc in the holder's x-y plane: the swage (where the
suture is attached) at arc angle 0, the tip at the arc's full angle, turning
counter-clockwise about the holder's z axis, so rotating the wrist about z drives
the tip forward along its own curve (the smooth rotation surgeons are taught).
The holder grips the needle at ``grip_fraction`` of the arc from the swage; that
point is the holder frame's origin. Vertex 0 of the polyline is the tip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import VascsimError


class NeedleError(VascsimError, ValueError):
    """A needle or pose parameter is out of range."""


@dataclass(frozen=True)
class Needle:
    """A needle: polyline vertices (tip first) in the holder frame, in metres.

    Build with :meth:`curved` or :meth:`straight`.
    """

    vertices: NDArray[np.float64] = field(repr=False)
    wire_diameter: float
    name: str
    tip_direction: NDArray[np.float64] = field(repr=False, default=None)  # unit, holder frame

    def __post_init__(self) -> None:
        if self.tip_direction is None:
            chord = self.vertices[0] - self.vertices[1]
            object.__setattr__(self, "tip_direction", _frozen(chord / np.linalg.norm(chord)))

    @classmethod
    def curved(
        cls,
        radius: float = 0.004,
        arc_fraction: float = 3 / 8,
        wire_diameter: float = 2.5e-4,
        segments: int = 16,
        grip_fraction: float = 1 / 3,
    ) -> Needle:
        """A circular-arc needle (3/8 circle by default; 1/2 circle with ``arc_fraction=0.5``).

        radius: arc radius (m); the default 4 mm, 3/8 circle is a 9.4 mm vascular needle.
        grip_fraction: where the holder grips, as a fraction of the arc from the swage.
        """
        _positive("radius", radius)
        _positive("wire_diameter", wire_diameter)
        if not 0 < arc_fraction < 1:
            raise NeedleError(f"arc_fraction must be in (0, 1) of a circle; got {arc_fraction}")
        if not 0 <= grip_fraction < 1:
            raise NeedleError(f"grip_fraction must be in [0, 1); got {grip_fraction}")
        if segments < 1:
            raise NeedleError(f"segments must be at least 1; got {segments}")
        full = 2 * math.pi * arc_fraction
        angles = np.linspace(full, 0.0, segments + 1)  # tip first
        arc = radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
        grip = radius * np.array([math.cos(grip_fraction * full), math.sin(grip_fraction * full), 0.0])
        tangent = _frozen(np.array([-math.sin(full), math.cos(full), 0.0]))  # exact, not the last chord
        return cls(
            _frozen(arc - grip), wire_diameter, f"{arc_fraction:g}-circle r={radius * 1e3:g} mm", tangent
        )

    @classmethod
    def straight(
        cls,
        length: float = 0.01,
        wire_diameter: float = 2.5e-4,
        segments: int = 4,
        grip_fraction: float = 1 / 3,
    ) -> Needle:
        """A straight needle along the holder's +x axis (tip at +x), mainly for tests."""
        _positive("length", length)
        _positive("wire_diameter", wire_diameter)
        if segments < 1:
            raise NeedleError(f"segments must be at least 1; got {segments}")
        along = np.linspace(length, 0.0, segments + 1) - grip_fraction * length
        vertices = np.column_stack([along, np.zeros_like(along), np.zeros_like(along)])
        return cls(_frozen(vertices), wire_diameter, f"straight {length * 1e3:g} mm")

    @property
    def segment_count(self) -> int:
        return len(self.vertices) - 1

    @property
    def wire_area(self) -> float:
        """Cross-section of the wire (m^2)."""
        return math.pi * (0.5 * self.wire_diameter) ** 2

    @property
    def length(self) -> float:
        """Length along the polyline (m)."""
        return float(np.linalg.norm(np.diff(self.vertices, axis=0), axis=1).sum())

    def world_vertices(self, pose: Pose) -> NDArray[np.float64]:
        """(S+1, 3) vertices in world coordinates, tip first."""
        return pose.position + self.vertices.dot(pose.rotation.T)  # .dot: a third of @'s overhead

    def tip_tangent(self, pose: Pose) -> NDArray[np.float64]:
        """Unit direction the tip points (the curve's tangent at the tip), world frame."""
        return pose.rotation.dot(self.tip_direction)

    def arc_position(self, segment: NDArray[np.int64], t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance from the tip (m) of points given as (segment, t along it)."""
        lengths = np.linalg.norm(np.diff(self.vertices, axis=0), axis=1)
        before = np.concatenate([[0.0], np.cumsum(lengths)])
        return before[segment] + t * lengths[segment]


@dataclass(frozen=True)
class Pose:
    """A rigid pose: ``position`` (3,) in metres and ``rotation`` (3, 3), world <- local."""

    position: NDArray[np.float64]
    rotation: NDArray[np.float64]

    def __post_init__(self) -> None:
        position = np.asarray(self.position, dtype=np.float64)
        rotation = np.asarray(self.rotation, dtype=np.float64)
        if position.shape != (3,) or not all(map(math.isfinite, position.tolist())):  # plain floats
            raise NeedleError(f"pose position must be 3 finite numbers (m); got {position}")
        if rotation.shape != (3, 3) or not _is_rotation(rotation):
            raise NeedleError("pose rotation must be a proper 3x3 rotation matrix")
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "rotation", rotation)

    @classmethod
    def unchecked(cls, position: NDArray[np.float64], rotation: NDArray[np.float64]) -> Pose:
        """A pose from arrays already known to be valid (compositions of valid poses)."""
        pose = object.__new__(cls)
        object.__setattr__(pose, "position", position)
        object.__setattr__(pose, "rotation", rotation)
        return pose

    @classmethod
    def identity(cls) -> Pose:
        return cls(np.zeros(3), np.eye(3))

    def compose(self, other: Pose) -> Pose:
        """self * other: apply ``other`` in this pose's frame."""
        # ndarray.dot rather than @ for these 3x3 products: the same BLAS call for a third of
        # the generalised-ufunc overhead (the FEM layer composes a pose every step)
        rotation = self.rotation
        return Pose.unchecked(self.position + rotation.dot(other.position), rotation.dot(other.rotation))

    def inverse(self) -> Pose:
        return Pose.unchecked(-self.rotation.T @ self.position, self.rotation.T)


def _is_rotation(r: NDArray[np.float64]) -> bool:
    """Orthonormal with determinant +1, to 1e-6 (plain floats: cheap enough for every haptic tick)."""
    rows = r.tolist()
    for i in range(3):
        for j in range(i, 3):
            dot = rows[i][0] * rows[j][0] + rows[i][1] * rows[j][1] + rows[i][2] * rows[j][2]
            if not abs(dot - (1.0 if i == j else 0.0)) <= 1e-6:  # also rejects NaN
                return False
    (a, b, c), (d, e, f), (g, h, i) = rows
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0


def rotation_about(axis: ArrayLike, angle_rad: float) -> NDArray[np.float64]:
    """Rotation matrix about an axis (need not be unit) by an angle (Rodrigues), in plain floats."""
    x, y, z = map(float, axis)
    norm = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / norm, y / norm, z / norm
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    t = 1.0 - c
    return np.array(
        [
            [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
            [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
            [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
        ]
    )


class TurnAbout:
    """A rigid pose turned about a fixed axis through a fixed centre: ``pose(angle)`` for any angle.

    Rodrigues' formula R = I + sin(angle) K + (1 - cos(angle)) K^2 (K the cross-product matrix of
    the unit axis) applied once to the pose's rotation and to its offset from the centre, so each
    call is twelve entries of plain-float arithmetic and one array: a scripted hand turning a
    needle through the wall, every haptic tick.
    """

    __slots__ = ("_terms",)

    def __init__(self, axis: ArrayLike, centre: ArrayLike, pose: Pose) -> None:
        x, y, z = (float(v) for v in axis)
        norm = math.sqrt(x * x + y * y + z * z)
        if not norm > 0:
            raise NeedleError("a turn needs a non-zero axis")
        x, y, z = x / norm, y / norm, z / norm
        cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        centre = np.asarray(centre, dtype=np.float64)
        offset = pose.position - centre
        # Rows: position (3 entries), then rotation row by row (9): value at 0, its K and K^2 terms.
        start = np.concatenate([centre + offset, pose.rotation.ravel()])
        once = np.concatenate([cross @ offset, (cross @ pose.rotation).ravel()])
        twice = np.concatenate([cross @ cross @ offset, (cross @ cross @ pose.rotation).ravel()])
        self._terms = tuple(zip(start.tolist(), once.tolist(), twice.tolist(), strict=True))

    def pose(self, angle: float) -> Pose:
        """The pose turned by ``angle`` (rad, right-handed about the axis)."""
        s, t = math.sin(angle), 1.0 - math.cos(angle)
        values = np.array([a + s * b + t * c for a, b, c in self._terms])
        return Pose.unchecked(values[:3], values[3:].reshape(3, 3))


def rotation_aligning(source: ArrayLike, target: ArrayLike) -> NDArray[np.float64]:
    """A rotation taking direction ``source`` onto direction ``target``."""
    a = np.asarray(source, dtype=np.float64) / np.linalg.norm(source)
    b = np.asarray(target, dtype=np.float64) / np.linalg.norm(target)
    axis = np.cross(a, b)
    sine, cosine = np.linalg.norm(axis), float(np.dot(a, b))
    if sine < 1e-12:
        if cosine > 0:
            return np.eye(3)
        perpendicular = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        return rotation_about(perpendicular, math.pi)
    return rotation_about(axis, math.atan2(sine, cosine))


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise NeedleError(f"{name} must be a positive number of metres; got {value}")


def _frozen(array: NDArray) -> NDArray:
    array.flags.writeable = False
    return array
