"""Construct validity, composite score, proficiency and learning curves on constructed cohorts."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from metrics import MetricsError
from metrics.study.learning import cusum, fit_learning_curve, retention
from metrics.study.proficiency import assess_proficiency, proficiency_benchmarks, trials_to_proficiency
from metrics.study.validity import construct_validity


def cohort(n_experts=6, n_trainees=8, sessions=4, seed=0):
    """Experts faster and smoother; path length unrelated to skill."""
    rng = np.random.default_rng(seed)
    rows = []
    for group, count, time_mean in (("expert", n_experts, 60.0), ("trainee", n_trainees, 90.0)):
        for p in range(count):
            person_time = rng.normal(time_mean, 5)
            for s in range(sessions):
                rows.append(
                    {
                        "session_id": f"{group}{p}-{s}",
                        "participant_id": f"{group}{p}",
                        "label": group,
                        "task_time": person_time + rng.normal(0, 3),
                        "spectral_arc_length": (-2.0 if group == "expert" else -2.6) + rng.normal(0, 0.1),
                        "path_length": rng.normal(0.3, 0.05),
                    }
                )
    return pd.DataFrame(rows)


def test_participant_level_is_the_default_and_uses_participant_medians():
    table = cohort()
    result = construct_validity(table, "label", ("expert", "trainee"), "participant_id")
    assert result.level == "participant"
    row = result.table.set_index("metric").loc["task_time"]
    medians = table.groupby("participant_id").agg(label=("label", "first"), task_time=("task_time", "median"))
    x = medians.loc[medians.label == "expert", "task_time"]
    y = medians.loc[medians.label == "trainee", "task_time"]
    assert row["n_expert"] == 6 and row["n_trainee"] == 8
    assert row["median_expert"] == pytest.approx(np.median(x))
    assert row["p_value"] == pytest.approx(stats.mannwhitneyu(x, y, method="exact").pvalue)
    assert row["p_method"] == "exact"
    assert row["auc"] == pytest.approx(1.0)  # every expert faster: oriented, P(expert does better)
    assert row["auc_raw"] == pytest.approx(0.0)  # P(expert time > trainee time)
    assert row["direction"] == "lower in expert" and row["as_expected"]
    assert set(result.discriminating()) == {"task_time", "spectral_arc_length"}
    assert "participant level" in result.notes[0]


def test_holm_correction_across_metrics():
    result = construct_validity(cohort(), "label", ("expert", "trainee"))
    p = result.table["p_value"].to_numpy()
    order = np.argsort(p)
    m = len(p)
    expected = np.maximum.accumulate(np.minimum(1, (m - np.arange(m)) * p[order]))
    np.testing.assert_allclose(result.table["p_holm"].to_numpy()[order], expected)


def test_swapping_groups_flips_direction_and_auc():
    table = cohort()
    a = construct_validity(table, "label", ("expert", "trainee"), n_boot=200).table.set_index("metric")
    b = construct_validity(table, "label", ("trainee", "expert"), n_boot=200).table.set_index("metric")
    np.testing.assert_allclose(a["auc"], 1 - b["auc"])
    np.testing.assert_allclose(a["p_value"], b["p_value"])
    assert a.loc["task_time", "direction"] == "lower in expert"
    assert b.loc["task_time", "direction"] == "higher in trainee"


def test_trial_level_only_on_request_and_says_so():
    result = construct_validity(cohort(), "label", ("expert", "trainee"), level="trial", n_boot=200)
    row = result.table.set_index("metric").loc["task_time"]
    assert row["n_expert"] == 24 and row["p_method"] == "exact"
    assert "overstate" in result.notes[0]


def test_few_participants_are_reported_as_little_power():
    result = construct_validity(cohort(3, 3), "label", ("expert", "trainee"), n_boot=200)
    assert any("Little power" in note for note in result.notes)
    assert result.discriminating() == []
    assert result.table["p_value"].min() == pytest.approx(0.1)  # the floor with 3 vs 3


def test_composite_score_validated_leave_one_participant_out():
    result = construct_validity(cohort(), "label", ("expert", "trainee"), n_boot=500)
    composite = result.composite
    assert composite.folds == 14
    assert composite.auc == pytest.approx(1.0)  # perfectly separated participants stay separated out of fold
    assert composite.weights["task_time"] < -0.9 and composite.weights["spectral_arc_length"] > 0.9
    assert abs(composite.weights["path_length"]) < 0.7


def test_rating_disagreeing_with_self_report_is_a_separate_label():
    table = cohort()
    table["grs_group"] = np.where(table["participant_id"].isin(["expert0", "trainee0"]), "low", "high")
    table.loc[table.label == "trainee", "grs_group"] = np.where(
        table.loc[table.label == "trainee", "participant_id"] == "trainee0", "high", "low"
    )
    result = construct_validity(table, "grs_group", ("high", "low"), n_boot=200)
    assert result.group_col == "grs_group"
    assert result.n_participants == {"high": 6, "low": 8}


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"groups": ("expert", "novice")}, "'novice' not found"),
        ({"groups": ("expert",)}, "two different groups"),
        ({"level": "session"}, "level must be"),
        ({"group_col": "nope"}, "no column 'nope'"),
    ],
)
def test_bad_arguments_name_the_problem(kwargs, message):
    arguments = {"group_col": "label", "groups": ("expert", "trainee")} | kwargs
    with pytest.raises(MetricsError, match=message):
        construct_validity(cohort(), **arguments)


def test_mixed_labels_within_a_participant_need_trial_level():
    table = cohort()
    table.loc[0, "label"] = "trainee"
    with pytest.raises(MetricsError, match="level='trial'"):
        construct_validity(table, "label", ("expert", "trainee"))


def test_benchmarks_and_pass_fail():
    table = cohort()
    benchmarks = proficiency_benchmarks(table, ["task_time", "spectral_arc_length"], rule="mean")
    experts = table[table.label == "expert"].groupby("participant_id")["task_time"].median()
    row = benchmarks.set_index("metric").loc["task_time"]
    assert row["benchmark"] == pytest.approx(experts.mean()) and row["better"] == "lower"
    assessed = assess_proficiency(table, benchmarks)
    expected = (table["task_time"] <= row["benchmark"]) & (
        table["spectral_arc_length"] >= benchmarks.set_index("metric").loc["spectral_arc_length", "benchmark"]
    )
    pd.testing.assert_series_equal(assessed["passed"], expected, check_names=False)
    percentile = proficiency_benchmarks(table, ["task_time"], rule="percentile:80")
    assert percentile["benchmark"][0] == pytest.approx(np.quantile(experts, 0.8))
    with pytest.raises(MetricsError, match="rule"):
        proficiency_benchmarks(table, ["task_time"], rule="best")


def test_consecutive_pass_criterion():
    assert trials_to_proficiency([False, True, False, True, True, True]) == 5
    assert trials_to_proficiency([True, False, True], consecutive=2) is None
    assert trials_to_proficiency([True], consecutive=1) == 1


@pytest.mark.parametrize("model", ["power", "exponential"])
def test_learning_curve_recovers_known_parameters(model):
    n = np.arange(1, 11, dtype=float)
    plateau, amplitude, rate = 60.0, 50.0, 0.7
    values = plateau + amplitude * (n**-rate if model == "power" else np.exp(-rate * (n - 1)))
    curve = fit_learning_curve(values, model=model, benchmark=70.0)
    assert curve.plateau == pytest.approx(plateau, rel=1e-4)
    assert curve.rate == pytest.approx(rate, rel=1e-4)
    reach = (10 / 50) ** (-1 / rate) if model == "power" else 1 - math.log(10 / 50) / rate
    assert curve.first_predicted_at_benchmark == math.ceil(reach)  # a whole trial, never 4.71
    assert curve.first_observed_at_benchmark == int(np.argmax(values <= 70.0)) + 1
    assert curve.plateau_determined
    never = fit_learning_curve(values, model=model, benchmark=55.0)
    assert never.first_predicted_at_benchmark is None and never.first_observed_at_benchmark is None


def test_retention_and_cusum_hand_worked():
    kept = retention([100, 80, 70, 66, 64], delayed=75, better="lower")
    assert kept.end_of_practice == pytest.approx(65) and kept.change == pytest.approx(10) and kept.worse
    # p0 = 0.1, p1 = 0.3: P = ln 3, Q = ln(9/7), s = Q / (P + Q) = 0.18617
    result = cusum([True] + [False] * 20, p0=0.1, p1=0.3, alpha=0.1, beta=0.1)
    big_p, big_q = math.log(3), math.log(9 / 7)
    s = big_q / (big_p + big_q)
    assert result.s == pytest.approx(s)
    assert result.h0 == pytest.approx(math.log(9) / (big_p + big_q))
    expected = np.cumsum([1 - s] + [-s] * 20)
    np.testing.assert_allclose(result.values, expected)
    # 0.8138 - k * 0.18617 <= -1.6277 first at k = 14 successes, i.e. trial 15
    assert result.competent_at == 15 and result.unacceptable_at is None
    with pytest.raises(MetricsError):
        cusum([True], p0=0.3, p1=0.1)
