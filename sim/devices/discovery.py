"""What is connected, and which driver serves it: the data behind ``vascsim devices``."""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib.util
import os
import sys
from dataclasses import asdict, dataclass

from sim.devices.base import DeviceError
from sim.devices.spacemouse import find_spacemice
from sim.devices.usb_discovery import scan_usb
from sim.tracking.video import list_cameras


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
    cameras = list_cameras()
    for name, product in cameras:
        reports.append(DeviceReport(f"{product} (instruments with printed markers)", "camera", name, "ready"))
    if not cameras:
        reports.append(
            DeviceReport(
                "camera (instruments with printed markers)", "camera", "camera:INDEX, URL or FILE",
                "no camera found; a stream URL or a video file still works",
            )
        )  # fmt: skip
    reports.append(DeviceReport("scripted trajectory", "scripted", "none (built in)", "ready"))
    reports.append(DeviceReport("recorded session", "replay", "none (built in)", "ready"))
    return reports


def display_available() -> bool:
    """Whether a window can open here (X11 or Wayland; Windows and macOS always can)."""
    return sys.platform in ("win32", "darwin") or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


def display_problem() -> str | None:
    """Why a window cannot open on this station's display, or None when it can.

    An X11 display named by ``DISPLAY`` is opened and closed once (libX11, which the window's OpenGL
    uses too): VTK crashes the process when its own connection is refused, so the station asks first
    and says which display it could not reach."""
    if not display_available():
        return "no display (DISPLAY or WAYLAND_DISPLAY is not set)"
    name = os.environ.get("DISPLAY")
    if sys.platform in ("win32", "darwin") or not name:
        return None
    found = ctypes.util.find_library("X11")
    if found is None:
        return None  # no libX11 to ask with; the window's own connection will tell
    xlib = ctypes.CDLL(found)
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    connection = xlib.XOpenDisplay(name.encode())
    if not connection:
        return (
            f"cannot connect to the X display {name!r} (is its X server running, and may this user open it?)"
        )
    xlib.XCloseDisplay(connection)
    return None
