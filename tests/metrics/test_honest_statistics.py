"""Issue 20, "what was seen" 3-5: oriented AUC, intervals that do not collapse, cluster-aware flags,
power counted in participants, and the composite read against its own null distribution."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

from metrics.study.composite import fit_composite, validate_composite
from metrics.study.statistics import (
    auc_interval,
    cluster_permutation_test,
    interval_is_informative,
    mann_whitney,
    oriented_auc,
)
from metrics.study.validity import construct_validity


def _newcombe_by_root_finding(theta_hat: float, m: int, n: int) -> tuple[float, float]:
    """Independent evaluation of the same interval: SciPy's brentq on the squared score equation."""
    z = stats.norm.ppf(0.975)
    n_star = (m + n) / 2 - 1

    def variance(t):
        return t * (1 - t) / (m * n) * (1 + (n_star - 1) * ((1 - t) / (2 - t) + t / (1 + t)))

    def gap(t, sign):
        return sign * (theta_hat - t) - 0.5 / (m * n) - z * math.sqrt(variance(t))

    low = 0.0 if gap(1e-15, 1) <= 0 else optimize.brentq(gap, 1e-15, theta_hat - 1e-12, args=(1,), xtol=1e-14)
    high = (
        1.0
        if gap(1 - 1e-15, -1) <= 0
        else optimize.brentq(gap, theta_hat + 1e-12, 1 - 1e-15, args=(-1,), xtol=1e-14)
    )
    return low, high


@pytest.mark.parametrize(
    "theta_hat, m, n", [(1.0, 2, 4), (1.0, 6, 6), (0.5, 6, 6), (0.8, 10, 10), (0.1, 5, 9)]
)
def test_auc_interval_matches_an_independent_root_finder(theta_hat, m, n):
    np.testing.assert_allclose(
        auc_interval(theta_hat, m, n), _newcombe_by_root_finding(theta_hat, m, n), atol=1e-9
    )


def test_complete_separation_still_has_a_wide_interval():
    """Seen: mann_whitney([1,2],[3,4,5,6]) has p = 0.133 but the bootstrap CI was (0.0, 0.0)."""
    test = mann_whitney([1, 2], [3, 4, 5, 6])
    assert test.p_value == pytest.approx(2 / 15)
    low, high = auc_interval(test.auc, 2, 4)
    assert low == 0.0 and high > 0.5  # the interval reaches past chance, as p = 0.133 says it must
    assert not interval_is_informative(2, 4)  # and the design is too small to print one at all
    low, high = auc_interval(1.0, 6, 6)
    assert 0.6 < low < 0.8 and high == 1.0


def test_interval_coverage_at_six_and_ten_per_group():
    """Coverage of the 95 % interval by simulation (normal shifts; benchmarks/auc_coverage.py runs more)."""
    rng = np.random.default_rng(3)
    for n in (6, 10):
        for shift in (0.0, 1.0, 2.5):
            truth = stats.norm.cdf(shift / math.sqrt(2))
            hits = 0
            for _ in range(600):
                x, y = rng.normal(shift, 1, n), rng.normal(0, 1, n)
                low, high = auc_interval(mann_whitney(x, y).auc, n, n)
                hits += low <= truth <= high
            assert hits / 600 >= 0.91, (n, shift, hits / 600)  # 0.93 nominal floor minus simulation error


def test_auc_is_oriented_to_skill():
    """Seen: a lower-is-better metric the experts win on every pair showed AUC 0 beside a ROC of 1.00."""
    assert oriented_auc(0.0, skilled_first=True, higher_is_better=False) == 1.0
    assert oriented_auc(0.25, skilled_first=False, higher_is_better=True) == 0.75
    table = _cohort(6, 6, trials=1)
    result = construct_validity(table, "label", ("expert", "trainee"))
    row = result.table.set_index("metric").loc["task_time"]
    assert row["better"] == "lower" and row["auc"] == 1.0 and row["auc_raw"] == 0.0


def _cohort(experts: int, trainees: int, trials: int, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(experts + trainees):
        expert = k < experts
        level = rng.normal(0.0 if expert else 1.0, 0.3)
        for t in range(trials):
            rows.append(
                {
                    "participant_id": f"P{k}",
                    "label": "expert" if expert else "trainee",
                    "trial": t + 1,
                    "task_time": 30 + 20 * (level + rng.normal(0, 0.05)),
                    "spectral_arc_length": -2 - (level + rng.normal(0, 0.05)),
                }
            )
    return pd.DataFrame(rows)


def test_trial_level_needs_participants_to_agree():
    """Seen: 2 v 4 participants x 5 trials gave Holm p = 6.7e-8 and discriminates = True."""
    table = _cohort(2, 4, trials=5)
    result = construct_validity(table, "label", ("expert", "trainee"), level="trial")
    row = result.table.set_index("metric").loc["task_time"]
    assert row["p_value"] < 1e-6  # the pseudo-replicated row-level test
    assert row["p_cluster"] >= 1 / 15 - 1e-12  # labels permuted across the 6 participants: 15 relabellings
    assert not row["discriminates"] and result.discriminating() == []
    assert any("2 and 4 participants" in note and "0.133" in note for note in result.notes)


def test_cluster_permutation_matches_brute_force():
    rng = np.random.default_rng(5)
    values = rng.normal(size=21)
    clusters = np.repeat(np.arange(7), 3)
    first = clusters < 3
    test = cluster_permutation_test(values, first, clusters)
    from itertools import combinations

    observed = abs(stats.mannwhitneyu(values[first], values[~first]).statistic - 9 * 12 / 2)
    extreme = 0
    chosen_sets = list(combinations(range(7), 3))
    for chosen in chosen_sets:
        mask = np.isin(clusters, chosen)
        u = stats.mannwhitneyu(values[mask], values[~mask]).statistic
        extreme += abs(u - 9 * 12 / 2) >= observed - 1e-9
    assert test.method == "exact" and test.p_value == pytest.approx(extreme / len(chosen_sets))


def _slow_out_of_fold(frame, metrics, skilled_group="expert"):
    """The plain leave-one-participant-out loop over fit_composite: the reference."""
    skilled = (frame["label"] == skilled_group).to_numpy()
    out = np.full(len(frame), np.nan)
    for participant in pd.unique(frame["participant_id"]):
        test = (frame["participant_id"] == participant).to_numpy()
        if skilled[~test].any() and (~skilled[~test]).any():
            out[test] = fit_composite(frame.loc[~test], metrics, skilled[~test]).score(frame.loc[test])
    return pd.Series(out).groupby(frame["participant_id"].to_numpy(), sort=False).mean()


@pytest.mark.parametrize("trials", [1, 3])
def test_fast_leave_one_out_equals_the_plain_loop(trials):
    table = _cohort(4, 5, trials=trials, seed=2)
    table.loc[3, "task_time"] = np.nan  # a missing value stays out of every sum
    metrics = ["task_time", "spectral_arc_length"]
    result = validate_composite(table, metrics, "label", "expert", "participant_id")
    expected = _slow_out_of_fold(table, metrics)
    np.testing.assert_allclose(
        result.scores.set_index("participant")["score"].loc[expected.index], expected, atol=1e-9
    )


def test_composite_at_two_versus_three_reads_against_its_null():
    """Seen: "AUC 1.00 (1.00-1.00)" at 2 v 3 participants."""
    table = _cohort(2, 3, trials=2)
    result = validate_composite(
        table, ["task_time", "spectral_arc_length"], "label", "expert", "participant_id"
    )
    assert result.auc == 1.0
    assert all(math.isnan(v) for v in result.auc_ci)  # too small for an interval: none is printed
    assert result.permutations == 10  # every relabelling of 5 participants into 2 + 3
    assert result.null_p95 == 1.0 and result.null_p >= 0.1  # chance alone reaches 1.00 here


def test_the_roc_curves_and_the_table_give_the_same_auc():
    """Seen: tables showed 0, 0.042, 0.167 for lower-is-better metrics beside ROC curves of 1.00, 0.96."""
    from sklearn.metrics import roc_auc_score

    from metrics.study.analysis import oriented

    table = _cohort(5, 6, trials=2, seed=9)
    result = construct_validity(table, "label", ("expert", "trainee"))
    medians = table.groupby("participant_id").agg(
        label=("label", "first"),
        task_time=("task_time", "median"),
        spectral_arc_length=("spectral_arc_length", "median"),
    )
    skilled = (medians["label"] == "expert").to_numpy()
    for row in result.table.itertuples():
        area = roc_auc_score(skilled, oriented(medians[row.metric], row.metric))  # what the ROC plot draws
        assert row.auc == pytest.approx(area, abs=1e-12), row.metric
