"""Learning curves that can be true (issue 20, seen 6): fits inside the metric's range, whole trials,
and a plateau the data cannot determine said so."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from metrics import compute_session_metrics
from metrics.session.registry import REGISTRY
from metrics.study.analysis import StudySettings, analyse_study
from metrics.study.learning import MODELS, fit_learning_curve
from metrics.synthetic import synthetic_study

PRIMARY = ("path_length", "spectral_arc_length", "entry_angle_error_deg", "task_time")
STEADY_DECLINE = [14.0, 11.5, 9.0, 6.6, 4.1, 1.9]  # an angle error still falling when practice ends


def test_a_non_negative_metric_never_gets_a_negative_plateau():
    """Seen: entry-angle error got plateaus of -129, -9.0, -4.3 and -2.8 deg."""
    free = fit_learning_curve(STEADY_DECLINE, model="power")
    assert free.plateau < -2  # unconstrained, the straight decline extrapolates below zero
    curve = fit_learning_curve(STEADY_DECLINE, model="power", bounds=REGISTRY["entry_angle_error_deg"].bounds)
    assert curve.plateau >= 0.0
    assert np.all(curve.predict(np.arange(1, 50)) >= -1e-12)
    assert not curve.plateau_determined  # six falling trials cannot say where it levels off


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 50.0), min_size=3, max_size=12),
    st.sampled_from(["power", "exponential"]),
)
def test_every_fit_stays_inside_its_bounds(values, model):
    curve = fit_learning_curve(values, model=model, bounds=(0.0, 50.0))
    trials = np.arange(1, 200, dtype=float)
    predicted = MODELS[model](trials, curve.plateau, curve.amplitude, curve.rate)
    assert np.all(predicted >= -1e-9) and np.all(predicted <= 50.0 + 1e-9)
    free = fit_learning_curve(values, model=model)
    sse = float(np.sum((np.asarray(values) - curve.predict(np.arange(1, len(values) + 1))) ** 2))
    sse_free = float(np.sum((np.asarray(values) - free.predict(np.arange(1, len(values) + 1))) ** 2))
    assert sse >= sse_free - 1e-7 * (1 + sse_free)  # the constraint can only cost fit


def test_trials_to_benchmark_are_whole_trials_in_the_metric_direction():
    """Seen: "trials to benchmark" 4.71."""
    values = [3.0, 2.0, 1.5, 1.2, 1.1, 1.05]  # SPARC-like numbers, but here higher is better
    rising = [-v for v in values]
    curve = fit_learning_curve(
        rising, model="power", benchmark=-1.3, better="higher", bounds=(-math.inf, 0.0)
    )
    assert curve.first_observed_at_benchmark == 4  # -1.2 is the first at or above -1.3
    assert isinstance(curve.first_predicted_at_benchmark, int)
    n = curve.first_predicted_at_benchmark
    assert curve.predict(n) >= -1.3 and (n == 1 or curve.predict(n - 1) < -1.3)


def test_study_curves_respect_ranges_and_trial_counts_are_integers():
    """Seen: "Proficient at trial 6.0"."""
    streams = synthetic_study(experts=4, trainees=5, trainee_sessions=6, duration=20, rate=250, seed=3)
    table = compute_session_metrics(streams)
    analysis = analyse_study(table, StudySettings(metrics=PRIMARY, benchmark_metrics=PRIMARY, n_boot=200))
    curves = analysis.learning_curves
    assert not curves.empty
    for row in curves.itertuples():
        low, high = REGISTRY[row.metric].bounds
        assert low - 1e-12 <= row.plateau <= high + 1e-12
    assert str(curves["first_predicted_at_benchmark"].dtype) == "Int64"
    assert str(analysis.trainees["trials_to_proficiency"].dtype) == "Int64"


@pytest.mark.parametrize("model", ["power", "exponential"])
def test_a_flat_sequence_is_a_flat_curve(model):
    curve = fit_learning_curve([2.0, 2.0, 2.0, 2.0], model=model, benchmark=2.0, bounds=(0.0, math.inf))
    assert curve.predict(10) == pytest.approx(2.0)
    assert curve.first_observed_at_benchmark == 1 and curve.first_predicted_at_benchmark == 1
