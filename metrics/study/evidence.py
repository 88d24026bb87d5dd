"""The validity argument beyond construct validity, for one study: reliability and standard setting.

Computed by :func:`metrics.study.analysis.analyse_study` for every front-end (report, CLI, dashboard), so the
same question gets the same answer everywhere. See docs/validity.md for each strand's formula.

- :func:`reliability_evidence`: test-retest ICC(3,1) of every metric over each participant's
  last two practice sessions; Cronbach's alpha of the benchmarked metrics as one composite
  (participants' medians, z-scored and oriented so higher is better); inter-rater agreement
  per rating instrument when the study has ratings (ICC(2,1), ICC(2,k), Krippendorff's alpha).
- :func:`standard_setting`: for every candidate rule, each benchmarked metric's pass mark and
  its false-pass and false-fail rates out of sample; what leaving one expert out does to the
  trainees' progression; what each rule does to the course (proficient trainees, median trials).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY
from metrics.study.proficiency import pass_condition
from metrics.study.reliability import CronbachAlpha, cronbach_alpha, rater_agreement, test_retest
from metrics.study.standards import leave_one_expert_out, misclassification_table, rule_comparison

CANDIDATE_RULES = ("mean", "median", "percentile:75", "mean+sd:2", "trimmed:10", "contrasting")
"""The rules every study's standard setting compares (the declared rule is added when not here)."""
RETEST_OCCASIONS = 2


@dataclass
class Reliability:
    test_retest: pd.DataFrame  # metric, unit, participants, icc, ci_low, ci_high, reading
    internal_consistency: CronbachAlpha | None
    raters: dict[str, pd.DataFrame] = field(default_factory=dict)  # instrument -> rater_agreement()
    notes: list[str] = field(default_factory=list)


@dataclass
class StandardSetting:
    rules: tuple[str, ...]
    misclassification: pd.DataFrame  # metric, rule, mark, pass_if, false_pass(+ci), false_fail(+ci)
    leave_one_expert_out: pd.DataFrame | None
    rule_comparison: pd.DataFrame
    notes: list[str] = field(default_factory=list)


def percent_with_interval(rate: float, low: float, high: float) -> str:
    """ "25 % (5-70 %)": a rate as a person reads it, with its Wilson interval."""
    if not math.isfinite(rate):
        return "n/a"
    return f"{100 * rate:.0f} % ({100 * low:.0f}-{100 * high:.0f} %)"


def reliability_evidence(
    practice: pd.DataFrame,
    metrics: Sequence[str],
    benchmarked: Sequence[str],
    cluster_col: str,
    ratings: pd.DataFrame | None = None,
) -> Reliability:
    notes = []
    rows = []
    for name in metrics:
        icc, used = test_retest(practice, name, cluster_col, occasions=RETEST_OCCASIONS)
        row = {"metric": name, "unit": REGISTRY[name].unit if name in REGISTRY else "", "participants": used}
        if icc is None:
            row.update(icc=math.nan, ci_low=math.nan, ci_high=math.nan, reading="too few participants")
        else:
            row.update(icc=icc.value, ci_low=icc.ci_low, ci_high=icc.ci_high, reading=icc.band)
        rows.append(row)
    retest = pd.DataFrame(rows)
    notes.append(
        f"Test-retest: ICC(3,1) (two-way mixed, consistency) of each participant's last {RETEST_OCCASIONS} "
        "practice sessions; a practice effect shared by everyone does not lower it, participants who "
        "still improve at different rates do."
    )
    consistency = None
    if len(benchmarked) >= 2:
        medians = practice.groupby(cluster_col)[list(benchmarked)].median()
        oriented = pd.DataFrame(index=medians.index)
        for name in benchmarked:
            column = medians[name]
            spread = column.std(ddof=1)
            if spread and math.isfinite(spread):
                z = (column - column.mean()) / spread
                oriented[name] = -z if REGISTRY[name].better == "lower" else z
        try:
            if oriented.shape[1] >= 2:
                consistency = cronbach_alpha(oriented.to_numpy(dtype=np.float64))
        except MetricsError as error:
            notes.append(f"No internal consistency: {error}.")
    raters: dict[str, pd.DataFrame] = {}
    if ratings is not None and not ratings.empty:
        for name in sorted(ratings["instrument"].str.upper().unique()):
            try:
                raters[name] = rater_agreement(ratings, name)
            except MetricsError as error:
                notes.append(f"Ratings of {name} not analysed: {error}.")
        if not any((table["raters"] >= 2).any() for table in raters.values()):
            notes.append("Inter-rater reliability needs sessions rated by at least two raters; none are.")
    return Reliability(retest, consistency, raters, notes)


def standard_setting(
    practice: pd.DataFrame,
    benchmarked: Sequence[str],
    declared_rule: str,
    group_col: str,
    skilled_group: str,
    cluster_col: str,
    required: int,
    window: int | None,
    judge: Callable[[pd.DataFrame, pd.DataFrame], pd.DataFrame],
) -> StandardSetting:
    """Every candidate rule (and the declared one) on the benchmarked metrics; the unskilled group of
    the contrasting-groups method and of the false-pass rate is each trainee's first practice
    session, the skilled group the experts' practice sessions."""
    rules = tuple(dict.fromkeys((declared_rule, *CANDIDATE_RULES)))
    skilled = practice[practice[group_col] == skilled_group]
    others = practice[practice[group_col] != skilled_group]
    first = others.sort_values("trial", kind="stable").groupby(cluster_col).head(1)
    table = misclassification_table(skilled, first, benchmarked, rules, cluster_col)
    if not table.empty:
        table.insert(
            3,
            "pass_if",
            [
                pass_condition(mark, REGISTRY[metric].better, REGISTRY[metric].unit)
                for metric, mark in zip(table["metric"], table["mark"], strict=True)
            ],
        )
        for kind in ("false_pass", "false_fail"):
            table[f"{kind}_shown"] = [
                percent_with_interval(*values)
                for values in zip(table[kind], table[f"{kind}_low"], table[f"{kind}_high"], strict=True)
            ]
    notes = [
        "False pass: a trainee's first practice session passing the metric's mark; false fail: an expert "
        "failing it; each participant judged by a mark set without them (leave-one-participant-out); 95 % "
        "Wilson intervals. With few participants the intervals are wide: read them, not the point."
    ]
    experts = skilled[cluster_col].nunique()
    loo = None
    if experts >= 2 and benchmarked:
        loo = leave_one_expert_out(
            practice,
            benchmarked,
            declared_rule,
            group_col,
            skilled_group,
            cluster_col,
            required,
            window,
            judge,
        )
    else:
        notes.append("Leaving one expert out needs at least two experts.")
    compared = rule_comparison(
        practice, benchmarked, rules, group_col, skilled_group, cluster_col, required, window, judge
    )
    return StandardSetting(rules, table, loo, compared, notes)
