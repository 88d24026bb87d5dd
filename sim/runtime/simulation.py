"""The layered multi-rate simulator (PAPER.md section 7) over one set of step functions.

Layers and their default rates: haptics 1000 Hz (device in, safe force out),
FEM 500 Hz (200-1000; needle follows the holder, local CD, contact forces,
piercing), graphics 30 Hz (global CD of the whole needle), display 30 Hz (renders
the previous graphics frame: one video frame of delay, as in the paper).

State crosses layers only as immutable snapshots in :class:`~sim.runtime.snapshots.Mailbox` slots; the
graphics layer's global-CD results are queued and applied by the FEM layer at
the start of its next step, so each mutable object has exactly one owner. The
haptic layer interpolates the FEM layer's force history at ``now - force_delay``
(one video frame by default) and passes it through :class:`ForceSafety`.

Two clocks drive the same steps: :meth:`Simulation.run_simulated` (deterministic,
as fast as the machine allows) and :meth:`Simulation.run_realtime` (threads).
"""

from __future__ import annotations

import collections
import heapq
import math
import threading
import time as wallclock
import traceback
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.devices.base import GRIP_BUTTON, STOP_BUTTON, Device, DeviceLostError
from sim.devices.suturing import planned_exits
from sim.fem import Tissue
from sim.fem.kernel import warm_kernel_geometry
from sim.forceps import Forceps, ForcepsEvent, ForcepsInteraction
from sim.forceps.grasp import with_grasp
from sim.needle import Needle, Pose
from sim.needle.forces import NeedleForces
from sim.needle.interaction import NeedleEvent, NeedleInteraction, PiercingRules
from sim.runtime.logs import ForceHistory, HapticLog
from sim.runtime.prefetch import Prefetcher, arc_ahead, line_ahead, needs_column_worker
from sim.runtime.realtime import process_prepared, run_realtime
from sim.runtime.safety import ForceSafety
from sim.runtime.settings import RuntimeSettings
from sim.runtime.snapshots import FemSnapshot, GraphicsSnapshot, HolderSnapshot, Mailbox, RuntimeEvent
from sim.runtime.telemetry import LAYERS, LoopTelemetry, RunResult

EXIT_REACH_KERNELS = 1.5
"""Surface nodes this many kernel radii from a bite's planned exit are asked of the column worker as a
real-time run starts (the reach it asks round a predicted crossing)."""


class Simulation:
    """One needle, one tissue, one device, run by layers at their rates."""

    def __init__(
        self,
        tissue: Tissue,
        needle: Needle,
        device: Device,
        settings: RuntimeSettings | None = None,
        rules: PiercingRules | None = None,
        renderer: Callable[[GraphicsSnapshot], None] | None = None,
        on_event: Callable[[NeedleEvent | RuntimeEvent], None] | None = None,
        on_sample: Callable[..., None] | None = None,
        forces: NeedleForces | None = None,
        region_forces: Mapping[int, NeedleForces] | None = None,
        subordinate: Device | None = None,
        forceps: Forceps | None = None,
        grasp_sites: ArrayLike | None = None,
        bites: list[tuple] | None = None,
    ) -> None:
        self.settings = settings or RuntimeSettings()
        self.device = device
        self.interaction = NeedleInteraction(
            tissue, needle, rules, forces=forces, region_forces=region_forces
        )
        self.subordinate = subordinate
        """The subordinate hand's device (its tool point is where the forceps' jaws close; its grip
        button closes them), or None for a one-handed session."""
        self.forceps = (
            None if subordinate is None else ForcepsInteraction(tissue, self.interaction.collision, forceps)
        )
        self.subordinate_holder = Mailbox()
        self.subordinate_sample = None  # the subordinate device's latest reading (haptic rate)
        self.grasp_sites = np.zeros((0, 3)) if grasp_sites is None else np.asarray(grasp_sites, float)
        """Where the task expects the forceps to take the edge (m, (k, 3)): a real-time run solves the
        columns of the nodes the jaws would hold there before its clock starts, and those of the nodes
        near the open jaws as they come (the graphics layer), so a grasp waits for no solve."""
        self.bites = list(bites or [])
        """The task's bites, (entry, normal, bite_direction) each: a real-time run has the whole
        columns of the surface nodes where a needle placed square on each mark comes out of the wall
        (:func:`sim.devices.suturing.planned_exits`) solved in the background from its start."""
        self.safety = ForceSafety(device.limits, self.settings.safety, tick=self.settings.period("haptic"))
        self.holder = Mailbox()
        self.fem = Mailbox()
        self.graphics = Mailbox()
        self.forces = ForceHistory()
        self.haptic_log = HapticLog()
        self.global_queue: collections.deque = collections.deque()
        self.global_posted = threading.Event()  # set with each frame queued (wakes the real-time FEM thread)
        self.events: list[NeedleEvent | RuntimeEvent] = []
        self.telemetry = {layer: LoopTelemetry(layer, self.settings.period(layer)) for layer in LAYERS}
        self.renderer = renderer
        self.on_event = on_event
        self.on_sample = on_sample  # (now, DeviceSample, force sent, latest FemSnapshot) every haptic tick
        # the real-time haptic process's compiled force path (sim/runtime/force_path.py), and what
        # its last tick cost (s); None: the Python channels and filter, as in process
        self.force_path = None
        self.force_path_seconds = 0.0
        self.on_haptic_start: Callable[[], None] | None = None  # runs in the haptic process before its loop
        self.on_graphics: Callable[[float, FemSnapshot], None] | None = (
            None  # each graphics frame (main process)
        )
        self.stop_reason: str | None = None
        self.error: str | None = None
        self.error_layer: str | None = None
        self._previous_frame: GraphicsSnapshot | None = None
        self._safety_seen = 0
        self.contact_latencies: dict[str, list[float]] = {"contact_start": [], "exit": [], "grasp": []}
        """Wall seconds from finding a contact change to the end of the FEM step that gave the exact
        forces for its triangle: a first touch, found by the FEM step's own continuous collision test
        (from that step's start); the exit face, found by a graphics frame (from its posting); a grasp,
        from the FEM step reading the closed jaws to the grasp's forces."""
        self._tissue = tissue
        tissue.warm_contact_caches()
        if self.interaction.forces.load == "kernel":
            warm_kernel_geometry(tissue.base)
        self._prefetcher: Prefetcher | None = None  # started for the length of a run (a worker process)
        self._previous_tip: NDArray[np.float64] | None = None  # at the last graphics frame
        self._tracking = 0  # the needle hand's pose: measured (0) or held (2) at the last change
        self.tracking_events: list[tuple[float, str, str]] = []

    # -- the four steps ----------------------------------------------------------------
    def haptic_step(self, now: float) -> None:
        try:
            sample = self.device.read(now)
        except DeviceLostError as error:
            self._emit(RuntimeEvent("device_lost", now, "haptic", str(error)))
            self.stop("device_lost", now)
            return
        pose = sample.pose if sample.pose is not None else Pose(sample.position, sample.rotation)
        grip = sample.pressed(GRIP_BUTTON)
        if sample.tracking != self._tracking and sample.tracking != 1:  # a camera lost or found it
            self._tracking_changed(now, sample.tracking)
        if sample.buttons >> STOP_BUTTON & 1:  # the trainee's stop, on the device itself
            self.stop("stopped_by_trainee", now)
        if self.force_path is not None:  # the same steps in one compiled call, the log included
            began = wallclock.perf_counter()
            force = self.force_path.tick(now, pose.position, pose.rotation, sample.velocity, grip)
            self.force_path_seconds = wallclock.perf_counter() - began
        else:
            self.holder.put(HolderSnapshot(now, pose, sample.velocity, grip))
            target = self.forces.at(now - self.settings.force_delay)
            if self.settings.haptic_scale != 1.0:
                target = self.settings.haptic_scale * target
            force = self.safety.filter(now, target, self.forces.latest_time)
        self._flush_safety_events()
        try:
            self.device.write_force(force)
        except DeviceLostError as error:
            self._emit(RuntimeEvent("device_lost", now, "haptic", str(error)))
            self.stop("device_lost", now)
            return
        if self.force_path is None:
            self.haptic_log.append(now, sample.position, grip, force)
        if self.subordinate is not None:
            self._read_subordinate(now)
        if self.on_sample is not None:
            self.on_sample(now, sample, force, self.fem.get())

    def _tracking_changed(self, now: float, tracking: int) -> None:
        """``tracking_lost`` when the pose becomes held (2), ``tracking_regained`` when it is measured (0)
        again (a predicted pose, 1, in between changes nothing and is not passed here)."""
        kind = "tracking_lost" if tracking == 2 else "tracking_regained"
        detail = "pose held" if tracking == 2 else "pose measured"
        self.tracking_events.append((now, kind, detail))  # the real-time loop passes these to the parent
        self._emit(RuntimeEvent(kind, now, "haptic", detail))
        self._tracking = tracking

    def _read_subordinate(self, now: float) -> None:
        """The subordinate hand's reading at the haptic rate (it is sent no force: the paper's
        subordinate device, a SpaceMouse, renders none)."""
        try:
            sample = self.subordinate.read(now)
        except DeviceLostError as error:
            self._emit(RuntimeEvent("device_lost", now, "haptic", f"subordinate hand: {error}"))
            self.stop("device_lost", now)
            return
        self.subordinate_sample = sample
        pose = sample.pose if sample.pose is not None else Pose(sample.position, sample.rotation)
        self.subordinate_holder.put(HolderSnapshot(now, pose, sample.velocity, sample.pressed(GRIP_BUTTON)))

    def fem_step(self, now: float) -> None:
        holder = self.holder.get()
        if holder is None:
            return
        for event in self.interaction.hold(holder.time, holder.pose, holder.grip):
            self._emit(event)
        began = wallclock.perf_counter()
        changed: list[tuple[str, float]] = []
        while self.global_queue:
            frame_time, vertices, hits, posted = self.global_queue.popleft()
            for event in self.interaction.apply_global(frame_time, vertices, hits):
                self._emit(event)
                if event.kind in self.contact_latencies:
                    changed.append((event.kind, posted))
        step = self.interaction.fem_step(now)
        # a first touch is found in this step by the continuous test: from the step's start
        changed += [(event.kind, began) for event in step.events if event.kind == "contact_start"]
        for kind, posted in changed:
            self.contact_latencies[kind].append(wallclock.perf_counter() - posted)
        for event in step.events:
            self._emit(event)
        grasp = self._forceps_step(now, step)
        self.forces.push(now, step.needle_force)
        contact = self.interaction.last_contact
        if type(contact) is tuple:  # a kernel drive is its own copy, worked out when the graphics reads it
            contact = (contact[0].copy(), contact[1].copy())
        vertices = self.interaction.needle_vertices()
        interaction = self.interaction
        nominated = interaction.contacts[0] if interaction.contacts else None
        self.fem.put(
            FemSnapshot(
                time=now,
                needle_force=step.needle_force,
                needle_vertices=vertices,
                state=interaction.state,
                contact_nodes=step.contact_nodes,
                reaction_forces=step.reaction_forces,
                contact=contact,
                tip_speed=interaction.tip_speed,
                tip_tangent=interaction.tip_tangent(),
                contact_triangle=-1 if nominated is None else nominated.triangle,
                barycentric=(math.nan,) * 3 if nominated is None else tuple(nominated.barycentric.tolist()),
                soft_share=interaction.soft_share,
                local_stress=interaction.local_stress,
                stretch=interaction.stretch,
                holder_time=holder.time,
                tip_velocity=interaction.tip_velocity,
                wrist_at_stop=interaction.wrist is not None and interaction.wrist.holding,
                **grasp,
            )
        )

    def _forceps_step(self, now: float, step) -> dict:
        """The subordinate hand's grasp at this FEM step, superposed with the needle's loads:
        the snapshot's grasp fields by name (the forceps' force on the tissue, the grasped tissue's
        displacement, the grasp's nodal loads, the jaws), none with no hand."""
        forceps, hand = self.forceps, self.subordinate_holder.get()
        if forceps is None or hand is None:
            return {}
        was_grasping, began = forceps.grasping, wallclock.perf_counter()
        forceps.hold(hand.time, hand.pose.position, hand.grip)
        grasp = forceps.fem_step(now, step.contact_nodes, step.reaction_forces, self.interaction.kernel_loads)
        if forceps.grasping and not was_grasping:
            self.contact_latencies["grasp"].append(wallclock.perf_counter() - began)
        for event in grasp.events:
            self._emit(event)
        held = (grasp.nodes.copy(), grasp.nodal_forces.copy()) if grasp.nodes.size else None
        return {
            "grasp_force": grasp.force,
            "grasp_displacement": grasp.displacement,
            "grasp_loads": held,
            "jaws": (forceps.jaw_point.copy(), forceps.jaw_closed),
        }

    def graphics_step(self, now: float) -> None:
        fem = self.fem.get()
        if fem is None:
            return
        if self._prefetcher is not None:  # first, so the FEM thread applying the query's result
            self._prefetch_ahead_of(fem)  # does not share the interpreter with this work
            if self.forceps is not None and not self.forceps.jaw_closed:  # what the jaws may take next
                self._prefetcher.near(self.forceps.jaw_point, self.forceps.prefetch_radius)
                self.forceps.prepare()
        if self.forceps is not None:  # the needle meets the tissue where the other hand holds it
            self.forceps.deform_collision()
        posted = wallclock.perf_counter()
        hits = self.interaction.collision.query(fem.needle_vertices)
        self.global_queue.append((now, fem.needle_vertices, hits, posted))
        self.global_posted.set()
        loads = None
        if fem.state != "free" and len(fem.contact_nodes):
            loads = (fem.contact_nodes, fem.reaction_forces, fem.soft_share)
        if fem.grasp_loads is not None:  # the display draws the wall where both hands put it
            loads = with_grasp(loads, *fem.grasp_loads)
        self.graphics.put(
            GraphicsSnapshot(
                now, fem.needle_vertices, fem.state, hits, fem.contact, fem.holder_time, loads, fem.jaws
            )
        )
        if self.on_graphics is not None:
            self.on_graphics(now, fem)

    def _prefetch_ahead_of(self, fem: FemSnapshot) -> None:
        """Ask for the columns the next contact changes will need (graphics layer, on-demand columns).

        Precomputed models only need columns for nodes off the candidates, i.e. where a needle in
        the wall may come out: the exit face its curve is heading for. The nodes the path crosses
        also get their tissue depth cast in the background (a first touch needs it). The path's
        crossings go ahead of the sphere around the tip (the later request is served first).
        """
        tip = fem.needle_vertices[0]
        previous, self._previous_tip = self._previous_tip, tip
        prefetcher, reach = self._prefetcher, self.settings.prefetch_reach
        if fem.state in ("free", "contact"):  # the body can touch too (issue 43): where it nears the wall,
            # first, so the tip's requests (newer) are served before them
            for point in self.interaction.collision.nearest_to_surface(fem.needle_vertices[1:], reach, 4):
                prefetcher.near(point, self.settings.prefetch_radius)
        if prefetcher.on_demand or fem.state in ("pierced", "exited"):
            prefetcher.near(tip, self.settings.prefetch_radius)
        if fem.state == "free":  # not yet touching: the needle goes where the hand moves it; where it
            # will come out depends on how it is then turned, and turning it along its own curve is
            # the likely way: that path's exit face is asked for now (a thin wall can be crossed in
            # a few hundred ms, too soon after the first touch for the worker to catch up), and
            # the next contact on the line of motion ahead of it (the newest request goes first)
            prefetcher.ahead(arc_ahead(fem.needle_vertices, reach), kind="arc")
            if previous is not None:
                prefetcher.ahead(line_ahead(tip, tip - previous, reach), crossings=1, kind="line")
        else:  # in contact or in the wall: the tip follows the needle's own curve
            prefetcher.ahead(arc_ahead(fem.needle_vertices, reach), kind="arc")

    def display_step(self, now: float) -> None:
        frame, self._previous_frame = self._previous_frame, self.graphics.get()
        if self.settings.display_delay_frames == 0:
            frame = self._previous_frame
        if frame is not None and self.renderer is not None:
            self.renderer(frame)  # one video frame late, as in the paper
        elif self.renderer is not None and hasattr(self.renderer, "idle"):
            self.renderer.idle()  # a window still answers its keys and mouse before the first frame

    # -- events and stopping -----------------------------------------------------------------
    def _emit(self, event: NeedleEvent | RuntimeEvent | ForcepsEvent) -> None:
        self.events.append(event)
        if self.on_event is not None:
            self.on_event(event)

    def _flush_safety_events(self) -> None:
        while self._safety_seen < len(self.safety.events):
            when, kind, detail = self.safety.events[self._safety_seen]
            self._safety_seen += 1
            self._emit(RuntimeEvent(kind, when, "haptic", detail))

    def stop(self, reason: str, now: float) -> None:
        if self.stop_reason is None:
            self.stop_reason = reason

    def fail(self, layer: str, now: float, error: BaseException) -> None:
        """A layer raised: record it with its layer and stop."""
        self.error = f"{type(error).__name__}: {error}"
        self.error_layer = layer
        self._emit(
            RuntimeEvent("layer_failed", now, layer, self.error + "\n" + traceback.format_exc(limit=3))
        )
        self.stop(f"{layer}_failed", now)

    def _wind_down(self, now: float) -> None:
        """Force to zero within the rate limit, unless the device is gone."""
        if self.stop_reason == "device_lost":
            return
        for when, force in self.safety.stop_sequence(now, self.settings.period("haptic")):
            try:
                self.device.write_force(force)
            except DeviceLostError:
                return
            self.haptic_log.append(
                when, self.haptic_log.position[-1] if self.haptic_log.count else np.zeros(3), False, force
            )
        self._emit(RuntimeEvent("stopped", now, "runtime", self.stop_reason or ""))

    def _cast_candidate_depths(self) -> None:
        """A first touch needs the tissue depth under its nodes, cast once per node (0.1-0.3 ms
        each): in real time, cast it for every precomputed contact candidate before the clock
        starts rather than on the FEM thread at the touch (the prefetcher casts the rest ahead
        of the needle). Simulated time casts as it goes: the same results, less work in all."""
        model = self._tissue.base
        if model.precomputation is not None:
            model.cast_depths(model.contact_nodes)

    def _solve_grasp_sites(self) -> None:
        """Before the clock: the whole K0^-1 columns of the surface nodes the jaws could hold at each
        of :attr:`grasp_sites` (the grasp's handle reads their free-surface rows)."""
        if self.forceps is None or not len(self.grasp_sites):
            return
        mesh = self._tissue.mesh
        surface = mesh.surface_nodes
        reach = self.forceps.prefetch_radius
        for site in self.grasp_sites.reshape(-1, 3):
            near = surface[np.linalg.norm(mesh.points[surface] - site, axis=1) <= reach]
            near = np.setdiff1d(near, self.forceps.model.clamped_nodes)
            if near.size:
                self.forceps.model.prefetch(near, full=True)
                self.forceps.rehearse(site)

    def _ask_for_exit_sites(self) -> None:
        """As the clock starts: ask the column worker for the whole K0^-1 columns of the surface nodes
        within the kernels' reach of where a needle planned square on each bite comes out, solved in
        the background while the hand approaches (the live stress reads them when the tip comes out:
        at the station the worker, asked only once the needle was in the wall, had left 24 of a
        first exit's nodes unsolved, and that exit waited 0.2 s for them)."""
        if self._prefetcher is None:
            return
        reach = EXIT_REACH_KERNELS * self.interaction.forces.kernel_radius
        for site in planned_exits(self.interaction.needle, self.interaction.collision, self.bites):
            self._prefetcher.near(site, reach)

    def _start_prefetching(self, whole_columns: bool = False) -> None:
        """Start solving on-demand columns ahead of contact, if some contact could need them (with
        ``whole_columns``, as the live local stress in real time does: whole columns of precomputed
        candidates too); before any of the run's threads start (the worker is forked). Real time
        only: simulated runs wait for a solve without falling behind a clock, so they solve what
        they lack when they need it."""
        if self._prefetcher is None and (needs_column_worker(self._tissue) or whole_columns):
            self._prefetcher = Prefetcher(
                self._tissue,
                self.interaction.collision,
                full_columns=whole_columns,
                load_radius=1.5 * self.interaction.forces.kernel_radius,  # the kernel's nodes, with margin
            )

    def close(self) -> None:
        """Stop the background prefetch worker (runs do at their end)."""
        if self._prefetcher is not None:
            prefetcher, self._prefetcher = self._prefetcher, None
            prefetcher.close()

    def run_result(self, end: float, wall: float) -> RunResult:
        """How the run ended and what it produced, at simulated time ``end`` after ``wall`` seconds."""
        return RunResult(
            self.stop_reason or "completed",
            end,
            self.events,
            {k: v.summary() for k, v in self.telemetry.items()},
            self.haptic_log,
            self.error,
            self.error_layer,
            wall,
        )

    # -- clocks ------------------------------------------------------------------------------------
    def run_simulated(self, duration: float) -> RunResult:
        """Deterministic simulated time: every step at its exact scheduled time, in time order."""
        periods = {layer: self.settings.period(layer) for layer in LAYERS}
        steps = {
            "haptic": self.haptic_step,
            "fem": self.fem_step,
            "graphics": self.graphics_step,
            "display": self.display_step,
        }
        # (scheduled time, layer order, step count, layer): times are count * period, exact.
        self.interaction.live_stress = True  # simulated time can afford the stress operator's solve
        see = getattr(self.device, "see_needle", None)
        if see is not None:  # a scripted hand in this process may look at where the needle lies
            see(lambda: self.interaction.needle_pose)
        queue = [(0.0, i, 0, layer) for i, layer in enumerate(LAYERS)]
        heapq.heapify(queue)
        # no prefetching: with no clock to fall behind, a contact solves the columns it lacks when it
        # needs them, in this process; a worker would only solve some it never needs, on a core that
        # is not free (the demo runs two sessions at once). The same columns, the same results.
        start_wall = wallclock.perf_counter()
        now = 0.0
        try:
            while self.stop_reason is None:
                now, rank, count, layer = queue[0]
                if now > duration:
                    break
                began = wallclock.perf_counter()
                try:
                    steps[layer](now)
                except Exception as error:  # any layer's failure stops the session cleanly
                    self.fail(layer, now, error)
                self.telemetry[layer].record(now, wallclock.perf_counter() - began)
                heapq.heapreplace(queue, ((count + 1) * periods[layer], rank, count + 1, layer))
        finally:
            self.close()
        self._wind_down(now)
        return self.run_result(min(now, duration), wallclock.perf_counter() - start_wall)

    def run_realtime(self, duration: float, pin_cpus: bool = True) -> RunResult:
        """Wall-clock time: the haptic layer in its own process (both hands' devices), the others in
        threads."""
        self.interaction.live_stress = self.settings.live_stress_in_real_time
        with process_prepared():  # before the column worker is forked: it inherits the settings
            self._cast_candidate_depths()
            self._start_prefetching(whole_columns=self.interaction.live_stress)
            self._solve_grasp_sites()
            self._ask_for_exit_sites()
            try:
                return run_realtime(self, duration, pin_cpus)
            finally:
                self.close()
