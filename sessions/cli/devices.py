"""`vascsim devices`: the haptic devices this machine can drive."""

from __future__ import annotations

import json

import click

from sessions.cli.base import (
    user_errors,
)


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print the list as JSON.")
@user_errors
def devices(as_json: bool) -> None:
    """List connected devices and the driver that serves each.

    Looks for 3Dconnexion SpaceMice through hidapi and for known haptic and input
    devices (3D Systems Touch/Phantom, Novint Falcon, Force Dimension, 3Dconnexion)
    on the USB bus through pyusb; reports whether the OpenHaptics driver can be
    used; the keyboard and mouse (the station window's needle holder) where a display
    exists; cameras (video4linux) for instruments tracked by their printed markers
    (``--device camera:INDEX``); the scripted and replay devices are always available.
    """
    from sim.devices.discovery import list_devices

    reports = list_devices()
    if as_json:
        click.echo(json.dumps([r.as_dict() for r in reports], indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Devices")
    for header in ("device", "driver", "connection", "status"):
        table.add_column(header)
    for r in reports:
        table.add_row(r.name, r.driver, r.connection, r.status)
    Console().print(table)
