"""The layered loop's settings (rates, the force display's delay, safety, prefetching, the display's
frame) and the errors of a setting out of range or a layer's process failing."""

from __future__ import annotations

from dataclasses import dataclass, field

from sim.errors import VascsimError
from sim.runtime.safety import SafetySettings


class RuntimeSettingsError(VascsimError, ValueError):
    """A runtime setting is out of range; the message names it and its range."""


class LayerProcessError(VascsimError, RuntimeError):
    """A layer's own process (haptic, display) failed; the message is the child's, with its layer."""


@dataclass(frozen=True)
class RuntimeSettings:
    """Layer rates (Hz), the force display delay (s), safety, and the on-demand prefetch radius (m).

    prefetch_radius: in on-demand mode the graphics layer asks a background worker to
    solve the contact columns of surface nodes within this distance of the needle tip,
    so a contact change rarely waits for a solve.
    prefetch_reach: before those, the nodes of the surface triangle a ray along the tip's
    tangent meets within this distance (m): the next contact, or the exit face.
    """

    haptic_rate: float = 1000.0
    fem_rate: float = 500.0
    graphics_rate: float = 30.0
    display_rate: float = 30.0
    force_delay: float = 1.0 / 30.0
    safety: SafetySettings = field(default_factory=SafetySettings)
    prefetch_radius: float = 0.002
    prefetch_reach: float = 0.01
    live_stress_in_real_time: bool = True
    """Stream the local stress in real-time runs too (simulated runs always do). Its operator reads
    whole K0^-1 columns of the contact's load nodes, which a background worker then solves ahead
    of the needle for precomputed models too; off, contact changes skip the operator (about 1 ms
    less) and scoring derives the indentation's stress afterwards."""
    haptic_scale: float = 1.0
    """Factor on the tissue's force before the device's clamp and rate limit, for a device that cannot
    render the tissue's force (a session header records it); the recorded reaction force is unscaled."""
    display_on_haptic_core: bool = False
    """Let the display process (and a software renderer's raster threads) also use the haptic core's idle
    time; the haptic process, real-time scheduled, preempts them. An on-screen window under Mesa's
    llvmpipe needs it: confined to the one spare core, which the FEM and graphics threads and the
    column worker share, a 960x540 frame took 27 ms to draw (18 ms with that core to itself, 10 ms
    with both) and the window ran at 25 frames/s; with it, 29-30 frames/s and the haptic loop's p99
    period unchanged (1.00 ms; docs/benchmarks.md, session 19)."""
    display_delay_frames: int = 1
    """1: the display renders the previous graphics frame (one video frame of delay, the paper's
    design); 0: the newest one, drawn a few ms after the graphics layer posts it (a person's live view:
    the FEM state it shows is still at most one frame old, and motion reaches the screen 33 ms sooner)."""

    def __post_init__(self) -> None:
        if not 0.0 < self.haptic_scale <= 1.0:
            raise RuntimeSettingsError(f"haptic_scale must be in (0, 1]; got {self.haptic_scale}")
        if not 200.0 <= self.fem_rate <= 1000.0:
            raise RuntimeSettingsError(
                f"fem_rate must be 200-1000 Hz (PAPER.md section 7); got {self.fem_rate}"
            )
        if self.haptic_rate < self.fem_rate:
            raise RuntimeSettingsError(
                f"haptic_rate ({self.haptic_rate} Hz) must be at least fem_rate ({self.fem_rate} Hz)"
            )
        for name in ("graphics_rate", "display_rate"):
            if not 1.0 <= getattr(self, name) <= 240.0:
                raise RuntimeSettingsError(f"{name} must be 1-240 Hz; got {getattr(self, name)}")
        for name in ("prefetch_radius", "prefetch_reach"):
            if not 0.0 <= getattr(self, name) <= 0.1:
                raise RuntimeSettingsError(f"{name} must be 0-0.1 m; got {getattr(self, name)}")
        if not 0.0 <= self.force_delay <= 0.2:
            raise RuntimeSettingsError(f"force_delay must be 0-0.2 s; got {self.force_delay}")
        if self.display_delay_frames not in (0, 1):
            raise RuntimeSettingsError(
                f"display_delay_frames must be 0 or 1; got {self.display_delay_frames}"
            )

    def period(self, layer: str) -> float:
        return 1.0 / getattr(self, f"{layer}_rate")
