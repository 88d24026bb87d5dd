"""Standard setting: pass-mark rules, contrasting groups, out-of-sample misclassification, the
Luursema sensitivity and MScore-style non-compensatory progression, on hand-worked cases."""

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from statsmodels.stats.proportion import proportion_confint

from metrics.errors import MetricsError
from metrics.study.proficiency import check_rule, proficiency_benchmarks, rule_value
from metrics.study.standards import (
    leave_one_expert_out,
    misclassification,
    non_compensatory_passes,
    progression_reached,
    rule_comparison,
)
from metrics.study.statistics import contrasting_groups_mark, wilson_interval


def test_contrasting_groups_crosses_where_the_two_normal_fits_meet():
    """Skilled 1, 2, 3 (mean 2, SD 1) and unskilled 4, 6, 8 (mean 6, SD 2): by hand,
    4 (x - 2)^2 = (x - 6)^2 + 8 ln 2, so 3x^2 - 4x - (20 + 8 ln 2) = 0 and x = 3.660."""
    mark = contrasting_groups_mark([1, 2, 3], [4, 6, 8])
    assert mark == pytest.approx((4 + math.sqrt(16 + 12 * (20 + 8 * math.log(2)))) / 6, rel=1e-12)
    assert stats.norm.pdf(mark, 2, 1) == pytest.approx(stats.norm.pdf(mark, 6, 2), rel=1e-9)  # scipy
    assert contrasting_groups_mark([1, 3], [5, 7]) == 4.0  # equal spreads: the midpoint
    assert math.isnan(contrasting_groups_mark([1.0], [5, 7]))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-50, 50), min_size=2, max_size=8),
    st.lists(st.floats(-50, 50), min_size=2, max_size=8),
)
def test_a_contrasting_mark_lies_between_the_group_means(skilled, unskilled):
    mark = contrasting_groups_mark(skilled, unskilled)
    low, high = sorted((np.mean(skilled), np.mean(unskilled)))
    if np.mean(skilled) == np.mean(unskilled):
        assert math.isnan(mark)
    else:
        assert low - 1e-9 <= mark <= high + 1e-9


def test_the_expert_rules_by_hand_and_against_scipy():
    values = np.array([10.0, 12.0, 14.0, 16.0, 40.0])
    sd = float(np.std(values, ddof=1))
    assert rule_value(values, "mean+sd:2", "lower") == pytest.approx(values.mean() + 2 * sd)
    assert rule_value(values, "mean+sd:2", "higher") == pytest.approx(values.mean() - 2 * sd)
    assert rule_value(values, "trimmed:20", "lower") == pytest.approx(stats.trim_mean(values, 0.2))
    assert rule_value(values, "trimmed:20", "lower") == pytest.approx(14.0)  # 12, 14, 16
    assert rule_value(values, "contrasting", "lower", np.array([50.0, 60.0, 70.0])) == pytest.approx(
        contrasting_groups_mark(values, [50.0, 60.0, 70.0])
    )
    for bad in ("trimmed:60", "mean+sd:x", "percentile:0", "best"):
        with pytest.raises(MetricsError, match="rule"):
            check_rule(bad)


def test_wilson_interval_equals_statsmodels():
    for successes, total in ((0, 4), (2, 4), (4, 4), (7, 23)):
        assert wilson_interval(successes, total) == pytest.approx(
            proportion_confint(successes, total, method="wilson"), abs=1e-12
        )


def cohort(skilled, unskilled, metric="task_time"):
    rows = [
        {"participant_id": f"E{k}", "label": "expert", "trial": 1, metric: v} for k, v in enumerate(skilled)
    ]
    rows += [
        {"participant_id": f"T{k}", "label": "trainee", "trial": 1, metric: v}
        for k, v in enumerate(unskilled)
    ]
    return pd.DataFrame(rows)


def test_misclassification_judges_each_participant_by_a_mark_set_without_them():
    """task_time (lower is better), experts 1 2 3 4, trainees 3.5 5 6 7, rule "mean". Left out in
    turn, each expert faces the mean of the other three: 3, 2.67, 2.33, 2 -> experts 3 and 4 fail
    (false-fail 2/4); no trainee reaches 2.5 (false-pass 0/4)."""
    table = cohort([1, 2, 3, 4], [3.5, 5, 6, 7])
    result = misclassification(
        table[table.label == "expert"], table[table.label == "trainee"], "task_time", "mean"
    )
    assert result.mark == 2.5
    assert result.false_fail == 0.5 and result.false_pass == 0.0
    assert result.false_fail_ci == pytest.approx(wilson_interval(2, 4))
    # contrasting groups: the mark moves with the trainees too; each trainee is judged without them
    contrasting = misclassification(
        table[table.label == "expert"], table[table.label == "trainee"], "task_time", "contrasting"
    )
    assert 2.5 < contrasting.mark < 5.4 and contrasting.unskilled == 4 and contrasting.skilled == 4


def test_progression_in_a_row_or_n_of_the_last_m():
    history = [True, False, True, False, True, True]
    assert progression_reached(history, 2) == 6  # two in a row
    assert progression_reached(history, 2, window=3) == 3  # two of the last three
    assert progression_reached(history, 3, window=4) == 6  # sessions 3-6: T F T T
    assert progression_reached([False, True], 2) is None
    with pytest.raises(MetricsError, match="N of the last M"):
        progression_reached(history, 4, window=3)


def test_a_never_event_fails_a_session_that_passes_every_metric():
    """Non-compensatory mode: the second session is faster than the benchmark yet caught the back
    wall; it fails outright. A missing safety count fails nothing."""
    table = pd.DataFrame(
        {
            "task_time": [10.0, 9.0, 30.0, 8.0],
            "back_wall_catches": [0.0, 1.0, 0.0, np.nan],
            "force_clamp_hits": [0.0, 0.0, 0.0, 0.0],
        }
    )
    benchmarks = pd.DataFrame([{"metric": "task_time", "benchmark": 12.0, "better": "lower"}])
    judged = non_compensatory_passes(table, benchmarks)
    assert judged["pass_task_time"].tolist() == [True, True, False, True]
    assert judged["safe"].tolist() == [True, False, True, True]
    assert judged["passed"].tolist() == [True, False, False, True]


def practice_cohort():
    """Three experts (task_time medians 10, 11, 20) and two trainees over four sessions."""
    rows = []
    for name, times in (("E1", [10, 10]), ("E2", [11, 11]), ("E3", [20, 20])):
        rows += [
            {"participant_id": name, "label": "expert", "trial": k + 1, "task_time": t}
            for k, t in enumerate(times)
        ]
    for name, times in (("T1", [30, 14, 13.5, 13]), ("T2", [30, 25, 12, 12])):
        rows += [
            {"participant_id": name, "label": "trainee", "trial": k + 1, "task_time": t}
            for k, t in enumerate(times)
        ]
    return pd.DataFrame(rows)


def test_leaving_one_expert_out_shows_how_far_one_expert_moves_progression():
    """Mean of 10, 11, 20 = 13.67: T1 passes at 3 and 4 (proficient at 4), T2 at 3 and 4 (at 4).
    Without E3 the mark is 10.5: neither is proficient (2 change). Without E1: 15.5, T1 passes
    from session 2 (proficient at 3: shift 1), T2 at 4. Without E2: 15, the same as without E1."""
    table = practice_cohort()
    assert proficiency_benchmarks(table, ["task_time"])["benchmark"].iloc[0] == pytest.approx(41 / 3)
    result = leave_one_expert_out(table, ["task_time"], "mean").set_index("left_out")
    assert result.loc["E3", "status_changed"] == 2 and result.loc["E3", "changed"] == "T1, T2"
    assert result.loc["E1", "status_changed"] == 0 and result.loc["E1", "largest_shift"] == 1
    assert result.loc["E2", "largest_shift"] == 1
    compared = rule_comparison(table, ["task_time"], ["mean", "median"]).set_index("rule")
    assert compared.loc["mean", "proficient"] == 2 and compared.loc["median", "proficient"] == 0  # 11
    with pytest.raises(MetricsError, match="at least 2 experts"):
        leave_one_expert_out(
            table[table.participant_id != "E1"][lambda t: t.participant_id != "E2"], ["task_time"], "mean"
        )


def test_a_participant_no_mark_can_be_set_for_is_not_counted_as_passing_or_failing():
    """Two experts: with one left out, contrasting groups has one expert value and no mark, so no
    expert is judged (rate n/a), not 0 % false fails."""
    table = cohort([1, 2], [5, 6, 7])
    result = misclassification(
        table[table.label == "expert"], table[table.label == "trainee"], "task_time", "contrasting"
    )
    assert result.skilled == 0 and math.isnan(result.false_fail)
    assert result.unskilled == 3 and result.false_pass == 0.0


def test_a_declared_non_compensatory_study_fails_sessions_with_never_events_and_counts_n_of_m():
    """analyse_study with non_compensatory: T1's third and fourth sessions beat the benchmark but the
    third caught the back wall, so T1 is not proficient by two in a row; with "2 of the last 3" T1
    is proficient at session 4 (sessions 2 and 4 pass)."""
    from metrics.study.analysis import StudySettings, analyse_study

    rows = []
    for name, times in (("E1", [10, 10]), ("E2", [11, 11]), ("E3", [12, 12])):
        for k, t in enumerate(times):
            rows.append({"participant_id": name, "label": "expert", "trial": k + 1, "task_time": t})
    for k, (t, caught) in enumerate([(30, 0), (10, 0), (10, 1), (10, 0)]):
        rows.append(
            {
                "participant_id": "T1",
                "label": "trainee",
                "trial": k + 1,
                "task_time": t,
                "back_wall_catches": caught,
            }
        )
    for k, t in enumerate([30, 25, 20, 18]):
        rows.append(
            {
                "participant_id": "T2",
                "label": "trainee",
                "trial": k + 1,
                "task_time": t,
                "back_wall_catches": 0,
            }
        )
    table = pd.DataFrame(rows).assign(session_id=lambda t: [f"s{k}" for k in range(len(t))])
    base = StudySettings(
        metrics=("task_time",),
        benchmark_metrics=("task_time",),
        benchmark_override="hand-worked case: three experts and two trainees give no AUC interval",
        n_boot=50,
    )
    compensatory = analyse_study(table, base)
    strict = analyse_study(table, dataclasses.replace(base, non_compensatory=True))
    windowed = analyse_study(table, dataclasses.replace(base, non_compensatory=True, progression_window=3))
    t1 = table.index[table.participant_id == "T1"]
    assert strict.proficiency.loc[t1, "passed"].tolist() == [False, True, False, True]
    assert compensatory.proficiency.loc[t1, "passed"].tolist() == [False, True, True, True]
    reached = {name: a.trainees.set_index("participant_id").loc["T1", "trials_to_proficiency"] for name, a in
               (("compensatory", compensatory), ("strict", strict), ("windowed", windowed))}  # fmt: skip
    assert reached["compensatory"] == 3 and pd.isna(reached["strict"]) and reached["windowed"] == 4
    with pytest.raises(MetricsError, match="progression window"):
        analyse_study(table, dataclasses.replace(base, progression_window=1))
