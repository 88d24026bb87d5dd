"""Concurrent validity against a continuous rating (issue 20): Spearman's rho at participant level,
oriented by direction, with permutation p and honest intervals."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from metrics.study.concurrent import concurrent_validity, permutation_spearman


def test_rho_and_exact_p_match_scipy():
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=7), rng.normal(size=7)
    rho, p = permutation_spearman(x, y)
    assert rho == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
    from itertools import permutations

    observed = abs(stats.spearmanr(x, y).statistic)
    rx, ry = stats.rankdata(x), stats.rankdata(y)
    null = [abs(np.corrcoef(rx, ry[list(order)])[0, 1]) for order in permutations(range(7))]
    assert p == pytest.approx(np.mean(np.array(null) >= observed - 1e-12), abs=1e-12)


def _table(n: int, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(n):
        skill = rng.uniform(0, 1)
        for trial in range(3):
            rows.append(
                {
                    "participant_id": f"P{k}",
                    "trial": trial + 1,
                    "grs_total": 10 + 20 * skill + rng.normal(0, 0.5),
                    "task_time": 120 - 80 * skill + rng.normal(0, 2),  # lower is better
                    "spectral_arc_length": -5 + 2 * skill + rng.normal(0, 0.05),  # higher is better
                }
            )
    return pd.DataFrame(rows)


def test_rho_is_oriented_so_positive_means_the_better_value_goes_with_the_higher_rating():
    result = concurrent_validity(_table(14), "grs_total", metrics=["task_time", "spectral_arc_length"])
    rows = result.table.set_index("metric")
    assert rows.loc["task_time", "rho"] > 0.8 and rows.loc["spectral_arc_length", "rho"] > 0.8
    assert rows["agrees"].all()
    assert (rows["rho_ci_low"] < rows["rho"]).all() and (rows["rho"] <= rows["rho_ci_high"] + 1e-12).all()
    assert result.participants == 14


def test_few_participants_get_no_interval_and_a_note():
    result = concurrent_validity(_table(5), "grs_total", metrics=["task_time"])
    row = result.table.iloc[0]
    assert math.isnan(row["rho_ci_low"]) and math.isnan(row["rho_ci_high"])
    assert any("too few for a bootstrap interval" in note for note in result.notes)
    assert any("smallest two-sided permutation p is 0.0167" in note for note in result.notes)  # 2 / 5!
    assert not row["agrees"] or row["p_holm"] < 0.05
