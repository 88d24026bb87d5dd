"""Learning curves, retention and CUSUM for one trainee's sequence of sessions.

Curves: ``power`` y(n) = plateau + amplitude * n^(-rate) (Newell and Rosenbloom
1981) or ``exponential`` y(n) = plateau + amplitude * exp(-rate (n - 1)); n is the
1-based trial number. ``trials_to_benchmark`` solves y(n) = benchmark on the fitted
curve (None when the plateau never reaches it).

CUSUM (learning-curve CUSUM, Bolsin and Colson 2000): each failure adds 1 - s, each
success subtracts s; with P = ln(p1/p0), Q = ln((1-p0)/(1-p1)), s = Q / (P + Q);
boundaries h0 = ln((1-alpha)/beta) / (P + Q) below zero (competence shown: the
failure rate is acceptable, p0) and h1 = ln((1-beta)/alpha) / (P + Q) above
(failure rate unacceptable, p1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from metrics.streams import MetricsError


def _power(n, plateau, amplitude, rate):
    return plateau + amplitude * np.power(n, -rate)


def _exponential(n, plateau, amplitude, rate):
    return plateau + amplitude * np.exp(-rate * (n - 1.0))


MODELS = {"power": _power, "exponential": _exponential}


@dataclass(frozen=True)
class LearningCurve:
    model: str
    plateau: float
    amplitude: float
    rate: float
    r_squared: float
    trials_to_benchmark: float | None
    n_trials: int

    def predict(self, trial: NDArray[np.float64] | float) -> NDArray[np.float64]:
        return MODELS[self.model](
            np.asarray(trial, dtype=np.float64), self.plateau, self.amplitude, self.rate
        )


def fit_learning_curve(
    values: Sequence[float],
    trials: Sequence[float] | None = None,
    model: str = "power",
    benchmark: float | None = None,
) -> LearningCurve:
    """Least-squares fit of one metric over a trainee's trials (NaN values skipped; needs >= 3)."""
    if model not in MODELS:
        raise MetricsError(f"learning-curve model must be 'power' or 'exponential'; got {model!r}")
    y = np.asarray(values, dtype=np.float64)
    n = np.arange(1, y.size + 1, dtype=np.float64) if trials is None else np.asarray(trials, dtype=np.float64)
    keep = ~np.isnan(y)
    y, n = y[keep], n[keep]
    if y.size < 3:
        raise MetricsError(f"a learning curve needs at least 3 trials with values; got {y.size}")
    function = MODELS[model]
    plateau, amplitude, rate = _fit(model, n, y)
    residual = y - function(n, plateau, amplitude, rate)
    total = float(np.sum((y - y.mean()) ** 2))
    r_squared = 1.0 - float(np.sum(residual**2)) / total if total > 0 else math.nan
    reach = _trials_to(model, plateau, amplitude, rate, benchmark) if benchmark is not None else None
    return LearningCurve(model, plateau, amplitude, rate, r_squared, reach, int(y.size))


RATE_GRID = np.geomspace(1e-3, 10.0, 240)


def _linear_part(model: str, n: NDArray, y: NDArray, rates: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """For each rate: least-squares plateau and amplitude (closed form) and the residual sum of squares."""
    shape = (
        np.power(n[None, :], -rates[:, None])
        if model == "power"
        else np.exp(-rates[:, None] * (n[None, :] - 1))
    )
    g_mean = shape.mean(axis=1, keepdims=True)
    y_mean = y.mean()
    centred = shape - g_mean
    variance = np.sum(centred * centred, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        amplitude = np.where(variance > 0, centred @ (y - y_mean) / variance, 0.0)
    plateau = y_mean - amplitude * g_mean[:, 0]
    residual = y[None, :] - plateau[:, None] - amplitude[:, None] * shape
    return plateau, amplitude, np.sum(residual * residual, axis=1)


def _fit(model: str, n: NDArray, y: NDArray) -> tuple[float, float, float]:
    """Variable projection: plateau and amplitude are linear given the rate, so search the rate only
    (a log-spaced grid, then a bounded scalar refinement around the best grid point)."""
    _, _, sse = _linear_part(model, n, y, RATE_GRID)
    best = int(np.argmin(sse))
    low = RATE_GRID[max(best - 1, 0)]
    high = RATE_GRID[min(best + 1, RATE_GRID.size - 1)]
    refined = optimize.minimize_scalar(
        lambda log_rate: float(_linear_part(model, n, y, np.array([math.exp(log_rate)]))[2][0]),
        bounds=(math.log(low), math.log(high)),
        method="bounded",
        options={"xatol": 1e-10},
    )
    rate = math.exp(refined.x) if refined.fun <= sse[best] else float(RATE_GRID[best])
    plateau, amplitude, _ = _linear_part(model, n, y, np.array([rate]))
    return float(plateau[0]), float(amplitude[0]), rate


def _trials_to(model: str, plateau: float, amplitude: float, rate: float, benchmark: float) -> float | None:
    if amplitude == 0:
        return 1.0 if plateau == benchmark else None
    ratio = (benchmark - plateau) / amplitude
    if ratio >= 1:  # the curve starts at or beyond the benchmark
        return 1.0
    if ratio <= 0:  # the plateau itself does not reach it
        return None
    if model == "power":
        return float(ratio ** (-1.0 / rate))
    return float(1.0 - math.log(ratio) / rate)


@dataclass(frozen=True)
class Retention:
    end_of_practice: float
    retention: float
    change: float
    relative_change: float
    worse: bool


def retention(practice: Sequence[float], delayed: float, better: str, last: int = 2) -> Retention:
    """Delayed session against the mean of the last ``last`` practice sessions; ``worse`` by direction."""
    values = np.asarray(practice, dtype=np.float64)
    values = values[~np.isnan(values)]
    if values.size == 0:
        raise MetricsError("retention needs at least one practice session with a value")
    end = float(values[-last:].mean())
    change = float(delayed - end)
    relative = change / abs(end) if end != 0 else math.nan
    worse = change > 0 if better == "lower" else change < 0
    return Retention(end, float(delayed), change, relative, bool(worse))


@dataclass(frozen=True)
class Cusum:
    values: NDArray[np.float64]
    s: float
    h0: float
    h1: float
    competent_at: int | None  # 1-based trial where the curve first reached -h0
    unacceptable_at: int | None  # 1-based trial where it first reached +h1


def cusum(
    failures: Sequence[bool], p0: float = 0.1, p1: float = 0.3, alpha: float = 0.1, beta: float = 0.1
) -> Cusum:
    """Learning-curve CUSUM over a sequence of failures (True) and successes (False)."""
    if not 0 < p0 < p1 < 1:
        raise MetricsError(f"CUSUM needs 0 < p0 < p1 < 1; got p0={p0}, p1={p1}")
    if not (0 < alpha < 1 and 0 < beta < 1):
        raise MetricsError(f"CUSUM error rates must be in (0, 1); got alpha={alpha}, beta={beta}")
    big_p = math.log(p1 / p0)
    big_q = math.log((1 - p0) / (1 - p1))
    s = big_q / (big_p + big_q)
    h0 = math.log((1 - alpha) / beta) / (big_p + big_q)
    h1 = math.log((1 - beta) / alpha) / (big_p + big_q)
    steps = np.where(np.asarray(failures, dtype=bool), 1.0 - s, -s)
    values = np.cumsum(steps)
    low = np.flatnonzero(values <= -h0)
    high = np.flatnonzero(values >= h1)
    return Cusum(
        values, s, h0, h1, int(low[0]) + 1 if low.size else None, int(high[0]) + 1 if high.size else None
    )
