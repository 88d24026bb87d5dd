"""3D Systems Touch / Phantom through OpenHaptics (pyopenhaptics), where that runtime is installed.

Imported only when chosen. OpenHaptics is proprietary and not on the package
registries, so on a machine without it opening the driver raises a DeviceError
that names exactly what is missing.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import TOUCH_LIMITS, DeviceError, DeviceIdentity, DeviceLostError, DeviceSample

MILLIMETRE = 1e-3


class OpenHapticsDevice:
    """A Touch/Phantom arm: position (mm -> m), gimbal rotation, buttons in; force out (N)."""

    limits = TOUCH_LIMITS

    def __init__(self, name: str = "Default Device") -> None:
        try:
            import pyOpenHaptics.hd as hd
            from pyOpenHaptics.hd_device import HapticDevice
        except ImportError as error:
            raise DeviceError(
                "the OpenHaptics driver needs the pyOpenHaptics package and 3D Systems' OpenHaptics runtime "
                f"(libHD) with the Touch device driver; not found here ({error}). Use the scripted or "
                "SpaceMouse device, or install OpenHaptics from 3D Systems",
                remedy=("choose-device", "scripted or spacemouse"),
            ) from error
        self._hd = hd
        try:
            self._device = HapticDevice(device_name=name, callback=None)
        except Exception as error:  # the vendor library raises its own types
            raise DeviceError(f"OpenHaptics could not open {name!r}: {error}") from error
        self.identity = DeviceIdentity("openhaptics", name)

    def read(self, time: float) -> DeviceSample:
        try:
            transform = np.array(self._hd.get_transform(), dtype=np.float64).reshape(4, 4).T
            velocity = np.array(self._hd.get_velocity(), dtype=np.float64) * MILLIMETRE
            buttons = int(self._hd.get_buttons())
        except Exception as error:
            raise DeviceLostError(f"{self.identity} stopped answering: {error}") from error
        return DeviceSample(time, transform[:3, 3] * MILLIMETRE, transform[:3, :3], velocity, buttons)

    def write_force(self, force: NDArray[np.float64]) -> None:
        try:
            self._hd.set_force([float(f) for f in force])
        except Exception as error:
            raise DeviceLostError(f"{self.identity} rejected a force command: {error}") from error

    def close(self) -> None:
        self._device.close()
