"""The device protocol: pose, velocity and buttons in; force out.

Every input device (haptic arm, SpaceMouse, scripted trajectory, replayed
session) implements :class:`Device`. The haptic layer calls ``read`` and
``write_force`` once per tick; a device that disappears raises
:class:`DeviceLostError` from either, and the runtime ends the session cleanly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from sim.errors import VascsimError
from sim.needle import Pose

GRIP_BUTTON = 0
"""A device's first button closes and opens the needle holder's jaws."""
STOP_BUTTON = 1
"""A device's second button (the Touch's second stylus button, the SpaceMouse's right button) asks to
stop the session, as Esc in the station's window does; devices with one button never press it."""

Trajectory = Callable[[float], tuple[Pose, bool]]
"""A scripted hand: time (s) -> the holder's pose and whether its grip is closed."""


class DeviceError(VascsimError):
    """A device could not be found, opened or understood."""


class DeviceLostError(DeviceError):
    """The device stopped answering (unplugged, powered off, driver gone)."""


@dataclass(frozen=True)
class DeviceIdentity:
    """What a device is: driver name, product, and USB ids where it has them."""

    driver: str
    product: str
    vendor_id: int | None = None
    product_id: int | None = None
    serial: str = ""

    def __str__(self) -> str:
        ids = f" {self.vendor_id:04x}:{self.product_id:04x}" if self.vendor_id is not None else ""
        return f"{self.product}{ids} ({self.driver})"


@dataclass(frozen=True)
class DeviceLimits:
    """Rated limits the safety layer enforces: force (N) and force rate (N/s)."""

    max_force: float
    max_force_rate: float


@dataclass(frozen=True)
class DeviceSample:
    """One reading: time (s), tool position (m) and rotation (world <- tool), velocity (m/s), buttons.

    ``pose``: the same position and rotation as a :class:`~sim.needle.Pose` where the device
    already holds one (scripted trajectories, whose poses are checked or composed from checked
    ones); otherwise None, and the haptic layer checks the raw arrays itself.
    """

    time: float
    position: NDArray[np.float64]
    rotation: NDArray[np.float64]
    velocity: NDArray[np.float64]
    buttons: int = 0
    pose: Pose | None = None
    tracking: int = 0
    """How the pose was obtained: 0 measured (every device but a camera, and a camera's pose from a frame
    that saw the instrument), 1 predicted (a camera's frames late), 2 held (tracking lost: frozen);
    sim.tracking.channel."""

    def pressed(self, button: int) -> bool:
        return bool(self.buttons >> button & 1)


@runtime_checkable
class Device(Protocol):
    """What the haptic layer needs from a device."""

    identity: DeviceIdentity
    limits: DeviceLimits

    def read(self, time: float) -> DeviceSample:
        """The tool's state now; raises DeviceLostError if the device is gone."""
        ...

    def write_force(self, force: NDArray[np.float64]) -> None:
        """Command a force (N, world frame); devices without actuators ignore it."""
        ...

    def close(self) -> None: ...


# Rated limits by device family, used by the safety clamp (continuous ratings).
TOUCH_LIMITS = DeviceLimits(max_force=0.88, max_force_rate=100.0)  # 3D Systems Touch: 0.88 N continuous
FALCON_LIMITS = DeviceLimits(max_force=9.0, max_force_rate=500.0)
INPUT_ONLY_LIMITS = DeviceLimits(max_force=0.0, max_force_rate=0.0)  # SpaceMouse: no actuators
SCRIPTED_LIMITS = DeviceLimits(max_force=3.3, max_force_rate=200.0)  # like a desktop Phantom
