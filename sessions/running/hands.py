"""Which device holds which instrument at a station: the needle holder and the subordinate hand's
forceps (``--device``, ``--sub-device``, ``--handedness``), and where the forceps start.

A right-handed trainee holds the needle holder with ``--device`` and the forceps with
``--sub-device``; ``--handedness left`` swaps the two devices' instruments (the station's devices
stay where they are: a Touch on the right and a SpaceMouse on the left serve a left-handed trainee
with the needle on the SpaceMouse and the forceps on the Touch), and mirrors each device's axes as
the live view's mapping does. The keyboard-and-mouse device lives in the live window and drives the
needle holder only. A subordinate device is mapped onto the task's scene like the needle's
(:func:`sessions.running.scene.mapped_onto_task`), its jaws starting open at the wound's edge beside
the first entry mark; its first button closes them.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from sessions.catalog import CatalogError
from sessions.running.camera import open_camera_device
from sessions.running.scene import access_direction, task_camera
from sessions.tasks import TaskSpec, grasp_sites
from sim.devices.openhaptics import OpenHapticsDevice
from sim.devices.spacemouse import SpaceMouse, find_spacemice
from sim.devices.workspace import WorkspaceMapping, view_axes
from sim.needle import Pose

SUB_DEVICES = ("none", "spacemouse", "openhaptics", "camera")
"""``--sub-device`` choices for a person's station: no second hand, the paper's SpaceMouse, a second
Touch (OpenHaptics), or real forceps with their marker cube tracked by the camera (the same camera as
a camera-tracked needle holder's). A scripted session's second hand is the scripted assisting hand."""
FORCEPS_START_HEIGHT_M = 0.3e-3
"""The open jaws start this far above the wound's edge, along the access direction: within the
forceps' reach (0.5 mm), so closing them there takes the edge."""


class Instruments(NamedTuple):
    """The device (a ``--device`` name) for each instrument; ``forceps`` is None when one-handed."""

    needle: str
    forceps: str | None


def instruments(device: str, sub_device: str | None, handedness: str = "right") -> Instruments:
    """Which device holds which instrument (see the module docstring); one line naming the options
    when the choice cannot work."""
    forceps = None if sub_device in (None, "none") else sub_device
    if forceps is not None and forceps not in SUB_DEVICES:
        raise CatalogError(f"unknown second device {sub_device!r}; one of {', '.join(SUB_DEVICES)}")
    if forceps is not None and device == "scripted":
        raise CatalogError(
            "a scripted session brings its own assisting hand: a second device is for a person's "
            "session (the needle on the mouse, a SpaceMouse or a Touch)"
        )
    if forceps is None or handedness != "left":
        return Instruments(device, forceps)
    if device == "mouse":
        raise CatalogError(
            "the keyboard and mouse drive the needle holder only, not the forceps: a left-handed "
            f"trainee with the forceps on the {forceps} needs a hand-held device for the needle too"
        )
    return Instruments(forceps, device)


def forceps_start(spec: TaskSpec) -> Pose:
    """Where the subordinate hand's jaws start: open, just above the wound's edge beside the first
    entry mark (the task's first grasp site), jaws pointing into the wall."""
    sites = grasp_sites(spec)
    if not len(sites):
        raise CatalogError(
            f"task {spec.name!r} has no wound edge for the forceps to hold: it is a one-handed task"
        )

    return Pose(sites[0] + FORCEPS_START_HEIGHT_M * access_direction(spec), np.eye(3))


def open_forceps_device(
    name: str,
    spec: TaskSpec,
    left_handed: bool = False,
    taken: str = "",
    home: Path | None = None,
    clock: str = "realtime",
):
    """The subordinate hand's device ``name`` (a :data:`SUB_DEVICES` entry), mapped onto the task's
    scene from :func:`forceps_start`; ``taken``: the needle's device name (two SpaceMice: the second
    one found holds the forceps); ``home``: the data directory (a camera's set-up)."""
    if name == "spacemouse":
        identity = None
        if taken == "spacemouse":
            found = find_spacemice()
            if len(found) < 2:
                raise CatalogError(f"both hands on a SpaceMouse need two plugged in; found {len(found)}")
            identity = found[1]
        device = SpaceMouse(identity)
    elif name == "openhaptics":
        device = OpenHapticsDevice()
    elif name == "camera":  # the needle on another device: the forceps alone in the camera's view
        device, _ = open_camera_device("camera", clock, home, instrument="forceps")
    else:
        raise CatalogError(f"unknown second device {name!r}; one of {', '.join(SUB_DEVICES[1:])}")
    return forceps_on(device, spec, left_handed)


def forceps_on(device, spec: TaskSpec, left_handed: bool = False):
    """An open hand-held ``device`` as the forceps: its first reading is :func:`forceps_start`, its axes
    the live view's (mirrored for a left hand), 1:1 (:class:`sim.devices.workspace.WorkspaceMapping`)."""

    return WorkspaceMapping(device, forceps_start(spec), view_axes(*task_camera(spec)), mirror=left_handed)
