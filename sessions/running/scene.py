"""What a live session shows and where the trainee's hand starts: the task's marks, wound edge and
camera, the heads-up strip's limits, the holder's starting pose, and the stop when the task is done."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from metrics.replay.wound import outline_edges, wound_nodes
from sessions.running.hud import HudLimits
from sessions.running.window import SceneFacts
from sessions.tasks import TaskSpec
from sim.devices.suturing import SuturingPass, SuturingPassParameters
from sim.devices.workspace import WorkspaceMapping, view_axes
from sim.needle import Needle, Pose

CAMERA_DISTANCE_M = 0.024
"""The camera's distance from what it looks at: about 13 mm of the scene fills the height of the view."""
CAMERA_TILT = 0.8
"""The camera looks along the access direction tilted this much (tan of the angle, about 39 deg)
along the wound, so the needle's curve, which lies in the plane of the normal and the bite, is seen
at an angle instead of edge-on."""
START_HEIGHT_M = 0.005
"""The loaded needle starts this far above the first entry mark, along the access direction."""
LIVE_TIME_FACTOR = 2.0
"""A live session with no duration runs until the task is done, the trainee stops it, or this many
times the task's time budget (the heads-up strip counts against the budget itself)."""


def access_direction(spec: TaskSpec) -> NDArray[np.float64]:
    """The direction the hand comes from: the restricted access's corridor, else the wall's normal."""
    direction = np.asarray(spec.access["approach"] if spec.access else spec.normal, dtype=np.float64)
    return direction / np.linalg.norm(direction)


def task_camera(spec: TaskSpec) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """(position, focal point, view up) looking down the task's access direction at its marks and the
    loaded needle above the first (the focal point is between the wall and where the needle starts)."""
    marks = spec.placement["entry_targets"] if spec.placement else [spec.entry]
    approach = access_direction(spec)
    focal = np.mean(np.asarray(marks, dtype=np.float64), axis=0) + 0.5 * START_HEIGHT_M * approach
    along = np.cross(
        np.asarray(spec.normal, dtype=np.float64), np.asarray(spec.bite_direction, dtype=np.float64)
    )
    along -= (along @ approach) * approach
    along /= np.linalg.norm(along)
    looking_from = approach + CAMERA_TILT * along
    looking_from /= np.linalg.norm(looking_from)
    position = focal + CAMERA_DISTANCE_M * looking_from
    up = along - (along @ looking_from) * looking_from
    return tuple(position.tolist()), tuple(focal.tolist()), tuple((up / np.linalg.norm(up)).tolist())


def start_pose(spec: TaskSpec, needle: Needle | None = None) -> Pose:
    """The holder with the needle loaded, square to the wall, :data:`START_HEIGHT_M` above the first
    entry mark along the access direction (where a scripted expert's approach begins)."""
    entry, normal, bite = spec.bites()[0]
    approach = spec.access["approach"] if spec.access else None
    parameters = SuturingPassParameters(approach_distance=START_HEIGHT_M)
    stitch = SuturingPass(needle or Needle.curved(), entry, normal, bite, parameters, approach=approach)
    return stitch.pose_and_grip(0.0)[0]


def scene_facts(spec: TaskSpec, mesh, limits: HudLimits) -> SceneFacts:
    """The live view's marks, wound rim and camera for ``spec`` on its ``mesh``."""
    placement = spec.placement or {}
    targets = np.asarray(
        list(placement.get("entry_targets", [])) + list(placement.get("exit_targets", [])), dtype=np.float64
    ).reshape(-1, 3)
    nodes = wound_nodes(mesh, placement.get("wound_point"), placement.get("wound_normal"))
    return SceneFacts(
        spec.name,
        targets,
        outline_edges(mesh.surface_triangles, nodes),
        task_camera(spec),
        np.asarray(spec.normal, dtype=np.float64),
        limits,
    )


def stop_when_done(simulation, stitches: int) -> None:
    """Stop ``simulation`` once ``stitches`` needles have been pulled clear of the wall (its events
    still go to whatever listened before)."""
    listener: Callable | None = simulation.on_event
    done = [0]

    def on_event(event) -> None:
        if listener is not None:
            listener(event)
        if getattr(event, "kind", "") == "pull_through":
            done[0] += 1
            if done[0] >= stitches:
                simulation.stop("task_done", event.time)

    simulation.on_event = on_event


def mapped_onto_task(device, spec: TaskSpec, left_handed: bool = False):
    """A position or rate device (Touch, SpaceMouse) seen through the task's view: its pose at the first
    reading is the task's starting pose, its axes the screen's, 1:1, mirrored for a left hand
    (:class:`sim.devices.workspace.WorkspaceMapping`)."""

    return WorkspaceMapping(device, start_pose(spec), view_axes(*task_camera(spec)), mirror=left_handed)
