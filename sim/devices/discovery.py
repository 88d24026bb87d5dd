"""What is connected, and which driver serves it: the data behind ``vascsim devices``."""

from __future__ import annotations

import importlib.util
import os
import sys
from dataclasses import asdict, dataclass

from sim.devices.base import DeviceError


@dataclass(frozen=True)
class DeviceReport:
    """One line of ``vascsim devices``."""

    name: str
    driver: str
    connection: str
    status: str

    def as_dict(self) -> dict[str, str]:
        return asdict(self)


def list_devices() -> list[DeviceReport]:
    """Connected SpaceMice (hidapi), known USB haptic/input devices (pyusb), and the drivers."""
    reports: list[DeviceReport] = []
    try:
        from sim.devices.spacemouse import find_spacemice

        for identity in find_spacemice():
            reports.append(
                DeviceReport(
                    identity.product,
                    "spacemouse",
                    f"hid {identity.vendor_id:04x}:{identity.product_id:04x}",
                    "ready",
                )
            )
    except (ImportError, OSError) as error:
        reports.append(DeviceReport("SpaceMouse family", "spacemouse", "hidapi", f"unavailable: {error}"))
    try:
        from sim.devices.usb_discovery import scan_usb

        seen = {r.connection for r in reports}
        for identity, known in scan_usb():
            connection = f"usb {identity.vendor_id:04x}:{identity.product_id:04x}"
            if f"hid {identity.vendor_id:04x}:{identity.product_id:04x}" not in seen:
                reports.append(DeviceReport(known.product, known.driver, connection, "found on USB"))
    except DeviceError as error:
        reports.append(DeviceReport("USB devices", "pyusb", "libusb", f"unavailable: {error}"))
    openhaptics = importlib.util.find_spec("pyOpenHaptics") is not None
    reports.append(
        DeviceReport(
            "3D Systems Touch / Phantom",
            "openhaptics",
            "OpenHaptics runtime",
            "driver available"
            if openhaptics
            else "not installed (needs pyOpenHaptics and 3D Systems' OpenHaptics)",
        )
    )
    reports.append(
        DeviceReport(
            "keyboard and mouse (needle holder; forces shown, not felt)",
            "mouse",
            "the station's window",
            "ready" if display_available() else "needs a display (the station's window)",
        )
    )
    reports.append(DeviceReport("scripted trajectory", "scripted", "none (built in)", "ready"))
    reports.append(DeviceReport("recorded session", "replay", "none (built in)", "ready"))
    return reports


def display_available() -> bool:
    """Whether a window can open here (X11 or Wayland; Windows and macOS always can)."""
    return sys.platform in ("win32", "darwin") or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )
