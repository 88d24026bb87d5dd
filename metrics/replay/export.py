"""A session's replay as video and stills: the 3-D scene with overlays, against an expert reference.

Modes: ``ghost`` draws the reference expert's needle-tip path and, at the aligned
moment, the expert's needle translucent in the trainee's scene; ``side-by-side``
shows the trainee (left) and the expert at the aligned moment (right) under one
camera. Both carry the reaction-force arrow at the tip, the insertion point, the
stress colour map of the deformed wall and the heads-up panel.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.replay import blind
from metrics.replay.blind import blind_keys, forceps_keys
from metrics.replay.hud import FrameLayout, HudLine, Key, draw_key, value_line
from metrics.replay.plots import write_signal_plots
from metrics.replay.reference import expert_reference
from metrics.replay.stills import insertion_frame_index, stress_map, write_stress_map
from metrics.replay.track import ReplayTrack, session_track
from metrics.replay.video import VideoWriter, check_video_path
from metrics.replay.wound import outline_edges, wound_nodes
from metrics.signals.alignment import PHASES, phase_starts
from metrics.signals.placement import (
    MARK_COLOURS,
    PlacementTargets,
    StitchPlacement,
    mark_colour,
    stitch_points,
)
from metrics.signals.tissue import with_tissue_fields
from metrics.streams import SessionStreams, from_recorded
from sim.fem.fields import TissueFieldReplay
from sim.render import FORCE_ARROW_M_PER_N, RenderFrame, TissueRenderer, stress_colours, write_image

MODES = ("ghost", "side-by-side")
T = TypeVar("T")


@dataclass(frozen=True)
class ReplaySettings:
    fps: int = 30
    size: tuple[int, int] = (1280, 720)
    mode: str = "ghost"
    anti_aliasing: bool = False
    zoom: float = 1.4
    blind: bool = False  # the session alone, for a blinded rater (metrics.replay.blind)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise MetricsError(f"replay mode must be one of {', '.join(MODES)}; got {self.mode!r}")
        if self.blind and self.mode != "ghost":
            raise MetricsError("a blind replay shows the session alone; it cannot be side by side")
        if not 1 <= self.fps <= 120:
            raise MetricsError(f"frame rate must be 1-120 frames/s; got {self.fps}")
        width, height = self.size
        if width % 2 or height % 2 or not (64 <= width <= 3840 and 64 <= height <= 2160):
            raise MetricsError(f"video size must be even, 64x64 to 3840x2160; got {width}x{height}")


@dataclass
class ReplayResult:
    path: Path
    frames: int
    seconds: float
    timings: dict[str, float] = field(default_factory=dict)
    stills: list[Path] = field(default_factory=list)

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("nan")


class SceneReplay:
    """Frames of one re-simulated session: tissue state, needle, force and insertion point per frame."""

    def __init__(self, session, tissue, streams: SessionStreams, fps: int) -> None:
        self.streams = streams
        self.track: ReplayTrack = session_track(session, tissue, fps)
        self.fields = TissueFieldReplay(tissue)
        self.rest = tissue.mesh.points
        self.phase_bounds = phase_starts(streams.needle_state, streams.time)
        pierces = streams.events.loc[streams.events["kind"] == "pierce"]
        self.pierce_time = float(pierces["time"].iloc[0]) if len(pierces) else None
        self.entry_angle = float(pierces["entry_angle_deg"].iloc[0]) if len(pierces) else float("nan")
        self.insertion_point = None
        if self.pierce_time is not None:
            k = int(np.searchsorted(self.track.times, self.pierce_time))
            self.insertion_point = self.track.tip[min(k, len(self.track) - 1)].copy()

    def index_at(self, when: float) -> int:
        return int(np.clip(np.searchsorted(self.track.times, when - 1e-9), 0, len(self.track) - 1))

    def phase_at(self, when: float) -> str:
        reached = [
            k
            for k in range(len(PHASES))
            if np.isfinite(self.phase_bounds[k]) and self.phase_bounds[k] <= when
        ]
        return PHASES[reached[-1]] if reached else PHASES[0]

    def frame(self, k: int, ghost: NDArray | None = None, ghost_needle: NDArray | None = None):

        track = self.track
        drive = track.drives[k]
        grasp = track.grasps[k] if track.grasps is not None else None  # the other hand holds the edge
        if drive is None:
            none = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
            displacement, stress = self.fields.state(*none, grasp=grasp)
        else:
            speed = float(track.tip_speed[k])
            displacement, stress = self.fields.state(drive[0], drive[1], speed, drive[2], grasp=grasp)
        shown = (
            self.insertion_point
            if self.pierce_time is not None and track.times[k] >= self.pierce_time
            else None
        )
        jaws = track.jaws[k] if track.jaws is not None else None
        points = self.rest + displacement
        return RenderFrame(points, stress, track.needle[k], shown, ghost, track.force[k], ghost_needle, jaws)


@dataclass(frozen=True)
class BiteMarks:
    """Where a session's bites went against its task's marks, for the replay: the marks (m), each
    entry and exit point (m) with its colour and the time it was made (s), and each stitch's
    entry distance from its mark (m) with its pierce time."""

    targets: np.ndarray
    points: np.ndarray
    colours: np.ndarray
    times: np.ndarray
    pierce_times: np.ndarray
    entry_off: np.ndarray

    @classmethod
    def of(cls, streams, mesh) -> BiteMarks | None:

        targets = PlacementTargets.from_attributes(dict(streams.attributes))
        stitches = stitch_points(streams.events, mesh)
        if targets is None or stitches.empty:
            return None
        placed = StitchPlacement.of(stitches, targets)
        exited = np.isfinite(stitches["exit_time"].to_numpy(dtype=float))
        entries = stitches[["entry_x", "entry_y", "entry_z"]].to_numpy(dtype=float)
        exits = stitches[["exit_x", "exit_y", "exit_z"]].to_numpy(dtype=float)[exited]
        pierced = stitches["pierce_time"].to_numpy(dtype=float)
        times = np.concatenate([pierced, stitches["exit_time"].to_numpy(dtype=float)[exited]])
        distances = np.concatenate([placed.entry_to_target, placed.exit_to_target[exited]])
        order = np.argsort(times, kind="stable")
        return cls(
            np.vstack([targets.entry_targets, targets.exit_targets]),
            np.vstack([entries, exits])[order],
            np.array([mark_colour(d) for d in distances[order]], dtype=np.uint8).reshape(-1, 3),
            times[order],
            pierced,
            placed.entry_to_target,
        )

    def made_by(self, when: float) -> int:
        """How many bite marks are made by time ``when``."""
        return int(np.searchsorted(self.times, when, side="right"))

    def hud_line(self, when: float) -> HudLine | None:
        """The latest bite's miss of its mark, once it has been made."""
        made = int(np.searchsorted(self.pierce_times, when, side="right"))
        if made == 0:
            return None
        return HudLine("bite", f"{1e3 * self.entry_off[made - 1]:.1f} mm off mark")


def _titled(prefix: str, readout: tuple[str, list[HudLine]]) -> tuple[str, list[HudLine]]:
    return prefix + readout[0], readout[1]


def _hud_lines(
    scene: SceneReplay, k: int, bands: dict[str, dict], marks: BiteMarks | None = None
) -> tuple[str, list[HudLine]]:
    when = float(scene.track.times[k])
    phase = scene.phase_at(when)
    force_band = bands.get("force", {}).get(phase)
    speed_band = bands.get("tip_speed", {}).get(phase)
    lines = [
        HudLine("phase", phase),
        value_line("force", float(np.linalg.norm(scene.track.force[k])), "mN", force_band, 1e3),
        value_line("tip speed", float(scene.track.tip_speed[k]), "mm/s", speed_band, 1e3),
        HudLine(
            "entry angle",
            f"{scene.entry_angle:.0f} deg"
            if scene.pierce_time is not None and when >= scene.pierce_time
            else "-",
        ),
    ]
    bite = marks.hud_line(when) if marks is not None else None
    if bite is not None:
        lines.append(bite)
    return f"t = {when:.2f} s", lines


def export_replay(
    session,
    tissue,
    out: str | Path,
    experts: list | None = None,
    settings: ReplaySettings | None = None,
    progress: Callable[[int, int], None] | None = None,
    stills: str | Path | None = None,
) -> ReplayResult:
    """Render ``session`` (a :class:`recorder.Session` on ``tissue``) to ``out`` (.mp4 or .webm).

    experts: recorder sessions of the same task; the medoid is shown (ghost or side by
    side) and all of them set the HUD's expert bands. progress(done, total) per frame.
    stills: a folder for ``insertion.png`` (the frame at the pierce), ``stress_insertion.exr``
    (surface von Mises in Pa seen along the wall normal) and ``signals.png``/``.svg``.
    """
    from threadpoolctl import threadpool_limits

    settings = settings or ReplaySettings()
    if settings.blind and experts:
        raise MetricsError("a blind replay shows the session alone; give it no expert sessions")
    check_video_path(out)
    started = time.perf_counter()
    timings: dict[str, float] = {}

    # the derived tissue streams (local stress) are only drawn in the signal plots
    def load(recorded):
        streams = from_recorded(recorded)
        return with_tissue_fields(streams, tissue) if stills is not None else streams

    streams = load(session)
    scene = SceneReplay(session, tissue, streams, settings.fps)
    reference = expert_scene = None
    if experts:
        expert_streams = [load(e) for e in experts]
        reference = expert_reference(streams, expert_streams)
        medoid = experts[expert_streams.index(reference.medoid)]
        expert_scene = SceneReplay(medoid, tissue, reference.medoid, settings.fps)
    elif settings.mode == "side-by-side":
        raise MetricsError(
            "side-by-side needs an expert session or group to show beside this one",
            remedy=("choose-versus", ""),
        )
    bands = {} if reference is None else {name: reference.phase_band(name) for name in ("force", "tip_speed")}
    timings["re-simulation"] = time.perf_counter() - started
    split = settings.mode == "side-by-side"
    marks = BiteMarks.of(streams, tissue.mesh)
    if marks is not None and settings.blind:  # where the bites went, not how far off their marks
        marks = replace(marks, colours=blind.neutral_bites(len(marks.colours)))
    total = len(scene.track)
    # the expert's moment matching each frame, in one pass over the alignment
    expert_ks: list[int | None] = [None] * total
    if expert_scene is not None:
        expert_times = reference.medoid_alignment.reference_time_at(scene.track.times)
        expert_ks = [expert_scene.index_at(float(t)) for t in expert_times]
    # every frame's readouts first: the strips are sized for the widest of them
    trainee = f"trainee {streams.participant_id or ''}  " if split else ""
    expert = f"expert {reference.medoid.participant_id or ''}  " if split else ""
    if settings.blind:
        readouts = [blind.readout()] * total
    else:
        readouts = [_titled(trainee, _hud_lines(scene, k, bands, marks)) for k in range(total)]
    beside_readouts = (
        [_titled(expert, _hud_lines(expert_scene, expert_k, bands)) for expert_k in expert_ks]
        if split
        else []
    )
    canvas = ReplayCanvas(
        tissue.mesh,
        streams,
        settings,
        ghost=expert_scene is not None and not split,
        marks=marks,
        readouts=readouts + beside_readouts,
        blind=settings.blind,
    )
    ghost_path = expert_scene.track.tip if expert_scene is not None and not split else None
    insertion = insertion_frame_index(streams, scene.track.times) if stills is not None else None
    written: list[Path] = []
    render_time = 0.0

    def scene_frames(k: int):
        """Frame k's scene (and the expert's beside it): the tissue state solved for that frame."""
        expert_k = expert_ks[k]
        if settings.blind:
            return blind.blind_frame(scene.frame(k)), None
        if split:
            return scene.frame(k), expert_scene.frame(expert_k)
        ghost_needle = expert_scene.track.needle[expert_k] if expert_k is not None else None
        return scene.frame(k, ghost_path, ghost_needle), None

    try:
        # one BLAS thread: idle OpenBLAS workers spin and would take the cores the rasteriser needs
        with VideoWriter(out, settings.size, settings.fps) as writer, threadpool_limits(1):
            for k, (frame, other) in enumerate(frames_ahead(scene_frames, total)):
                began = time.perf_counter()
                title, lines = readouts[k]
                beside = (other, *beside_readouts[k]) if split else None
                pixels = canvas.draw(float(scene.track.times[k]), frame, title, lines, beside)
                if k == insertion:
                    written += _write_insertion_stills(Path(stills), scene, k, frame, pixels)
                render_time += time.perf_counter() - began
                writer.write(pixels)
                if progress is not None:
                    progress(k + 1, total)
    finally:
        canvas.close()
    timings["render"] = render_time
    if stills is not None:
        written += write_signal_plots(streams, stills, reference)
    seconds = time.perf_counter() - started
    timings["total"] = seconds
    return ReplayResult(Path(out), total, seconds, timings, written)


class ReplayCanvas:
    """Draws replay frames: the 3-D view (two side by side), a heads-up strip above each and the key
    beside them (:class:`metrics.replay.hud.FrameLayout`), the wound's rim and the bite marks in the
    scene. ``ghost``: the expert's needle and tip path are drawn in the trainee's view; ``readouts``: every
    (title, lines) the strips will show (their height is set for the widest; without them, for
    :data:`metrics.replay.hud.WIDEST_LINES`)."""

    def __init__(
        self,
        mesh,
        streams: SessionStreams,
        settings: ReplaySettings,
        ghost: bool,
        marks=None,
        readouts: list[tuple[str, list[HudLine]]] = (),
        blind: bool = False,
    ) -> None:

        views = 2 if settings.mode == "side-by-side" else 1
        self.layout = FrameLayout.of(settings.size, views, readouts)
        width, height = self.layout.view_size
        # a view narrower than 16:9 sees less across: zoom in less, so the scene is not cropped
        zoom = settings.zoom * min(1.0, (width / height) / (16 / 9)) ** 0.5
        self.marks = marks
        self.renderers = [
            TissueRenderer(
                mesh,
                size=self.layout.view_size,
                offscreen=True,
                anti_aliasing=settings.anti_aliasing,
                scalar_bar=False,  # the key beside the views carries the scale
                zoom=zoom,
            )
            for _ in range(views)
        ]
        if marks is not None:  # the trainee's view shows the task's marks and where the bites went
            self.renderers[0].show_placement(marks.targets, marks.points, marks.colours)
        wound = wound_outline(streams, mesh)
        for renderer in self.renderers:
            renderer.show_outline(wound)
        stress_kpa = None if blind else tuple(v / 1e3 for v in self.renderers[0].stress_range)
        shown = {
            "marks": marks is not None,
            "wound": len(wound) > 0,
            "forceps": streams.forceps_jaw is not None,
        }
        keys = blind_keys(**shown) if blind else replay_keys(ghost=ghost, **shown)
        layout = self.layout
        self.key = draw_key(layout.height, layout.panel, layout.scale, stress_kpa, stress_colours(), keys)
        self._camera_shared = False

    def draw(self, when: float, frame, title: str, lines: list[HudLine], beside=None) -> NDArray[np.uint8]:
        """The frame at time ``when`` (s): ``frame`` (a :class:`sim.render.RenderFrame`) under its
        readout; ``beside``: (frame, title, lines) for the second view of a side-by-side replay."""
        if self.marks is not None:
            self.renderers[0].reveal_bites(self.marks.made_by(when))
        views = [(self.renderers[0].render(frame), title, lines)]
        if beside is not None:
            if not self._camera_shared:  # one camera for both sides
                self.renderers[1].share_camera(self.renderers[0])
                self._camera_shared = True
            views.append((self.renderers[1].render(beside[0]), beside[1], beside[2]))
        return self.layout.compose(views, self.key)

    def close(self) -> None:
        for renderer in self.renderers:
            renderer.close()


def wound_outline(streams: SessionStreams, mesh) -> NDArray[np.int64]:
    """The rim of the wound's cut faces ((E, 2) node ids) for the session's task, empty when the task
    has no wound (:mod:`metrics.replay.wound`)."""

    targets = PlacementTargets.from_attributes(dict(streams.attributes))
    point, normal = (None, None) if targets is None else (targets.wound_point, targets.wound_normal)
    return outline_edges(mesh.surface_triangles, wound_nodes(mesh, point, normal))


def replay_keys(ghost: bool, marks: bool, wound: bool, forceps: bool = False) -> list[Key]:
    """What the key says, for what the video shows (colours as :class:`sim.render.TissueRenderer`
    draws them); ``forceps``: a two-handed session's subordinate hand."""

    (near, on_mark), (far, near_mark), (_, off_mark) = MARK_COLOURS
    keys = []
    if ghost:
        keys += [
            Key("line", ((50, 205, 50),), "expert's tip path"),
            Key("line", ((60, 179, 113),), "expert's needle"),
        ]
    keys += [
        Key("line", ((192, 192, 192),), "trainee's needle" if ghost else "needle"),
        Key("arrow", ((30, 144, 255),), f"force on the needle, {1e3 * FORCE_ARROW_M_PER_N:.0f} mm per N"),
        Key("dot", ((0, 191, 255),), "entry point"),
    ]
    if marks:
        keys += [
            Key("dot", ((255, 255, 255),), "target marks"),
            Key(
                "dot",
                (on_mark, near_mark, off_mark),
                f"bites: within {1e3 * near:.2g} mm of the mark, {1e3 * far:.2g} mm, farther",
            ),
        ]
    if wound:
        keys.append(Key("line", ((107, 10, 26),), "wound edge"))
    if forceps:
        keys += forceps_keys()
    return keys


def frames_ahead(make: Callable[[int], T], total: int, depth: int = 2) -> Iterator[T]:
    """make(0), ..., make(total - 1), each computed in a worker thread up to ``depth`` items ahead
    of the consumer: the next frame's tissue state is solved while this one renders (VTK's render
    call releases the interpreter lock). An exception in ``make`` is raised here, in order."""
    from concurrent.futures import ThreadPoolExecutor

    pending: collections.deque = collections.deque()
    with ThreadPoolExecutor(1, thread_name_prefix="vascsim-replay-state") as worker:
        try:
            for k in range(min(depth, total)):
                pending.append(worker.submit(make, k))
            for k in range(total):
                item = pending.popleft().result()
                if k + depth < total:
                    pending.append(worker.submit(make, k + depth))
                yield item
        finally:
            for future in pending:
                future.cancel()


def _write_insertion_stills(
    folder: Path, scene: SceneReplay, k: int, frame, pixels: NDArray[np.uint8]
) -> list[Path]:
    """The insertion frame as rendered (PNG) and its surface stress seen along the wall normal (EXR)."""

    folder.mkdir(parents=True, exist_ok=True)
    mesh = scene.fields.mesh
    sample = min(int(np.searchsorted(scene.streams.time, scene.track.times[k])), scene.streams.time.size - 1)
    triangle = int(scene.streams.contact_triangle[sample])
    corners = mesh.points[mesh.surface_triangles[max(triangle, 0)]]
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    image, _, _ = stress_map(frame.points, mesh.surface_triangles, frame.triangle_stress, normal)
    return [
        write_image(folder / "insertion.png", pixels),
        write_stress_map(folder / "stress_insertion.exr", image),
    ]
