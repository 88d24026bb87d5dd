"""A scripted pass filmed: the video a station's camera would take of a real needle holder moved
exactly as a scripted hand moves it, so a ``camera:FILE`` session can be checked against the scripted
session that made it (issue 47's end-to-end test and ``benchmarks/camera.py``).

The holder's poses (world frame, the task's scene) are read from the scripted device at the video's
frame times and put in front of the camera through the inverse of what the camera device and the
workspace mapping do (:mod:`sim.devices.camera`, :class:`sim.devices.workspace.WorkspaceMapping`), so
that playing the video back through them reproduces the scripted motion 1:1 about its first pose. The
marker cube sits on the holder's shaft (the holder frame's z axis, about which the wrist turns the
needle), rolled by ``roll_deg`` about it; its tip (the holder frame's origin) starts ``distance_m``
from the camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sessions.running.runner import SessionPlan, open_device
from sessions.running.scene import access_direction, task_camera
from sessions.tasks import task_spec
from sim.devices.assisting import ScriptedHands
from sim.devices.camera import PLACEMENTS
from sim.devices.scripted import SuturingPassParameters
from sim.devices.workspace import view_axes
from sim.tracking.markers import FORCEPS, NEEDLE_HOLDER, MarkerBody
from sim.tracking.synthetic import default_camera_matrix, rotation_xyz, write_instrument_video

HOLDER_FROM_BODY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""The cube's axes in the holder's frame: its x along the holder's x, its y (towards the instrument's
back end) along the holder's -z (the shaft), its z along the holder's y."""


def film_scripted_pass(
    task: str,
    parameters: SuturingPassParameters | ScriptedHands,
    path: str | Path,
    size: tuple[int, int] = (1280, 720),
    fps: float = 30.0,
    placement: str = "facing",
    roll_deg: float = 0.0,
    distance_m: float = 0.32,
    body: MarkerBody = NEEDLE_HOLDER,
    hidden: tuple[float, float] | None = None,
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Render the pass (``hidden``: from and to when (s) a hand covers the cube; both hands' parameters
    (:class:`ScriptedHands`): the forceps filmed too, 8 cm to the holder's left); returns (its duration
    in s, the camera matrix, the holder's tip path in the camera frame at each frame (m))."""
    plan = SessionPlan("filmed", "filmed", task, 1)
    device, duration, assisting = open_device("scripted", plan, None, parameters)
    times = np.arange(0.0, duration, 1.0 / fps)
    to_camera = PLACEMENTS[placement].T @ view_axes(*task_camera(task_spec(task))).T  # world -> camera
    mount = HOLDER_FROM_BODY @ rotation_xyz(np.array([0.0, np.radians(roll_deg), 0.0]))
    start = np.array([0.0, 0.08, distance_m])  # the tip low in the image, the cube above it
    cubes, origins, tips = _filmed(device, times, to_camera, mount, start, body)
    others = ()
    if assisting is not None:  # the forceps' cube on their shaft, which comes in along the access
        left = start + np.array([0.08, 0.0, 0.0])  # the trainee's left is the image's right
        forceps = _filmed(
            assisting, times, to_camera, _shaft_along(access_direction(task_spec(task))), left, FORCEPS
        )
        others = ((FORCEPS, forceps[0], forceps[1]),)
    matrix = default_camera_matrix(size, focal_px=size[0] * 0.9)
    covered = None if hidden is None else (times >= hidden[0]) & (times < hidden[1])
    write_instrument_video(path, cubes, origins, body, fps, size, matrix, occluded=covered, others=others)
    return float(duration), matrix, tips


def _shaft_along(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """A cube mount whose y axis (the instrument's back end) points along ``direction`` (tool frame)."""
    back = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    across = np.cross(back, [0.0, 0.0, 1.0] if abs(back[2]) < 0.9 else [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    return np.column_stack([across, back, np.cross(across, back)])


def _filmed(device, times, to_camera, mount, start, body: MarkerBody):
    """(cube rotations, cube origins, tips) in the camera frame of a scripted hand's instrument."""
    samples = [device.read(t) for t in times]
    positions = np.array([s.position for s in samples])
    cubes = np.array([to_camera @ s.rotation @ mount for s in samples])
    tips = start + (positions - positions[0]) @ to_camera.T
    return cubes, tips - np.einsum("nij,j->ni", cubes, np.asarray(body.tip_offset_m)), tips
