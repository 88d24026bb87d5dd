"""Rank statistics for two groups: Mann-Whitney U (exact or asymptotic), AUC, Cliff's delta, Holm,
small-sample AUC intervals, and permutation tests that respect participants.

Conventions: ``x`` is the first group, ``y`` the second. ``U`` counts pairs with
x > y (ties count one half), so ``AUC = U / (n_x n_y) = P(X > Y) + P(X = Y) / 2``,
Cliff's delta = rank-biserial correlation = 2 AUC - 1. Swapping the groups gives
1 - AUC and the opposite direction. What a reader is shown is the *oriented* AUC
(:func:`oriented_auc`): the probability that a skilled participant does better.

Two-sided p with ties: the exact test uses the permutation distribution of the
sum of midranks, and p = P(|W - E W| >= |w - E W|) under that distribution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from metrics.errors import MetricsError

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


def oriented_auc(raw_auc: float, skilled_first: bool, higher_is_better: bool) -> float:
    """P(a skilled participant does better than an unskilled one) from the raw P(first > second).

    1 = perfect separation in the expected direction, 0.5 = none, 0 = perfectly reversed.
    """
    skilled_higher = raw_auc if skilled_first else 1.0 - raw_auc
    return skilled_higher if higher_is_better else 1.0 - skilled_higher


def _hanley_mcneil_variance(theta: float, n_x: int, n_y: int) -> float:
    """Newcombe's (2006) Hanley-McNeil variance: both sample sizes replaced by n* = (n_x + n_y)/2 - 1."""
    n_star = (n_x + n_y) / 2.0 - 1.0
    spread = (1.0 - theta) / (2.0 - theta) + theta / (1.0 + theta)
    return theta * (1.0 - theta) / (n_x * n_y) * (1.0 + (n_star - 1.0) * spread)


def _bisect(function, low: float, high: float) -> float:
    """Root of a function positive at ``low`` and not positive at ``high`` (60 halvings: below 1e-17)."""
    for _ in range(60):
        middle = 0.5 * (low + high)
        if function(middle) > 0:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def auc_interval(auc_value: float, n_x: int, n_y: int, confidence: float = 0.95) -> tuple[float, float]:
    """Score-type interval for an AUC that does not collapse at complete separation.

    Newcombe's method 5 (Stat Med 2006; 25:559-573): the limits are the theta whose
    Hanley-McNeil variance, evaluated *at theta* with n* = (n_x + n_y)/2 - 1, puts
    the observed AUC at z standard errors, with a continuity correction of half a
    pair, 1/(2 n_x n_y). At AUC = 1 the lower limit stays below 1 (e.g. 6 v 6: 0.70).
    Simulated coverage of the 95 % interval (benchmarks/auc_coverage.py): at least
    0.94 at 6 v 6 and 10 v 10 for true AUCs from 0.5 to 0.998.
    """
    if not (0.0 <= auc_value <= 1.0) or n_x < 1 or n_y < 1:
        raise MetricsError(
            f"auc_interval needs an AUC in [0, 1] and positive group sizes; got {auc_value}, {n_x}, {n_y}"
        )
    z = float(stats.norm.ppf(0.5 + confidence / 2.0))
    half_pair = 0.5 / (n_x * n_y)

    def below(theta: float) -> float:  # > 0 while theta is still inside the interval, from below
        return auc_value - theta - half_pair - z * math.sqrt(_hanley_mcneil_variance(theta, n_x, n_y))

    def above(theta: float) -> float:
        return theta - auc_value - half_pair - z * math.sqrt(_hanley_mcneil_variance(theta, n_x, n_y))

    low = 0.0 if below(0.0) <= 0 else _bisect(below, 0.0, auc_value)
    high = 1.0 if above(1.0) <= 0 else 1.0 - _bisect(lambda u: above(1.0 - u), 0.0, 1.0 - auc_value)
    return low, high


def interval_is_informative(n_x: int, n_y: int, alpha: float = 0.05) -> bool:
    """False when no outcome of this design could reach two-sided p < alpha (e.g. 2 v 3: p >= 0.2).

    An interval printed for such a design would look like evidence where there can be none.
    """
    return minimum_exact_p(n_x, n_y) < alpha


@dataclass(frozen=True)
class PermutationTest:
    """A test of group labels permuted across clusters (participants), not across rows."""

    p_value: float
    method: str  # "exact" (every relabelling) or "monte-carlo"
    permutations: int
    minimum_p: float  # the smallest p this design can give


EXACT_RELABELLINGS = 20_000
"""Enumerate every relabelling of participants up to this many; sample 10,000 above it."""


def relabellings(
    n_clusters: int, n_first: int, n_samples: int, seed: int, exact_up_to: int = EXACT_RELABELLINGS
) -> tuple[NDArray[np.bool_], str]:
    """Which clusters are in the first group: every choice of ``n_first`` (when at most ``exact_up_to``)
    or ``n_samples`` drawn at random; returns (masks, "exact" or "monte-carlo")."""
    from itertools import combinations

    if math.comb(n_clusters, n_first) <= max(exact_up_to, n_samples):
        masks = np.zeros((math.comb(n_clusters, n_first), n_clusters), dtype=bool)
        for row, chosen in enumerate(combinations(range(n_clusters), n_first)):
            masks[row, list(chosen)] = True
        return masks, "exact"
    rng = np.random.default_rng(seed)
    order = np.argsort(rng.random((n_samples, n_clusters)), axis=1)
    masks = np.zeros((n_samples, n_clusters), dtype=bool)
    np.put_along_axis(masks, order[:, :n_first], True, axis=1)
    return masks, "monte-carlo"


def cluster_permutation_test(
    values: ArrayLike, in_first: ArrayLike, clusters: ArrayLike, n_samples: int = 10_000, seed: int = 0
) -> PermutationTest:
    """Two-sided test of the row-level Mann-Whitney U with group labels permuted across participants.

    Rows of one participant move together, so repeated trials do not count as independent
    evidence: 2 v 4 participants can never give p below 1/15, however many trials each did.
    The statistic is |U - n_x n_y / 2| of the rows; the p value counts relabellings at least
    as extreme (exact enumeration, or Monte Carlo with (b + 1)/(B + 1)).
    """
    values = np.asarray(values, dtype=np.float64)
    in_first = np.asarray(in_first, dtype=bool)
    clusters = np.asarray(clusters)
    keep = ~np.isnan(values)
    values, in_first, clusters = values[keep], in_first[keep], clusters[keep]
    ids, index = np.unique(clusters, return_inverse=True)
    first_of = np.zeros(ids.size, dtype=bool)
    first_of[index[in_first]] = True
    if np.any(first_of[index] != in_first):
        raise MetricsError("a participant's rows carry both group labels; permutation needs one label each")
    n_first = int(first_of.sum())
    if n_first == 0 or n_first == ids.size:
        raise MetricsError("both groups need at least one participant with a value")
    ranks = stats.rankdata(values)
    rank_sum_of = np.bincount(index, weights=ranks, minlength=ids.size)
    rows_of = np.bincount(index, minlength=ids.size).astype(np.float64)

    def centred_u(masks: NDArray[np.bool_]) -> NDArray[np.float64]:
        n_x = masks.astype(np.float64) @ rows_of
        n_y = values.size - n_x
        u = masks.astype(np.float64) @ rank_sum_of - n_x * (n_x + 1) / 2
        return np.abs(u - n_x * n_y / 2)

    observed = centred_u(first_of[None, :])[0]
    masks, method = relabellings(ids.size, n_first, n_samples, seed)
    extreme = int(np.sum(centred_u(masks) >= observed - 1e-9))
    if method == "exact":
        p = extreme / masks.shape[0]
        floor = 1.0 / masks.shape[0]  # the observed labelling alone (its mirror need not be as extreme)
    else:
        p = (extreme + 1) / (masks.shape[0] + 1)
        floor = max(1.0 / math.comb(ids.size, n_first), 1.0 / (masks.shape[0] + 1))
    return PermutationTest(min(1.0, p), method, int(masks.shape[0]), floor)


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


def wilson_interval(successes: int, total: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval of a proportion (nan, nan without trials)."""
    if total == 0:
        return math.nan, math.nan
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    p = successes / total
    centre = (p + z * z / (2 * total)) / (1 + z * z / total)
    half = z * math.sqrt(p * (1 - p) / total + z * z / (4 * total * total)) / (1 + z * z / total)
    return max(0.0, centre - half), min(1.0, centre + half)


def contrasting_groups_mark(skilled: ArrayLike, unskilled: ArrayLike) -> float:
    """The contrasting-groups pass mark (Livingston & Zieky 1982; in simulation e.g. Jørgensen et al.
    2018, Adv Simul 3:5): where the normal fits of the two groups' values cross, between their
    means (nan when either group has fewer than 2 values or the means coincide). Equal spreads:
    the midpoint of the means."""
    a, b = np.asarray(skilled, dtype=np.float64), np.asarray(unskilled, dtype=np.float64)
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if len(a) < 2 or len(b) < 2:
        return math.nan
    m1, m2 = float(a.mean()), float(b.mean())
    s1, s2 = float(a.std(ddof=1)), float(b.std(ddof=1))
    if m1 == m2:
        return math.nan
    low, high = min(m1, m2), max(m1, m2)
    if s1 <= 0 or s2 <= 0 or math.isclose(s1, s2, rel_tol=1e-9):
        return 0.5 * (m1 + m2)
    # log N(x; m1, s1) = log N(x; m2, s2):  a x^2 + b x + c = 0
    qa = 1 / (2 * s2**2) - 1 / (2 * s1**2)
    qb = m1 / s1**2 - m2 / s2**2
    qc = m2**2 / (2 * s2**2) - m1**2 / (2 * s1**2) + math.log(s2 / s1)
    roots = np.roots([qa, qb, qc])
    between = [float(r.real) for r in roots if abs(r.imag) < 1e-12 and low <= r.real <= high]
    if not between:
        return 0.5 * (m1 + m2)
    return min(between, key=lambda r: abs(r - 0.5 * (m1 + m2)))
