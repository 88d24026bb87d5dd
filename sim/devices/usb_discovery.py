"""Known haptic and input devices found on the USB bus through pyusb, with the driver that serves each."""

from __future__ import annotations

from dataclasses import dataclass

from sim.devices.base import DeviceError, DeviceIdentity
from sim.devices.spacemouse import SPACEMOUSE_PRODUCTS


@dataclass(frozen=True)
class KnownDevice:
    """A USB id we recognise: its product and which vascsim driver serves it."""

    product: str
    driver: str


# (vendor, product) -> device; product None matches any product of that vendor.
KNOWN_USB: dict[tuple[int, int | None], KnownDevice] = {
    (0x0301, 0x2988): KnownDevice("3D Systems Touch (USB)", "openhaptics"),
    (0x2988, 0x0302): KnownDevice("3D Systems Touch", "openhaptics"),
    (0x0403, 0xCB48): KnownDevice("Novint Falcon", "none (libnifalcon not packaged)"),
    (0x1451, None): KnownDevice("Force Dimension haptic device", "none (Force Dimension SDK)"),
    **{key: KnownDevice(name, "spacemouse (hidapi)") for key, name in SPACEMOUSE_PRODUCTS.items()},
}


def identify(vendor_id: int, product_id: int) -> KnownDevice | None:
    """The known device for a USB id pair, if any."""
    return KNOWN_USB.get((vendor_id, product_id)) or KNOWN_USB.get((vendor_id, None))


def scan_usb(backend: object | None = None) -> list[tuple[DeviceIdentity, KnownDevice]]:
    """Known devices on the USB bus. Raises DeviceError if no libusb backend is available."""
    import usb.core

    try:
        devices = list(usb.core.find(find_all=True, backend=backend))
    except usb.core.NoBackendError as error:
        raise DeviceError(
            "no libusb backend for pyusb: install libusb-1.0-0 (scripts/bootstrap does)"
        ) from error
    found = []
    for device in devices:
        known = identify(device.idVendor, device.idProduct)
        if known is not None:
            found.append((DeviceIdentity("pyusb", known.product, device.idVendor, device.idProduct), known))
    return found
