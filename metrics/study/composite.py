"""A composite skill score from many metrics, validated by leave-one-participant-out cross-validation.

The score of a session is a weighted mean of its metrics' z-scores. Both the
standardisation (mean, SD) and the weights are learnt from the training
participants only: each metric's weight is its rank-biserial correlation with
membership of the skilled group (oriented so that a higher score means more
skilled), so a metric that does not separate the groups gets a weight near zero.
Nothing about the left-out participant enters its own score.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from metrics.study.statistics import auc, auc_interval, interval_is_informative, relabellings


@dataclass(frozen=True)
class CompositeModel:
    """Per-metric centre, scale and weight; ``score`` applies them."""

    metrics: tuple[str, ...]
    centre: np.ndarray
    scale: np.ndarray
    weight: np.ndarray

    def score(self, frame: pd.DataFrame) -> np.ndarray:
        values = frame[list(self.metrics)].to_numpy(dtype=np.float64)
        z = (values - self.centre) / self.scale
        present = ~np.isnan(z)
        weights = np.where(present, np.abs(self.weight), 0.0)
        signed = np.where(present, z * np.sign(self.weight), 0.0)
        total = weights.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, (weights * signed).sum(axis=1) / total, np.nan)

    def weights(self) -> pd.Series:
        return pd.Series(self.weight, index=list(self.metrics), name="weight")


def fit_composite(frame: pd.DataFrame, metrics: Sequence[str], skilled: np.ndarray) -> CompositeModel:
    """Fit on rows ``frame`` with boolean ``skilled`` marking the skilled group."""
    values = frame[list(metrics)].to_numpy(dtype=np.float64)
    centre = np.nanmean(values, axis=0)
    scale = np.nanstd(values, axis=0)
    weight = np.zeros(len(metrics))
    for k in range(len(metrics)):
        column = values[:, k]
        ok = ~np.isnan(column)
        if scale[k] > 0 and np.any(ok & skilled) and np.any(ok & ~skilled):
            weight[k] = 2.0 * auc(column[ok & skilled], column[ok & ~skilled]) - 1.0
    scale = np.where(scale > 0, scale, 1.0)
    return CompositeModel(tuple(metrics), np.nan_to_num(centre), scale, weight)


@dataclass(frozen=True)
class CompositeValidation:
    """Out-of-fold scores per participant, their AUC, its interval, and what chance alone gives.

    ``null_p95`` is the 95th percentile of the out-of-fold AUC when the group labels are
    permuted across participants and the whole leave-one-out fit is repeated: at 2 v 3
    participants a perfect-looking 1.00 is also what labels drawn at random often give.
    """

    scores: pd.DataFrame  # participant, group, score (out of fold)
    auc: float
    auc_ci: tuple[float, float]  # NaN when the design is too small for an interval to mean anything
    weights: pd.Series
    folds: int
    null_p95: float = math.nan
    null_p: float = math.nan  # share of relabellings with an out-of-fold AUC at least as high
    permutations: int = 0


NULL_RELABELLINGS = 1000
"""Relabellings for the composite's null distribution (every one when the design has fewer)."""


class _PairSums:
    """What a leave-one-participant-out fit needs, summed per participant once.

    For each metric: per participant the count, sum and sum of squares of its rows'
    values, and per pair of participants (p, q) the Mann-Whitney count of their rows'
    pairs (p's value above q's, ties one half) and the number of such pairs. A fold's
    standardisation and rank-biserial weights are then whole-sample sums minus the
    left-out participant's share, for any labelling of the participants.
    """

    def __init__(self, values: np.ndarray, cluster: np.ndarray, n_clusters: int) -> None:
        self.values, self.cluster = values, cluster
        valid = ~np.isnan(values)
        one_hot = np.zeros((values.shape[0], n_clusters))
        one_hot[np.arange(values.shape[0]), cluster] = 1.0
        filled = np.where(valid, values, 0.0)
        self.count = one_hot.T @ valid.astype(np.float64)  # participants x metrics
        self.total = one_hot.T @ filled
        self.squares = one_hot.T @ (filled * filled)
        metrics = values.shape[1]
        self.above = np.empty((n_clusters, n_clusters, metrics))
        for k in range(metrics):
            column = values[:, k]
            wins = (column[:, None] > column[None, :]) + 0.5 * (column[:, None] == column[None, :])
            self.above[:, :, k] = one_hot.T @ wins @ one_hot
        self.pairs = self.count[:, None, :] * self.count[None, :, :]

    def fold_models(self, skilled: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per left-out participant: centre, scale, weight (participants x metrics), and if its fold fits."""
        count = self.count.sum(axis=0) - self.count
        with np.errstate(invalid="ignore", divide="ignore"):
            centre = (self.total.sum(axis=0) - self.total) / count
            variance = (self.squares.sum(axis=0) - self.squares) / count - centre * centre
        constant = ~(variance > 1e-12 * centre * centre)  # also NaN: no training values
        scale = np.where(constant, 1.0, np.sqrt(np.where(constant, 1.0, variance)))
        s = skilled.astype(np.float64)
        u = 1.0 - s
        wins, pairs = (self._without_each(grid, s, u) for grid in (self.above, self.pairs))
        with np.errstate(invalid="ignore", divide="ignore"):
            weight = np.where((pairs > 0) & ~constant, 2.0 * wins / pairs - 1.0, 0.0)
        n_skilled = s.sum()
        fitted = (n_skilled - s > 0) & (skilled.size - n_skilled - u > 0)
        return np.nan_to_num(centre), scale, weight, fitted

    @staticmethod
    def _without_each(grid: np.ndarray, s: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Skilled-over-other sums of ``grid`` over everyone but p, for every p (participants x metrics)."""
        whole = np.einsum("p,pqk,q->k", s, grid, u)
        mine = s[:, None] * np.einsum("pqk,q->pk", grid, u) + u[:, None] * np.einsum("p,pqk->qk", s, grid)
        return whole - mine

    def out_of_fold(self, skilled: np.ndarray) -> np.ndarray:
        """Each participant's mean out-of-fold score (NaN where its fold could not be fitted)."""
        centre, scale, weight, fitted = self.fold_models(skilled)
        c = self.cluster
        z = (self.values - centre[c]) / scale[c]
        present = ~np.isnan(z)
        weights = np.where(present, np.abs(weight[c]), 0.0)
        signed = np.where(present, z * np.sign(weight[c]), 0.0)
        total = weights.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            row_score = np.where((total > 0) & fitted[c], (weights * signed).sum(axis=1) / total, np.nan)
        scored = ~np.isnan(row_score)
        sums = np.bincount(c[scored], weights=row_score[scored], minlength=skilled.size)
        rows = np.bincount(c[scored], minlength=skilled.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(rows > 0, sums / np.maximum(rows, 1), np.nan)


def _participant_auc(scores: np.ndarray, skilled: np.ndarray) -> float:
    valid = ~np.isnan(scores)
    if not (np.any(skilled & valid) and np.any(~skilled & valid)):
        return math.nan
    return auc(scores[skilled & valid], scores[~skilled & valid])


def validate_composite(
    frame: pd.DataFrame,
    metrics: Sequence[str],
    group_col: str,
    skilled_group: str,
    cluster_col: str,
    n_boot: int = 2000,
    seed: int = 0,
    alpha: float = 0.05,
) -> CompositeValidation:
    """Leave-one-participant-out: fit on the others, score the left-out participant's rows.

    A participant's out-of-fold score is the mean over its rows; the AUC compares the
    skilled group against the other at the participant level, with the small-sample
    interval of :func:`metrics.study.statistics.auc_interval` and the null distribution of
    the same procedure under relabelled participants. ``n_boot`` is kept for callers;
    the interval no longer resamples.
    """
    participants = frame[cluster_col].to_numpy()
    unique, cluster = np.unique(participants, return_inverse=True)
    labels = frame[group_col].to_numpy()
    skilled_of = np.zeros(unique.size, dtype=bool)
    skilled_of[cluster[labels == skilled_group]] = True
    group_of = np.empty(unique.size, dtype=object)
    group_of[cluster] = labels
    sums = _PairSums(frame[list(metrics)].to_numpy(dtype=np.float64), cluster, unique.size)
    out_of_fold = sums.out_of_fold(skilled_of)
    order = pd.unique(participants)
    position = np.searchsorted(unique, order)
    scores = pd.DataFrame({"participant": order, "group": group_of[position], "score": out_of_fold[position]})
    value = _participant_auc(out_of_fold, skilled_of)
    n_skilled = int(skilled_of.sum())
    n_other = unique.size - n_skilled
    ci = (math.nan, math.nan)
    null_p95 = null_p = math.nan
    permutations = 0
    if not math.isnan(value):
        if interval_is_informative(n_skilled, n_other, alpha):
            ci = auc_interval(value, n_skilled, n_other)
        masks, _ = relabellings(
            unique.size, n_skilled, NULL_RELABELLINGS, seed, exact_up_to=NULL_RELABELLINGS
        )
        null = np.array([_participant_auc(sums.out_of_fold(mask), mask) for mask in masks])
        null = null[~np.isnan(null)]
        if null.size:
            null_p95 = float(np.quantile(null, 0.95))
            null_p = float(np.mean(null >= value - 1e-12))
            permutations = int(null.size)
    full = fit_composite(frame, metrics, frame[group_col].to_numpy() == skilled_group)
    return CompositeValidation(
        scores, value, ci, full.weights(), int(unique.size), null_p95, null_p, permutations
    )
