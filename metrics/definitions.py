"""The registered per-session metrics. Importing this module fills :data:`metrics.registry.REGISTRY`.

Thresholds are module constants, documented in docs/metrics.md; changing one means
bumping :data:`metrics.registry.REGISTRY_VERSION`.
"""

from __future__ import annotations

import math

import numpy as np

from metrics import kinematics
from metrics.context import SessionContext
from metrics.registry import HIGHER, LOWER, metric

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
FORCE_RATE_WINDOW_S = 0.01
"""Force rate is taken over 10 ms differences of the force vector (device-rate noise averages out)."""

MOTION_REF = "Oropesa et al. 2013, Surg Endosc 27:1029 (motion analysis review)"
SMOOTH_REF = "Balasubramanian et al. 2015, J NeuroEng Rehabil 12:112"
PAPER_REF = "the vascsim source paper (haptic simulator for suturing in vascular surgery), section 10"


# -- motion --------------------------------------------------------------------------
@metric(
    "task_time",
    advice="Work through the steps without pauses; speed follows a settled routine.",
    unit="s",
    definition="Time from the first to the last sample of the session.",
    better=LOWER,
    reference=MOTION_REF,
    group="motion",
)
def task_time(context: SessionContext) -> float:
    return context.streams.duration


@metric(
    "path_length",
    advice="Move the holder less: plan each bite and go straight to it.",
    unit="m",
    definition=(
        "Length the dominant tool travels within its movements (speed above 2 mm/s, rest to rest), on "
        "the same path the speed comes from: low-passed at 6 Hz (zero phase) before decimation to "
        "<= 100 Hz, so sensor noise and a still hand's jitter add no length."
    ),
    better=LOWER,
    reference=MOTION_REF,
    group="motion",
)
def path_length(context: SessionContext) -> float:
    return kinematics.moving_path_length(context.motion, context.movements)


@metric(
    "movement_count",
    advice="Make fewer, deliberate movements instead of many corrections.",
    unit="1",
    definition=(
        "Number of submovements of the tool's speed (6 Hz zero-phase low-pass, then <= 100 Hz): "
        "stretches above 2 mm/s lasting >= 0.1 s, each split at valleys that its peaks rise >= 2 mm/s "
        "above; a stretch without such a peak (constant speed) is one."
    ),
    better=LOWER,
    reference=MOTION_REF,
    group="motion",
)
def movement_count(context: SessionContext) -> float:
    return float(context.movements.count)


@metric(
    "economy_of_motion",
    advice="Take the direct route between the steps.",
    unit="1",
    definition=(
        "Sum over submovements of the straight-line distance from start to end (rest or the valley "
        "between peaks) divided by the path length within them; 1 when every movement is straight."
    ),
    better=HIGHER,
    reference=MOTION_REF,
    group="motion",
    bounds=(0.0, 1.0),
)
def economy_of_motion(context: SessionContext) -> float:
    return kinematics.economy_of_motion(context.motion, context.movements)


@metric(
    "log_dimensionless_jerk",
    advice="Move smoothly: start and stop the holder gently.",
    unit="1",
    definition=(
        "Median over submovements of -ln((T^3 / v_peak^2) * integral of |jerk|^2 dt), jerk of the tool "
        "path low-passed at 20 Hz (quintic spline below 200 Hz); closer to zero is smoother, a "
        "minimum-jerk reach scores -5.32. Per movement, so it is not task time in disguise."
    ),
    better=HIGHER,
    reference=SMOOTH_REF,
    group="motion",
    bounds=(-math.inf, 0.0),
)
def log_dimensionless_jerk(context: SessionContext) -> float:
    fine = context.jerk_motion
    return kinematics.log_dimensionless_jerk(
        fine, kinematics.on_grid(context.movements, context.motion, fine)
    )


@metric(
    "spectral_arc_length",
    advice="Move smoothly, in one flowing motion per step.",
    unit="1",
    definition=(
        "SPARC of the tool's speed profile: arc length of its normalised Fourier magnitude up to the last "
        "frequency <= 10 Hz above 5 % magnitude (zero-padded 2^4 times); closer to zero is smoother."
    ),
    better=HIGHER,
    reference=SMOOTH_REF,
    group="motion",
    bounds=(-math.inf, 0.0),
)
def spectral_arc_length(context: SessionContext) -> float:
    return kinematics.spectral_arc_length(context.motion.speed, context.motion.rate)


@metric(
    "idle_time",
    advice="Keep the hands working; decide the next move before finishing this one.",
    unit="s",
    definition="Total time in stretches of >= 0.25 s with the tool's smoothed speed below 1 mm/s.",
    better=LOWER,
    reference=MOTION_REF,
    group="motion",
)
def idle_time(context: SessionContext) -> float:
    return kinematics.idle_time(context.motion)


# -- insertion -----------------------------------------------------------------------
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
)
def contact_to_pierce_time(context: SessionContext) -> float:
    values = [i.pierce_time - i.contact_time for i in context.insertions]
    return float(np.mean(values)) if values else NAN


# -- force ---------------------------------------------------------------------------
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
)
def force_clamp_hits(context: SessionContext) -> float:
    return float(np.sum(context.streams.events["kind"].to_numpy() == "force_clamped"))


# -- tissue --------------------------------------------------------------------------
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
)
def wound_edge_tears(context: SessionContext) -> float:
    return float(np.sum(context.streams.events["kind"].to_numpy() == "edge_overstress"))
