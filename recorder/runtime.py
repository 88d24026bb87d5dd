"""Recording a running simulation: one sample row per haptic tick, every event."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from recorder.scene import SceneLog
from recorder.schema import COLUMN, SAMPLE_COLUMNS, column_span
from recorder.writer import SessionWriter
from sim.devices.base import DeviceSample
from sim.needle import Pose
from sim.runtime.simulation import Simulation
from sim.runtime.snapshots import STATE_CODES, FemSnapshot

# the sample row's places, by name (recorder/schema.py declares the order)
_TIME, _TIP_SPEED, _TRIANGLE = COLUMN["time"], COLUMN["tip_speed"], COLUMN["contact_triangle"]
_LOCAL_STRESS, _STRETCH, _STATE = COLUMN["local_stress"], COLUMN["stretch"], COLUMN["pierced"]
_GRIP, _PERIOD = COLUMN["grip"], COLUMN["period"]
_TOOL = column_span("tool_x", "tool_y", "tool_z")
_TOOL_ROTATION = column_span("tool_qw", "tool_qx", "tool_qy", "tool_qz")
_TOOL_VELOCITY = column_span("tool_vx", "tool_vy", "tool_vz")
_TIP = column_span("tip_x", "tip_y", "tip_z")
_TANGENT = column_span("tangent_x", "tangent_y", "tangent_z")
_FORCE = column_span("force_x", "force_y", "force_z")
_BARYCENTRIC = column_span("bary_0", "bary_1", "bary_2")
_REACTION = column_span("reaction_x", "reaction_y", "reaction_z")
_TIP_VELOCITY = column_span("tip_vx", "tip_vy", "tip_vz")
_SUB_DISPLACEMENT = column_span("sub_dx", "sub_dy", "sub_dz")
_SUB_TOOL = column_span("sub_x", "sub_y", "sub_z")
_SUB_ROTATION = column_span("sub_qw", "sub_qx", "sub_qy", "sub_qz")
_SUB_JAW = COLUMN["sub_jaw"]
_GRASP_DISPLACEMENT = column_span("grasp_dx", "grasp_dy", "grasp_dz")
_GRASP_FORCE = column_span("grasp_fx", "grasp_fy", "grasp_fz")
_TOOL_TRACKING, _SUB_TRACKING = COLUMN["tool_tracking"], COLUMN["sub_tracking"]


def quaternion_of(rotation: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix, in plain floats (cheap enough per haptic tick)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = rotation.tolist()
    trace = m00 + m11 + m22
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        return 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    if m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        return (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    if m11 >= m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        return (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
    return (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s


class RuntimeRecorder:
    """Feeds a :class:`Simulation`'s haptic ticks and events into a :class:`SessionWriter`."""

    def __init__(self, writer: SessionWriter) -> None:
        self.writer = writer
        self._row = np.zeros(len(SAMPLE_COLUMNS))
        self._row[_LOCAL_STRESS] = math.nan
        self._row[_STRETCH] = math.nan
        self._row[_TIP_VELOCITY] = math.nan  # not known before the first FEM step
        self._row[_SUB_TOOL] = math.nan  # no subordinate hand (a one-handed session)
        self._row[_SUB_ROTATION] = math.nan
        self._subordinate = None  # the simulation, when it has a subordinate hand
        self._sub_start = None  # the subordinate hand's first position: sub_dx/dy/dz count from it
        self._row_cells = memoryview(self._row)  # what record() copies cheapest (recorder/_ring.c)
        self._last_time: float | None = None
        self._needle_at = None  # (tip, tangent) of the grasped needle for a device sample, once attached

    def attach(self, simulation: Simulation) -> Simulation:
        interaction = simulation.interaction

        def needle_at(sample) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            holder = sample.pose if sample.pose is not None else Pose(sample.position, sample.rotation)
            pose = holder.compose(interaction.grasp)
            return interaction.needle.world_vertices(pose)[0], interaction.needle.tip_tangent(pose)

        self._needle_at = needle_at
        if simulation.subordinate is not None:
            self._subordinate = simulation
        simulation.on_sample = self.on_sample
        simulation.on_event = self.on_event
        simulation.on_haptic_start = self.writer.prefault
        simulation.on_graphics = self.on_graphics
        self.writer.scene = SceneLog()
        return simulation

    def on_graphics(self, now: float, fem: FemSnapshot) -> None:
        """One scene frame per graphics step: what a replay needs to draw it without re-simulating."""
        drive = fem.contact if fem.state != "free" else None
        self.writer.scene.add(
            now,
            STATE_CODES.get(fem.state, 0),
            fem.tip_speed,
            fem.needle_force,
            fem.needle_vertices,
            drive,
            fem.soft_share,
            fem.grasp_loads,
            fem.jaws,
        )

    def on_sample(
        self, now: float, sample: DeviceSample, force: NDArray[np.float64], fem: FemSnapshot | None
    ) -> None:
        row = self._row
        row[_TIME] = now
        row[_TOOL] = sample.position
        row[_TOOL_ROTATION] = quaternion_of(sample.rotation)
        row[_TOOL_VELOCITY] = sample.velocity
        if fem is not None:
            row[_TIP] = fem.needle_vertices[0]
            row[_TIP_SPEED] = fem.tip_speed
            if fem.tip_tangent is not None:
                row[_TANGENT] = fem.tip_tangent
            row[_TIP_VELOCITY] = fem.tip_velocity if fem.tip_velocity is not None else math.nan
            row[_TRIANGLE] = fem.contact_triangle
            row[_BARYCENTRIC] = fem.barycentric
            row[_LOCAL_STRESS] = fem.local_stress  # held between FEM steps: the latest snapshot's
            row[_STRETCH] = fem.stretch
            row[_STATE] = STATE_CODES.get(fem.state, 0)
        elif self._needle_at is not None:  # before the first FEM step: where the holder puts the needle
            row[_TIP], row[_TANGENT] = self._needle_at(sample)
        row[_FORCE] = force
        if fem is not None:
            row[_REACTION] = fem.needle_force  # the tissue's, not what the device was sent
        row[_GRIP] = sample.buttons & 1
        row[_TOOL_TRACKING] = sample.tracking
        if self._subordinate is not None:
            self._subordinate_hand(row, fem)
        row[_PERIOD] = 0.0 if self._last_time is None else now - self._last_time
        self._last_time = now
        self.writer.record(self._row_cells)

    def _subordinate_hand(self, row: NDArray[np.float64], fem: FemSnapshot | None) -> None:
        """The subordinate hand's columns: its tool point, its displacement since its first reading,
        orientation and jaws (this tick's reading), the grasp's tissue displacement and force (the
        latest FEM step's)."""
        sample = self._subordinate.subordinate_sample
        if sample is None:
            return
        if self._sub_start is None:
            self._sub_start = sample.position.copy()
        row[_SUB_TOOL] = sample.position
        row[_SUB_DISPLACEMENT] = sample.position - self._sub_start
        row[_SUB_ROTATION] = quaternion_of(sample.rotation)
        row[_SUB_JAW] = sample.buttons & 1
        row[_SUB_TRACKING] = sample.tracking
        if fem is not None and fem.grasp_force is not None:
            row[_GRASP_DISPLACEMENT] = fem.grasp_displacement
            row[_GRASP_FORCE] = fem.grasp_force

    def on_event(self, event) -> None:
        self.writer.event(
            event.time,
            event.kind,
            triangle=getattr(event, "triangle", -1),
            barycentric=getattr(event, "barycentric", (math.nan,) * 3),
            entry_angle_deg=getattr(event, "entry_angle_deg", math.nan),
            tip_speed=getattr(event, "tip_speed", math.nan),
            layer=getattr(event, "layer", "fem" if hasattr(event, "triangle") else ""),
            detail=event.detail.splitlines()[0] if event.detail else "",
        )
