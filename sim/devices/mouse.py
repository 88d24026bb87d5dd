"""Keyboard and mouse as the needle holder, so anyone can try a stitch with no special hardware.

The station's window turns the trainee's mouse and keys into a holder pose (:class:`MouseHand`) and
publishes it, once a frame, through a :class:`PoseChannel` (an anonymous shared mapping made before
the run forks, so the window's process writes it and the haptic process reads it).
:class:`MouseDevice` is the haptic layer's side: it eases from the last pose to the newest over one
display frame, so the needle moves smoothly at 1 kHz instead of jumping 30 times a second (the price:
one display frame, 33 ms, of added lag). Forces are shown on the heads-up gauge, never felt.

The mapping (docs/station.md):

- drag with the left button: the holder moves in the view plane, as far as the point under the cursor
  moves at the holder's depth (the needle stays under the cursor);
- wheel: towards (down) or away from (up) the tissue along the view direction,
  :attr:`MouseMapping.wheel_step_m` a notch;
- D / Right arrow held: the wrist turns the needle forward along its own curve, about the needle's
  centre (the movement that matters); A / Left arrow: back; at :attr:`MouseMapping.turn_rate_deg_s`;
  a left-handed mapping (``handedness="left"``) swaps the two, as the mirrored hand turns the other way;
- G: close or open the jaws (grip / release; closing near the needle grasps it again).
"""

from __future__ import annotations

import math
import mmap
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import INPUT_ONLY_LIMITS, DeviceError, DeviceIdentity, DeviceSample
from sim.geometry import circle_through
from sim.needle import Pose, rotation_about
from sim.needle.reach import WristStop
from sim.runtime.shared import consistent_copy

HANDEDNESS = ("right", "left")
FORWARD_KEYS = ("d", "Right")
BACK_KEYS = ("a", "Left")
GRIP_KEYS = ("g",)


@dataclass(frozen=True)
class MouseMapping:
    """How mouse and keys map onto the holder (the defaults are what docs/station.md states).

    wheel_step_m: depth moved per wheel notch (m); turn_rate_deg_s: the wrist's turn while a turn key
    is held (deg/s; 60 deg/s turns a 4 mm needle's tip at 4.2 mm/s, a scripted expert's insertion
    speed); handedness: "right" or "left" (swaps the forward and back turn keys).
    """

    wheel_step_m: float = 2.5e-4
    turn_rate_deg_s: float = 60.0
    handedness: str = "right"

    def __post_init__(self) -> None:
        if self.handedness not in HANDEDNESS:
            raise DeviceError(f"handedness must be 'right' or 'left'; got {self.handedness!r}")
        if not 0 < self.wheel_step_m <= 0.005:
            raise DeviceError(f"wheel_step_m must be in (0, 5 mm]; got {self.wheel_step_m}")
        if not 0 < self.turn_rate_deg_s <= 720:
            raise DeviceError(f"turn_rate_deg_s must be in (0, 720]; got {self.turn_rate_deg_s}")

    def turn_direction(self, key: str) -> int:
        """+1 for a key that turns the needle forward along its curve, -1 back, 0 for another key."""
        sign = 1 if self.handedness == "right" else -1
        if key in FORWARD_KEYS:
            return sign
        if key in BACK_KEYS:
            return -sign
        return 0


class PoseChannel:
    """The latest holder pose, written by the station window and read by the haptic process (seqlock).

    Layout: [seq, time, position 3, rotation 9, grip]. Made before the run forks.
    """

    DOUBLES = 15

    def __init__(self) -> None:
        self._map = mmap.mmap(-1, 8 * self.DOUBLES)
        self._slot = np.frombuffer(self._map, dtype=np.float64)

    def put(self, time: float, pose: Pose, grip: bool) -> None:
        slot = self._slot
        slot[0] += 1  # odd: writing
        slot[1] = time
        slot[2:5] = pose.position
        slot[5:14] = pose.rotation.ravel()
        slot[14] = 1.0 if grip else 0.0
        slot[0] += 1

    def get(self) -> tuple[int, float, Pose, bool] | None:
        """(sequence, time, pose, grip) of the newest write, or None before the first."""
        copy = consistent_copy(self._slot)
        if copy is None:
            return None
        pose = Pose.unchecked(copy[2:5].copy(), copy[5:14].reshape(3, 3).copy())
        return int(copy[0]), float(copy[1]), pose, bool(copy[14])


def needle_circle(vertices: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """(centre, unit axis) of a curved needle's circle from its world vertices (tip first), the axis
    oriented so that a positive turn about it drives the tip forward along its curve; None for a
    straight needle."""
    vertices = np.asarray(vertices, dtype=np.float64)
    circle = circle_through(vertices[0], vertices[len(vertices) // 2], vertices[-1])
    if circle is None:
        return None
    centre, _ = circle
    axis = np.cross(vertices[len(vertices) // 2] - centre, vertices[0] - centre)
    norm = float(np.linalg.norm(axis))
    if not norm > 0:
        return None
    axis /= norm
    forward = vertices[0] - vertices[1]
    if np.dot(np.cross(axis, vertices[0] - centre), forward) < 0:
        axis = -axis
    return centre, axis


class MouseHand:
    """The holder as the trainee's mouse and keys move it (pure arithmetic: the window feeds it)."""

    def __init__(
        self,
        start: Pose,
        mapping: MouseMapping | None = None,
        grip: bool = True,
        stop: WristStop | None = None,
    ) -> None:
        self.mapping = mapping or MouseMapping()
        self.pose = start
        self.grip = grip
        self.stop = stop
        """Where the task's approach stops the wrist (:class:`sim.needle.reach.WristStop`): a back turn
        of the held needle goes no further than it, so the keys never wind the hand past what the
        needle shows (a turn forward then moves it at once)."""

    def move(self, offset: NDArray[np.float64]) -> None:
        """Translate the holder by ``offset`` (m, world)."""
        self.pose = Pose.unchecked(
            self.pose.position + np.asarray(offset, dtype=np.float64), self.pose.rotation
        )

    def wheel(self, notches: float, towards: NDArray[np.float64]) -> None:
        """Move ``notches`` wheel steps along ``towards`` (a direction, e.g. the view's)."""
        direction = np.asarray(towards, dtype=np.float64)
        self.move(notches * self.mapping.wheel_step_m * direction / np.linalg.norm(direction))

    def turn(self, seconds: float, direction: int, needle_vertices: NDArray[np.float64]) -> None:
        """Turn the wrist for ``seconds`` in ``direction`` (+1 forward along the needle's curve, -1
        back) about the needle's centre and axis (from its current world vertices); an open hand, or a
        straight needle, turns about the jaws on the same axis."""
        if direction == 0 or seconds <= 0:
            return
        circle = needle_circle(needle_vertices)
        if circle is None:
            return
        centre, axis = circle
        if not self.grip:
            centre = self.pose.position
        angle = direction * math.radians(self.mapping.turn_rate_deg_s) * seconds
        if angle < 0 and self.grip and self.stop is not None:  # no further back than the stop
            tip = np.cross(axis, needle_vertices[0] - centre)  # forward along the curve at the tip
            past = self.stop.turn_past(tip / np.linalg.norm(tip), axis)
            if math.isfinite(past):
                angle = max(angle, -max(past, 0.0))
                if angle == 0.0:
                    return
        turn = rotation_about(axis, angle)
        position = centre + turn @ (self.pose.position - centre)
        self.pose = Pose.unchecked(position, turn @ self.pose.rotation)

    def toggle_grip(self) -> None:
        self.grip = not self.grip


def _eased(start: Pose, stop: Pose, fraction: float) -> Pose:
    """The pose ``fraction`` (0-1) of the way from ``start`` to ``stop``: position on the line, rotation
    about the one axis that turns one into the other (constant speed: the device is moving, not
    starting or stopping)."""
    if fraction >= 1.0:
        return stop
    relative = stop.rotation @ start.rotation.T
    axis = np.array(
        [relative[2, 1] - relative[1, 2], relative[0, 2] - relative[2, 0], relative[1, 0] - relative[0, 1]]
    )
    sine = 0.5 * float(np.linalg.norm(axis))
    angle = math.atan2(sine, (float(np.trace(relative)) - 1.0) / 2.0)
    rotation = start.rotation if sine < 1e-12 else rotation_about(axis, fraction * angle) @ start.rotation
    return Pose.unchecked(start.position + fraction * (stop.position - start.position), rotation)


class MouseDevice:
    """The haptic layer's side of the keyboard and mouse: the window's newest pose, eased in over
    ``ease`` seconds (one display frame by default) so the needle moves smoothly at the haptic rate.
    Button 0 is the grip. No actuators: forces are shown, not felt."""

    limits = INPUT_ONLY_LIMITS
    identity = DeviceIdentity("station", "keyboard and mouse")

    def __init__(self, start: Pose, channel: PoseChannel | None = None, ease: float = 1.0 / 30.0) -> None:
        self.channel = channel or PoseChannel()
        self.start = start
        self.ease = ease
        self._seq = 0
        self._from = self._to = start
        self._since = 0.0
        self._grip = True
        self._last: tuple[float, NDArray[np.float64]] | None = None

    def read(self, time: float) -> DeviceSample:
        newest = self.channel.get()
        if newest is not None and newest[0] != self._seq:
            self._from = self._pose_at(time)
            self._seq, _, self._to, self._grip = newest
            self._since = time
        pose = self._pose_at(time)
        velocity = np.zeros(3)
        if self._last is not None and time > self._last[0]:
            velocity = (pose.position - self._last[1]) / (time - self._last[0])
        self._last = (time, pose.position)
        return DeviceSample(time, pose.position, pose.rotation, velocity, int(self._grip), pose)

    def _pose_at(self, time: float) -> Pose:
        if self.ease <= 0:
            return self._to
        return _eased(self._from, self._to, max(time - self._since, 0.0) / self.ease)

    def write_force(self, force: NDArray[np.float64]) -> None:
        """Keyboard and mouse have no actuators: the force is shown on the window's gauge."""

    def close(self) -> None:
        """Nothing to release (the channel's mapping goes with the process)."""
