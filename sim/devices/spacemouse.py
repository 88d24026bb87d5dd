"""3Dconnexion SpaceMouse family over hidapi: discovery, report decoding, a pose for the subordinate hand.

Report formats (USB HID, little-endian signed 16-bit axes, about +/-350 full scale):

- older models (SpaceNavigator, SpaceExplorer, SpaceMouse Pro, ...): report id 1
  carries translation x, y, z (7 bytes with the id), report id 2 rotation rx, ry, rz
  (7 bytes), report id 3 a button bitmap;
- newer models (SpaceMouse Wireless, Compact, Enterprise, the universal receiver):
  report id 1 carries translation and rotation together (13 bytes), buttons still
  in report id 3.

The live device and the tests use the same :class:`SpaceMouseDecoder`, fed raw
report bytes.
"""

from __future__ import annotations

import struct
import time as clock
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import INPUT_ONLY_LIMITS, DeviceError, DeviceIdentity, DeviceLostError, DeviceSample
from sim.needle import rotation_about

VENDOR_LOGITECH, VENDOR_3DCONNEXION = 0x046D, 0x256F
SPACEMOUSE_PRODUCTS = {
    (VENDOR_LOGITECH, 0xC603): "SpaceMouse Plus XT",
    (VENDOR_LOGITECH, 0xC605): "CADman",
    (VENDOR_LOGITECH, 0xC606): "SpaceMouse Classic",
    (VENDOR_LOGITECH, 0xC621): "SpaceBall 5000",
    (VENDOR_LOGITECH, 0xC623): "SpaceTraveler",
    (VENDOR_LOGITECH, 0xC625): "SpacePilot",
    (VENDOR_LOGITECH, 0xC626): "SpaceNavigator",
    (VENDOR_LOGITECH, 0xC627): "SpaceExplorer",
    (VENDOR_LOGITECH, 0xC628): "SpaceNavigator for Notebooks",
    (VENDOR_LOGITECH, 0xC629): "SpacePilot Pro",
    (VENDOR_LOGITECH, 0xC62B): "SpaceMouse Pro",
    (VENDOR_3DCONNEXION, 0xC62E): "SpaceMouse Wireless (cable)",
    (VENDOR_3DCONNEXION, 0xC62F): "SpaceMouse Wireless (receiver)",
    (VENDOR_3DCONNEXION, 0xC631): "SpaceMouse Pro Wireless (cable)",
    (VENDOR_3DCONNEXION, 0xC632): "SpaceMouse Pro Wireless (receiver)",
    (VENDOR_3DCONNEXION, 0xC633): "SpaceMouse Enterprise",
    (VENDOR_3DCONNEXION, 0xC635): "SpaceMouse Compact",
    (VENDOR_3DCONNEXION, 0xC636): "SpaceMouse Module",
    (VENDOR_3DCONNEXION, 0xC652): "3Dconnexion Universal Receiver",
}
FULL_SCALE = 350.0


@dataclass
class SpaceMouseState:
    """Latest decoded axes, normalised to [-1, 1] (may exceed slightly), and buttons."""

    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    buttons: int = 0


class SpaceMouseDecoder:
    """Turns raw HID reports into axis and button state (both report formats)."""

    def __init__(self) -> None:
        self.state = SpaceMouseState(np.zeros(3), np.zeros(3))

    def feed(self, report: bytes) -> SpaceMouseState:
        """Apply one report (report id first); unknown ids are ignored."""
        if not report:
            return self.state
        report_id, payload = report[0], bytes(report[1:])
        if report_id == 1 and len(payload) >= 12:
            values = struct.unpack_from("<6h", payload)
            self.state.translation = np.array(values[:3]) / FULL_SCALE
            self.state.rotation = np.array(values[3:]) / FULL_SCALE
        elif report_id == 1 and len(payload) >= 6:
            self.state.translation = np.array(struct.unpack_from("<3h", payload)) / FULL_SCALE
        elif report_id == 2 and len(payload) >= 6:
            self.state.rotation = np.array(struct.unpack_from("<3h", payload)) / FULL_SCALE
        elif report_id == 3:
            self.state.buttons = int.from_bytes(payload[:4].ljust(4, b"\0"), "little")
        elif report_id in (1, 2):
            raise DeviceError(
                f"SpaceMouse report {report_id} too short: {len(report)} bytes ({report.hex()})"
            )
        return self.state


class RateIntegrator:
    """SpaceMouse axes are rate controls: integrate them into a pose for the subordinate hand.

    max_speed: translation speed (m/s) at full deflection; max_turn: rad/s at full deflection;
    deadband: deflection below which an axis reads zero.
    """

    def __init__(
        self,
        origin: NDArray[np.float64],
        max_speed: float = 0.02,
        max_turn: float = 1.0,
        deadband: float = 0.05,
    ) -> None:
        self.position = np.array(origin, dtype=np.float64)
        self.rotation = np.eye(3)
        self.max_speed, self.max_turn, self.deadband = max_speed, max_turn, deadband
        self._last_time: float | None = None
        self.velocity = np.zeros(3)

    def step(self, time: float, state: SpaceMouseState) -> DeviceSample:
        dt = 0.0 if self._last_time is None else max(time - self._last_time, 0.0)
        self._last_time = time
        move = np.where(np.abs(state.translation) > self.deadband, state.translation, 0.0)
        turn = np.where(np.abs(state.rotation) > self.deadband, state.rotation, 0.0)
        self.velocity = self.max_speed * move
        self.position = self.position + self.velocity * dt
        angle = float(np.linalg.norm(turn)) * self.max_turn * dt
        if angle > 0:
            self.rotation = rotation_about(turn, angle) @ self.rotation
        return DeviceSample(
            time, self.position.copy(), self.rotation.copy(), self.velocity.copy(), state.buttons
        )


def find_spacemice() -> list[DeviceIdentity]:
    """SpaceMouse-family devices visible through hidapi (by vendor and product id)."""
    import hid

    found = []
    for info in hid.enumerate():
        key = (info["vendor_id"], info["product_id"])
        if key in SPACEMOUSE_PRODUCTS:
            found.append(
                DeviceIdentity(
                    "hidapi", SPACEMOUSE_PRODUCTS[key], key[0], key[1], info.get("serial_number") or ""
                )
            )
    return found


class SpaceMouse:
    """A live SpaceMouse: reads HID reports without blocking and integrates a pose.

    ``source`` is the open HID handle (anything with ``read(size) -> list[int]`` that
    returns an empty list when no report waits and raises OSError when the device
    is gone); by default the first SpaceMouse hidapi finds is opened.

    A SpaceMouse is a rate control (deflection sets speed, not position: :class:`RateIntegrator`);
    in the paper it is the subordinate hand's device. As the dominant hand's it works, but no force is
    felt, and the station's instructions say so; the station maps its axes onto the view
    (:class:`sim.devices.workspace.WorkspaceMapping`).
    """

    limits = INPUT_ONLY_LIMITS

    def __init__(
        self,
        identity: DeviceIdentity | None = None,
        origin: NDArray[np.float64] | None = None,
        source: object | None = None,
    ) -> None:
        if source is None:
            identity, source = _open_hid(identity)
        self.identity = identity or DeviceIdentity("hidapi", "SpaceMouse")
        self._hid = source
        self.decoder = SpaceMouseDecoder()
        self.integrator = RateIntegrator(np.zeros(3) if origin is None else origin)

    def read(self, time: float | None = None) -> DeviceSample:
        now = clock.perf_counter() if time is None else time
        try:
            while report := self._hid.read(64):
                self.decoder.feed(bytes(report))
        except OSError as error:
            raise DeviceLostError(f"{self.identity} stopped answering: {error}") from error
        return self.integrator.step(now, self.decoder.state)

    def write_force(self, force: NDArray[np.float64]) -> None:
        """A SpaceMouse has no actuators."""

    def close(self) -> None:
        self._hid.close()


def _open_hid(identity: DeviceIdentity | None) -> tuple[DeviceIdentity, object]:
    import hid

    candidates = [identity] if identity else find_spacemice()
    if not candidates:
        raise DeviceError("no SpaceMouse found: plug one in (USB) and check read access to /dev/hidraw*")
    chosen = candidates[0]
    handle = hid.device()
    try:
        handle.open(chosen.vendor_id, chosen.product_id)
    except OSError as error:
        raise DeviceError(f"cannot open {chosen}: {error}; check permissions on /dev/hidraw*") from error
    handle.set_nonblocking(True)
    return chosen, handle
