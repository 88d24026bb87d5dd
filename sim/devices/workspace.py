"""A device's workspace mapped onto the task's scene, as the station's view shows it.

A haptic arm reports poses in its own frame (the Touch: x to the user's right, y up, z towards the
user, origin at the middle of its workspace); a SpaceMouse integrates its deflection from the origin.
:class:`WorkspaceMapping` makes the pose the device holds at the session's first reading the task's
starting pose (the loaded needle above the first mark), and from there moves the needle holder as the
hand moves, **1:1** (a millimetre of hand is a millimetre of holder, so motion metrics are the hand's
own), along the view's axes: the device's right, up and towards-the-user are the screen's right, up
and out of the screen. A left hand (``mirror=True``) is mirrored across the screen's vertical plane:
moving and turning to the left is what the right hand does to the right. Forces go back the same way
(into the device's frame, mirrored for a left hand).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import DeviceSample
from sim.needle import Pose

MIRROR = np.diag([-1.0, 1.0, 1.0])
"""The reflection across the screen's vertical plane, in the device's frame."""


class WorkspaceMapping:
    """``device`` seen through the view's axes (``view``: 3x3, columns the screen's right, up and out of
    the screen in world coordinates), anchored at ``start`` (see the module docstring)."""

    def __init__(self, device, start: Pose, view: NDArray[np.float64], mirror: bool = False) -> None:
        self.device = device
        self.identity, self.limits = device.identity, device.limits
        self.start = start
        frame = np.asarray(view, dtype=np.float64)
        self._to_world = frame @ MIRROR if mirror else frame  # device coordinates -> world
        self._anchor: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None

    def read(self, time: float) -> DeviceSample:
        sample = self.device.read(time)
        if self._anchor is None:
            self._anchor = (sample.position.copy(), sample.rotation.copy())
        origin, turned_from = self._anchor
        to_world = self._to_world
        position = self.start.position + to_world @ (sample.position - origin)
        turn = to_world @ (sample.rotation @ turned_from.T) @ to_world.T  # the hand's turn, in the world
        rotation = turn @ self.start.rotation
        velocity = to_world @ sample.velocity
        pose = Pose.unchecked(position, rotation)
        return DeviceSample(time, position, rotation, velocity, sample.buttons, pose, sample.tracking)

    def tracking_problem(self) -> str | None:
        """The device's own word on its tracking (a camera's: instrument lost, frames late), if any."""
        ask = getattr(self.device, "tracking_problem", None)
        return ask() if ask is not None else None

    @property
    def toggle_grip(self):
        """The device's own jaw switch (a camera-tracked holder's, worked by a key), or None."""
        return getattr(self.device, "toggle_grip", None)

    def write_force(self, force: NDArray[np.float64]) -> None:
        """The tissue's force (world) in the device's own frame."""
        self.device.write_force(self._to_world.T @ np.asarray(force, dtype=np.float64))

    def close(self) -> None:
        self.device.close()


def view_axes(position, focal, up) -> NDArray[np.float64]:
    """3x3, columns the screen's right, up and out-of-the-screen directions of a camera (world)."""
    position, focal, up = (np.asarray(v, dtype=np.float64) for v in (position, focal, up))
    back = position - focal
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    return np.column_stack([right, np.cross(back, right), back])
