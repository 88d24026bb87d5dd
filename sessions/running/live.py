"""A real-time session's view on the station's display: which kind (``--view``), and the window built
for one session's task, device and study."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from sessions.config import cache_dir
from sessions.running.hud import HudLimits
from sessions.running.scene import scene_facts
from sessions.running.window import LiveWindow, ViewSettings
from sessions.scoring.review import expert_band
from sessions.tasks import task_preset, tissue_for
from sessions.tasks.build import wrist_stop
from sim.devices.discovery import display_available
from sim.devices.mouse import MouseDevice, MouseHand, MouseMapping

VIEWS = ("window", "none")
"""``--view`` choices: a window on this station's display, or none (the dashboard's live page still
shows the session's plots)."""


def live_view_path(home: Path, uid: str) -> Path:
    """Where a recording session's window publishes its view for the dashboard (a JPEG replaced in
    place; removed when the session ends): outside the session's folder, so it is never catalogued."""
    return home / "live" / f"{uid}.jpg"


def default_view() -> str:
    """``window`` where a display exists, else ``none``."""
    return "window" if display_available() else "none"


@dataclass(frozen=True)
class LiveView:
    """How a real-time session is shown: the window's settings, the keyboard-and-mouse mapping, and
    (for the motion-to-photon benchmark) a file for each frame's latency."""

    settings: ViewSettings = field(default_factory=ViewSettings)
    mapping: MouseMapping = field(default_factory=MouseMapping)
    latency_log: Path | None = None

    def window(self, spec, device, catalog, home: Path, ids: tuple[int, int], uid: str = "") -> LiveWindow:
        """The window for session ``uid`` of task ``spec`` with ``device``, in study and task ``ids``;
        it publishes its view for the dashboard (:func:`live_view_path`) when ``uid`` is given."""

        band = expert_band(catalog, *ids).get("peak_force")
        limits = HudLimits(
            time_budget_s=spec.time_budget_s,
            stitches=spec.stitch_count,
            expert_force_n=None if band is None else (band["expert_q1"], band["expert_q3"]),
            device_max_n=device.limits.max_force,
            damage_stress_pa=task_preset(spec).forces.damage_stress,
        )
        tissue = tissue_for(spec, cache_dir(home))
        facts = scene_facts(spec, tissue.mesh, limits)
        hand = channel = None
        if isinstance(device, MouseDevice):
            hand, channel = MouseHand(device.start, self.mapping, stop=wrist_stop(spec)), device.channel
        published = live_view_path(home, uid) if uid else None
        window = LiveWindow(tissue, facts, self.settings, hand, channel, self.latency_log, published)
        window.tracking_problem = getattr(device, "tracking_problem", None)  # a camera's: lost, late
        window.toggle_grip = getattr(device, "toggle_grip", None)  # a camera-tracked holder's jaws
        return window
