"""A whole study's analysis: construct validity, benchmarks, proficiency, learning curves, retention,
reliability and standard setting (:mod:`metrics.study.evidence`).

Input is the per-session metrics table (``compute_session_metrics``) with the
columns ``participant_id``, a group label, ``trial`` (1-based order of a
participant's sessions) and optionally ``phase`` (``"practice"`` or ``"retention"``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY
from metrics.study.concurrent import ConcurrentValidityResult, concurrent_validity
from metrics.study.evidence import Reliability, StandardSetting, reliability_evidence, standard_setting
from metrics.study.learning import cusum, fit_learning_curve, retention
from metrics.study.proficiency import assess_proficiency, proficiency_benchmarks
from metrics.study.standards import non_compensatory_passes, progression_reached
from metrics.study.validity import ConstructValidityResult, construct_validity

RATING_COLUMNS = ("grs_total", "osats_total")
"""Rating totals the catalog adds to a study's table (sessions.running.runner): concurrent validity uses the
first present when the analysis declares no rating column."""


@dataclass(frozen=True)
class StudySettings:
    """How a study is analysed; every choice here is printed in the report."""

    group_col: str = "label"
    groups: tuple[str, str] = ("expert", "trainee")
    skilled_group: str = "expert"
    cluster_col: str = "participant_id"
    level: str = "participant"
    metrics: tuple[str, ...] | None = None  # metrics validated (default: every metric with values)
    benchmark_rule: str = "mean"
    benchmark_metrics: tuple[str, ...] | None = None  # default: the discriminating metrics
    # a declared benchmark metric whose AUC interval includes 0.5 is kept only with a reason (logged)
    benchmark_override: str = ""
    min_experts: int = 5  # fewer experts behind a mark: the standard is provisional (MScore-style)
    consecutive_passes: int = 2
    progression_window: int | None = None  # N of the last M sessions (M); None: N in a row
    non_compensatory: bool = False  # safety events (metrics.study.standards.SAFETY_METRICS) fail a session
    retention_baseline: int = (
        2  # retention: the last delayed session against the mean of this many last practice ones
    )
    # construct validity compares the skilled group with the other group's first N practice sessions
    # (their baseline, before practice changed them); None: every practice session of both
    baseline_trials: int | None = None
    rating_col: str | None = None  # a continuous rating for concurrent validity (e.g. "grs_total")
    task: str | None = None  # the task whose sessions are analysed (None: the study's only task)
    learning_model: str = "power"
    cusum_p0: float = 0.2
    cusum_p1: float = 0.5
    alpha: float = 0.05
    n_boot: int = 2000
    seed: int = 0


@dataclass
class StudyAnalysis:
    settings: StudySettings
    sessions: pd.DataFrame
    validity: ConstructValidityResult
    benchmarks: pd.DataFrame
    proficiency: pd.DataFrame  # per session: pass_<metric>, passed
    trainees: pd.DataFrame  # per trainee: status, trials to proficiency, retention, CUSUM
    learning_curves: pd.DataFrame  # per trainee and benchmark metric
    synthetic: bool = False
    notes: list[str] = field(default_factory=list)
    concurrent: ConcurrentValidityResult | None = None
    reliability: Reliability | None = None
    standards: StandardSetting | None = None
    # participants of the study who are not in this analysis, and why (code, group, reason): filled by
    # the catalog's analysis (sessions.scoring.analysis), so every report accounts for every participant
    left_out: list[dict] = field(default_factory=list)
    # the stored standard judged against ("standard v2, set 2026-12-05 from 4 experts (12 sessions)");
    # "" when the marks were computed from this table (candidates)
    standard_label: str = ""
    # each standard version a session's verdict was given under: version -> (label, its marks); the
    # proficiency table's ``standard_version`` says which (sessions.scoring.verdicts); empty for candidates
    judged_under: dict[int, tuple[str, pd.DataFrame]] = field(default_factory=dict)
    # the standard's marks that today's experts would move beyond their interval at setting
    # (metrics.study.proficiency.mark_drift entries); empty when none would, or for candidates
    standard_drift: list[dict] = field(default_factory=list)


def practice_mask(table: pd.DataFrame) -> pd.Series:
    """True for practice sessions (rows without a ``phase`` column all count as practice)."""
    if "phase" not in table.columns:
        return pd.Series(True, index=table.index)
    return table["phase"].fillna("practice") != "retention"


def validity_mask(table: pd.DataFrame, practice: pd.Series, settings: StudySettings) -> pd.Series:
    """The sessions construct validity compares: every practice session, or, with
    ``settings.baseline_trials`` N, the skilled group's practice sessions and each other participant's
    first N (in trial order; ``table`` sorted by participant and trial)."""
    if settings.baseline_trials is None:
        return practice
    order = table[practice].groupby(settings.cluster_col, sort=False).cumcount()
    early = pd.Series(False, index=table.index)
    early[order.index] = order < settings.baseline_trials
    skilled = table[settings.group_col] == settings.skilled_group
    return practice & (skilled | early)


def sessions_of_task(table: pd.DataFrame, task: str | None) -> pd.DataFrame:
    """The table's sessions of ``task``: trials count per task, so one analysis never mixes tasks. A
    table of several tasks needs one named; one without a ``task`` column is taken as it is."""
    if "task" not in table.columns:
        return table
    tasks = sorted(map(str, pd.unique(table["task"])))
    if task is None:
        if len(tasks) > 1:
            raise MetricsError(
                f"the study has sessions of {len(tasks)} tasks ({', '.join(tasks)}); analyse one at a time "
                "(choose the analysis's task)",
                remedy=("choose-task", ", ".join(tasks)),
            )
        return table
    if task not in tasks:
        raise MetricsError(f"the study has no scored session of task {task!r}; its tasks: {', '.join(tasks)}")
    return table[table["task"] == task].reset_index(drop=True)


def benchmark_choice(
    validity: ConstructValidityResult, settings: StudySettings
) -> tuple[list[str], list[str]]:
    """The metrics a study benchmarks, and notes on any refused: the declared benchmark metrics or else
    the discriminating ones, each kept only where the skilled group does better (oriented AUC > 0.5)
    and its participant-level AUC interval excludes 0.5 (or, for declared metrics, the analysis gives
    ``benchmark_override``, a reason that is printed). A mark on a metric where trainees do as well or
    better would pass them for it: no standard rather than a wrong one."""
    table = validity.table.set_index("metric")
    candidates = list(settings.benchmark_metrics or validity.discriminating())
    chosen, refused, notes = [], [], []
    for name in candidates:
        if name not in table.index:
            refused.append(f"{name} (not analysed)")
            continue
        auc, low = float(table.at[name, "auc"]), float(table.at[name, "auc_ci_low"])
        if not auc > 0.5:
            refused.append(f"{name} (experts do not do better: AUC {auc:.2f})")
        elif low > 0.5:
            chosen.append(name)
        elif settings.benchmark_metrics and settings.benchmark_override:
            chosen.append(name)
            shown = "no interval" if math.isnan(low) else f"interval from {low:.2f}"
            notes.append(
                f"{name} is benchmarked though its AUC {shown} includes 0.5: {settings.benchmark_override}"
            )
        else:
            shown = "no interval (too few participants)" if math.isnan(low) else f"interval from {low:.2f}"
            refused.append(f"{name} (AUC {auc:.2f}, {shown}: it may not separate the groups)")
    if refused:
        notes.append("Not benchmarked: " + "; ".join(refused) + ".")
    if not chosen:
        notes.append(
            "No standard: no analysed metric shows the experts doing better with an AUC interval above 0.5, "
            "so no session can pass; gather more expert and trainee sessions, or declare benchmark "
            "metrics with a reason (benchmark_override)."
        )
    return chosen, notes


def session_judge(settings: StudySettings) -> Callable[[pd.DataFrame, pd.DataFrame], pd.DataFrame]:
    """How a session is judged against the benchmarks: every benchmarked metric (compensation
    impossible either way), plus, in non-compensatory mode, no safety event."""
    return non_compensatory_passes if settings.non_compensatory else assess_proficiency


def analyse_study(
    table: pd.DataFrame,
    settings: StudySettings | None = None,
    ratings: pd.DataFrame | None = None,
    benchmarks: pd.DataFrame | None = None,
) -> StudyAnalysis:
    """Everything the study report shows, from one table of per-session metrics (and the study's
    ratings, long: session_id, rater, instrument, item, score). ``benchmarks``: a standard's marks as
    they were set (columns of :func:`metrics.study.proficiency.proficiency_benchmarks`), used as they are
    instead of marks computed from this table."""
    settings = settings or StudySettings()
    if settings.progression_window is not None and settings.progression_window < settings.consecutive_passes:
        raise MetricsError(
            f"progression window {settings.progression_window} is shorter than the "
            f"{settings.consecutive_passes} passes it must hold"
        )
    if "trial" not in table.columns:
        raise MetricsError(
            "the sessions table needs a 'trial' column (1-based order of each participant's sessions)"
        )
    table = sessions_of_task(table, settings.task)
    table = table.sort_values([settings.cluster_col, "trial"], kind="stable").reset_index(drop=True)
    practice = practice_mask(table)
    validity = construct_validity(
        table[validity_mask(table, practice, settings)],
        settings.group_col,
        settings.groups,
        settings.cluster_col,
        settings.level,
        metrics=list(settings.metrics) if settings.metrics else None,
        skilled_group=settings.skilled_group,
        alpha=settings.alpha,
        n_boot=settings.n_boot,
        seed=settings.seed,
    )
    if benchmarks is not None:  # a standard set earlier: its marks stand, whatever today's data say
        chosen, notes = [m for m in benchmarks["metric"] if m in table.columns], []
        benchmarks = benchmarks[benchmarks["metric"].isin(chosen)].reset_index(drop=True)
    else:
        chosen, notes = benchmark_choice(validity, settings)
        benchmarks = proficiency_benchmarks(
            table[practice],
            chosen,
            settings.group_col,
            settings.skilled_group,
            settings.cluster_col,
            settings.benchmark_rule,
        )
    experts = int(benchmarks["experts"].min()) if not benchmarks.empty else 0
    benchmarks["provisional"] = experts < settings.min_experts
    if not benchmarks.empty and experts < settings.min_experts:
        notes.append(
            f"The benchmarks are provisional: {experts} expert(s) set them, fewer than the "
            f"{settings.min_experts} the rule asks for."
        )
    if settings.baseline_trials is not None:
        others = " and ".join(g for g in settings.groups if g != settings.skilled_group)
        notes.insert(
            0,
            f"Construct validity compares every {settings.skilled_group} practice session with each "
            f"{others} participant's first {settings.baseline_trials} practice session(s): their baseline, "
            "before practice changed them.",
        )
    judge = session_judge(settings)
    proficiency = judge(table, benchmarks)
    proficiency.insert(0, "session_id", table["session_id"])
    trainees, curves = _per_trainee(table, practice, proficiency, benchmarks, settings)
    synthetic = (
        bool(table["synthetic"].fillna(False).astype(bool).any()) if "synthetic" in table.columns else False
    )
    concurrent = None
    rating_col = settings.rating_col
    if rating_col is None:  # ratings in the table (the catalog's GRS/OSATS totals): use them, and say so
        found = [c for c in RATING_COLUMNS if c in table.columns and table.loc[practice, c].notna().any()]
        if found:
            rating_col = found[0]
            notes.append(
                f"Concurrent validity against '{rating_col}' (each session's total, mean over its raters), "
                "the study's ratings; no rating column was declared."
            )
    if rating_col is not None:
        if rating_col not in table.columns or table[rating_col].notna().sum() == 0:
            notes.append(f"No concurrent validity: no session has a value in '{rating_col}'.")
        else:
            concurrent = concurrent_validity(
                table[practice],
                rating_col,
                settings.cluster_col,
                validity.table["metric"].tolist(),
                settings.alpha,
                settings.n_boot,
                settings.seed,
            )
    in_practice = table[practice]
    if ratings is not None and "session_id" in ratings.columns:
        ratings = ratings[ratings["session_id"].isin(set(table["session_id"]))]
    reliability = reliability_evidence(
        in_practice, validity.table["metric"].tolist(), chosen, settings.cluster_col, ratings
    )
    standards = (
        None
        if benchmarks.empty
        else standard_setting(
            in_practice,
            chosen,
            settings.benchmark_rule,
            settings.group_col,
            settings.skilled_group,
            settings.cluster_col,
            settings.consecutive_passes,
            settings.progression_window,
            judge,
        )
    )
    return StudyAnalysis(
        settings,
        table,
        validity,
        benchmarks,
        proficiency,
        trainees,
        curves,
        synthetic,
        notes,
        concurrent,
        reliability,
        standards,
    )


def with_verdicts(analysis: StudyAnalysis, proficiency: pd.DataFrame) -> StudyAnalysis:
    """``analysis`` with its per-session judgements replaced by ``proficiency`` (the same rows: the
    verdicts each session keeps, :mod:`sessions.scoring.verdicts`), and the trainees' passes, proficiency,
    retention and CUSUM derived again from them."""
    if not proficiency["session_id"].equals(analysis.proficiency["session_id"]):
        raise MetricsError("verdicts must be given for the analysis' sessions, in its order")
    table = analysis.sessions
    trainees, curves = _per_trainee(
        table, practice_mask(table), proficiency, analysis.benchmarks, analysis.settings
    )
    return dataclasses.replace(analysis, proficiency=proficiency, trainees=trainees, learning_curves=curves)


def _per_trainee(table, practice, proficiency, benchmarks, settings):
    others = [g for g in settings.groups if g != settings.skilled_group]
    rows, curves = [], []
    for participant, rows_of in table[table[settings.group_col].isin(others)].groupby(settings.cluster_col):
        in_practice = rows_of[practice.loc[rows_of.index]]
        delayed = rows_of[~practice.loc[rows_of.index]]
        passed = proficiency.loc[in_practice.index, "passed"].to_numpy(dtype=bool)
        reached = progression_reached(passed, settings.consecutive_passes, settings.progression_window)
        chart = cusum(~passed, settings.cusum_p0, settings.cusum_p1)
        record = {
            "participant_id": participant,
            "group": rows_of[settings.group_col].iloc[0],
            "practice_sessions": len(in_practice),
            "passes": int(passed.sum()),
            "proficient": reached is not None,
            "trials_to_proficiency": reached,
            "cusum_final": float(chart.values[-1]) if chart.values.size else math.nan,
            "cusum_competent_at": chart.competent_at,
        }
        if not delayed.empty:
            retained = bool(proficiency.loc[delayed.index[-1], "passed"])
            record["retention_passed"] = retained
            changes = []
            for bench in benchmarks.itertuples():
                later = float(delayed[bench.metric].iloc[-1])
                if math.isnan(later) or in_practice[bench.metric].isna().all():
                    record[f"retention_change_{bench.metric}"] = math.nan  # not measured: no change known
                    continue
                kept = retention(in_practice[bench.metric], later, bench.better, settings.retention_baseline)
                changes.append(kept.worse)
                record[f"retention_change_{bench.metric}"] = kept.change
            record["retention_worse_metrics"] = int(np.sum(changes))
        rows.append(record)
        for bench in benchmarks.itertuples():
            values = in_practice[bench.metric].to_numpy(dtype=np.float64)
            trials = in_practice["trial"].to_numpy(dtype=np.float64)
            try:
                metric = REGISTRY[bench.metric]
                curve = fit_learning_curve(
                    values, trials, settings.learning_model, bench.benchmark, metric.better, metric.bounds
                )
            except MetricsError:
                continue
            curves.append(
                {
                    "participant_id": participant,
                    "metric": bench.metric,
                    "model": curve.model,
                    "plateau": curve.plateau,
                    "plateau_determined": curve.plateau_determined,
                    "amplitude": curve.amplitude,
                    "rate": curve.rate,
                    "r_squared": curve.r_squared,
                    "benchmark": bench.benchmark,
                    "first_observed_at_benchmark": curve.first_observed_at_benchmark,
                    "first_predicted_at_benchmark": curve.first_predicted_at_benchmark,
                }
            )
    trainees = pd.DataFrame(rows)
    curves = pd.DataFrame(curves)
    whole = [
        (trainees, ("trials_to_proficiency", "cusum_competent_at")),
        (curves, ("first_observed_at_benchmark", "first_predicted_at_benchmark")),
    ]
    for frame, columns in whole:  # whole trials, never "6.0"
        for column in columns:
            if column in frame.columns:
                frame[column] = pd.array(frame[column], dtype="Int64")
    return trainees, curves


def metric_unit(name: str) -> str:
    return REGISTRY[name].unit if name in REGISTRY else ""


def oriented(values: Sequence[float], metric: str) -> np.ndarray:
    """Values signed so that higher is better (for ROC curves and composites)."""
    sign = REGISTRY[metric].sign if metric in REGISTRY else 1
    return sign * np.asarray(values, dtype=np.float64)
