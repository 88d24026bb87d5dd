"""Reliability: do raters agree, does a metric repeat, do a composite's parts hang together?

- :func:`intraclass_correlation`: Shrout & Fleiss (1979, Psychol Bull 86:420) ICC(1,1),
  ICC(2,1), ICC(3,1) and their average-measure forms ICC(1,k), ICC(2,k), ICC(3,k) from the
  two-way ANOVA of a complete targets x raters table, each with its F test and the
  confidence interval of McGraw & Wong (1996, Psychol Methods 1:30). ICC(2,*) (two-way
  random, absolute agreement) is the inter-rater figure: raters are a sample of raters and a
  rater who scores everyone higher disagrees. ICC(3,1) (two-way mixed, consistency) is the
  test-retest figure: the occasions are fixed and a shared practice effect is not
  disagreement.
- :func:`krippendorff_alpha`: Krippendorff's alpha from the coincidence matrix, any number of
  raters, missing ratings allowed, nominal / ordinal / interval / ratio distances
  (Krippendorff 2011, "Computing Krippendorff's alpha-reliability"); a percentile bootstrap
  interval resampling units.
- :func:`cronbach_alpha`: internal consistency of items (or a composite's components) with
  Feldt's F interval.

Interpretation bands (Koo & Li 2016, J Chiropr Med 15:155): ICC below 0.5 poor, 0.5-0.75
moderate, 0.75-0.9 good, above 0.9 excellent; judge by the interval, not the point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from metrics.errors import MetricsError
from metrics.instruments import TOTAL, instrument
from metrics.units import interval_text

ICC_KINDS = ("ICC(1,1)", "ICC(2,1)", "ICC(3,1)", "ICC(1,k)", "ICC(2,k)", "ICC(3,k)")
ICC_MEANING = {
    "ICC(1,1)": "one-way random, single rater",
    "ICC(2,1)": "two-way random, absolute agreement, single rater",
    "ICC(3,1)": "two-way mixed, consistency, single rater",
    "ICC(1,k)": "one-way random, mean of k raters",
    "ICC(2,k)": "two-way random, absolute agreement, mean of k raters",
    "ICC(3,k)": "two-way mixed, consistency, mean of k raters",
}
ALPHA_LEVELS = ("nominal", "ordinal", "interval", "ratio")
MIN_RETEST_PARTICIPANTS = 5
"""Below this an ICC's interval spans most of [-1, 1]: no test-retest figure is given."""


@dataclass(frozen=True)
class Icc:
    """One ICC form: its value, F test and confidence interval."""

    kind: str
    value: float
    f: float
    df1: float
    df2: float
    p_value: float
    ci_low: float
    ci_high: float

    @property
    def band(self) -> str:
        """Koo & Li's reading of the point value (poor / moderate / good / excellent)."""
        return agreement_band(self.value)


def agreement_band(value: float) -> str:
    """Koo & Li (2016): < 0.5 poor, 0.5-0.75 moderate, 0.75-0.9 good, > 0.9 excellent."""
    if not math.isfinite(value):
        return "not estimable"
    if value < 0.5:
        return "poor"
    if value < 0.75:
        return "moderate"
    if value <= 0.9:
        return "good"
    return "excellent"


def _complete_matrix(scores: ArrayLike) -> NDArray[np.float64]:
    matrix = np.asarray(scores, dtype=np.float64)
    if matrix.ndim != 2:
        raise MetricsError(f"an ICC needs a targets x raters table; got {matrix.ndim} dimension(s)")
    n, k = matrix.shape
    if n < 2 or k < 2:
        raise MetricsError(f"an ICC needs at least 2 targets and 2 raters; got {n} x {k}")
    if not np.all(np.isfinite(matrix)):
        raise MetricsError("an ICC needs every target rated by every rater (missing or non-finite scores)")
    return matrix


def intraclass_correlation(scores: ArrayLike, confidence: float = 0.95) -> dict[str, Icc]:
    """The six Shrout & Fleiss ICCs of a complete (targets, raters) table, by kind (:data:`ICC_KINDS`);
    nan where a table without variation leaves one undefined (e.g. every score the same)."""
    x = _complete_matrix(scores)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _iccs(x, confidence)


def _iccs(x: NDArray[np.float64], confidence: float) -> dict[str, Icc]:
    n, k = x.shape
    grand = x.mean()
    ss_rows = k * float(np.sum((x.mean(axis=1) - grand) ** 2))
    ss_cols = n * float(np.sum((x.mean(axis=0) - grand) ** 2))
    ss_total = float(np.sum((x - grand) ** 2))
    ss_error = ss_total - ss_rows - ss_cols
    msr = ss_rows / (n - 1)
    msc = ss_cols / (k - 1)
    mse = ss_error / ((n - 1) * (k - 1))
    msw = (ss_total - ss_rows) / (n * (k - 1))
    alpha = 1.0 - confidence
    q = 1.0 - alpha / 2

    def ratio(numerator: float, denominator: float) -> float:
        return float(numerator / denominator) if denominator != 0 else math.nan

    icc1 = ratio(msr - msw, msr + (k - 1) * msw)
    icc2 = ratio(msr - mse, msr + (k - 1) * mse + k * (msc - mse) / n)
    icc3 = ratio(msr - mse, msr + (k - 1) * mse)
    icc1k = ratio(msr - msw, msr)
    icc2k = ratio(msr - mse, msr + (msc - mse) / n)
    icc3k = ratio(msr - mse, msr)

    # one-way: F = MSR / MSW on (n - 1, n (k - 1))
    f1, d1a, d1b = ratio(msr, msw), n - 1, n * (k - 1)
    f1_low = f1 / stats.f.ppf(q, d1a, d1b)
    f1_high = f1 * stats.f.ppf(q, d1b, d1a)
    # two-way: F = MSR / MSE on (n - 1, (n - 1)(k - 1))
    f3, d3a, d3b = ratio(msr, mse), n - 1, (n - 1) * (k - 1)
    f3_low = f3 / stats.f.ppf(q, d3a, d3b)
    f3_high = f3 * stats.f.ppf(q, d3b, d3a)
    # ICC(2,1): Satterthwaite's degrees of freedom (McGraw & Wong 1996, case 2A)
    fc = ratio(msc, mse)
    spread = n * (1 + (k - 1) * icc2) - k * icc2
    v = ratio((k - 1) * (n - 1) * (k * icc2 * fc + spread) ** 2, (n - 1) * k**2 * icc2**2 * fc**2 + spread**2)
    f2_upper = stats.f.ppf(q, n - 1, v)
    f2_lower = stats.f.ppf(q, v, n - 1)
    middle = k * msc + (k * n - k - n) * mse
    icc2_low = n * (msr - f2_upper * mse) / (f2_upper * middle + n * msr)
    icc2_high = n * (f2_lower * msr - mse) / (middle + n * f2_lower * msr)

    def p_of(f: float, df1: float, df2: float) -> float:
        return float(stats.f.sf(f, df1, df2)) if math.isfinite(f) else math.nan

    def average(value: float) -> float:
        return value * k / (1 + value * (k - 1))

    rows = [
        ("ICC(1,1)", icc1, f1, d1a, d1b, (f1_low - 1) / (f1_low + k - 1), (f1_high - 1) / (f1_high + k - 1)),
        ("ICC(2,1)", icc2, f3, d3a, d3b, icc2_low, icc2_high),
        ("ICC(3,1)", icc3, f3, d3a, d3b, (f3_low - 1) / (f3_low + k - 1), (f3_high - 1) / (f3_high + k - 1)),
        ("ICC(1,k)", icc1k, f1, d1a, d1b, 1 - 1 / f1_low, 1 - 1 / f1_high),
        ("ICC(2,k)", icc2k, f3, d3a, d3b, average(icc2_low), average(icc2_high)),
        ("ICC(3,k)", icc3k, f3, d3a, d3b, 1 - 1 / f3_low, 1 - 1 / f3_high),
    ]
    return {
        kind: Icc(kind, float(value), float(f), float(a), float(b), p_of(f, a, b), float(low), float(high))
        for kind, value, f, a, b, low, high in rows
    }


# -- Krippendorff's alpha ---------------------------------------------------------------------------------
def _unit_counts(data: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(values, counts): the distinct values and, per unit of a raters x units table, how many raters
    gave each value ((units, values); units with fewer than two values dropped: they say nothing
    about agreement)."""
    values = np.unique(data[np.isfinite(data)])
    present = np.isfinite(data)
    index = np.searchsorted(values, np.where(present, data, values[0] if len(values) else 0.0))
    counts = np.zeros((data.shape[1], len(values)))
    units = np.broadcast_to(np.arange(data.shape[1]), data.shape)
    np.add.at(counts, (units[present], index[present]), 1.0)
    return values, counts[counts.sum(axis=1) >= 2]


def _coincidence_matrices(counts: NDArray[np.float64]) -> NDArray[np.float64]:
    """(draws, V, V) coincidence matrices of (draws, units, V) count tables:
    o[c, k] = sum over units of n_uc (n_uk - [c == k]) / (m_u - 1)."""
    weighted = counts / (counts.sum(axis=2, keepdims=True) - 1.0)
    o = np.einsum("buc,buk->bck", counts, weighted)
    diagonal = np.arange(counts.shape[2])
    o[:, diagonal, diagonal] -= weighted.sum(axis=1)
    return o


def _distances(values: NDArray[np.float64], totals: NDArray[np.float64], level: str) -> NDArray[np.float64]:
    """(draws, V, V) delta^2 between every pair of values at the measurement ``level`` (``totals``:
    (draws, V) marginal counts, which the ordinal distance depends on)."""
    c, k = values[:, None], values[None, :]
    if level == "nominal":
        fixed = (c != k).astype(np.float64)
    elif level == "interval":
        fixed = (c - k) ** 2
    elif level == "ratio":
        with np.errstate(invalid="ignore", divide="ignore"):
            fixed = np.nan_to_num(((c - k) / (c + k)) ** 2)
    else:  # ordinal: the values' ranks through the marginal counts between them
        cumulative = np.concatenate([np.zeros((len(totals), 1)), np.cumsum(totals, axis=1)], axis=1)
        i, j = np.indices((len(values), len(values)))
        low, high = np.minimum(i, j), np.maximum(i, j)
        between = cumulative[:, high + 1] - cumulative[:, low]
        return (between - (totals[:, i] + totals[:, j]) / 2) ** 2
    return np.broadcast_to(fixed, (len(totals), *fixed.shape))


def _alphas(values: NDArray[np.float64], counts: NDArray[np.float64], level: str) -> NDArray[np.float64]:
    """Krippendorff's alpha of each of a batch of (units, V) count tables ((draws,); nan where
    undefined: no pairable values, or everyone used one value)."""
    o = _coincidence_matrices(counts)
    totals = o.sum(axis=2)
    n = totals.sum(axis=1)
    delta = _distances(values, totals, level)
    observed = np.einsum("bck,bck->b", o, delta)
    with np.errstate(invalid="ignore", divide="ignore"):
        expected = np.einsum("bc,bk,bck->b", totals, totals, delta) / (n - 1)
        alpha = 1.0 - observed / expected
    defined = (n > 1) & (np.count_nonzero(totals, axis=1) >= 2) & (expected > 0)
    return np.where(defined, alpha, math.nan)


def _alpha_of(values: NDArray[np.float64], counts: NDArray[np.float64], level: str) -> float:
    if len(counts) == 0 or len(values) == 0:
        return math.nan
    return float(_alphas(values, counts[None], level)[0])


@dataclass(frozen=True)
class KrippendorffAlpha:
    level: str
    value: float
    ci_low: float
    ci_high: float
    units: int  # units rated by at least two raters
    raters: int

    @property
    def band(self) -> str:
        """Krippendorff's (2004) reading: >= 0.8 reliable, 0.667-0.8 tentative, below: not."""
        if not math.isfinite(self.value):
            return "not estimable"
        if self.value >= 0.8:
            return "reliable"
        return "tentative conclusions only" if self.value >= 0.667 else "unreliable"


def krippendorff_alpha(
    reliability_data: ArrayLike,
    level: str = "ordinal",
    confidence: float = 0.95,
    resamples: int = 2000,
    seed: int = 0,
) -> KrippendorffAlpha:
    """Krippendorff's alpha of a (raters, units) table (NaN = not rated) at ``level``, with a
    percentile bootstrap interval over units (``resamples`` = 0: no interval)."""
    if level not in ALPHA_LEVELS:
        raise MetricsError(f"alpha's level must be one of {', '.join(ALPHA_LEVELS)}; got {level!r}")
    data = np.asarray(reliability_data, dtype=np.float64)
    if data.ndim != 2:
        raise MetricsError(f"Krippendorff's alpha needs a raters x units table; got {data.ndim} dimension(s)")
    values, counts = _unit_counts(data)
    value = _alpha_of(values, counts, level)
    low = high = math.nan
    if resamples and math.isfinite(value) and len(counts) >= 2:
        rng = np.random.default_rng(seed)
        draws = _alphas(values, counts[rng.integers(0, len(counts), (resamples, len(counts)))], level)
        finite = draws[np.isfinite(draws)]
        if len(finite):
            tail = (1 - confidence) / 2
            low, high = (float(x) for x in np.quantile(finite, [tail, 1 - tail]))
    raters = int(np.any(np.isfinite(data), axis=1).sum())
    return KrippendorffAlpha(level, value, low, high, len(counts), raters)


# -- internal consistency -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class CronbachAlpha:
    value: float
    ci_low: float
    ci_high: float
    items: int
    subjects: int

    @property
    def reading(self) -> str:
        """Nunnally's 0.7 for research use; a negative alpha: the items do not measure one thing."""
        if not math.isfinite(self.value):
            return "not estimable"
        if self.value < 0:
            return "negative: the parts do not measure one thing"
        return "acceptable (>= 0.7)" if self.value >= 0.7 else "low (< 0.7)"


def cronbach_alpha(items: ArrayLike, confidence: float = 0.95) -> CronbachAlpha:
    """Cronbach's alpha of a (subjects, items) table (rows with a missing item dropped), with Feldt's
    (1965) F interval."""
    x = np.asarray(items, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] < 2:
        raise MetricsError("Cronbach's alpha needs a subjects x items table with at least 2 items")
    x = x[np.all(np.isfinite(x), axis=1)]
    n, k = x.shape
    if n < 3:
        raise MetricsError(f"Cronbach's alpha needs at least 3 complete subjects; got {n}")
    total = x.sum(axis=1).var(ddof=1)
    value = k / (k - 1) * (1 - x.var(axis=0, ddof=1).sum() / total) if total > 0 else math.nan
    tail = (1 - confidence) / 2
    df1, df2 = n - 1, (n - 1) * (k - 1)
    low = 1 - (1 - value) * stats.f.ppf(1 - tail, df1, df2)
    high = 1 - (1 - value) * stats.f.ppf(tail, df1, df2)
    return CronbachAlpha(float(value), float(low), float(high), k, n)


# -- from tables ---------------------------------------------------------------------------------------------
def complete_block(wide: pd.DataFrame) -> pd.DataFrame:
    """The largest block of a targets x raters table rated by every one of its raters, found by
    dropping, one at a time, the rater whose removal keeps the most complete targets (ties: the
    rater with fewer ratings). Raters are columns; NaN = not rated."""
    block = wide.copy()
    while block.shape[1] > 2:
        complete = int(block.notna().all(axis=1).sum())
        gains = {rater: int(block.drop(columns=rater).notna().all(axis=1).sum()) for rater in block.columns}
        best = max(gains, key=lambda r: (gains[r], -int(block[r].notna().sum())))
        if gains[best] <= complete:
            break
        block = block.drop(columns=best)
    return block[block.notna().all(axis=1)]


def test_retest(
    table: pd.DataFrame,
    metric: str,
    cluster_col: str = "participant_id",
    order_col: str = "trial",
    occasions: int = 2,
) -> tuple[Icc | None, int]:
    """ICC(3,1) of ``metric`` over each participant's last ``occasions`` sessions (at plateau: the
    caller passes the sessions that count, e.g. the experts', or practice after the learning curve
    levels). Returns (ICC or None when fewer than :data:`MIN_RETEST_PARTICIPANTS` have that many,
    participants used)."""
    rows = []
    for _, group in table.dropna(subset=[metric]).sort_values(order_col).groupby(cluster_col):
        if len(group) >= occasions:
            rows.append(group[metric].to_numpy(dtype=np.float64)[-occasions:])
    if len(rows) < MIN_RETEST_PARTICIPANTS:
        return None, len(rows)
    return intraclass_correlation(np.array(rows))["ICC(3,1)"], len(rows)


test_retest.__test__ = False  # a statistic, not a pytest test


def rater_agreement(ratings: pd.DataFrame, instrument_name: str, confidence: float = 0.95) -> pd.DataFrame:
    """Inter-rater reliability of one instrument from a long ratings table (columns ``session_id``,
    ``rater``, ``instrument``, ``item``, ``score``; a rater's repeated rating of a session: the
    latest counts, rows in time order). One row per item and the total: sessions and raters in the
    largest complete block, ICC(2,1) and ICC(2,k) with their intervals (absolute agreement), and
    Krippendorff's alpha over every rating (ordinal for items, interval for the total)."""

    spec = instrument(instrument_name)
    mine = ratings[ratings["instrument"].str.upper() == spec.name]
    rows = []
    for item in (*spec.item_names, TOTAL):
        of_item = mine[mine["item"] == item]
        wide = of_item.groupby(["session_id", "rater"])["score"].last().unstack("rater")
        row: dict[str, object] = {
            "item": item,
            "sessions_rated": int(len(wide)),
            "raters": int(wide.shape[1]),
        }
        block = complete_block(wide) if wide.shape[1] >= 2 else wide.iloc[0:0]
        row["sessions"], row["block_raters"] = int(len(block)), int(block.shape[1])
        for kind in ("ICC(2,1)", "ICC(2,k)"):
            key = "icc21" if kind == "ICC(2,1)" else "icc2k"
            row[key] = row[f"{key}_low"] = row[f"{key}_high"] = math.nan
        if len(block) >= 2 and block.shape[1] >= 2:
            iccs = intraclass_correlation(block.to_numpy(dtype=np.float64), confidence)
            for kind, key in (("ICC(2,1)", "icc21"), ("ICC(2,k)", "icc2k")):
                row[key], row[f"{key}_low"], row[f"{key}_high"] = (
                    iccs[kind].value,
                    iccs[kind].ci_low,
                    iccs[kind].ci_high,
                )
        row["alpha"] = row["alpha_low"] = row["alpha_high"] = math.nan
        if wide.shape[1] >= 2:
            alpha = krippendorff_alpha(
                wide.T.to_numpy(dtype=np.float64), "interval" if item == TOTAL else "ordinal", confidence
            )
            row["alpha"], row["alpha_low"], row["alpha_high"] = alpha.value, alpha.ci_low, alpha.ci_high
        row["reading"] = agreement_band(float(row["icc21"]))  # type: ignore[arg-type]
        rows.append(row)
    return pd.DataFrame(rows)


def agreement_shown(table: pd.DataFrame, compact: bool = False) -> pd.DataFrame:
    """:func:`rater_agreement`'s table as a person reads it: each estimate with its interval (and
    Koo & Li's reading for ICC(2,1)); ``compact`` (80 columns) leaves ICC(2,k) out."""

    def estimates(key: str, reading: bool = False) -> list[str]:
        readings = table["reading"] if reading else [""] * len(table)
        columns = zip(table[key], table[f"{key}_low"], table[f"{key}_high"], readings, strict=True)
        return [interval_text(v, lo, hi, r) for v, lo, hi, r in columns]

    shown = {
        "item": table["item"],
        "sessions" if compact else "sessions (all raters)": table["sessions"],
        "raters": table["block_raters"],
        "ICC(2,1)" if compact else "ICC(2,1) (95 % CI), reading": estimates("icc21", reading=True),
    }
    if not compact:
        shown["ICC(2,k) (95 % CI)"] = estimates("icc2k")
    shown["alpha" if compact else "Krippendorff's alpha (95 % CI)"] = estimates("alpha")
    return pd.DataFrame(shown)
