"""A recorded session re-simulated frame by frame: needle, tissue drive and force at each video frame.

The recorder keeps the tool's pose and grip at every haptic tick, which is all the
runtime takes as input; played back through a :class:`sim.devices.ReplayDevice` in
simulated time the same runtime reproduces the session (bit for bit for a session
that ran in simulated time). The FEM layer's snapshot at each frame time gives what
the scene needs: needle vertices, the nodes the tissue was driven at and how far,
the needle state, tip speed, and the force sent to the device.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from recorder.scene import read_scene
from sim.devices import ReplayDevice
from sim.needle import Needle
from sim.needle.forces import NeedleForces
from sim.runtime import Simulation
from sim.runtime.snapshots import STATE_CODES

STATE_NAMES = {code: name for name, code in STATE_CODES.items()}


@dataclass(frozen=True)
class ReplayTrack:
    """Per video frame: time (F,) s; needle (F, V, 3) m, tip first; state (F,) 0 free .. 3 exited;
    force (F, 3) N, the tissue's reaction on the needle; tip_speed (F,) m/s; drives: per frame the
    contact nodes, intended displacements (k, 3) m the tissue was driven at and the biphase soft share
    of the drive (nan: derived from the drive), or None; grasps: per frame the nodes the subordinate
    hand's forceps hold and their force on each (k, 3) N, or None; jaws: per frame the forceps' jaw
    point (m) and whether closed, or None (one hand)."""

    times: NDArray[np.float64]
    needle: NDArray[np.float64]
    state: NDArray[np.int8]
    force: NDArray[np.float64]
    tip_speed: NDArray[np.float64]
    drives: list[tuple[NDArray[np.int64], NDArray[np.float64], float] | None]
    grasps: list[tuple[NDArray[np.int64], NDArray[np.float64]] | None] | None = None
    jaws: list[tuple[NDArray[np.float64], bool] | None] | None = None

    @property
    def tip(self) -> NDArray[np.float64]:
        return self.needle[:, 0]

    def __len__(self) -> int:
        return len(self.times)


def session_track(session, tissue, fps: float = 30.0) -> ReplayTrack:
    """The frames of a recorded session: from its scene stream when it has one (the nearest recorded
    graphics frame to each video frame), else by re-simulating it."""

    scene = read_scene(session)
    if scene is None or scene.num_rows == 0:
        return replay_track(session, tissue, fps)
    return scene_track(scene, fps)


def scene_track(scene, fps: float = 30.0) -> ReplayTrack:
    """Frames at ``fps`` from a recorded scene table (nearest recorded frame at or before each time)."""
    if not fps > 0:
        raise MetricsError(f"frame rate must be positive; got {fps}")
    recorded = scene.column("time").to_numpy()
    frame_times = np.arange(recorded[0], recorded[-1] + 1e-9, 1.0 / fps)
    pick = np.clip(np.searchsorted(recorded, frame_times + 1e-9, side="right") - 1, 0, len(recorded) - 1)
    needle_flat = scene.column("needle").combine_chunks()
    vertices = len(needle_flat[0]) // 3
    needle = needle_flat.flatten().to_numpy().reshape(-1, vertices, 3)
    force = scene.column("force").combine_chunks().flatten().to_numpy().reshape(-1, 3)
    nodes = scene.column("drive_nodes").to_pylist()
    intended = scene.column("drive_intended").to_pylist()
    shares = scene.column("drive_soft_share").to_numpy()
    drives = [
        (
            np.asarray(nodes[k], dtype=np.int64),
            np.asarray(intended[k], dtype=np.float64).reshape(-1, 3),
            float(shares[k]),
        )
        if nodes[k]
        else None
        for k in pick
    ]
    held, pulls = scene.column("grasp_nodes").to_pylist(), scene.column("grasp_forces").to_pylist()
    points, closed = scene.column("jaws").to_pylist(), scene.column("jaws_closed").to_pylist()
    return ReplayTrack(
        times=frame_times,
        needle=needle[pick],
        state=scene.column("state").to_numpy().astype(np.int8)[pick],
        force=force[pick],
        tip_speed=scene.column("tip_speed").to_numpy()[pick],
        drives=drives,
        grasps=[
            (np.asarray(held[k], dtype=np.int64), np.asarray(pulls[k], dtype=np.float64).reshape(-1, 3))
            if held[k]
            else None
            for k in pick
        ],
        jaws=[None if closed[k] is None else (np.asarray(points[k]), bool(closed[k])) for k in pick],
    )


def replay_track(session, tissue, fps: float = 30.0, needle: Needle | None = None) -> ReplayTrack:
    """Re-simulate a :class:`recorder.Session` and keep one FEM snapshot per frame at ``fps``."""
    if not fps > 0:
        raise MetricsError(f"frame rate must be positive; got {fps}")
    samples = session.samples
    if samples.num_rows < 2:
        raise MetricsError(f"session {session.path} has fewer than 2 samples; nothing to replay")

    def column(name: str) -> NDArray:
        return samples.column(name).to_numpy()

    time = column("time").astype(np.float64)
    device = ReplayDevice(
        time,
        np.column_stack([column(n) for n in ("tool_x", "tool_y", "tool_z")]),
        np.column_stack([column(n) for n in ("tool_qw", "tool_qx", "tool_qy", "tool_qz")]),
        column("grip"),
        session=str(session.header.get("session_id", session.path.name)),
    )
    duration = float(time[-1])
    frame_times = np.arange(0.0, duration + 1e-9, 1.0 / fps)
    captured: list = []
    # the law it ran under: since the wall can tear and slide, the needle's path depends on it
    recorded = session.header.get("needle_forces")
    forces = NeedleForces.from_dict(dict(recorded)) if isinstance(recorded, dict) else None
    hand = _subordinate_hand(session, column)  # a two-handed session replays with both hands
    simulation = Simulation(tissue, needle or Needle.curved(), device, forces=forces, subordinate=hand)
    state = {"next": 0}

    def on_sample(now, sample, force, fem) -> None:
        while state["next"] < len(frame_times) and now >= frame_times[state["next"]] - 1e-9:
            reaction = np.zeros(3) if fem is None else np.array(fem.needle_force, dtype=np.float64)
            captured.append((now, fem, reaction))
            state["next"] += 1

    simulation.on_sample = on_sample
    result = simulation.run_simulated(duration)
    if result.error:
        raise MetricsError(
            f"replaying session {session.path} failed in the {result.error_layer} layer: {result.error}"
        )
    # frames before the first FEM snapshot show the needle where the first snapshot has it
    first = next((fem for _, fem, _ in captured if fem is not None), None)
    if first is None:
        raise MetricsError(f"replaying session {session.path} produced no FEM state")
    frames = len(captured)
    vertices = first.needle_vertices.shape[0]
    needle_path = np.empty((frames, vertices, 3))
    states = np.zeros(frames, dtype=np.int8)
    speeds = np.zeros(frames)
    drives: list = []
    grasps: list = []
    jaws: list = []
    for k, (_, fem, _) in enumerate(captured):
        fem = fem or first
        needle_path[k] = fem.needle_vertices
        states[k] = STATE_CODES.get(fem.state, 0)
        speeds[k] = fem.tip_speed
        contact = fem.contact if fem.state in ("contact", "pierced", "exited") else None
        drives.append(
            None
            if contact is None or len(contact[0]) == 0
            else (contact[0].copy(), contact[1].copy(), float(fem.soft_share))
        )
        grasps.append(fem.grasp_loads)
        jaws.append(fem.jaws)
    return ReplayTrack(
        times=np.array([when for when, _, _ in captured]),
        needle=needle_path,
        state=states,
        force=np.array([force for _, _, force in captured]),
        tip_speed=speeds,
        drives=drives,
        grasps=grasps,
        jaws=jaws,
    )


def _subordinate_hand(session, column) -> ReplayDevice | None:
    """The recorded subordinate hand as a device (its tool point, orientation and jaws at every tick),
    or None for a session recorded one-handed (its columns NaN or absent)."""
    if "sub_jaw" not in session.samples.column_names:
        return None
    position = np.column_stack([column(n) for n in ("sub_x", "sub_y", "sub_z")])
    if not np.all(np.isfinite(position)):
        return None
    return ReplayDevice(
        column("time").astype(np.float64),
        position,
        np.column_stack([column(n) for n in ("sub_qw", "sub_qx", "sub_qy", "sub_qz")]),
        column("sub_jaw"),
        session=str(session.header.get("session_id", session.path.name)),
    )
