"""The force metrics: the needle's force on the tissue, its rate and the device's clamp.
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
from metrics.signals import kinematics

NAN = math.nan
FORCE_RATE_WINDOW_S = 0.01
"""Force rate is taken over 10 ms differences of the force vector (device-rate noise averages out)."""


@metric(
    "peak_force",
    advice="Use less force: let the needle's curve do the work.",
    unit="N",
    definition=(
        "Largest magnitude of the tissue's reaction force on the needle (before the device's clamp; "
        "sessions recorded before schema 2: the force the device was sent)."
    ),
    streams=("force",),
    better=LOWER,
    reference="O'Toole et al. 1999, J Am Coll Surg 189:114",
    group="force",
    kind="safety",
)
def peak_force(context: SessionContext) -> float:
    magnitude = context.force_magnitude
    return NAN if magnitude is None else float(magnitude.max())


def _contact_force(context: SessionContext):
    magnitude = context.force_magnitude
    if magnitude is None:
        return None
    selected = magnitude[context.in_tissue]
    return selected if selected.size else None


@metric(
    "mean_force",
    advice="Keep the load on the tissue lower throughout the bite.",
    unit="N",
    definition="Mean force magnitude over samples with the needle touching or inside the tissue.",
    streams=("force",),
    better=LOWER,
    reference="O'Toole et al. 1999, J Am Coll Surg 189:114",
    group="force",
    kind="efficiency",
)
def mean_force(context: SessionContext) -> float:
    selected = _contact_force(context)
    return NAN if selected is None else float(selected.mean())


@metric(
    "rms_force",
    advice="Keep the load on the tissue lower throughout the bite.",
    unit="N",
    definition="Root-mean-square force magnitude over samples with the needle touching or inside the tissue.",
    streams=("force",),
    better=LOWER,
    reference="O'Toole et al. 1999, J Am Coll Surg 189:114",
    group="force",
    kind="efficiency",
)
def rms_force(context: SessionContext) -> float:
    selected = _contact_force(context)
    return NAN if selected is None else float(np.sqrt(np.mean(selected * selected)))


@metric(
    "force_at_insertion",
    advice="Pierce with less force: a sharp, square entry needs less.",
    unit="N",
    definition="Force magnitude at the instant of each pierce (interpolated), averaged over insertions.",
    streams=("force", "events"),
    better=LOWER,
    reference="Moody et al. 2003 (grip forces at insertion); " + PAPER_REF,
    group="force",
    kind="efficiency",
)
def force_at_insertion(context: SessionContext) -> float:
    magnitude = context.force_magnitude
    if magnitude is None or not context.insertions:
        return NAN
    times = [i.pierce_time for i in context.insertions]
    return float(np.mean(np.interp(times, context.streams.time, magnitude)))


@metric(
    "peak_force_rate",
    advice="Load the tissue gradually, without jerks.",
    unit="N/s",
    definition="Largest |F(t + 10 ms) - F(t)| / 10 ms of the force vector (resampled to 1 kHz).",
    streams=("force",),
    better=LOWER,
    reference="Trejos et al. 2014, Surg Endosc 28:2530 (force derivatives in skill assessment)",
    group="force",
    kind="efficiency",
)
def peak_force_rate(context: SessionContext) -> float:
    force = context.streams.force
    if force is None:
        return NAN
    grid, uniform = kinematics.resample_uniform(context.streams.time, force, rate=1000.0)
    lag = max(1, int(round(FORCE_RATE_WINDOW_S * 1000.0)))
    if uniform.shape[0] <= lag:
        return NAN
    change = np.linalg.norm(uniform[lag:] - uniform[:-lag], axis=1)
    return float(change.max() / (grid[lag] - grid[0]))


@metric(
    "force_clamp_hits",
    advice="Never push beyond what the device (and the wall) can take.",
    unit="1",
    definition="Times the runtime's safety layer clamped the force to the device's rated maximum.",
    streams=("events",),
    better=LOWER,
    reference="vascsim runtime safety (docs/runtime.md)",
    group="force",
    kind="safety",
)
def force_clamp_hits(context: SessionContext) -> float:
    return float(np.sum(context.streams.events["kind"].to_numpy() == "force_clamped"))
