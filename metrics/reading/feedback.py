"""What a trainee should work on next, and what they already do well, against the experts' band.

The never events first (back-wall catches, wound-edge tears, force beyond the device's rating: never
cut from the list), then the rest of safety (each metric registered with ``kind="safety"``:
partial-thickness bites, extra punctures, excessive force, the tissue's load), the quality of the
stitch (placement), then efficiency (motion, insertion, the remaining forces, the assisting
hand); within each, by how far outside the experts' interquartile band the value lies, in band
widths. Each item carries a sentence a supervisor would say (each metric's ``advice`` in the
registry, required when it registers), so the CLI, the dashboard and the report say the same
thing. Strengths are the metrics better than the experts' middle half (then the safety and quality
metrics level with it), in the same order. :func:`session_feedback` gives both for one session,
:func:`participant_feedback` for a trainee's recent practice.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import pandas as pd

from metrics.reading.band import against_band, expert_quartiles
from metrics.session.registry import KINDS, REGISTRY, display_name
from metrics.study.analysis import StudyAnalysis, practice_mask
from metrics.study.standards import SAFETY_METRICS
from metrics.units import shown, significant


def kind_of(metric: str) -> str:
    """The metric's kind as registered (``@metric(kind=...)``: safety, quality or efficiency); a
    metric outside the registry (an imported column) counts as efficiency."""
    return REGISTRY[metric].kind if metric in REGISTRY else "efficiency"


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
    """The metrics a session did worse on than the experts (rows as :func:`metrics.reading.band.against_band`
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
                "advice": REGISTRY[row["metric"]].advice,
                "row": row,
            }
        )
    items.sort(key=lambda i: (i["metric"] not in SAFETY_METRICS, KINDS.index(i["kind"]), -i["widths"]))
    return items


def benchmark_gaps(values: Mapping[str, float | None], benchmarks: pd.DataFrame | None) -> list[dict]:
    """The pass marks ``values`` (SI, by metric) do not meet, furthest (relative to the mark) first:
    what stops the next session passing. Each: metric, kind "benchmark", gap (SI, by direction), line
    (the advice, then the value, the mark and the gap in display units). A metric with no value or no
    mark is left out (it neither blocks nor passes)."""
    if benchmarks is None or benchmarks.empty:
        return []
    items = []
    for bench in benchmarks.itertuples():
        value = values.get(bench.metric)
        if value is None or not math.isfinite(value) or not math.isfinite(bench.benchmark):
            continue
        if bench.metric not in REGISTRY:
            continue
        gap = value - bench.benchmark if bench.better == "lower" else bench.benchmark - value
        if gap <= 0:
            continue
        metric = REGISTRY[bench.metric]
        line = (
            f"{metric.advice} ({display_name(bench.metric)} {shown(value, metric.unit)}; the pass mark is "
            f"{bench.pass_if}: {shown(gap, metric.unit)} to go)"
        )
        relative = gap / abs(bench.benchmark) if bench.benchmark else math.inf
        items.append(
            {"metric": bench.metric, "kind": "benchmark", "gap": gap, "relative": relative, "line": line}
        )
    items.sort(key=lambda item: -item["relative"])
    return [{k: v for k, v in item.items() if k != "relative"} for item in items]


def feedback_line(item: dict) -> str:
    """ "Aim the needle tip at the entry mark before piercing. (entry_to_target 0.65 mm; experts
    0.07-0.10 mm, lower is better)": what to do, then the numbers behind it in display units."""
    value, experts = _numbers(item["row"])
    return f"{item['advice']} ({value}; {experts})"


def strength_line(item: dict) -> str:
    """ "Better than the experts' middle half: entry_to_target 0.05 mm (experts 0.07-0.10 mm, lower is
    better)", or "Level with the experts: ..." for a value inside their band."""
    better = item["position"] == "better"
    lead = "Better than the experts' middle half" if better else "Level with the experts"
    value, experts = _numbers(item["row"])
    return f"{lead}: {value} ({experts})"


def _numbers(row: dict) -> tuple[str, str]:
    """("entry_to_target 0.65 mm", "experts 0.07-0.10 mm, lower is better") in display units."""
    display = row["display"]
    unit = f" {row['display_unit']}" if row["display_unit"] else ""
    low, high = significant(display["expert_q1"]), significant(display["expert_q3"])
    experts = low if low == high else f"{low}-{high}"
    value = f"{display_name(row['metric'])} {significant(display['value'])}{unit}"
    return value, f"experts {experts}{unit}, {row['better']} is better"


def session_feedback(
    rows: Sequence[dict], limit: int = 3, benchmarks: pd.DataFrame | None = None
) -> dict[str, list[dict]]:
    """What to work on and strengths for rows as :func:`metrics.reading.band.against_band` gives them, each
    item ready to show: metric, kind, line. What to work on leads with the pass marks of
    ``benchmarks`` (the study's, for this task) the values miss (:func:`benchmark_gaps`: what stops
    the next pass), then the never events and safety, then the rest, at most ``limit`` after the
    marks. The session page, ``vascsim sessions show``, the station's feedback screen, the
    participant page and the report all show these."""
    gaps = benchmark_gaps({row["metric"]: row["value"] for row in rows}, benchmarks)
    blocking = {gap["metric"] for gap in gaps}
    band = [row for row in rows if row["metric"] not in blocking]
    return {
        "work_on": [{k: gap[k] for k in ("metric", "kind", "line")} for gap in gaps]
        + [
            {"metric": i["metric"], "kind": i["kind"], "line": feedback_line(i)}
            for i in what_to_work_on(band, max(limit - len(gaps), 1))
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
    feedback = session_feedback(against_band(values, band), benchmarks=analysis.benchmarks)
    return {**feedback, "trials": [int(t) for t in mine["trial"]]}
