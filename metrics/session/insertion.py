"""The insertion metrics: the needle's speed near the entry, its angle, attempts and regrabs.
Importing this module registers them.

Thresholds are module constants, documented in docs/metrics.md; changing one means bumping
:data:`metrics.session.registry.REGISTRY_VERSION`.
"""

from __future__ import annotations

import math

import numpy as np

from metrics.session.context import SessionContext
from metrics.session.references import PAPER_REF
from metrics.session.registry import LOWER, metric

NAN = math.nan


def _tip_speed_near(context: SessionContext, after: bool) -> float:
    speed = context.tip_speed
    point = context.insertion_point
    if speed is None or point is None or not context.insertions:
        return NAN
    tip = context.streams.tip_position
    near = np.linalg.norm(tip - point, axis=1) <= context.insertion_radius
    values = []
    previous_end = context.streams.time[0]
    for insertion in context.insertions:
        if after:
            window = context.span(insertion.pierce_time, insertion.end_time)
        else:
            window = context.span(previous_end, insertion.pierce_time)
        previous_end = insertion.end_time
        selected = speed[window][near[window]]
        if selected.size:
            values.append(float(selected.mean()))
    return float(np.mean(values)) if values else NAN


@metric(
    "tip_speed_before_pierce",
    advice="Approach the wall more slowly and in control.",
    unit="m/s",
    definition=(
        "Mean needle-tip speed within 5 mm of the insertion point (the tip at the first pierce) before each "
        "pierce, averaged over insertions."
    ),
    streams=("tip_position", "events"),
    better=LOWER,
    reference=PAPER_REF,
    group="insertion",
    kind="efficiency",
)
def tip_speed_before_pierce(context: SessionContext) -> float:
    return _tip_speed_near(context, after=False)


@metric(
    "tip_speed_after_pierce",
    advice="Drive the needle through the wall more slowly.",
    unit="m/s",
    definition=(
        "Mean needle-tip speed within 5 mm of the insertion point from each pierce to the end of its "
        "passage (exit, pull-through or next pierce), averaged over insertions."
    ),
    streams=("tip_position", "events"),
    better=LOWER,
    reference=PAPER_REF,
    group="insertion",
    kind="efficiency",
)
def tip_speed_after_pierce(context: SessionContext) -> float:
    return _tip_speed_near(context, after=True)


@metric(
    "entry_angle_error_deg",
    advice="Meet the wall at a right angle before you push.",
    unit="deg",
    definition=(
        "Angle between the needle tip's direction and the inward surface normal when it first touches the "
        "tissue in each episode that ends in a pierce (0 = perpendicular, the ideal bite), averaged."
    ),
    streams=("events",),
    better=LOWER,
    reference="Moorthy et al. 2003, BMJ 327:1032 (needle entry perpendicular to tissue)",
    group="insertion",
    kind="efficiency",
)
def entry_angle_error_deg(context: SessionContext) -> float:
    angles = [abs(i.entry_angle_deg) for i in context.insertions if not math.isnan(i.entry_angle_deg)]
    return float(np.mean(angles)) if angles else NAN


@metric(
    "attempts",
    advice="Commit to one entry: set the angle, then pierce in one attempt.",
    unit="1",
    definition="Contact episodes (contact start to contact end) that ended without the needle piercing.",
    streams=("events",),
    better=LOWER,
    reference=PAPER_REF,
    group="insertion",
    kind="efficiency",
)
def attempts(context: SessionContext) -> float:
    kinds = context.streams.events["kind"].to_numpy()
    failed = 0
    open_episode = False
    pierced = False
    for kind in kinds:
        if kind == "contact_start":
            open_episode, pierced = True, False
        elif kind == "pierce":
            pierced = True
        elif kind == "contact_end" and open_episode:
            failed += not pierced
            open_episode = False
    return float(failed)


@metric(
    "regrabs",
    advice="Load the needle once where you need it, to avoid re-grasping.",
    unit="1",
    definition="Times the needle holder let go of the needle and took it again (one per stitch is usual).",
    streams=("events",),
    better=LOWER,
    reference="Reznick et al. 1997, Am J Surg 173:226 (OSATS instrument handling)",
    group="insertion",
    kind="efficiency",
)
def regrabs(context: SessionContext) -> float:
    return float(np.sum(context.streams.events["kind"].to_numpy() == "regrab"))


@metric(
    "contact_to_pierce_time",
    advice="Once the tip is on the wall, pierce decisively.",
    unit="s",
    definition="Time from the first contact of an episode to its pierce, averaged over insertions.",
    streams=("events",),
    better=LOWER,
    reference=PAPER_REF,
    group="insertion",
    kind="efficiency",
)
def contact_to_pierce_time(context: SessionContext) -> float:
    values = [i.pierce_time - i.contact_time for i in context.insertions]
    return float(np.mean(values)) if values else NAN
