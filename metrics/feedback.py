"""What a trainee should work on next: the metrics a session did worse on than the experts, ranked.

Safety first (the never events: back-wall catches, wound-edge tears, force beyond the device's
rating), then the quality of the stitch (placement, the tissue's load), then efficiency (motion,
insertion, forces, the assisting hand); within each, by how far outside the experts' interquartile
band the value lies, in band widths. Each item carries a sentence a supervisor would say
(:data:`ADVICE`, one per registered metric, checked by a test), so the CLI, the dashboard and the
report say the same thing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from metrics.registry import REGISTRY
from metrics.standards import SAFETY_METRICS

KINDS = ("safety", "quality", "efficiency")
"""The order feedback is ranked in: what harms the patient, then what makes the anastomosis, then speed
and economy."""

QUALITY_GROUPS = ("placement", "tissue")

ADVICE: dict[str, str] = {
    "task_time": "Work through the steps without pauses; speed follows a settled routine.",
    "path_length": "Move the holder less: plan each bite and go straight to it.",
    "movement_count": "Make fewer, deliberate movements instead of many corrections.",
    "economy_of_motion": "Take the direct route between the steps.",
    "log_dimensionless_jerk": "Move smoothly: start and stop the holder gently.",
    "spectral_arc_length": "Move smoothly, in one flowing motion per step.",
    "idle_time": "Keep the hands working; decide the next move before finishing this one.",
    "tip_speed_before_pierce": "Approach the wall more slowly and in control.",
    "tip_speed_after_pierce": "Drive the needle through the wall more slowly.",
    "entry_angle_error_deg": "Meet the wall at a right angle before you push.",
    "attempts": "Commit to one entry: set the angle, then pierce in one attempt.",
    "regrabs": "Load the needle once where you need it, to avoid re-grasping.",
    "contact_to_pierce_time": "Once the tip is on the wall, pierce decisively.",
    "peak_force": "Use less force: let the needle's curve do the work.",
    "mean_force": "Keep the load on the tissue lower throughout the bite.",
    "rms_force": "Keep the load on the tissue lower throughout the bite.",
    "force_at_insertion": "Pierce with less force: a sharp, square entry needs less.",
    "peak_force_rate": "Load the tissue gradually, without jerks.",
    "force_clamp_hits": "Never push beyond what the device (and the wall) can take.",
    "high_stress_area": "Spread less stress through the wall: follow the needle's curve.",
    "stress_concentration": "Avoid concentrating stress: rotate the needle, do not lever it.",
    "peak_stretch": "Stretch the wall less: do not pull or lever on the needle.",
    "time_above_strain_limit": "Spend less time overstretching the wall.",
    "wound_edge_tears": "Protect the wound edge: do not lever the needle against it.",
    "subordinate_displacement": "Keep the assisting hand steady.",
    "subordinate_activity": "Let the assisting hand hold, not chase.",
    "subordinate_path_length": "Move the assisting hand less.",
    "bite_error_entry": "Enter at the planned bite width from the edge.",
    "bite_error_exit": "Come out at the planned bite width from the edge.",
    "entry_to_target": "Aim the needle tip at the entry mark before piercing.",
    "exit_to_target": "Bring the needle out at the exit mark: rotate along its curve.",
    "bite_asymmetry": "Take equal bites on both sides of the wound.",
    "full_thickness_fraction": "Take every bite through the full thickness of the wall.",
    "spacing_error": "Space the stitches as planned.",
    "spacing_variation": "Keep the spacing between stitches even.",
    "needle_track_offset": "Follow the needle's own curve through the wall.",
    "tissue_swept_area": "Sweep less tissue: rotate the needle about its centre.",
    "wound_edge_stress": "Load the wound edge less while passing the needle.",
    "back_wall_catches": "Never catch the back wall: keep the lumen in view on every bite.",
    "extra_punctures": "Place only the planned stitches; each extra puncture is a leak point.",
}


def kind_of(metric: str) -> str:
    """safety, quality or efficiency."""
    if metric in SAFETY_METRICS:
        return "safety"
    return "quality" if metric in REGISTRY and REGISTRY[metric].group in QUALITY_GROUPS else "efficiency"


def band_widths_outside(value: float, q1: float, q3: float, better: str) -> float:
    """How far ``value`` lies on the worse side of the band [q1, q3], in band widths (0 inside). A
    zero-width band (every expert alike) measures the excess against the experts' value itself, or
    against 1 when that is 0 (e.g. every expert at 0 back-wall catches: 2 catches are 2 widths)."""
    excess = value - q3 if better == "lower" else q1 - value
    if excess <= 0:
        return 0.0
    return excess / (q3 - q1 if q3 > q1 else abs(q3) or 1.0)


def what_to_work_on(rows: Sequence[dict], limit: int = 3) -> list[dict]:
    """The metrics a session did worse on than the experts (rows as :func:`sessions.review.against_band`
    gives them), safety first, then quality, then efficiency, each kind by distance outside the band;
    at most ``limit`` items, every safety item kept. Each: metric, kind, widths, advice."""
    items = []
    for row in rows:
        if row.get("versus_experts") != "worse" or row["metric"] not in REGISTRY:
            continue
        q1, q3, value = row["expert_q1"], row["expert_q3"], row["value"]
        if None in (q1, q3, value) or not all(map(math.isfinite, (q1, q3, value))):
            continue
        widths = band_widths_outside(value, q1, q3, row["better"])
        items.append(
            {
                "metric": row["metric"],
                "kind": kind_of(row["metric"]),
                "widths": widths,
                "advice": ADVICE.get(row["metric"], REGISTRY[row["metric"]].definition),
                "row": row,
            }
        )
    items.sort(key=lambda item: (KINDS.index(item["kind"]), -item["widths"]))
    safety = [item for item in items if item["kind"] == "safety"]
    return safety + [item for item in items if item["kind"] != "safety"][: max(limit - len(safety), 0)]


def feedback_line(item: dict) -> str:
    """ "Aim the needle tip at the entry mark before piercing. (entry_to_target 0.65 mm; experts
    0.07-0.10 mm, lower is better)": what to do, then the numbers behind it in display units."""
    row, shown = item["row"], item["row"]["display"]
    unit = f" {row['display_unit']}" if row["display_unit"] else ""
    low, high = shown["expert_q1"], shown["expert_q3"]
    experts = f"{low:.3g}" if f"{low:.3g}" == f"{high:.3g}" else f"{low:.3g}-{high:.3g}"
    return (
        f"{item['advice']} ({row['metric']} {shown['value']:.3g}{unit}; experts {experts}{unit}, "
        f"{row['better']} is better)"
    )
