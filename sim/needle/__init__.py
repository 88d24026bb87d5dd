"""The needle and what it does to the tissue, one module per idea:

- :mod:`sim.needle.geometry`: its shape and pose;
- :mod:`sim.needle.sweep`: the continuous collision test of its swept path between two poses;
- :mod:`sim.needle.forces`: the needle-tissue force law's parameters (puncture, friction, cutting);
- :mod:`sim.needle.load`: that law applied through force kernels on the tissue, per FEM step;
- :mod:`sim.needle.events`: what happens to it (contact, pierce, exit, tear) as records;
- :mod:`sim.needle.passage`: where it crosses the wall while it passes through;
- :mod:`sim.needle.interaction`: the FEM layer's step that ties them together.

Only the geometry is imported here; the rest import the tissue model and are imported by name.
"""

from sim.needle.geometry import (
    Needle,
    NeedleError,
    Pose,
    TurnAbout,
    rotation_about,
    rotation_aligning,
)

__all__ = ["Needle", "NeedleError", "Pose", "TurnAbout", "rotation_about", "rotation_aligning"]
