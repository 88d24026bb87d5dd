"""Proficiency-based progression: benchmarks from the expert group, pass/fail per session.

Benchmark rules (per metric, from one value per expert: the median of their sessions):

- ``"mean"``: the expert mean (Gallagher et al. 2005, Ann Surg 241:364): a trainee
  passes a metric when at least as good as the average expert;
- ``"median"``: the expert median;
- ``"percentile:Q"``: the value that Q % of experts reach, e.g. ``"percentile:80"``;
- ``"mean+sd:K"``: K standard deviations from the expert mean on the worse side (Lap
  Mentor's "expert mean + 2 SD": ``"mean+sd:2"``);
- ``"trimmed:P"``: the expert mean with P % cut from each end (robust to one outlying expert);
- ``"contrasting"``: the contrasting-groups mark (:func:`metrics.study.statistics.contrasting_groups_mark`):
  where the normal fits of the experts' values and the unskilled group's (each trainee's first
  practice session) cross.

A session passes a metric when its value is on the better side of (or equal to) the
benchmark; it passes overall when it passes every benchmarked metric it has. A
trainee is proficient after ``consecutive`` overall passes in a row (default 2,
Gallagher's criterion).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY, display_name
from metrics.study.statistics import contrasting_groups_mark
from metrics.units import shown

RULE_FORMS = "'mean', 'median', 'percentile:Q', 'mean+sd:K', 'trimmed:P' or 'contrasting'"


def _share(rule: str, low: float, high: float, what: str) -> float:
    try:
        share = float(rule.split(":", 1)[1])
    except ValueError:
        share = math.nan
    if not low <= share <= high or (share == low and what != "a number of SDs"):
        raise MetricsError(f"{rule.split(':')[0]} rule needs {what} in ({low:g}, {high:g}]; got {rule!r}")
    return share


def rule_value(values: np.ndarray, rule: str, better: str, unskilled: np.ndarray | None = None) -> float:
    """The pass mark of ``rule`` from the experts' ``values`` (one per expert); ``"contrasting"``
    needs the unskilled group's ``unskilled`` values too."""
    if rule == "mean":
        return float(np.mean(values))
    if rule == "median":
        return float(np.median(values))
    if rule.startswith("percentile:"):
        share = _share(rule, 0.0, 100.0, "a share")
        # the value that share % of experts reach: worse-side quantile
        q = share / 100 if better == "lower" else 1 - share / 100
        return float(np.quantile(values, q))
    if rule.startswith("mean+sd:"):
        k = _share(rule, 0.0, 10.0, "a number of SDs")
        spread = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
        return float(np.mean(values)) + (k if better == "lower" else -k) * spread
    if rule.startswith("trimmed:"):
        cut = _share(rule, 0.0, 49.0, "a percentage cut from each end")
        return float(stats.trim_mean(values, cut / 100))
    if rule == "contrasting":
        return contrasting_groups_mark(values, np.zeros(0) if unskilled is None else unskilled)
    raise MetricsError(f"benchmark rule must be {RULE_FORMS}; got {rule!r}")


def check_rule(rule: str) -> None:
    """MetricsError unless ``rule`` is a benchmark rule this module knows."""
    rule_value(np.array([1.0, 2.0]), rule, "lower", np.array([3.0, 5.0]))


BENCHMARK_COLUMNS = ("metric", "benchmark", "better", "pass_if", "rule", "experts")
"""A benchmarks table's columns (also when it has no row: no metric could be benchmarked)."""


def proficiency_benchmarks(
    table: pd.DataFrame,
    metrics: Sequence[str],
    group_col: str = "label",
    expert_group: str = "expert",
    cluster_col: str = "participant_id",
    rule: str = "mean",
) -> pd.DataFrame:
    """One row per metric: ``metric``, ``benchmark``, ``better``, ``pass_if`` (e.g. "<= 3.04 deg"),
    ``rule``, ``experts`` (count)."""
    per_expert, per_novice = _per_participant(table, metrics, group_col, expert_group, cluster_col)
    rows = []
    for name in metrics:
        if name not in REGISTRY:
            raise MetricsError(f"unknown metric {name!r}: benchmarks need the registry's direction")
        better = REGISTRY[name].better
        values = per_expert[name].dropna().to_numpy()
        novices = per_novice[name].dropna().to_numpy()
        benchmark = rule_value(values, rule, better, novices) if values.size else math.nan
        rows.append(
            {
                "metric": name,
                "benchmark": benchmark,
                "better": better,
                "pass_if": pass_condition(benchmark, better, REGISTRY[name].unit),
                "rule": rule,
                "experts": values.size,
            }
        )
    return pd.DataFrame(rows, columns=BENCHMARK_COLUMNS)


def _per_participant(
    table: pd.DataFrame, metrics: Sequence[str], group_col: str, expert_group: str, cluster_col: str
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Each expert's median per metric, and each other participant's first session (the unskilled
    group of contrasting groups)."""
    experts = table[table[group_col] == expert_group]
    if experts.empty:
        raise MetricsError(f"no sessions with {group_col} == {expert_group!r} to set benchmarks from")
    per_expert = experts.groupby(cluster_col)[list(metrics)].median()
    first = table[table[group_col] != expert_group]
    if "trial" in first.columns:  # the unskilled group of contrasting groups: each trainee's first session
        first = first.sort_values("trial", kind="stable").groupby(cluster_col).head(1)
    return per_expert, first.groupby(cluster_col)[list(metrics)].median()


def mark_intervals(
    table: pd.DataFrame,
    metrics: Sequence[str],
    group_col: str = "label",
    expert_group: str = "expert",
    cluster_col: str = "participant_id",
    rule: str = "mean",
    n_boot: int = 2000,
    seed: int = 0,
    level: float = 0.95,
) -> dict[str, tuple[float, float]]:
    """Per metric, the ``level`` percentile bootstrap interval of its pass mark, resampling experts
    (and, for contrasting groups, the unskilled participants) with replacement: how far the mark
    could move with another draw of the same number of experts. NaN bounds with fewer than two."""
    per_expert, per_novice = _per_participant(table, metrics, group_col, expert_group, cluster_col)
    rng = np.random.default_rng(seed)
    tail = (1 - level) / 2
    found = {}
    for name in metrics:
        better = REGISTRY[name].better
        values = per_expert[name].dropna().to_numpy()
        novices = per_novice[name].dropna().to_numpy()
        if values.size < 2:
            found[name] = (math.nan, math.nan)
            continue
        draws = rng.integers(0, values.size, size=(n_boot, values.size))
        others = rng.integers(0, max(novices.size, 1), size=(n_boot, novices.size))
        marks = np.array(
            [
                rule_value(values[d], rule, better, novices[o] if novices.size else None)
                for d, o in zip(draws, others, strict=True)
            ]
        )
        marks = marks[np.isfinite(marks)]
        low, high = np.quantile(marks, [tail, 1 - tail]) if marks.size else (math.nan, math.nan)
        found[name] = (float(low), float(high))
    return found


def mark_drift(marks: Sequence[dict], today: pd.DataFrame) -> list[dict]:
    """Marks as set (each with its ``interval`` when it was set) whose value computed from today's
    experts (``today``: a :func:`proficiency_benchmarks` table) lies outside that interval: the
    metric, the mark as set and as it would be now, the interval, the unit, and whether the move
    would make passing harder ("stricter") or easier ("more lenient")."""
    now = dict(zip(today["metric"], today["benchmark"], strict=True))
    moved = []
    for mark in marks:
        low, high = (math.nan if v is None else v for v in mark.get("interval") or (None, None))
        value = now.get(mark["metric"], math.nan)
        if not (np.isfinite(low) and np.isfinite(high) and np.isfinite(value)) or low <= value <= high:
            continue
        lower = value < mark["benchmark"]
        stricter = lower if mark["better"] == "lower" else not lower
        moved.append(
            {
                "metric": mark["metric"],
                "set": float(mark["benchmark"]),
                "now": float(value),
                "low": float(low),
                "high": float(high),
                "unit": REGISTRY[mark["metric"]].unit if mark["metric"] in REGISTRY else "",
                "direction": "stricter" if stricter else "more lenient",
            }
        )
    return moved


def drift_line(entry: dict) -> str:
    """One drift entry in words and display units: "peak force: today's experts would put the mark at
    <= 520 mN (set at <= 400 mN, interval 360 mN to 450 mN): more lenient"."""

    sign = "<=" if REGISTRY[entry["metric"]].better == "lower" else ">="
    return (
        f"{display_name(entry['metric'])}: today's experts would put the mark at {sign} "
        f"{shown(entry['now'], entry['unit'])} (set at {sign} {shown(entry['set'], entry['unit'])}, "
        f"interval {shown(entry['low'], entry['unit'])} to {shown(entry['high'], entry['unit'])}): "
        f"{entry['direction']}"
    )


def benchmarks_heading(benchmarks: pd.DataFrame, min_experts: int, standard: str = "") -> str:
    """What a page calls a study's benchmarks: the stored standard's label when they are one
    (``standard``, e.g. "standard v2, set 2026-12-05 from 4 expert(s) (12 sessions)"); provisional
    when fewer than ``min_experts`` experts set them; "no standard" when no metric could be
    benchmarked (the page says why)."""
    if standard:
        return f"Proficiency benchmarks: {standard}"
    if benchmarks.empty:
        return "Proficiency benchmarks: no standard (no metric shows the experts clearly better)"
    experts = int(benchmarks["experts"].min())
    if experts < min_experts:
        return f"Proficiency benchmarks (provisional: {experts} expert(s), the rule asks for {min_experts})"
    return f"Proficiency benchmarks (from {experts} experts)"


def pass_condition(benchmark: float, better: str, unit: str) -> str:
    """What passing means, by direction, in display units: "<= 3.04 deg" for lower-is-better,
    ">= 0.8" for higher, "<= 0.173 mm" for a distance kept in metres."""
    if math.isnan(benchmark):
        return "no benchmark (no expert values)"
    sign = "<=" if better == "lower" else ">="
    return f"{sign} {shown(benchmark, unit)}"  # in the units a surgeon reads (metrics.units)


def assess_proficiency(table: pd.DataFrame, benchmarks: pd.DataFrame) -> pd.DataFrame:
    """Pass/fail per session and benchmarked metric (``pass_<metric>``) and overall (``passed``)."""
    result = pd.DataFrame(index=table.index)
    passes = []
    for row in benchmarks.itertuples():
        if math.isnan(row.benchmark):
            continue
        values = table[row.metric].to_numpy(dtype=np.float64)
        ok = values <= row.benchmark if row.better == "lower" else values >= row.benchmark
        column = pd.array(np.where(np.isnan(values), pd.NA, ok), dtype="boolean")
        result[f"pass_{row.metric}"] = column
        passes.append(f"pass_{row.metric}")
    if passes:
        passed = result[passes].fillna(True).all(axis=1) & result[passes].notna().any(axis=1)
        result["passed"] = passed.astype(bool)
    else:
        result["passed"] = False
    return result


def band_position(value: float, low: float, high: float, better: str) -> str:
    """Where ``value`` lies against a reference band [low, high] (e.g. the experts' quartiles), by direction.

    "within" inside the band (ends included); outside it, "better" on the side the metric's
    direction favours (``better`` is "lower" or "higher") and "worse" on the other.
    """
    if better not in ("lower", "higher"):
        raise MetricsError(f"better must be 'lower' or 'higher'; got {better!r}")
    if low > high:
        raise MetricsError(f"band runs from {low} to {high}: its low end is above its high end")
    if low <= value <= high:
        return "within"
    above = value > high
    return "better" if above == (better == "higher") else "worse"


def trials_to_proficiency(passed: Sequence[bool], consecutive: int = 2) -> int | None:
    """1-based trial at which the ``consecutive``-th pass in a row happened, or None."""
    if consecutive < 1:
        raise MetricsError(f"consecutive must be at least 1; got {consecutive}")
    run = 0
    for index, ok in enumerate(passed, start=1):
        run = run + 1 if ok else 0
        if run >= consecutive:
            return index
    return None
