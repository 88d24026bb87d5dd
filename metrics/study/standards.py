"""Standard setting: where the pass mark goes, how often it misjudges, and how much it moves.

- the rules of :func:`metrics.study.proficiency.rule_value`, the contrasting-groups method among them
  (:func:`metrics.study.statistics.contrasting_groups_mark`).
- :func:`misclassification`: for every rule, the **false-pass rate** (unskilled who would
  pass) and the **false-fail rate** (skilled who would fail), each participant judged by a
  mark set without them (leave-one-participant-out), with Wilson 95 % intervals.
- :func:`leave_one_expert_out`: the Luursema effect (Luursema et al. 2015: a different set
  of experts moved LapSim graduation by 1.5 sessions): with each expert left out in turn,
  how many trainees change status and how far their trials-to-proficiency move.
- :func:`non_compensatory_passes`: MScore-style progression: a session passes only when
  every chosen metric passes and no safety ("never") event happened; proficiency needs N
  passes in a row, or N of the last M sessions.

Units are participants throughout: each contributes the median of the sessions the caller
passes (e.g. the experts' sessions and the trainees' first practice sessions).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY
from metrics.study.proficiency import (
    assess_proficiency,
    proficiency_benchmarks,
    rule_value,
    trials_to_proficiency,
)
from metrics.study.statistics import wilson_interval

SAFETY_METRICS = ("back_wall_catches", "wound_edge_tears", "force_clamp_hits")
"""Never events: a session with any of these above zero fails outright in non-compensatory mode
(a back-wall catch, a torn wound edge, a force beyond the device's rating)."""


def passes(value: float, mark: float, better: str) -> bool:
    """Whether ``value`` is on the better side of (or at) ``mark``."""
    return value <= mark if better == "lower" else value >= mark


def mark_of(rule: str, skilled: np.ndarray, unskilled: np.ndarray, better: str) -> float:
    """The pass mark of ``rule`` from the skilled group's values (and, for ``"contrasting"``, the
    unskilled group's): every rule of :func:`metrics.study.proficiency.rule_value` plus contrasting groups."""
    skilled = skilled[np.isfinite(skilled)]
    return rule_value(skilled, rule, better, unskilled[np.isfinite(unskilled)]) if skilled.size else math.nan


@dataclass(frozen=True)
class Misclassification:
    metric: str
    rule: str
    mark: float  # set from everyone
    false_pass: float  # share of unskilled who pass (each judged by a mark set without them)
    false_pass_ci: tuple[float, float]
    false_fail: float  # share of skilled who fail
    false_fail_ci: tuple[float, float]
    unskilled: int  # judged: those the others could set a mark for
    skilled: int


def participant_values(table: pd.DataFrame, metric: str, cluster_col: str = "participant_id") -> pd.Series:
    """Each participant's median of ``metric`` over the rows given."""
    return table.groupby(cluster_col)[metric].median().dropna()


def misclassification(
    skilled_table: pd.DataFrame,
    unskilled_table: pd.DataFrame,
    metric: str,
    rule: str,
    cluster_col: str = "participant_id",
) -> Misclassification:
    """False-pass and false-fail rates of ``rule`` on ``metric``, out of sample: each participant is
    judged against the mark set from everyone else (leave-one-participant-out)."""
    better = REGISTRY[metric].better
    skilled = participant_values(skilled_table, metric, cluster_col)
    unskilled = participant_values(unskilled_table, metric, cluster_col)
    a, b = skilled.to_numpy(dtype=np.float64), unskilled.to_numpy(dtype=np.float64)
    # a participant for whom the others cannot set a mark (e.g. one expert left for contrasting
    # groups) is not judged: the rate counts only those judged, and is nan when none were
    false_fails = judged_skilled = 0
    for k in range(len(a)):
        mark = mark_of(rule, np.delete(a, k), b, better)
        if math.isfinite(mark):
            judged_skilled += 1
            false_fails += int(not passes(a[k], mark, better))
    false_passes = judged_unskilled = 0
    for k in range(len(b)):
        mark = mark_of(rule, a, np.delete(b, k), better)
        if math.isfinite(mark):
            judged_unskilled += 1
            false_passes += int(passes(b[k], mark, better))
    return Misclassification(
        metric,
        rule,
        mark_of(rule, a, b, better),
        false_passes / judged_unskilled if judged_unskilled else math.nan,
        wilson_interval(false_passes, judged_unskilled),
        false_fails / judged_skilled if judged_skilled else math.nan,
        wilson_interval(false_fails, judged_skilled),
        judged_unskilled,
        judged_skilled,
    )


def misclassification_table(
    skilled_table: pd.DataFrame,
    unskilled_table: pd.DataFrame,
    metrics: Sequence[str],
    rules: Sequence[str],
    cluster_col: str = "participant_id",
) -> pd.DataFrame:
    """One row per metric and rule: the mark and its out-of-sample false-pass and false-fail rates."""
    rows = []
    for metric in metrics:
        for rule in rules:
            m = misclassification(skilled_table, unskilled_table, metric, rule, cluster_col)
            rows.append(
                {
                    "metric": metric,
                    "rule": rule,
                    "mark": m.mark,
                    "false_pass": m.false_pass,
                    "false_pass_low": m.false_pass_ci[0],
                    "false_pass_high": m.false_pass_ci[1],
                    "false_fail": m.false_fail,
                    "false_fail_low": m.false_fail_ci[0],
                    "false_fail_high": m.false_fail_ci[1],
                    "unskilled": m.unskilled,
                    "skilled": m.skilled,
                }
            )
    return pd.DataFrame(rows)


# -- progression -------------------------------------------------------------------------------
def progression_reached(passed: Sequence[bool], required: int, window: int | None = None) -> int | None:
    """1-based session at which progression is reached: ``required`` passes in a row (``window``
    None), or ``required`` passes among the last ``window`` sessions; None if never."""
    if window is None:
        return trials_to_proficiency(passed, required)
    if not 1 <= required <= window:
        raise MetricsError(f"N of the last M needs 1 <= N <= M; got N = {required}, M = {window}")
    flags = [bool(p) for p in passed]
    for index in range(1, len(flags) + 1):
        if sum(flags[max(0, index - window) : index]) >= required:
            return index
    return None


def non_compensatory_passes(
    table: pd.DataFrame, benchmarks: pd.DataFrame, safety_metrics: Sequence[str] = SAFETY_METRICS
) -> pd.DataFrame:
    """Per session: every benchmarked metric must pass (no metric makes up for another) and no
    safety event may have happened (``safety_<metric>`` False when its count is above zero; a
    session without the metric's value is not failed for it). Columns as
    :func:`metrics.study.proficiency.assess_proficiency`'s plus ``safe`` and ``passed`` (both)."""
    result = assess_proficiency(table, benchmarks)
    safe = pd.Series(True, index=table.index)
    for name in safety_metrics:
        if name in table.columns:
            counts = table[name].to_numpy(dtype=np.float64)
            ok = ~(np.nan_to_num(counts, nan=0.0) > 0)
            result[f"safety_{name}"] = ok
            safe &= ok
    result["safe"] = safe.to_numpy(dtype=bool)
    result["passed"] = result["passed"].to_numpy(dtype=bool) & result["safe"].to_numpy(dtype=bool)
    return result


# -- sensitivity -------------------------------------------------------------------------------
def trainee_progress(
    table: pd.DataFrame,
    benchmarks: pd.DataFrame,
    trainees: Sequence[str],
    required: int,
    window: int | None,
    cluster_col: str,
    judge: Callable[[pd.DataFrame, pd.DataFrame], pd.DataFrame] = assess_proficiency,
) -> dict[str, int | None]:
    """Per trainee: the practice session (1-based) at which progression is reached, or None."""
    judged = judge(table, benchmarks)
    reached = {}
    for trainee in trainees:
        rows = table.index[table[cluster_col] == trainee]
        order = table.loc[rows].sort_values("trial").index
        reached[trainee] = progression_reached(judged.loc[order, "passed"].tolist(), required, window)
    return reached


def leave_one_expert_out(
    practice: pd.DataFrame,
    metrics: Sequence[str],
    rule: str,
    group_col: str = "label",
    skilled_group: str = "expert",
    cluster_col: str = "participant_id",
    required: int = 2,
    window: int | None = None,
    judge: Callable[[pd.DataFrame, pd.DataFrame], pd.DataFrame] = assess_proficiency,
) -> pd.DataFrame:
    """With each expert left out of the benchmarks in turn: trainees whose status (proficient or not)
    changes against the benchmarks from every expert, and the largest shift (sessions) in
    trials-to-proficiency among trainees proficient both ways. One row per left-out expert."""
    experts = sorted(practice.loc[practice[group_col] == skilled_group, cluster_col].unique())
    trainees = sorted(practice.loc[practice[group_col] != skilled_group, cluster_col].unique())
    if len(experts) < 2:
        raise MetricsError("leaving one expert out needs at least 2 experts")
    full = proficiency_benchmarks(practice, metrics, group_col, skilled_group, cluster_col, rule)
    baseline = trainee_progress(practice, full, trainees, required, window, cluster_col, judge)
    rows = []
    for expert in experts:
        kept = practice[practice[cluster_col] != expert]
        benchmarks = proficiency_benchmarks(kept, metrics, group_col, skilled_group, cluster_col, rule)
        reached = trainee_progress(practice, benchmarks, trainees, required, window, cluster_col, judge)
        changed = [t for t in trainees if (reached[t] is None) != (baseline[t] is None)]
        shifts = [
            reached[t] - baseline[t] for t in trainees if reached[t] is not None and baseline[t] is not None
        ]
        rows.append(
            {
                "left_out": expert,
                "status_changed": len(changed),
                "trainees": len(trainees),
                "changed": ", ".join(changed),
                "largest_shift": max((abs(s) for s in shifts), default=0),
                "mean_shift": float(np.mean(shifts)) if shifts else 0.0,
            }
        )
    return pd.DataFrame(rows)


def rule_comparison(
    practice: pd.DataFrame,
    metrics: Sequence[str],
    rules: Sequence[str],
    group_col: str = "label",
    skilled_group: str = "expert",
    cluster_col: str = "participant_id",
    required: int = 2,
    window: int | None = None,
    judge: Callable[[pd.DataFrame, pd.DataFrame], pd.DataFrame] = assess_proficiency,
) -> pd.DataFrame:
    """Per rule: trainees who reach proficiency and their median trials-to-proficiency, so a change of
    rule shows what it does to the course."""
    trainees = sorted(practice.loc[practice[group_col] != skilled_group, cluster_col].unique())
    rows = []
    for rule in rules:
        benchmarks = proficiency_benchmarks(practice, metrics, group_col, skilled_group, cluster_col, rule)
        reached = trainee_progress(practice, benchmarks, trainees, required, window, cluster_col, judge)
        trials = [r for r in reached.values() if r is not None]
        rows.append(
            {
                "rule": rule,
                "proficient": len(trials),
                "trainees": len(trainees),
                "median_trials": float(np.median(trials)) if trials else math.nan,
            }
        )
    return pd.DataFrame(rows)
