"""Rank statistics against SciPy/statsmodels and hand-worked cases; property tests."""

import gc
import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from statsmodels.stats.multitest import multipletests

from metrics.study.statistics import (
    auc,
    bootstrap_auc,
    cliffs_delta,
    exact_rank_sum_distribution,
    holm,
    mann_whitney,
    minimum_exact_p,
)

samples = st.lists(st.integers(-20, 20), min_size=1, max_size=9)


def test_hand_worked_case():
    # x = [1, 2, 2, 3], y = [2, 3, 3, 4, 5]: x > y in 1 pair (3 > 2); ties in 4 pairs (2 = 2 twice,
    # 3 = 3 twice) -> U = 1 + 4 / 2 = 3 of 20 pairs; x < y in 15 pairs -> delta = (1 - 15) / 20
    test = mann_whitney([1, 2, 2, 3], [2, 3, 3, 4, 5])
    assert test.u == 3.0
    assert test.auc == pytest.approx(0.15)
    assert test.cliffs_delta == pytest.approx(-0.7)
    assert test.method == "exact"


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=1, max_size=8, unique=True), st.data())
def test_exact_p_matches_scipy_without_ties(x, data):
    y = data.draw(
        st.lists(st.floats(-10, 10).filter(lambda v: v not in x), min_size=1, max_size=8, unique=True)
    )
    ours = mann_whitney(x, y, method="exact")
    reference = stats.mannwhitneyu(x, y, alternative="two-sided", method="exact")
    assert ours.u == pytest.approx(reference.statistic)
    assert ours.p_value == pytest.approx(reference.pvalue, rel=1e-9)


@settings(max_examples=40, deadline=None)
@given(samples, samples)
def test_exact_p_with_ties_matches_full_enumeration(x, y):
    """Two-sided permutation p of |U - n_x n_y / 2|, by enumerating every split (independent of the DP)."""
    pooled = np.array(x + y, dtype=float)
    n = len(x)
    if math.comb(pooled.size, n) > 20_000:
        return
    ranks = stats.rankdata(pooled)
    centre = n * (pooled.size + 1) / 2
    observed = abs(ranks[:n].sum() - centre)
    splits = [abs(ranks[list(c)].sum() - centre) for c in itertools.combinations(range(pooled.size), n)]
    expected = np.mean(np.array(splits) >= observed - 1e-9)
    assert mann_whitney(x, y, method="exact").p_value == pytest.approx(expected, rel=1e-9)


def test_exact_distribution_sums_to_one_and_is_symmetric_without_ties():
    values, probabilities = exact_rank_sum_distribution(np.arange(1, 11, dtype=float), 4)
    assert probabilities.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(probabilities, probabilities[::-1])
    assert values[0] == 10 and values[-1] == 34


def test_asymptotic_matches_scipy():
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=40), rng.normal(0.5, size=45)
    ours = mann_whitney(x, y)
    assert ours.method == "asymptotic"
    reference = stats.mannwhitneyu(x, y, alternative="two-sided", method="asymptotic")
    assert ours.p_value == pytest.approx(reference.pvalue, rel=1e-12)


def statsmodels_holm(p):
    """statsmodels' Holm adjustment, without the full garbage collection its Holm branch ends with
    (``gc.collect()``: 0.5 s a call in a test worker holding the suite's objects, 60 ms alone)."""
    collect = gc.collect
    gc.collect = lambda generation=2: 0
    try:
        return multipletests(p, method="holm")[1]
    finally:
        gc.collect = collect


@settings(max_examples=30)
@given(st.lists(st.floats(0, 1), min_size=1, max_size=25))
def test_holm_matches_statsmodels(p):
    np.testing.assert_allclose(holm(p), statsmodels_holm(p), rtol=1e-12, atol=1e-15)


def test_holm_ignores_missing_p_values():
    adjusted = holm([0.01, math.nan, 0.04])
    assert (
        adjusted[0] == pytest.approx(0.02) and math.isnan(adjusted[1]) and adjusted[2] == pytest.approx(0.04)
    )


@given(samples, samples)
def test_swapping_groups_flips_auc_and_delta(x, y):
    assert auc(y, x) == pytest.approx(1 - auc(x, y))
    assert cliffs_delta(y, x) == pytest.approx(-cliffs_delta(x, y))
    assert mann_whitney(x, y).p_value == pytest.approx(mann_whitney(y, x).p_value)


@given(samples, samples)
def test_cliffs_delta_by_pair_counting_equals_rank_biserial(x, y):
    assert cliffs_delta(x, y) == pytest.approx(mann_whitney(x, y).rank_biserial)


@given(samples, samples, st.sampled_from([np.exp, np.arctan, lambda v: v**3 + v]))
def test_rank_statistics_are_invariant_to_monotone_transforms(x, y, transform):
    x, y = np.array(x, float) / 10, np.array(y, float) / 10
    before, after = mann_whitney(x, y), mann_whitney(transform(x), transform(y))
    assert after.auc == pytest.approx(before.auc)
    assert after.p_value == pytest.approx(before.p_value)


def test_minimum_exact_p():
    assert minimum_exact_p(3, 3) == pytest.approx(0.1)
    assert mann_whitney([4, 5, 6], [1, 2, 3]).p_value == pytest.approx(0.1)


def test_bootstrap_interval_brackets_the_estimate_and_cluster_resampling_widens_it():
    rng = np.random.default_rng(0)
    participants = np.repeat(np.arange(12), 5)
    skilled = participants < 6
    participant_effect = rng.normal(0, 1.0, 12)[participants]
    values = participant_effect + 0.8 * skilled + rng.normal(0, 0.2, participants.size)
    estimate = auc(values[skilled], values[~skilled])
    naive = bootstrap_auc(values, skilled, n_boot=1000, seed=1)
    clustered = bootstrap_auc(values, skilled, participants, n_boot=1000, seed=1)
    assert naive[0] <= estimate <= naive[1]
    assert clustered[0] <= estimate <= clustered[1]
    assert clustered[1] - clustered[0] > naive[1] - naive[0]
