"""What a trainee should work on next, and what they already do well, against the experts' band.

The never events first (back-wall catches, wound-edge tears, force beyond the device's rating: never
cut from the list), then the rest of safety (:data:`SAFETY_GROUP`: partial-thickness bites, extra
punctures, excessive force, the tissue's load), the quality of the stitch (placement), then
efficiency (motion, insertion, the remaining forces, the assisting hand); within each, by how far
outside the experts' interquartile band the value lies, in band widths. Each item carries a
sentence a supervisor would say (:data:`ADVICE`, one per registered metric, checked by a test),
so the CLI, the dashboard and the report say the same thing. Strengths are the metrics better
than the experts' middle half (then the safety and quality metrics level with it), in the same
order. :func:`session_feedback` gives both for one session, :func:`participant_feedback` for a
trainee's recent practice.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import pandas as pd

from metrics.band import against_band, expert_quartiles
from metrics.registry import REGISTRY
from metrics.standards import SAFETY_METRICS
from metrics.study import StudyAnalysis, practice_mask
from metrics.units import significant

KINDS = ("safety", "quality", "efficiency")
"""The order feedback is ranked in: what harms the patient, then what makes the anastomosis, then speed
and economy."""

SAFETY_GROUP = (
    *SAFETY_METRICS,
    "full_thickness_fraction",
    "extra_punctures",
    "peak_force",
    "wound_edge_stress",
    "high_stress_area",
    "stress_concentration",
    "peak_stretch",
    "time_above_strain_limit",
)
"""What harms the patient: the never events, partial-thickness bites and extra punctures (leaks),
excessive force, and the load on the tissue (stress, stretch, the wound edge)."""

QUALITY_GROUPS = ("placement",)

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
    """safety (:data:`SAFETY_GROUP`), quality (where the stitch went) or efficiency."""
    if metric in SAFETY_GROUP:
        return "safety"
    return "quality" if metric in REGISTRY and REGISTRY[metric].group in QUALITY_GROUPS else "efficiency"


def band_widths_outside(value: float, q1: float, q3: float, better: str, side: str = "worse") -> float:
    """How far ``value`` lies on the ``side`` ("worse" or "better") of the band [q1, q3], in band
    widths (0 inside or on the other side). A zero-width band (every expert alike) measures the excess
    against the experts' value itself, or against 1 when that is 0 (e.g. every expert at 0 back-wall
    catches: 2 catches are 2 widths)."""
    worse_excess = value - q3 if better == "lower" else q1 - value
    excess = worse_excess if side == "worse" else (q1 - value if better == "lower" else value - q3)
    if excess <= 0:
        return 0.0
    return excess / (q3 - q1 if q3 > q1 else abs(q3) or 1.0)


def what_to_work_on(rows: Sequence[dict], limit: int = 3) -> list[dict]:
    """The metrics a session did worse on than the experts (rows as :func:`metrics.band.against_band`
    gives them): the never events, then safety, quality and efficiency, each kind by distance outside
    the band; at most ``limit`` items, every never event kept. Each: metric, kind, widths, advice."""
    items = _ranked(rows, ("worse",), "worse")
    never = [item for item in items if item["metric"] in SAFETY_METRICS]
    others = [item for item in items if item["metric"] not in SAFETY_METRICS]
    return never + others[: max(limit - len(never), 0)]


def strengths(rows: Sequence[dict], limit: int = 2) -> list[dict]:
    """What the session did well: the metrics better than the experts' middle half (safety, quality,
    efficiency; each kind by distance beyond the band), then the safety and quality metrics level
    with the experts; at most ``limit``. Each: metric, kind, widths, position, row."""
    better = _ranked(rows, ("better",), "better")
    level = [item for item in _ranked(rows, ("within",), "better") if item["kind"] != "efficiency"]
    return (better + level)[:limit]


def _ranked(rows: Sequence[dict], positions: tuple[str, ...], side: str) -> list[dict]:
    items = []
    for row in rows:
        if row.get("versus_experts") not in positions or row["metric"] not in REGISTRY:
            continue
        q1, q3, value = row["expert_q1"], row["expert_q3"], row["value"]
        if None in (q1, q3, value) or not all(map(math.isfinite, (q1, q3, value))):
            continue
        items.append(
            {
                "metric": row["metric"],
                "kind": kind_of(row["metric"]),
                "widths": band_widths_outside(value, q1, q3, row["better"], side),
                "position": row["versus_experts"],
                "advice": ADVICE.get(row["metric"], REGISTRY[row["metric"]].definition),
                "row": row,
            }
        )
    items.sort(key=lambda i: (i["metric"] not in SAFETY_METRICS, KINDS.index(i["kind"]), -i["widths"]))
    return items


def feedback_line(item: dict) -> str:
    """ "Aim the needle tip at the entry mark before piercing. (entry_to_target 0.65 mm; experts
    0.07-0.10 mm, lower is better)": what to do, then the numbers behind it in display units."""
    return f"{item['advice']} ({_numbers(item['row'])})"


def strength_line(item: dict) -> str:
    """ "Better than the experts' middle half: entry_to_target 0.05 mm (experts 0.07-0.10 mm, lower is
    better)", or "Level with the experts: ..." for a value inside their band."""
    better = item["position"] == "better"
    lead = "Better than the experts' middle half" if better else "Level with the experts"
    numbers = _numbers(item["row"]).split("; ", 1)
    return f"{lead}: {numbers[0]} ({numbers[1]})"


def _numbers(row: dict) -> str:
    shown = row["display"]
    unit = f" {row['display_unit']}" if row["display_unit"] else ""
    low, high = shown["expert_q1"], shown["expert_q3"]
    experts = (
        significant(low)
        if significant(low) == significant(high)
        else f"{significant(low)}-{significant(high)}"
    )
    value = significant(shown["value"])
    return f"{row['metric']} {value}{unit}; experts {experts}{unit}, {row['better']} is better"


def session_feedback(rows: Sequence[dict], limit: int = 3) -> dict[str, list[dict]]:
    """What to work on and strengths for rows as :func:`metrics.band.against_band` gives them, each
    item ready to show: metric, kind, line. The session page, ``vascsim sessions show``, the
    participant page and the report all show these."""
    return {
        "work_on": [
            {"metric": i["metric"], "kind": i["kind"], "line": feedback_line(i)}
            for i in what_to_work_on(rows, limit)
        ],
        "strengths": [
            {"metric": i["metric"], "kind": i["kind"], "line": strength_line(i)} for i in strengths(rows)
        ],
    }


METRIC_GROUPS = (("safety", "Safety"), ("quality-efficiency", "Quality and efficiency"))
"""How a session's metrics are shown: the never events and tissue harm first, then the rest (the
grouping surgical simulators' users know)."""


def metric_groups(rows: Sequence[dict]) -> list[dict]:
    """``rows`` split into the groups of :data:`METRIC_GROUPS` (kind, title, metrics), registry order
    kept inside each; an empty group is left out."""
    safety = [row for row in rows if kind_of(row["metric"]) == "safety"]
    rest = [row for row in rows if kind_of(row["metric"]) != "safety"]
    return [
        {"kind": kind, "title": title, "metrics": members}
        for (kind, title), members in zip(METRIC_GROUPS, (safety, rest), strict=True)
        if members
    ]


RECENT_SESSIONS = 3
"""How many of a trainee's latest practice sessions their feedback summarises (the median of each)."""


def participant_feedback(analysis: StudyAnalysis, code: str, recent: int = RECENT_SESSIONS) -> dict:
    """A trainee's feedback from their latest ``recent`` practice sessions of the analysed task: the
    median of each metric against the experts' band (the quartiles of every expert session in the
    analysis). Keys: work_on, strengths (as :func:`session_feedback`), trials (the trials summarised;
    empty when the trainee has no practice session or no expert has one)."""
    settings, table = analysis.settings, analysis.sessions
    names = [name for name in table.columns if name in REGISTRY]
    experts = table[table[settings.group_col] == settings.skilled_group]
    band = expert_quartiles(experts[names].melt(var_name="metric", value_name="value"))
    mine = table[(table[settings.cluster_col] == code) & practice_mask(table)].sort_values("trial")
    mine = mine.tail(recent)
    if mine.empty or not band:
        return {"work_on": [], "strengths": [], "trials": []}
    medians = mine[names].median(skipna=True)
    values = {name: (None if pd.isna(medians[name]) else float(medians[name])) for name in names}
    return {**session_feedback(against_band(values, band)), "trials": [int(t) for t in mine["trial"]]}
