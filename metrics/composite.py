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

from metrics.statistics import auc, bootstrap_auc


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
    """Out-of-fold scores per participant, their AUC and its bootstrap CI, and the full-data weights."""

    scores: pd.DataFrame  # participant, group, score (out of fold)
    auc: float
    auc_ci: tuple[float, float]
    weights: pd.Series
    folds: int


def validate_composite(
    frame: pd.DataFrame,
    metrics: Sequence[str],
    group_col: str,
    skilled_group: str,
    cluster_col: str,
    n_boot: int = 2000,
    seed: int = 0,
) -> CompositeValidation:
    """Leave-one-participant-out: fit on the others, score the left-out participant's rows.

    A participant's out-of-fold score is the mean over its rows; the AUC compares
    skilled against the other group at the participant level, CI by bootstrap.
    """
    skilled = (frame[group_col] == skilled_group).to_numpy()
    participants = frame[cluster_col].to_numpy()
    out_of_fold = np.full(len(frame), np.nan)
    unique = pd.unique(participants)
    for participant in unique:
        test = participants == participant
        train = ~test
        if not (np.any(skilled[train]) and np.any(~skilled[train])):
            continue
        model = fit_composite(frame.loc[train], metrics, skilled[train])
        out_of_fold[test] = model.score(frame.loc[test])
    scores = (
        pd.DataFrame(
            {"participant": participants, "group": frame[group_col].to_numpy(), "score": out_of_fold}
        )
        .groupby(["participant", "group"], sort=False, as_index=False)["score"]
        .mean()
    )
    first = (scores["group"] == skilled_group).to_numpy()
    valid = ~scores["score"].isna().to_numpy()
    if np.any(first & valid) and np.any(~first & valid):
        value = auc(scores["score"][first & valid], scores["score"][~first & valid])
        ci = bootstrap_auc(scores["score"].to_numpy(), first, n_boot=n_boot, seed=seed)
    else:
        value, ci = math.nan, (math.nan, math.nan)
    full = fit_composite(frame, metrics, skilled)
    return CompositeValidation(scores, value, ci, full.weights(), int(unique.size))
