"""The layered multi-rate loop: haptics, FEM, graphics and display, with haptic safety."""

from sim.runtime.safety import ForceSafety, SafetySettings
from sim.runtime.simulation import (
    LayerProcessError,
    RunResult,
    RuntimeEvent,
    RuntimeSettings,
    RuntimeSettingsError,
    Simulation,
)

__all__ = [
    "ForceSafety",
    "LayerProcessError",
    "RunResult",
    "RuntimeEvent",
    "RuntimeSettings",
    "RuntimeSettingsError",
    "SafetySettings",
    "Simulation",
]
