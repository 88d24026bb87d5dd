"""What the station's heads-up strip says, frame by frame: pure arithmetic on FEM snapshots.

The window (:mod:`sessions.running.window`) draws it; this module decides it, so it is tested
without a display: time against the task's budget, the stitch being placed, the force against the
experts' band and the device's limit, and a plain-words line when something unsafe happens.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from metrics.units import display_unit, in_display_units
from sim.forceps import Forceps

STATE_WORDS = {
    "free": "needle free",
    "contact": "needle touching the wall",
    "pierced": "needle in the wall",
    "exited": "needle through the wall",
}


@dataclass(frozen=True)
class HudLimits:
    """What the strip measures against.

    time_budget_s: the task's time budget; stitches: the task's stitch count; expert_force_n: the
    experts' middle half (q1, q3) of peak force on this task (N), or None before any expert session;
    device_max_n: the device's rated force (N; 0 for a device without actuators); damage_stress_pa and
    edge_damage_stress_pa: the local and wound-edge stresses whose crossing is a damage event (Pa);
    edge_tear_n: the force on the grasped edge at which it tears out of the forceps (N).
    """

    time_budget_s: float
    stitches: int
    expert_force_n: tuple[float, float] | None = None
    device_max_n: float = 0.0
    damage_stress_pa: float | None = None
    gauge_full_n: float = 3.0
    edge_tear_n: float = Forceps.edge_tear_force


@dataclass
class HudReading:
    """One frame's strip: the words and the gauge's fill (0-1 of ``gauge_full_n``)."""

    clock: str
    over_time: bool
    stitch: str
    force: str
    force_fraction: float
    state: str
    warning: str
    forceps: str = ""  # the other hand's line ("" for a one-handed session)


@dataclass
class HudTracker:
    """Follows the FEM snapshots the display sees: stitches completed (a needle pulled clear after it
    went in), where each bite went in and came out, and the latest warning (kept for two seconds)."""

    limits: HudLimits
    completed: int = 0
    entries: list = field(default_factory=list)
    exits: list = field(default_factory=list)
    _state: str = "free"
    _warning: str = ""
    _warning_until: float = -math.inf
    _forceps: float | None = None  # the forceps' force on the edge (N); None: one hand

    def update(
        self,
        now: float,
        state: str,
        force: np.ndarray,
        tip: np.ndarray,
        local_stress: float,
        grasp_force: np.ndarray | None = None,
        wrist_at_stop: bool = False,
    ) -> None:
        """``grasp_force``: the subordinate hand's forceps' force on the tissue (N; zero when they hold
        nothing), None for a one-handed session; ``wrist_at_stop``: the task's approach holds the
        needle hand's wrist (it cannot turn the needle back further)."""
        previous, self._state = self._state, state
        self._forceps = None if grasp_force is None else float(np.linalg.norm(grasp_force))
        if previous in ("free", "contact") and state in ("pierced", "exited"):
            self.entries.append(np.array(tip, dtype=np.float64))
        if previous == "pierced" and state == "exited":
            self.exits.append(np.array(tip, dtype=np.float64))
        if previous in ("pierced", "exited") and state in ("free", "contact"):
            self.completed += 1
        magnitude = float(np.linalg.norm(force))
        limits = self.limits
        if limits.damage_stress_pa is not None and local_stress >= limits.damage_stress_pa:
            self._warn(now, "wall over-stressed near the needle: ease off and follow the needle's curve")
        elif limits.device_max_n > 0 and magnitude >= limits.device_max_n:
            self._warn(now, f"force at the device's limit ({_force(limits.device_max_n)}): ease off")
        elif limits.expert_force_n is not None and magnitude > 2.0 * limits.expert_force_n[1]:
            self._warn(now, "more than twice the experts' force: turn the wrist, do not push")
        elif self._forceps is not None and self._forceps >= 0.8 * limits.edge_tear_n:
            self._warn(
                now,
                f"the forceps pull hard on the edge: lift less (it tears at {_force(limits.edge_tear_n)})",
            )
        elif wrist_at_stop and state in ("free", "contact"):
            self._warn(now, "your wrist is at the end of its turn: evert the edge to meet the wall square")

    def warn(self, now: float, text: str) -> None:
        """Show ``text`` on the warning line for two seconds from ``now`` (said again, it stays)."""
        self._warn(now, text)

    def _warn(self, now: float, text: str) -> None:
        self._warning, self._warning_until = text, now + 2.0

    def reading(self, now: float, force: np.ndarray) -> HudReading:
        limits = self.limits
        magnitude = float(np.linalg.norm(force))
        stitch = min(self.completed + 1, limits.stitches)
        done = self.completed >= limits.stitches
        return HudReading(
            clock=f"{_clock(now)} of {_clock(limits.time_budget_s)}",
            over_time=now > limits.time_budget_s,
            stitch="all stitches placed" if done else f"stitch {stitch} of {limits.stitches}",
            force=f"force {_force(magnitude)}" + self._force_context(),
            force_fraction=min(magnitude / limits.gauge_full_n, 1.0),
            state=STATE_WORDS.get(self._state, self._state),
            forceps=self._forceps_words(),
            warning=self._warning if now <= self._warning_until else "",
        )

    def _forceps_words(self) -> str:
        """The other hand: what the forceps hold, and how hard (nothing for a one-handed session)."""
        if self._forceps is None:
            return ""
        if self._forceps == 0.0:
            return "forceps not holding the edge"
        return f"forceps holding the edge, {_force(self._forceps)}"

    def _force_context(self) -> str:
        """What the gauge's marks are: the experts' middle half (green) and the device's limit (red)."""
        limits, parts = self.limits, []
        if limits.expert_force_n is not None:
            low, high = limits.expert_force_n
            parts.append(f"experts {_force(low, unit=False)}-{_force(high)}")
        if limits.device_max_n > 0:
            parts.append(f"device max {_force(limits.device_max_n)}")
        return f" ({'; '.join(parts)})" if parts else ""


def _force(newtons: float, unit: bool = True) -> str:
    """A force as the trainee reads it everywhere ("830 mN": metrics.units' display unit)."""
    value = in_display_units(newtons, "N")
    text = "-" if value is None else f"{value:.0f}"
    return f"{text} {display_unit('N')}" if unit else text


def _clock(seconds: float) -> str:
    seconds = max(int(seconds), 0)
    return f"{seconds // 60}:{seconds % 60:02d}"
