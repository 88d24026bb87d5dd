"""The layered multi-rate loop: haptics, FEM, graphics and display, with haptic safety."""

from sim.runtime.safety import ForceSafety, SafetySettings
from sim.runtime.settings import LayerProcessError, RuntimeSettings, RuntimeSettingsError
from sim.runtime.simulation import Simulation
from sim.runtime.snapshots import RuntimeEvent
from sim.runtime.telemetry import RunResult

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
