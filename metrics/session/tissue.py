"""The tissue metrics: stress near the stitch, stretch, time over the strain limit, torn edges.
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
STRAIN_LIMIT_STRETCH = 1.3
"""Stretch (the largest edge stretch around the contact in the displayed field) above which the wall is
taken to be damaged: arterial failure stretches are ~1.3-1.5 (Holzapfel 2005; 1.50 for human carotid
layers, Teng et al. 2009, J Biomech 42:2535)."""
HIGH_STRESS_PA = 36e3
"""Surface von Mises stress counted as high: the calibrated porcine-artery wall's elastin modulus times
its strain limit (300 kPa x 0.12 = 36 kPa), the stress beyond which the stiff collagen phase carries
load (registry version 4; version 3 had 4 kPa, the paper's 20 kPa wall)."""
STRESS_RADIUS_M = 0.005
"""Stress localisation looks at the surface within 5 mm of the insertion point."""


def _stress_near(context: SessionContext):
    field = context.streams.stress_field
    point = context.insertion_point
    if field is None or point is None or len(field) == 0:
        return None
    centres = field[["x", "y", "z"]].to_numpy(dtype=np.float64)
    near = np.linalg.norm(centres - point, axis=1) <= STRESS_RADIUS_M
    if not near.any():
        return None
    return field["area"].to_numpy(dtype=np.float64)[near], field["von_mises"].to_numpy(dtype=np.float64)[near]


@metric(
    "high_stress_area",
    advice="Spread less stress through the wall: follow the needle's curve.",
    unit="m^2",
    definition=(
        "Tissue surface within 5 mm of the insertion point whose von Mises stress at the moment of "
        "insertion exceeds 4 kPa (elastin modulus x strain limit: collagen engaged): how widely the bite "
        "loads the wall."
    ),
    streams=("stress_field",),
    better=LOWER,
    reference=PAPER_REF + " (stress localisation)",
    group="tissue",
    kind="safety",
)
def high_stress_area(context: SessionContext) -> float:
    near = _stress_near(context)
    if near is None:
        return NAN
    area, stress = near
    return float(area[stress > HIGH_STRESS_PA].sum())


@metric(
    "stress_concentration",
    advice="Avoid concentrating stress: rotate the needle, do not lever it.",
    unit="1",
    definition=(
        "Area-weighted mean von Mises stress within 5 mm of the insertion point divided by its peak there, "
        "at the moment of insertion: near 0 when the load is focused on the bite, 1 when it is spread."
    ),
    streams=("stress_field",),
    better=LOWER,
    reference=PAPER_REF + " (stress localisation)",
    group="tissue",
    kind="safety",
)
def stress_concentration(context: SessionContext) -> float:
    near = _stress_near(context)
    if near is None:
        return NAN
    area, stress = near
    peak = float(stress.max())
    if peak <= 0 or area.sum() <= 0:
        return NAN
    return float(np.sum(area * stress) / area.sum() / peak)


@metric(
    "peak_stretch",
    advice="Stretch the wall less: do not pull or lever on the needle.",
    unit="1",
    definition=(
        "Largest stretch of the wall around the needle over the session: the deformed over the rest length "
        "of the edges of the elements within 1 mm of the contact, in the displacement field shown."
    ),
    streams=("stretch",),
    better=LOWER,
    reference="Holzapfel et al. 2005, Am J Physiol Heart 289:H2048 (arterial failure stretch)",
    group="tissue",
    kind="safety",
)
def peak_stretch(context: SessionContext) -> float:
    stretch = context.streams.stretch
    if stretch is None or np.all(np.isnan(stretch)):
        return NAN
    return float(np.nanmax(stretch))


@metric(
    "time_above_strain_limit",
    advice="Spend less time overstretching the wall.",
    unit="s",
    definition="Time with the wall around the needle stretched above 1.3 (arterial failure: 1.3-1.5).",
    streams=("stretch",),
    better=LOWER,
    reference="Holzapfel et al. 2005, Am J Physiol Heart 289:H2048 (arterial failure stretch)",
    group="tissue",
    kind="safety",
)
def time_above_strain_limit(context: SessionContext) -> float:
    stretch = context.streams.stretch
    if stretch is None or np.all(np.isnan(stretch)):
        return NAN
    dt = np.diff(context.streams.time)
    above = np.nan_to_num(stretch[:-1], nan=0.0) > STRAIN_LIMIT_STRETCH
    return float(np.sum(dt[above]))


@metric(
    "wound_edge_tears",
    advice="Protect the wound edge: do not lever the needle against it.",
    unit="1",
    definition="Times the wound edge was stressed past the tissue's damage threshold (edge_overstress "
    "events: a bite too near the edge, or a needle levered towards it): a tear risk, a never event.",
    streams=("events",),
    better=LOWER,
    reference="vascsim tissue model, edge_damage_stress (docs/tissue-model.md)",
    group="tissue",
    kind="safety",
)
def wound_edge_tears(context: SessionContext) -> float:
    return float(np.sum(context.streams.events["kind"].to_numpy() == "edge_overstress"))
