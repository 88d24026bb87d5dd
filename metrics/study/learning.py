"""Learning curves, retention and CUSUM for one trainee's sequence of sessions.

Curves: ``power`` y(n) = plateau + amplitude * n^(-rate) (Newell and Rosenbloom
1981) or ``exponential`` y(n) = plateau + amplitude * exp(-rate (n - 1)); n is the
1-based trial number. Both run monotonically from y(1) = plateau + amplitude to the
plateau, so a fit whose plateau and first value lie in the metric's range (``bounds``,
e.g. [0, inf) for an angle error) stays in range at every trial: the fit is
constrained so. ``first_observed_at_benchmark`` is the first observed trial at or
better than the benchmark; ``first_predicted_at_benchmark`` the first whole trial the
fitted curve puts there (None when its plateau never gets there).
``plateau_determined`` is False when the data cannot pin the plateau down: the fit
sits on a bound of the range or of the rate, or at the last observed trial more than
half of the fitted improvement is still to come.

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

from metrics.errors import MetricsError


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
    n_trials: int
    plateau_determined: bool = True
    first_observed_at_benchmark: int | None = None
    first_predicted_at_benchmark: int | None = None

    def predict(self, trial: NDArray[np.float64] | float) -> NDArray[np.float64]:
        return MODELS[self.model](
            np.asarray(trial, dtype=np.float64), self.plateau, self.amplitude, self.rate
        )


def fit_learning_curve(
    values: Sequence[float],
    trials: Sequence[float] | None = None,
    model: str = "power",
    benchmark: float | None = None,
    better: str = "lower",
    bounds: tuple[float, float] = (-math.inf, math.inf),
) -> LearningCurve:
    """Least-squares fit of one metric over a trainee's trials (NaN values skipped; needs >= 3),
    with plateau and first value kept inside ``bounds``; ``better`` orients the benchmark."""
    if model not in MODELS:
        raise MetricsError(f"learning-curve model must be 'power' or 'exponential'; got {model!r}")
    if better not in ("lower", "higher"):
        raise MetricsError(f"better must be 'lower' or 'higher'; got {better!r}")
    low, high = bounds
    if not low < high:
        raise MetricsError(f"bounds must run from low to high; got {bounds!r}")
    y = np.asarray(values, dtype=np.float64)
    n = np.arange(1, y.size + 1, dtype=np.float64) if trials is None else np.asarray(trials, dtype=np.float64)
    keep = ~np.isnan(y)
    y, n = y[keep], n[keep]
    if y.size < 3:
        raise MetricsError(f"a learning curve needs at least 3 trials with values; got {y.size}")
    function = MODELS[model]
    plateau, amplitude, rate = _fit(model, n, y, low, high)
    residual = y - function(n, plateau, amplitude, rate)
    total = float(np.sum((y - y.mean()) ** 2))
    r_squared = 1.0 - float(np.sum(residual**2)) / total if total > 0 else math.nan
    observed = predicted = None
    if benchmark is not None and math.isfinite(benchmark):
        at = y <= benchmark if better == "lower" else y >= benchmark
        observed = int(n[np.argmax(at)]) if at.any() else None
        predicted = _first_predicted(model, plateau, amplitude, rate, benchmark, better)
    return LearningCurve(
        model,
        plateau,
        amplitude,
        rate,
        r_squared,
        int(y.size),
        _determined(model, plateau, amplitude, rate, float(n.max()), low, high),
        observed,
        predicted,
    )


RATE_GRID = np.geomspace(1e-3, 10.0, 240)


def _shape(model: str, n: NDArray, rates: NDArray) -> NDArray:
    if model == "power":
        return np.power(n[None, :], -rates[:, None])
    return np.exp(-rates[:, None] * (n[None, :] - 1))


def _linear_part(
    model: str, n: NDArray, y: NDArray, rates: NDArray, low: float = -math.inf, high: float = math.inf
) -> tuple[NDArray, NDArray, NDArray]:
    """For each rate: least-squares plateau and amplitude with plateau and plateau + amplitude (the
    first trial's value) in [low, high], and the residual sum of squares.

    The unconstrained solution in closed form; where it leaves the range, the best of the
    solutions on the range's edges (plateau on a bound, first value on a bound, or both)."""
    shape = _shape(model, n, rates)
    g_mean = shape.mean(axis=1, keepdims=True)
    y_mean = y.mean()
    centred = shape - g_mean
    variance = np.sum(centred * centred, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        amplitude = np.where(variance > 0, centred @ (y - y_mean) / variance, 0.0)
    plateau = y_mean - amplitude * g_mean[:, 0]
    candidates = [(plateau, amplitude)]
    edges = [b for b in (low, high) if math.isfinite(b)]
    for edge in edges:
        # plateau on the edge: y - edge = a g
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.sum(shape * (y - edge), axis=1) / np.sum(shape * shape, axis=1)
        candidates.append((np.full_like(a, edge), a))
        # first value on the edge: y - edge = a (g - 1)
        rest = shape - 1.0
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.where(
                np.any(rest != 0, axis=1),
                np.sum(rest * (y - edge), axis=1) / np.sum(rest * rest, axis=1),
                0.0,
            )
        candidates.append((edge - a, a))
        for other in edges:
            candidates.append((np.full_like(a, edge), np.full_like(a, other - edge)))
    best_p = np.full(rates.size, np.nan)
    best_a = np.full(rates.size, np.nan)
    best_sse = np.full(rates.size, np.inf)
    tolerance = 1e-12 * (1.0 + max((abs(b) for b in edges), default=0.0))
    for p, a in candidates:
        first = p + a
        feasible = (
            np.isfinite(p)
            & np.isfinite(a)
            & (p >= low - tolerance)
            & (p <= high + tolerance)
            & (first >= low - tolerance)
            & (first <= high + tolerance)
        )
        residual = y[None, :] - p[:, None] - a[:, None] * shape
        sse = np.where(feasible, np.sum(residual * residual, axis=1), np.inf)
        better = sse < best_sse
        best_p, best_a, best_sse = (
            np.where(better, p, best_p),
            np.where(better, a, best_a),
            np.minimum(sse, best_sse),
        )
    return best_p, best_a, best_sse


def _fit(model: str, n: NDArray, y: NDArray, low: float, high: float) -> tuple[float, float, float]:
    """Variable projection: plateau and amplitude are linear given the rate, so search the rate only
    (a log-spaced grid, then a bounded scalar refinement around the best grid point)."""
    _, _, sse = _linear_part(model, n, y, RATE_GRID, low, high)
    best = int(np.argmin(sse))
    lower = RATE_GRID[max(best - 1, 0)]
    upper = RATE_GRID[min(best + 1, RATE_GRID.size - 1)]
    refined = optimize.minimize_scalar(
        lambda log_rate: float(_linear_part(model, n, y, np.array([math.exp(log_rate)]), low, high)[2][0]),
        bounds=(math.log(lower), math.log(upper)),
        method="bounded",
        options={"xatol": 1e-10},
    )
    rate = math.exp(refined.x) if refined.fun <= sse[best] else float(RATE_GRID[best])
    plateau, amplitude, _ = _linear_part(model, n, y, np.array([rate]), low, high)
    return float(plateau[0]), float(amplitude[0]), rate


def _determined(
    model: str, plateau: float, amplitude: float, rate: float, last: float, low: float, high: float
) -> bool:
    """Whether the observed trials pin the plateau down (see the module's docstring)."""
    if rate <= RATE_GRID[1] or rate >= RATE_GRID[-2]:
        return False
    scale = 1e-9 * (1.0 + abs(plateau))
    if any(math.isfinite(b) and abs(plateau - b) <= scale for b in (low, high)):
        return False
    remaining = last**-rate if model == "power" else math.exp(-rate * (last - 1.0))
    return amplitude == 0 or remaining <= 0.5


def _first_predicted(
    model: str, plateau: float, amplitude: float, rate: float, benchmark: float, better: str
) -> int | None:
    """First whole trial n >= 1 at which the fitted curve is at or better than the benchmark."""
    sign = 1.0 if better == "lower" else -1.0  # in "lower is better" terms
    start, end = sign * (plateau + amplitude), sign * plateau
    target = sign * benchmark
    if start <= target:
        return 1
    if end >= target:  # the curve never gets there (it only approaches its plateau)
        return None
    ratio = (benchmark - plateau) / amplitude  # in (0, 1): the share of the improvement left
    n = ratio ** (-1.0 / rate) if model == "power" else 1.0 - math.log(ratio) / rate
    whole = max(1, math.ceil(n - 1e-9))
    function = MODELS[model]
    while sign * float(function(np.float64(whole), plateau, amplitude, rate)) > target:
        whole += 1  # guard against rounding at an exact crossing
    return whole


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
