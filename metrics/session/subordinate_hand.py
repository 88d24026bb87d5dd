"""The subordinate hand's metrics: how the forceps hold the wound edge while the needle goes in.

From the recorded subordinate hand (schema 4: its tool point, jaws, the grasped tissue and the
forceps' force on it) or an imported trial's other hand (JIGSAWS' slave-left); a session recorded
one-handed has no subordinate stream, and these metrics are then not measured (NaN), not zero.
"""

from __future__ import annotations

import math

import numpy as np

from metrics.session.context import SessionContext
from metrics.session.registry import HIGHER, LOWER, metric
from metrics.signals import kinematics

NAN = math.nan


def _insertion_mask(context: SessionContext):
    if not context.insertions:
        return None
    mask = np.zeros(context.streams.time.size, dtype=bool)
    for insertion in context.insertions:
        mask[context.span(insertion.pierce_time, insertion.end_time)] = True
    return mask


@metric(
    "subordinate_displacement",
    advice="Keep the assisting hand steady.",
    unit="m",
    definition=(
        "Largest displacement of the subordinate hand from where it was at each pierce, during the "
        "insertions (it should hold the tissue still)."
    ),
    streams=("subordinate_displacement", "events"),
    better=LOWER,
    reference="Datta et al. 2001, J Am Coll Surg 193:479 (ICSAD, both hands)",
    group="subordinate",
    kind="efficiency",
)
def subordinate_displacement(context: SessionContext) -> float:
    moved = context.streams.subordinate_displacement
    if moved is None or not context.insertions:
        return NAN
    largest = 0.0
    for insertion in context.insertions:
        segment = moved[context.span(insertion.pierce_time, insertion.end_time)]
        if len(segment):
            largest = max(largest, float(np.linalg.norm(segment - segment[0], axis=1).max()))
    return largest


@metric(
    "subordinate_activity",
    advice="Let the assisting hand hold, not chase.",
    unit="m",
    definition="Path length of the subordinate hand during the insertions (pierce to end of passage).",
    streams=("subordinate_displacement", "events"),
    better=LOWER,
    reference="Datta et al. 2001, J Am Coll Surg 193:479 (ICSAD, both hands)",
    group="subordinate",
    kind="efficiency",
)
def subordinate_activity(context: SessionContext) -> float:
    moved = context.streams.subordinate_displacement
    mask = _insertion_mask(context)
    if moved is None or mask is None:
        return NAN
    steps = np.linalg.norm(np.diff(moved, axis=0), axis=1)
    return float(steps[mask[1:] & mask[:-1]].sum())


@metric(
    "subordinate_path_length",
    advice="Move the assisting hand less.",
    unit="m",
    definition="Length the subordinate hand travels within its movements, measured as path_length is.",
    streams=("subordinate_displacement",),
    better=LOWER,
    reference="Datta et al. 2001, J Am Coll Surg 193:479 (ICSAD, both hands)",
    group="subordinate",
    kind="efficiency",
)
def subordinate_path_length(context: SessionContext) -> float:
    moved = context.streams.subordinate_displacement
    if moved is None:
        return NAN
    motion = kinematics.UniformMotion.of(context.streams.time, moved, min(100.0, context.streams.sample_rate))
    return kinematics.moving_path_length(motion, kinematics.find_movements(motion))


@metric(
    "edge_held_at_insertion",
    advice="Hold the wound edge with the forceps before the needle goes in.",
    unit="fraction",
    definition=(
        "Share of the insertions' time (pierce to end of passage) during which the subordinate hand's "
        "forceps held the tissue (stored 0-1, shown in per cent: 0 never, 100 throughout): the access the "
        "other hand gives the needle."
    ),
    streams=("forceps_jaw", "grasp_force", "events"),
    better=HIGHER,
    reference="PAPER.md: the subordinate hand gives access inside the wound's edge",
    group="subordinate",
    kind="efficiency",
    bounds=(0.0, 1.0),
)
def edge_held_at_insertion(context: SessionContext) -> float:
    force = context.streams.grasp_force
    mask = _insertion_mask(context)
    if force is None or mask is None or not mask.any():
        return NAN
    holding = np.any(force != 0.0, axis=1)  # the jaws closed on tissue (closed on air: no force)
    return float(np.mean(holding[mask]))


@metric(
    "peak_grasp_force",
    advice="Hold the edge gently: lift it only as far as the needle needs.",
    unit="N",
    definition=(
        "Largest force of the subordinate hand's forceps on the tissue they hold (not measured when "
        "they never held any)."
    ),
    streams=("grasp_force",),
    better=LOWER,
    reference="Heijnsdijk et al. 2004, Surg Endosc 18:974 (grasper forces and tissue damage)",
    group="subordinate",
    kind="safety",
)
def peak_grasp_force(context: SessionContext) -> float:
    force = context.streams.grasp_force
    if force is None or not force.any():
        return NAN
    return float(np.linalg.norm(force, axis=1).max())


@metric(
    "forceps_tears",
    advice="Lift the edge less: it tore out of the forceps.",
    unit="1",
    definition="Times the grasped edge tore out of the forceps' jaws (edge_torn events).",
    streams=("grasp_force", "events"),
    better=LOWER,
    reference="Konig et al. 2009, Biomaterials 30:1542 (suture retention strength of arteries)",
    group="subordinate",
    kind="safety",
)
def forceps_tears(context: SessionContext) -> float:
    if context.streams.grasp_force is None:
        return NAN
    return float(np.sum(context.streams.events["kind"].to_numpy() == "edge_torn"))


@metric(
    "bimanual_dexterity",
    advice="Move the assisting hand with the needle hand: present the edge as the needle comes.",
    unit="1",
    definition=(
        "Correlation (Pearson, -1 to 1) of the two hands' speeds over the session, each path resampled "
        "to 100 Hz and low-passed as path_length's is: 1 when they speed up and slow down together, "
        "about 0 when one works while the other waits, not measured when a hand never moves."
    ),
    streams=("subordinate_displacement",),
    better=HIGHER,
    reference="Hofstad et al. 2013, Surg Endosc 27:854 (bimanual dexterity: the instruments' velocity "
    "correlation)",
    group="subordinate",
    kind="efficiency",
    bounds=(-1.0, 1.0),
)
def bimanual_dexterity(context: SessionContext) -> float:
    moved = context.streams.subordinate_displacement
    if moved is None or not np.all(np.isfinite(moved)):
        return NAN
    needle = context.motion
    assisting = kinematics.UniformMotion.of(context.streams.time, moved, needle.rate)
    return speed_correlation(needle.speed, assisting.speed)


def speed_correlation(first: np.ndarray, second: np.ndarray) -> float:
    """Pearson correlation of two speed profiles on the same grid (NaN when either is constant)."""
    n = min(first.size, second.size)
    a, b = first[:n] - first[:n].mean(), second[:n] - second[:n].mean()
    spread = math.sqrt(float(a @ a) * float(b @ b))
    if not spread > 0:
        return NAN
    return float(np.clip((a @ b) / spread, -1.0, 1.0))
