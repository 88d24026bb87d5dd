"""The needle: its geometry and pose (:mod:`sim.needle.geometry`) and the continuous collision test of
its swept path between two poses (:mod:`sim.needle.sweep`).

The rest of the needle's modules (forces, load, events, passage, interaction) join this package in
the layout move (issue 48); until then they sit beside it in :mod:`sim`.
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
