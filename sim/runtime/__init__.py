"""The layered multi-rate loop: haptics, FEM, graphics and display, with haptic safety."""

from sim.runtime.safety import ForceSafety, SafetySettings
from sim.runtime.simulation import RunResult, RuntimeEvent, RuntimeSettings, Simulation

__all__ = ["ForceSafety", "RunResult", "RuntimeEvent", "RuntimeSettings", "SafetySettings", "Simulation"]
