"""Concurrent validity: does each metric agree with a continuous rating of skill?

The rating is a column of the sessions table: a GRS/OSATS total per session, or years
of experience per participant. As with the group comparison, participants are the
units: each contributes the median of their sessions' metric and the median of their
ratings. Per metric: Spearman's rho, *oriented* by the metric's direction (positive =
the better value goes with the higher rating), a permutation p over participants
(exact up to 8 participants, else 10,000 relabellings), Holm across metrics, and a
percentile bootstrap interval resampling participants, printed only from
:data:`MIN_FOR_INTERVAL` participants up (below it the bootstrap interval is unreliable).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import permutations

import numpy as np
import pandas as pd
from scipy import stats

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY
from metrics.study.statistics import holm

MIN_FOR_INTERVAL = 10
"""Fewer participants than this get no interval for rho, and the notes say why."""
EXACT_UP_TO = 8
"""Every ordering of the ratings is enumerated up to 8 participants (40,320); sampled above."""


@dataclass(frozen=True)
class ConcurrentValidityResult:
    table: pd.DataFrame  # metric, unit, better, n, rho, rho_ci_low, rho_ci_high, p_value, p_holm, agrees
    rating_col: str
    participants: int
    alpha: float
    notes: list[str] = field(default_factory=list)


def _ranked(values: np.ndarray) -> np.ndarray:
    """Centred ranks of unit length (NaN for a constant column, which has no rank order)."""
    ranks = stats.rankdata(values)
    spread = np.sqrt(np.sum((ranks - ranks.mean()) ** 2))
    return (ranks - ranks.mean()) / spread if spread > 0 else np.full(len(ranks), math.nan)


def permutation_spearman(x: Sequence[float], y: Sequence[float], seed: int = 0) -> tuple[float, float]:
    """Spearman's rho and its two-sided permutation p (exact up to :data:`EXACT_UP_TO` pairs)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.size != y.size or x.size < 3:
        raise MetricsError(f"Spearman's rho needs at least 3 pairs; got {min(x.size, y.size)}")
    rx, ry = _ranked(x), _ranked(y)
    if not (np.all(np.isfinite(rx)) and np.all(np.isfinite(ry))):
        return math.nan, math.nan  # one side is constant: no rank correlation
    rho = float(rx @ ry)
    if x.size <= EXACT_UP_TO:
        orders = np.array(list(permutations(range(x.size))))
        null = ry[orders] @ rx
        p = float(np.mean(np.abs(null) >= abs(rho) - 1e-12))
    else:
        rng = np.random.default_rng(seed)
        orders = np.argsort(rng.random((10_000, x.size)), axis=1)
        null = ry[orders] @ rx
        p = float((np.sum(np.abs(null) >= abs(rho) - 1e-12) + 1) / (orders.shape[0] + 1))
    return rho, min(1.0, p)


def concurrent_validity(
    table: pd.DataFrame,
    rating_col: str,
    cluster_col: str = "participant_id",
    metrics: Sequence[str] | None = None,
    alpha: float = 0.05,
    n_boot: int = 2000,
    seed: int = 0,
) -> ConcurrentValidityResult:
    """Per metric, participant-level Spearman's rho with ``rating_col`` (higher rating = more skilled)."""
    for column in (rating_col, cluster_col):
        if column not in table.columns:
            raise MetricsError(f"table has no column {column!r}")
    names = list(metrics) if metrics is not None else [m.name for m in REGISTRY if m.name in table.columns]
    grouped = table.groupby(cluster_col)
    per_participant = grouped[[*names, rating_col]].median()
    rated = per_participant[per_participant[rating_col].notna()]
    rng = np.random.default_rng(seed)
    records = []
    for name in names:
        pairs = rated[[name, rating_col]].dropna()
        better = REGISTRY[name].better if name in REGISTRY else ""
        sign = -1.0 if better == "lower" else 1.0
        record = {"metric": name, "unit": REGISTRY[name].unit if name in REGISTRY else "", "better": better}
        record["n"] = int(len(pairs))
        if len(pairs) >= 3:
            rho, p = permutation_spearman(pairs[name].to_numpy(), pairs[rating_col].to_numpy(), seed)
            low = high = math.nan
            if len(pairs) >= MIN_FOR_INTERVAL and not math.isnan(rho):
                picks = rng.integers(0, len(pairs), size=(n_boot, len(pairs)))
                x, y = pairs[name].to_numpy()[picks], pairs[rating_col].to_numpy()[picks]
                rx = stats.rankdata(x, axis=1)
                ry = stats.rankdata(y, axis=1)
                rx -= rx.mean(axis=1, keepdims=True)
                ry -= ry.mean(axis=1, keepdims=True)
                with np.errstate(invalid="ignore", divide="ignore"):
                    boot = np.sum(rx * ry, axis=1) / np.sqrt(
                        np.sum(rx * rx, axis=1) * np.sum(ry * ry, axis=1)
                    )
                boot = sign * boot[np.isfinite(boot)]
                if boot.size:
                    low, high = (float(v) for v in np.quantile(boot, [0.025, 0.975]))
            record.update(rho=sign * rho if not math.isnan(rho) else math.nan, p_value=p)
            record.update(rho_ci_low=low, rho_ci_high=high)
        else:
            record.update(rho=math.nan, p_value=math.nan, rho_ci_low=math.nan, rho_ci_high=math.nan)
        records.append(record)
    result = pd.DataFrame(records)
    if result.empty:
        raise MetricsError("no metric to correlate with the rating")
    result["p_holm"] = holm(result["p_value"].to_numpy())
    result["agrees"] = (result["p_holm"] < alpha) & (result["rho"] > 0)
    n = int(len(rated))
    notes = [
        f"Concurrent validity against '{rating_col}' at participant level ({n} rated participants; each "
        "the median of their sessions); rho oriented so that positive means the better metric value goes "
        "with the higher rating."
    ]
    if n < MIN_FOR_INTERVAL:
        notes.append(
            f"No intervals for rho: {n} participants are too few for a bootstrap interval to mean anything "
            f"(at least {MIN_FOR_INTERVAL})."
        )
    if n >= 3:
        floor = 2.0 / math.factorial(n) if n <= EXACT_UP_TO else 1.0 / 10_001
        notes.append(f"With {n} participants the smallest two-sided permutation p is {floor:.3g}.")
    return ConcurrentValidityResult(result, rating_col, n, alpha, notes)
