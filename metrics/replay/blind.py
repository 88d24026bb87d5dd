"""The blind render: what a rater scoring a session blind may see of it, and nothing more.

A blinded rating (GRS, OSATS) is evidence of concurrent validity only if the rater cannot see
who performed the session or what the metrics already say about it. The blind render therefore
shows the trainee's session alone: the deforming wall in one tissue colour (no stress map), the
needle, the entry point, the task's target marks, the bites in one neutral colour (no on/off-mark
verdict) and the wound edge. It leaves out names and codes, group and trial, the expert's ghost and
band colours, every readout (force, tip speed, entry angle, a bite's miss of its mark, the clock)
and the force arrow. The strip above the view and the key beside it are the same in every frame, so
a test can compare each decoded frame with them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from metrics.replay.hud import HudLine, Key
from sim.render import FORCEPS_CLOSED_COLOUR, FORCEPS_OPEN_COLOUR

TITLE = "blinded replay"
"""The strip's only text, the same in every frame."""
BITE_COLOUR = (60, 60, 60)
"""Every bite's colour: dark grey, which says nothing about how far it landed from its mark."""


def readout() -> tuple[str, list[HudLine]]:
    """The strip of every blind frame: the title and no readout."""
    return TITLE, []


def blind_frame(frame):
    """``frame`` (a :class:`sim.render.RenderFrame`) without what a blinded rater must not see: the wall
    unstressed in colour (its shape still deformed), no force arrow, no ghost path or needle."""
    return replace(
        frame,
        triangle_stress=np.zeros_like(frame.triangle_stress),
        force=None,
        ghost=None,
        ghost_needle=None,
    )


def neutral_bites(count: int) -> np.ndarray:
    """``count`` bites in the one neutral colour ((count, 3) uint8)."""
    return np.tile(np.array(BITE_COLOUR, dtype=np.uint8), (count, 1))


def forceps_keys() -> list[Key]:
    """The subordinate hand's forceps, as :class:`sim.render.TissueRenderer` draws them."""

    return [
        Key("line", (tuple(round(255 * c) for c in FORCEPS_OPEN_COLOUR),), "forceps, open"),
        Key("line", (tuple(round(255 * c) for c in FORCEPS_CLOSED_COLOUR),), "forceps, closed"),
    ]


def blind_keys(marks: bool, wound: bool, forceps: bool = False) -> list[Key]:
    """The blind key: what each thing in the scene is, with no scale and no verdict."""
    keys = [Key("line", ((192, 192, 192),), "needle"), Key("dot", ((0, 191, 255),), "entry point")]
    if marks:
        keys += [Key("dot", ((255, 255, 255),), "target marks"), Key("dot", (BITE_COLOUR,), "bites")]
    if wound:
        keys.append(Key("line", ((107, 10, 26),), "wound edge"))
    if forceps:
        keys += forceps_keys()
    return keys
