"""The registered stitch-placement metrics (:mod:`metrics.signals.placement`); importing fills the registry.

Each is the mean over the session's stitches (NaN when the session has no stitch points or its
task declares no targets). Distances are in m, errors never negative.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from metrics.session.context import SessionContext
from metrics.session.registry import HIGHER, LOWER, metric
from metrics.signals.placement import StitchPlacement, mean_or_nan

NAN = math.nan
TARGETS_REF = (
    "the task's target marks, as a course's template draws them; "
    "AMBF suturing challenge scoring (Munawar et al. 2022)"
)
OSATS_REF = "Martin et al. 1997, Br J Surg 84:273 (OSATS: respect for tissue)"


def _over_stitches(context: SessionContext, per_stitch: Callable[[StitchPlacement], np.ndarray]) -> float:
    """The mean over the session's stitches of ``per_stitch`` (NaN without placement)."""
    placed = context.placement
    return NAN if placed is None else mean_or_nan(per_stitch(placed))


@metric(
    "bite_error_entry",
    advice="Enter at the planned bite width from the edge.",
    unit="m",
    definition="Mean over stitches of |entry point's distance from the wound edge - the task's target bite|.",
    streams=("stitches",),
    better=LOWER,
    reference=TARGETS_REF,
    group="placement",
    kind="quality",
)
def bite_error_entry(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: np.abs(placed.entry_bite - placed.target_bite))


@metric(
    "bite_error_exit",
    advice="Come out at the planned bite width from the edge.",
    unit="m",
    definition="Mean over stitches of |exit point's distance from the wound edge - the task's target "
    "exit bite| (the entry's target unless the task states one).",
    streams=("stitches",),
    better=LOWER,
    reference=TARGETS_REF,
    group="placement",
    kind="quality",
)
def bite_error_exit(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: np.abs(placed.exit_bite - placed.target_exit_bite))


@metric(
    "entry_to_target",
    advice="Aim the needle tip at the entry mark before piercing.",
    unit="m",
    definition="Mean over stitches of the distance from the entry point to the nearest target entry mark.",
    streams=("stitches",),
    better=LOWER,
    reference=TARGETS_REF,
    group="placement",
    kind="quality",
)
def entry_to_target(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: placed.entry_to_target)


@metric(
    "exit_to_target",
    advice="Bring the needle out at the exit mark: rotate along its curve.",
    unit="m",
    definition="Mean over stitches of the distance from the exit point to the nearest target exit mark.",
    streams=("stitches",),
    better=LOWER,
    reference=TARGETS_REF,
    group="placement",
    kind="quality",
)
def exit_to_target(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: placed.exit_to_target)


@metric(
    "bite_asymmetry",
    advice="Take equal bites on both sides of the wound.",
    unit="m",
    definition="Mean over stitches of |(entry distance from the wound edge - its target) - (exit distance "
    "- its target)|: a bite that takes as much tissue on the way out as the template asks for the way "
    "in scores 0 (on a flat wall the two targets are equal; through a curved wall they differ).",
    streams=("stitches",),
    better=LOWER,
    reference=OSATS_REF,
    group="placement",
    kind="quality",
)
def bite_asymmetry(context: SessionContext) -> float:
    return _over_stitches(
        context,
        lambda p: np.abs((p.entry_bite - p.target_bite) - (p.exit_bite - p.target_exit_bite)),
    )


@metric(
    "full_thickness_fraction",
    advice="Take every bite through the full thickness of the wall.",
    unit="1",
    definition="Fraction of stitches whose needle came out through the far (luminal) surface, i.e. "
    "through every wall layer; a stitch out through the cut edge missed the intima, one without an "
    "exit is incomplete.",
    streams=("stitches",),
    better=HIGHER,
    reference=OSATS_REF,
    group="placement",
    kind="safety",
    bounds=(0.0, 1.0),
)
def full_thickness_fraction(context: SessionContext) -> float:
    placed = context.placement
    if placed is None:
        return NAN
    through = np.nan_to_num(placed.full_thickness, nan=0.0)  # no exit: not a full-thickness bite
    return float(through.mean())


@metric(
    "spacing_error",
    advice="Space the stitches as planned.",
    unit="m",
    definition="Mean over successive stitches of |their distance along the wound - the task's target "
    "spacing| (a row of stitches; NaN for a single stitch or a task without a row).",
    streams=("stitches",),
    better=LOWER,
    reference=TARGETS_REF,
    group="placement",
    kind="quality",
)
def spacing_error(context: SessionContext) -> float:
    placed = context.placement
    if placed is None or placed.target_spacing is None or not placed.spacing.size:
        return NAN
    return float(np.mean(np.abs(placed.spacing - placed.target_spacing)))


@metric(
    "spacing_variation",
    advice="Keep the spacing between stitches even.",
    unit="1",
    definition="Coefficient of variation (standard deviation / mean) of the distances along the wound "
    "between successive stitches: 0 for an even row (at least three stitches).",
    streams=("stitches",),
    better=LOWER,
    reference=OSATS_REF,
    group="placement",
    kind="quality",
)
def spacing_variation(context: SessionContext) -> float:
    placed = context.placement
    if placed is None or placed.spacing.size < 2 or not placed.spacing.mean() > 0:
        return NAN
    return float(placed.spacing.std() / placed.spacing.mean())


PASSAGE_REF = (
    "needle-curve following: vascular technique (rotate the needle along its curve, never lever); "
    "tissue damage as swept area: PerkTutor (Ungi et al. 2012, IEEE TBME 59:3475)"
)


@metric(
    "needle_track_offset",
    advice="Follow the needle's own curve through the wall.",
    unit="m",
    definition="Mean over stitches of the mean distance, while the needle is in the wall, from the "
    "stitch's entry point to the needle's own curve: near 0 when the wrist turns the needle along its "
    "curve, larger when the needle is levered sideways through its hole.",
    streams=("stitches",),
    better=LOWER,
    reference=PASSAGE_REF,
    group="placement",
    kind="quality",
)
def needle_track_offset(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: placed.track_offset)


@metric(
    "tissue_swept_area",
    advice="Sweep less tissue: rotate the needle about its centre.",
    unit="m^2",
    definition="Mean over stitches of the wall the needle swept beyond its own track: the sideways "
    "movement of the needle at the entry hole times the length of needle inside the wall, summed over "
    "the frames it is in the wall (tremor and levering inside the wall both count).",
    streams=("stitches",),
    better=LOWER,
    reference=PASSAGE_REF,
    group="placement",
    kind="quality",
)
def tissue_swept_area(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: placed.swept_area)


@metric(
    "wound_edge_stress",
    advice="Load the wound edge less while passing the needle.",
    unit="Pa",
    definition="Mean over stitches of the peak von Mises stress of the elements on the wound's cut faces "
    "during the stitch (the tissue model's linear far field under the recorded needle load): a bite too "
    "near the edge, or a levered needle, loads the edge that must hold the suture.",
    streams=("stitches",),
    better=LOWER,
    reference=OSATS_REF,
    group="placement",
    kind="safety",
)
def wound_edge_stress(context: SessionContext) -> float:
    return _over_stitches(context, lambda placed: placed.wound_edge_stress)


@metric(
    "back_wall_catches",
    advice="Never catch the back wall: keep the lumen in view on every bite.",
    unit="1",
    definition="Pierces in through the vessel's luminal surface (entry face within 45 deg of the far "
    "normal): the needle caught the back wall, which narrows or closes the vessel.",
    streams=("stitches",),
    better=LOWER,
    reference=OSATS_REF,
    group="placement",
    kind="safety",
)
def back_wall_catches(context: SessionContext) -> float:
    placed = context.placement
    return NAN if placed is None else float(placed.back_wall_catches)


@metric(
    "extra_punctures",
    advice="Place only the planned stitches; each extra puncture is a leak point.",
    unit="1",
    definition="Stitches beyond the task's target marks: each a further hole through the wall (a "
    "withdrawn and re-inserted needle), never fewer than 0.",
    streams=("stitches",),
    better=LOWER,
    reference=OSATS_REF,
    group="placement",
    kind="safety",
)
def extra_punctures(context: SessionContext) -> float:
    placed = context.placement
    return NAN if placed is None else float(max(0, placed.entry_bite.size - placed.marks))
