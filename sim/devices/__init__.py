"""Input and haptic devices behind one protocol, plus discovery of what is connected."""

from sim.devices.base import (
    Device,
    DeviceError,
    DeviceIdentity,
    DeviceLimits,
    DeviceLostError,
    DeviceSample,
)
from sim.devices.scripted import ReplayDevice, ScriptedDevice, SuturingPass, SuturingPassParameters

__all__ = [
    "Device",
    "DeviceError",
    "DeviceIdentity",
    "DeviceLimits",
    "DeviceLostError",
    "DeviceSample",
    "ReplayDevice",
    "ScriptedDevice",
    "SuturingPass",
    "SuturingPassParameters",
]
