"""A standard's marks carry the interval they had when set, and a page warns when today's experts
would move a mark beyond it (issue 44, seen 1): the interval checked against SciPy's percentile
bootstrap, the drift's direction worked by hand."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from metrics.study.proficiency import drift_line, mark_drift, mark_intervals


def _table(expert_values: list[float], metric: str = "peak_force") -> pd.DataFrame:
    rows = [
        {"participant_id": f"E{k}", "label": "expert", "trial": 1, metric: value}
        for k, value in enumerate(expert_values)
    ]
    rows.append({"participant_id": "T1", "label": "trainee", "trial": 1, metric: 9.0})
    return pd.DataFrame(rows)


def test_the_mark_interval_is_scipys_percentile_bootstrap_of_the_rule():
    values = [0.31, 0.42, 0.38, 0.55, 0.47, 0.36, 0.51, 0.44]
    low, high = mark_intervals(_table(values), ["peak_force"], rule="mean", n_boot=20_000, seed=3)[
        "peak_force"
    ]
    reference = stats.bootstrap(
        (np.array(values),), np.mean, n_resamples=20_000, method="percentile", random_state=5
    ).confidence_interval
    spread = max(values) - min(values)
    assert abs(low - reference.low) < 0.02 * spread and abs(high - reference.high) < 0.02 * spread
    assert np.isnan(mark_intervals(_table([0.4]), ["peak_force"], rule="mean")["peak_force"][0])


def test_drift_is_reported_only_beyond_the_interval_with_its_direction():
    marks = [
        {"metric": "peak_force", "benchmark": 0.40, "better": "lower", "interval": [0.36, 0.45]},
        {"metric": "economy_of_motion", "benchmark": 0.80, "better": "higher", "interval": [0.75, 0.85]},
        {"metric": "path_length", "benchmark": 0.06, "better": "lower"},  # set before intervals: no check
    ]
    today = pd.DataFrame(
        {"metric": ["peak_force", "economy_of_motion", "path_length"], "benchmark": [0.52, 0.84, 0.5]}
    )
    moved = mark_drift(marks, today)
    assert [(m["metric"], m["direction"]) for m in moved] == [("peak_force", "more lenient")]
    today.loc[1, "benchmark"] = 0.9  # a higher-is-better mark moving up: harder to pass
    moved = mark_drift(marks, today)
    assert [(m["metric"], m["direction"]) for m in moved] == [
        ("peak_force", "more lenient"),
        ("economy_of_motion", "stricter"),
    ]
    line = drift_line(moved[0])
    assert line.startswith("peak force: today's experts would put the mark at <= 520 mN (set at <= 400 mN")
    assert line.endswith("interval 360 mN to 450 mN): more lenient")
