"""The station's live view: the deforming wall in a window on the trainee's display.

A :class:`LiveWindow` is the simulation's display callback. It is made in the session's process
(where it factorises the display's tissue model) and opens its window in the display process the
real-time run forks (:meth:`LiveWindow.prepare`), which then calls it once a display frame with the
previous graphics snapshot (one video frame behind the FEM state, as in the paper). Each frame it
answers the window's keys and mouse (Escape stops the session; with the keyboard-and-mouse device,
:class:`sim.devices.mouse.MouseHand` turns them into the holder's pose and publishes it), draws the
wall coloured by stress, the needle and its shadow on the wall (the depth cue), the wound edge, the
task's target marks and each bite's entry and exit as it happens, and the heads-up strip
(:mod:`sessions.running.hud`).
"""

from __future__ import annotations

import math
import os
import time as clock
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sessions.running.hud import HudLimits, HudTracker
from sim.devices.mouse import GRIP_KEYS, MouseHand, PoseChannel
from sim.errors import VascsimError
from sim.render import TissueRenderer
from sim.runtime.display import DisplayScene, instruments_now

FORCEPS_KEYS = ("f",)
"""The key (or a second foot pedal sending it) that closes and opens camera-tracked forceps' jaws."""
LIVE_VIEW_EVERY = 2
"""The window publishes every this many frames for the dashboard's live page (15 frames/s at 30)."""
STEREO_MODES = ("anaglyph", "split", "crystal-eyes")
"""VTK's stereo modes offered by ``--stereo``: red-cyan glasses, left and right halves of the window
(side-by-side 3-D displays), and quad-buffered shutter glasses where the driver offers it."""
SHADOW_LIFT_M = 3e-5
"""The needle's shadow is drawn this far above the wall, so the wall never hides it."""


class WindowError(VascsimError):
    """The live window could not be opened or set up."""


@dataclass(frozen=True)
class ViewSettings:
    """The window: size in pixels, title, a stereo mode (None or one of :data:`STEREO_MODES`)."""

    size: tuple[int, int] = (960, 540)
    title: str = "vascsim"
    stereo: str | None = None

    def __post_init__(self) -> None:
        if self.stereo is not None and self.stereo not in STEREO_MODES:
            raise WindowError(f"stereo must be one of {', '.join(STEREO_MODES)}; got {self.stereo!r}")
        width, height = self.size
        if not (320 <= width <= 7680 and 240 <= height <= 4320):
            raise WindowError(f"window size must be 320x240 to 7680x4320 pixels; got {width}x{height}")


@dataclass(frozen=True)
class SceneFacts:
    """What the view shows beside the tissue and needle (SI units, plain values).

    targets: (K, 3) the task's target marks; wound_edges: (E, 2) node pairs of the wound's rim;
    camera: (position, focal point, view up); surface_normal: the wall's outward normal at the
    stitch (the shadow falls along it); limits: what the heads-up strip measures against.
    """

    task: str
    targets: NDArray[np.float64]
    wound_edges: NDArray[np.int64]
    camera: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    surface_normal: NDArray[np.float64]
    limits: HudLimits


class LiveWindow:
    """The live view as a display callback (see the module docstring).

    ``hand`` and ``channel``: the keyboard-and-mouse device's hand and the channel its haptic side
    reads (None for other devices: the window then only shows, and Escape still stops).
    ``latency_log``: a file the window writes, at its end, each frame's (holder sample time, swap
    time) in session seconds, for the motion-to-photon figure.
    """

    def __init__(
        self,
        tissue,
        facts: SceneFacts,
        settings: ViewSettings | None = None,
        hand: MouseHand | None = None,
        channel: PoseChannel | None = None,
        latency_log: Path | None = None,
        published: Path | None = None,
    ) -> None:
        self.scene = DisplayScene(tissue, None)  # factorises here, before the run forks
        self.facts = facts
        self.settings = settings or ViewSettings()
        self.hand, self.channel = hand, channel
        self.simulation = None  # set by the runner: the display process reads the FEM snapshot from it
        self.tracker = HudTracker(facts.limits)
        self.tracking_problem: Callable[[], str | None] | None = None  # a camera device's, per frame
        self.toggle_grip: Callable[[], None] | None = None  # a camera device's jaws, on the G key
        self.toggle_forceps: Callable[[], None] | None = None  # camera-tracked forceps' jaws, on the F key
        self.forceps_problem: Callable[[], str | None] | None = None
        self.latency_log = latency_log
        self.published = published  # a JPEG of the view, every LIVE_VIEW_EVERY frames, for the dashboard
        self._pixels = None
        self._latencies: list[tuple[float, float]] = []
        self._request_stop: Callable[..., None] = lambda *_: None
        self._renderer = None
        self._held: set[str] = set()
        self._sent: tuple = (None, None)  # the hand's pose and grip last published
        self._dragging: tuple[int, int] | None = None
        self._needle = np.zeros((2, 3))
        self._session_time: Callable[[], float] = clock.perf_counter
        self._last = 0.0
        self.frames = 0

    # -- in the display process ----------------------------------------------------------------
    def prepare(self, request_stop: Callable[..., None], session_time: Callable[[], float]) -> None:
        """Open the window (in the display process: the process that draws into it).
        ``request_stop(reason)`` stops the run; ``session_time()`` is the session's clock (s)."""

        self._request_stop, self._session_time = request_stop, session_time
        settings = self.settings
        renderer = TissueRenderer(
            self.scene.mesh,
            size=settings.size,
            offscreen=False,
            anti_aliasing=False,  # 4x MSAA triples a software-rendered frame
            title=f"{settings.title}: {self.facts.task}",
        )
        self._renderer = renderer
        facts = self.facts
        if len(facts.targets):
            renderer.show_placement(facts.targets, np.zeros((0, 3)), np.zeros((0, 3), dtype=np.uint8))
        renderer.show_outline(facts.wound_edges)
        renderer.set_camera(*facts.camera)
        # the needle moves anywhere in front of the camera: clip nothing from 1 mm to 0.2 m (set once;
        # the renderer then keeps it, where resetting it to the scene's bounds costs 0.7 ms a frame)
        camera = renderer.plotter.renderer.GetActiveCamera()
        camera.SetClippingRange(0.001, 0.2)
        renderer.plotter.renderer.SetAutomaticLightCreation(False)
        self._add_overlays(renderer)
        if settings.stereo is not None:
            self._stereo(renderer, settings.stereo)
        renderer.plotter.show(auto_close=False, interactive_update=True)
        renderer.plotter.set_background("white")  # opening the window applies the theme's own
        self._bind_input(renderer.plotter.iren.interactor)
        renderer.plotter.render()

    def idle(self) -> None:
        """A display step before the first graphics frame: answer input, draw the scene at rest."""
        self._input()
        self._draw(None)

    def __call__(self, snapshot) -> None:
        self._needle = snapshot.needle_vertices
        self._input()
        self._draw(snapshot)

    def _publish(self) -> None:
        """The frame just drawn as a JPEG at :attr:`published`, replaced in place (a reader never
        sees half a file); what the dashboard's live page shows. Read back from the window's front
        buffer (no second render) and encoded by OpenCV: about 4 ms at 960x540."""
        import cv2
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

        window = self._renderer.plotter.render_window
        if self._pixels is None:
            self._pixels = vtkUnsignedCharArray()
            self.published.parent.mkdir(parents=True, exist_ok=True)
        width, height = window.GetSize()
        window.GetPixelData(0, 0, width - 1, height - 1, 1, self._pixels, 0)
        image = vtk_to_numpy(self._pixels).reshape(height, width, 3)[::-1, :, ::-1]  # top row first, BGR
        ok, data = cv2.imencode(".jpg", np.ascontiguousarray(image), [cv2.IMWRITE_JPEG_QUALITY, 75])
        if ok:
            partial = self.published.with_suffix(".part")
            partial.write_bytes(data.tobytes())
            os.replace(partial, self.published)

    def finish(self) -> None:
        """Close the window (and take its published view away); write the latency log when asked for."""
        if self.published is not None:
            self.published.unlink(missing_ok=True)
        if self.latency_log is not None and self._latencies:
            np.save(self.latency_log, np.array(self._latencies))
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # -- drawing --------------------------------------------------------------------------------
    def _now(self) -> float:
        return max(self._session_time(), 0.0)

    def _draw(self, snapshot) -> None:
        renderer = self._renderer
        # the wall as the graphics frame left it (at most a frame old, as in the paper), solved first
        frame = self.scene.frame_of(snapshot) if snapshot is not None else None
        now = self._now()
        fem = self.simulation.fem.get() if self.simulation is not None else None
        force = np.zeros(3) if fem is None else np.asarray(fem.needle_force)
        if fem is not None:
            self.tracker.update(
                now,
                fem.state,
                force,
                fem.needle_vertices[0],
                fem.local_stress,
                fem.grasp_force,
                fem.wrist_at_stop,
            )
        for ask in (self.tracking_problem, self.forceps_problem):
            problem = ask() if ask is not None else None
            if problem:  # said for as long as it lasts: the instrument does not move while it does
                self.tracker.warn(now, problem)
        shown = math.nan
        if frame is not None:
            frame, shown = instruments_now(frame, snapshot, fem)
            self._needle = frame.needle
            renderer.update(frame)
            self._place_shadow(frame.needle)
        self._show_bites()
        self._show_hud(now, force)
        renderer.plotter.render_window.Render()  # draws and swaps
        self.frames += 1
        if self.published is not None and self.frames % LIVE_VIEW_EVERY == 0:
            self._publish()
        if frame is not None and self.latency_log is not None:
            self._latencies.append((shown, self._session_time()))

    def _add_overlays(self, renderer) -> None:
        import pyvista as pv
        from vtkmodules.vtkRenderingCore import vtkTextActor

        plotter = renderer.plotter
        self._shadow = pv.PolyData(np.zeros((2, 3)), lines=np.array([2, 0, 1]))
        self._shadow_actor = plotter.add_mesh(self._shadow, color="#3a3a3a", line_width=4)
        self._entries = pv.PolyData(np.zeros((1, 3)))
        self._entry_actor = plotter.add_mesh(
            self._entries, color="royalblue", point_size=12, render_points_as_spheres=True
        )
        self._exits = pv.PolyData(np.zeros((1, 3)))
        self._exit_actor = plotter.add_mesh(
            self._exits, color="darkorange", point_size=12, render_points_as_spheres=True
        )
        self._entry_actor.SetVisibility(False)
        self._exit_actor.SetVisibility(False)
        self._shown_bites = (0, 0)
        width, height = self.settings.size
        self._texts = {}
        for name, x, y, size, bold in (
            ("stitch", 12, height - 30, 18, True),
            ("clock", int(0.24 * width), height - 30, 18, True),
            ("force", int(0.42 * width), height - 30, 15, False),
            ("state", 12, height - 56, 14, False),
            ("forceps", 12, height - 78, 14, False),
            ("warning", 12, 14, 16, True),
        ):
            actor = vtkTextActor()
            prop = actor.GetTextProperty()
            prop.SetFontSize(size)
            prop.SetBold(bold)
            prop.SetColor(0.1, 0.1, 0.1)
            actor.SetDisplayPosition(x, y)
            plotter.renderer.AddViewProp(actor)
            self._texts[name] = actor
        self._texts["warning"].GetTextProperty().SetColor(0.75, 0.05, 0.05)
        self._gauge = _ForceGauge(
            plotter.renderer, (int(0.42 * width), height - 44), int(0.36 * width), self.facts.limits
        )

    def _place_shadow(self, needle: NDArray[np.float64]) -> None:
        """The needle projected onto the wall along the surface normal: how high it is above the wall."""
        shadow = _projected(needle, self.facts.surface_normal, self._locator())
        self._shadow_actor.SetVisibility(len(shadow) > 1)
        if len(shadow) < 2:
            return
        self._shadow.points = shadow
        self._shadow.lines = np.concatenate([[len(shadow)], np.arange(len(shadow))])
        self._shadow.Modified()

    def _locator(self):
        if not hasattr(self, "_cells"):
            from vtkmodules.vtkCommonDataModel import vtkStaticCellLocator

            self._cells = vtkStaticCellLocator()
            self._cells.SetDataSet(self._renderer.surface.copy())  # the wall at rest
            self._cells.BuildLocator()
        return self._cells

    def _show_bites(self) -> None:
        tracker = self.tracker
        shown = (len(tracker.entries), len(tracker.exits))
        if shown == self._shown_bites:
            return
        self._shown_bites = shown
        for points, poly, actor in (
            (tracker.entries, self._entries, self._entry_actor),
            (tracker.exits, self._exits, self._exit_actor),
        ):
            actor.SetVisibility(bool(points))
            if points:
                poly.points = np.array(points)
                poly.Modified()

    def _show_hud(self, now: float, force: NDArray[np.float64]) -> None:
        reading = self.tracker.reading(now, force)
        texts = self._texts
        texts["stitch"].SetInput(reading.stitch)
        texts["clock"].SetInput(reading.clock + ("  (over time)" if reading.over_time else ""))
        colour = (0.75, 0.05, 0.05) if reading.over_time else (0.1, 0.1, 0.1)
        texts["clock"].GetTextProperty().SetColor(*colour)
        texts["force"].SetInput(reading.force)
        texts["state"].SetInput(reading.state + "   (Esc: stop)")
        texts["forceps"].SetInput(reading.forceps)
        texts["warning"].SetInput(reading.warning)
        self._gauge.show(float(np.linalg.norm(force)))

    @staticmethod
    def _stereo(renderer, mode: str) -> None:
        window = renderer.plotter.render_window
        if mode == "anaglyph":
            window.SetStereoTypeToAnaglyph()
        elif mode == "split":
            window.SetStereoTypeToSplitViewportHorizontal()
        else:
            window.SetStereoCapableWindow(True)
            window.SetStereoTypeToCrystalEyes()
        window.StereoRenderOn()

    # -- input ------------------------------------------------------------------------------------
    def _bind_input(self, interactor) -> None:
        from vtkmodules.vtkInteractionStyle import vtkInteractorStyleUser

        interactor.RemoveAllObservers()  # no camera moves or PyVista keys during a trial
        interactor.SetInteractorStyle(vtkInteractorStyleUser())
        for event, handler in (
            ("KeyPressEvent", self._key_down),
            ("KeyReleaseEvent", self._key_up),
            ("LeftButtonPressEvent", self._press),
            ("LeftButtonReleaseEvent", self._release),
            ("MouseMoveEvent", self._move),
            ("MouseWheelForwardEvent", lambda obj, _: self._wheel(+1)),
            ("MouseWheelBackwardEvent", lambda obj, _: self._wheel(-1)),
            ("ExitEvent", lambda obj, _: self._request_stop("stopped_by_trainee")),
        ):
            interactor.AddObserver(event, handler, 10.0)
        self._interactor = interactor

    def _input(self) -> None:
        """Take the window's pending events, turn the wrist for held keys, publish the hand's pose."""
        now = self._now()
        dt, self._last = now - self._last, now
        self._interactor.ProcessEvents()
        hand = self.hand
        if hand is None:
            return
        for key in self._held:
            hand.turn(dt, hand.mapping.turn_direction(key), self._needle)
        if hand.pose is not self._sent[0] or hand.grip != self._sent[1]:
            # only what changed (each move makes a new pose): the haptic side eases only when it must
            self.channel.put(now, hand.pose, hand.grip)
            self._sent = (hand.pose, hand.grip)

    def _key_down(self, interactor, _event) -> None:
        key = interactor.GetKeySym()
        repeat = key in self._held
        self._held.add(key)
        if key == "Escape":
            self._request_stop("stopped_by_trainee")
        elif key in GRIP_KEYS and self.hand is not None and not repeat:
            self.hand.toggle_grip()
        elif key in GRIP_KEYS and self.toggle_grip is not None and not repeat:
            self.toggle_grip()  # a camera-tracked holder's jaws: the G key, or a foot pedal sending G
        elif key in FORCEPS_KEYS and self.toggle_forceps is not None and not repeat:
            self.toggle_forceps()

    def _key_up(self, interactor, _event) -> None:
        self._held.discard(interactor.GetKeySym())

    def _press(self, interactor, _event) -> None:
        self._dragging = interactor.GetEventPosition()

    def _release(self, interactor, _event) -> None:
        self._dragging = None

    def _move(self, interactor, _event) -> None:
        if self._dragging is None or self.hand is None:
            return
        x, y = interactor.GetEventPosition()
        dx, dy = x - self._dragging[0], y - self._dragging[1]
        self._dragging = (x, y)
        right, up, _, per_pixel = self._view_axes()
        self.hand.move(per_pixel * (dx * right + dy * up))

    def _wheel(self, notches: int) -> None:
        if self.hand is not None:  # forward (away from you): into the scene, towards the wall
            _, _, into, _ = self._view_axes()
            self.hand.wheel(notches, into)

    def _view_axes(self) -> tuple[NDArray, NDArray, NDArray, float]:
        """The view's right, up and into-the-scene unit vectors, and metres per pixel at the holder."""
        camera = self._renderer.plotter.renderer.GetActiveCamera()
        position = np.array(camera.GetPosition())
        into = np.array(camera.GetDirectionOfProjection())
        up = np.array(camera.GetViewUp())
        right = np.cross(into, up)
        right /= np.linalg.norm(right)
        up = np.cross(right, into)
        depth = max(float(np.dot(self.hand.pose.position - position, into)), 1e-4)
        height = self.settings.size[1]
        per_pixel = 2.0 * depth * np.tan(np.radians(camera.GetViewAngle()) / 2.0) / height
        return right, up, into, per_pixel


class _ForceGauge:
    """A horizontal bar: the force now (blue), the experts' middle half (green) and the device's
    limit (red tick), 0 to ``gauge_full_n`` newtons."""

    def __init__(self, renderer, origin: tuple[int, int], length: int, limits: HudLimits) -> None:
        self.origin, self.length, self.full = origin, length, limits.gauge_full_n
        self.bar = _rectangle(renderer, (0.85, 0.85, 0.85))
        self._place(self.bar, 0.0, 1.0, 10)
        if limits.expert_force_n is not None:
            band = _rectangle(renderer, (0.45, 0.75, 0.45))
            low, high = limits.expert_force_n
            self._place(band, low / self.full, high / self.full, 10)
        if limits.device_max_n > 0:
            tick = _rectangle(renderer, (0.8, 0.1, 0.1))
            at = min(limits.device_max_n / self.full, 1.0)
            self._place(tick, at - 0.006, at + 0.006, 14)
        self.value = _rectangle(renderer, (0.15, 0.35, 0.8))

    def show(self, force: float) -> None:
        self._place(self.value, 0.0, min(force / self.full, 1.0), 5)

    def _place(self, poly_actor, start: float, stop: float, height: int) -> None:
        poly, _ = poly_actor
        x0, y0 = self.origin
        left, right = x0 + start * self.length, x0 + max(stop, start) * self.length
        points = poly.GetPoints()
        for k, (x, y) in enumerate(((left, y0), (right, y0), (right, y0 + height), (left, y0 + height))):
            points.SetPoint(k, x, y - height / 2, 0.0)
        points.Modified()


def _rectangle(renderer, colour: tuple[float, float, float]):
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkRenderingCore import vtkActor2D, vtkPolyDataMapper2D

    points = vtkPoints()
    for _ in range(4):
        points.InsertNextPoint(0.0, 0.0, 0.0)
    cells = vtkCellArray()
    cells.InsertNextCell(4)
    for k in range(4):
        cells.InsertCellPoint(k)
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(cells)
    mapper = vtkPolyDataMapper2D()
    mapper.SetInputData(poly)
    actor = vtkActor2D()
    actor.SetMapper(mapper)
    actor.GetProperty().SetColor(*colour)
    renderer.AddViewProp(actor)
    return poly, actor


def _projected(points: NDArray[np.float64], normal: NDArray[np.float64], locator) -> NDArray[np.float64]:
    """Each point moved along ``-normal`` onto the wall at rest (the first surface met from 20 mm above
    it), lifted by :data:`SHADOW_LIFT_M`; points with no wall beneath cast no shadow (left out)."""
    from vtkmodules.vtkCommonCore import mutable, reference

    normal = np.asarray(normal, dtype=np.float64)
    out = []
    hit = [0.0, 0.0, 0.0]
    pcoords = [0.0, 0.0, 0.0]
    t, sub = mutable(0.0), mutable(0)
    cell = reference(0)
    for point in points:
        above, below = point + 0.02 * normal, point - 0.02 * normal
        if locator.IntersectWithLine(above, below, 1e-9, t, hit, pcoords, sub, cell):
            out.append(np.array(hit) + SHADOW_LIFT_M * normal)
    return np.array(out).reshape(-1, 3)
