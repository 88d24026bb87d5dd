"""The motion metrics: time, path, movements, economy and smoothness of the needle hand.
Importing this module registers them.

Thresholds are module constants, documented in docs/metrics.md; changing one means bumping
:data:`metrics.session.registry.REGISTRY_VERSION`.
"""

from __future__ import annotations

import math

from metrics.session.context import SessionContext
from metrics.session.references import MOTION_REF, SMOOTH_REF
from metrics.session.registry import HIGHER, LOWER, metric
from metrics.signals import kinematics


@metric(
    "task_time",
    advice="Work through the steps without pauses; speed follows a settled routine.",
    unit="s",
    definition="Time from the first to the last sample of the session.",
    better=LOWER,
    reference=MOTION_REF,
    group="motion",
    kind="efficiency",
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
    kind="efficiency",
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
    kind="efficiency",
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
    kind="efficiency",
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
    kind="efficiency",
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
    kind="efficiency",
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
    kind="efficiency",
)
def idle_time(context: SessionContext) -> float:
    return kinematics.idle_time(context.motion)
