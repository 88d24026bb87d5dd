"""Rank statistics for two groups: Mann-Whitney U (exact or asymptotic), AUC, Cliff's delta, Holm, bootstrap.

Conventions: ``x`` is the first group, ``y`` the second. ``U`` counts pairs with
x > y (ties count one half), so ``AUC = U / (n_x n_y) = P(X > Y) + P(X = Y) / 2``,
Cliff's delta = rank-biserial correlation = 2 AUC - 1. Swapping the groups gives
1 - AUC and the opposite direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from metrics.streams import MetricsError

EXACT_MAX_TOTAL = 60
"""Exact (permutation) p-values for up to 60 observations in all; the normal approximation above."""


@dataclass(frozen=True)
class RankTest:
    u: float
    p_value: float
    method: str  # "exact" or "asymptotic"
    auc: float
    n_x: int
    n_y: int

    @property
    def cliffs_delta(self) -> float:
        return 2.0 * self.auc - 1.0

    @property
    def rank_biserial(self) -> float:
        return 2.0 * self.auc - 1.0


def _clean(values: ArrayLike, what: str) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64).ravel()
    array = array[~np.isnan(array)]
    if array.size == 0:
        raise MetricsError(f"{what} has no values")
    return array


def u_statistic(x: ArrayLike, y: ArrayLike) -> float:
    """U of the first group: pairs with x > y plus half the ties (midrank formula)."""
    x, y = _clean(x, "first group"), _clean(y, "second group")
    ranks = stats.rankdata(np.concatenate([x, y]))
    return float(ranks[: x.size].sum() - x.size * (x.size + 1) / 2)


def exact_rank_sum_distribution(
    ranks: NDArray[np.float64], n_x: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Permutation distribution of the sum of ``n_x`` of ``ranks`` (midranks allowed): values, probabilities.

    Counts subsets by dynamic programming over doubled (integer) ranks, so ties are exact.
    """
    doubled = np.rint(2 * np.asarray(ranks)).astype(np.int64)
    total = int(doubled.sum())
    # counts[k, s]: number of k-subsets of the items seen so far with doubled-rank sum s
    counts = np.zeros((n_x + 1, total + 1), dtype=np.float64)
    counts[0, 0] = 1.0
    for r in doubled:
        counts[1:, r:] += counts[:-1, : total + 1 - r].copy()
    sums = np.flatnonzero(counts[n_x])
    probabilities = counts[n_x, sums] / math.comb(doubled.size, n_x)
    return sums / 2.0, probabilities


def mann_whitney(x: ArrayLike, y: ArrayLike, method: str = "auto") -> RankTest:
    """Two-sided Mann-Whitney U test.

    method: ``"exact"`` (permutation distribution of the rank sum, exact with ties),
    ``"asymptotic"`` (normal approximation with tie and continuity correction, as
    SciPy's), or ``"auto"``: exact up to :data:`EXACT_MAX_TOTAL` observations.
    """
    x, y = _clean(x, "first group"), _clean(y, "second group")
    n_x, n_y = x.size, y.size
    pooled = np.concatenate([x, y])
    ranks = stats.rankdata(pooled)
    u = float(ranks[:n_x].sum() - n_x * (n_x + 1) / 2)
    auc = u / (n_x * n_y)
    if method == "auto":
        method = "exact" if n_x + n_y <= EXACT_MAX_TOTAL else "asymptotic"
    if method == "exact":
        sums, probabilities = exact_rank_sum_distribution(ranks, n_x)
        mean = n_x * (n_x + n_y + 1) / 2
        observed = abs(ranks[:n_x].sum() - mean)
        p = float(probabilities[np.abs(sums - mean) >= observed - 1e-9].sum())
    elif method == "asymptotic":
        p = float(stats.mannwhitneyu(x, y, alternative="two-sided", method="asymptotic").pvalue)
    else:
        raise MetricsError(f"method must be 'auto', 'exact' or 'asymptotic'; got {method!r}")
    return RankTest(u, min(1.0, p), method, auc, n_x, n_y)


def minimum_exact_p(n_x: int, n_y: int) -> float:
    """Smallest two-sided exact p a rank test can give with these group sizes (no ties)."""
    return min(1.0, 2.0 / math.comb(n_x + n_y, n_x))


def holm(p_values: ArrayLike) -> NDArray[np.float64]:
    """Holm step-down adjusted p-values; NaN entries stay NaN and do not count towards m."""
    p = np.asarray(p_values, dtype=np.float64)
    adjusted = np.full_like(p, np.nan)
    valid = np.flatnonzero(~np.isnan(p))
    m = valid.size
    if m == 0:
        return adjusted
    order = valid[np.argsort(p[valid], kind="stable")]
    running = 0.0
    for k, index in enumerate(order):
        running = max(running, min(1.0, (m - k) * p[index]))
        adjusted[index] = running
    return adjusted


def auc(x: ArrayLike, y: ArrayLike) -> float:
    """P(X > Y) + P(X = Y) / 2."""
    x, y = _clean(x, "first group"), _clean(y, "second group")
    return u_statistic(x, y) / (x.size * y.size)


def cliffs_delta(x: ArrayLike, y: ArrayLike) -> float:
    """(#(x > y) - #(x < y)) / (n_x n_y), by direct pair counting."""
    x, y = _clean(x, "first group"), _clean(y, "second group")
    diff = x[:, None] - y[None, :]
    return float((np.sum(diff > 0) - np.sum(diff < 0)) / diff.size)


def bootstrap_auc(
    values: ArrayLike,
    in_first: ArrayLike,
    clusters: ArrayLike | None = None,
    n_boot: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap CI of the AUC, resampling clusters (participants) within each group.

    values: one per row; in_first: True for rows of the first group; clusters: the
    participant of each row (default: every row its own cluster). NaN rows are dropped.
    """
    values = np.asarray(values, dtype=np.float64)
    in_first = np.asarray(in_first, dtype=bool)
    clusters = np.arange(values.size) if clusters is None else np.asarray(clusters)
    keep = ~np.isnan(values)
    values, in_first, clusters = values[keep], in_first[keep], clusters[keep]
    rng = np.random.default_rng(seed)
    first_ids = np.unique(clusters[in_first])
    second_ids = np.unique(clusters[~in_first])
    if first_ids.size == 0 or second_ids.size == 0:
        return math.nan, math.nan
    tail = (1.0 - confidence) / 2.0
    singletons = np.unique(clusters).size == clusters.size
    if singletons:
        x, y = values[in_first], values[~in_first]
        bx = x[rng.integers(0, x.size, size=(n_boot, x.size))]
        by = y[rng.integers(0, y.size, size=(n_boot, y.size))]
        ranks = stats.rankdata(np.concatenate([bx, by], axis=1), axis=1)
        aucs = (ranks[:, : x.size].sum(axis=1) - x.size * (x.size + 1) / 2) / (x.size * y.size)
    else:
        rows_of = {c: np.flatnonzero(clusters == c) for c in np.unique(clusters)}
        aucs = np.empty(n_boot)
        for b in range(n_boot):
            pick_x = rng.choice(first_ids, first_ids.size)
            pick_y = rng.choice(second_ids, second_ids.size)
            x = values[np.concatenate([rows_of[c] for c in pick_x])]
            y = values[np.concatenate([rows_of[c] for c in pick_y])]
            ranks = stats.rankdata(np.concatenate([x, y]))
            aucs[b] = (ranks[: x.size].sum() - x.size * (x.size + 1) / 2) / (x.size * y.size)
    low, high = np.quantile(aucs, [tail, 1.0 - tail])
    return float(low), float(high)
