"""A session's metrics against the expert band read by direction (issue 20, seen 1)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from metrics.errors import MetricsError
from metrics.study.proficiency import band_position
from sessions.scoring.review import against_band

BAND = {"expert_q1": 10.0, "expert_median": 12.0, "expert_q3": 14.0}


def test_faster_than_every_expert_is_better_not_outside():
    """Seen: demo trainee T01 was red for a shorter task time, a quicker contact-to-pierce and less time
    above the strain limit than every expert."""
    values = {"task_time": 4.0, "contact_to_pierce_time": 0.1, "time_above_strain_limit": 0.0}
    band = dict.fromkeys(values, BAND)
    rows = against_band(values, band)
    assert [r["versus_experts"] for r in rows] == ["better", "better", "better"]
    assert all(r["better"] == "lower" for r in rows)


def test_higher_is_better_metric_and_the_band_edges():
    band = {"spectral_arc_length": BAND}
    assert against_band({"spectral_arc_length": 20.0}, band)[0]["versus_experts"] == "better"
    assert against_band({"spectral_arc_length": 5.0}, band)[0]["versus_experts"] == "worse"
    assert against_band({"spectral_arc_length": 14.0}, band)[0]["versus_experts"] == "within"
    assert against_band({"spectral_arc_length": None}, band)[0]["versus_experts"] is None
    assert against_band({"spectral_arc_length": 3.0}, {})[0]["versus_experts"] is None


@given(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), st.floats(0, 1e6), st.sampled_from(["lower", "higher"]))
def test_mirroring_a_metric_swaps_better_and_worse(value, low, width, better):
    high = low + width
    other = "higher" if better == "lower" else "lower"
    here = band_position(value, low, high, better)
    mirrored = band_position(-value, -high, -low, other)
    assert here == mirrored
    flipped = band_position(value, low, high, other)
    assert {here, flipped} == {"within"} or {here, flipped} == {"better", "worse"}


def test_a_band_upside_down_is_refused():
    with pytest.raises(MetricsError, match="low end is above its high end"):
        band_position(1.0, 3.0, 2.0, "lower")
