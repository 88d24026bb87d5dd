"""The subordinate hand's metrics on hand-built streams with known answers."""

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from metrics import SessionStreams, metrics_of
from metrics.signals.kinematics import UniformMotion


def streams(grasp_force=None, jaw=None, events=None, moved=None):
    time = np.arange(0.0, 3.0, 0.001)
    n = time.size
    return SessionStreams(
        "s",
        time,
        np.zeros((n, 3)),
        subordinate_displacement=np.zeros((n, 3)) if moved is None else moved,
        forceps_jaw=jaw,
        grasp_force=grasp_force,
        events=events
        if events is not None
        else pd.DataFrame(
            {"time": [1.0, 1.2, 1.6, 2.6], "kind": ["contact_start", "pierce", "exit", "pull_through"]}
        ),
    )


def test_the_edge_held_share_peak_force_and_tears_have_known_answers():
    time = np.arange(0.0, 3.0, 0.001)
    force = np.zeros((time.size, 3))
    held = (time >= 1.4) & (time < 2.5)
    force[held] = [0.0, 0.3, 0.4]  # 0.5 N
    force[np.argmin(np.abs(time - 2.0))] = [0.0, 0.0, 0.8]
    events = pd.DataFrame(
        {
            "time": [1.0, 1.2, 1.6, 2.45, 2.6],
            "kind": ["contact_start", "pierce", "exit", "edge_torn", "pull_through"],
        }
    )
    values = metrics_of(streams(force, held.astype(float), events))
    # the insertion runs from the pierce (1.2 s) to the exit (1.6 s); the forceps hold from 1.4 s
    assert values["edge_held_at_insertion"] == pytest.approx(0.5, abs=0.01)
    assert values["peak_grasp_force"] == pytest.approx(0.8)
    assert values["forceps_tears"] == 1.0


def test_a_hand_that_never_takes_the_edge_holds_it_none_of_the_insertion():
    time = np.arange(0.0, 3.0, 0.001)
    values = metrics_of(streams(np.zeros((time.size, 3)), np.ones(time.size)))  # jaws shut on air
    assert values["edge_held_at_insertion"] == 0.0 and math.isnan(values["peak_grasp_force"])


def test_without_a_recorded_subordinate_hand_its_metrics_are_not_measured():
    time = np.arange(0.0, 3.0, 0.001)
    one_handed = SessionStreams(
        "s",
        time,
        np.zeros((time.size, 3)),
        events=pd.DataFrame({"time": [1.0, 1.2, 1.6], "kind": ["contact_start", "pierce", "exit"]}),
    )
    values = metrics_of(one_handed)
    for name in (
        "edge_held_at_insertion",
        "peak_grasp_force",
        "forceps_tears",
        "subordinate_displacement",
        "subordinate_activity",
        "bimanual_dexterity",
    ):
        assert math.isnan(values[name]), name


def two_hands(needle, assisting, duration=6.0):
    """Streams whose needle hand and assisting hand follow the paths ``needle(t)`` and ``assisting(t)``."""
    time = np.arange(0.0, duration, 0.001)
    return SessionStreams(
        "s",
        time,
        needle(time),
        subordinate_displacement=assisting(time),
        forceps_jaw=np.zeros(time.size),
        grasp_force=np.zeros((time.size, 3)),
        events=pd.DataFrame({"time": [1.0, 1.2, 1.6], "kind": ["contact_start", "pierce", "exit"]}),
    )


def reach(period, phase=0.0, amplitude=0.01, axis=0):
    """Back-and-forth reaches along one axis: speed |cos| with the given period (s) and phase."""

    def path(time):
        moved = np.zeros((time.size, 3))
        moved[:, axis] = amplitude * np.sin(2 * np.pi * time / period + phase)
        return moved

    return path


def test_hands_that_move_together_have_a_bimanual_dexterity_of_one():
    values = metrics_of(two_hands(reach(2.0), reach(2.0, amplitude=0.003, axis=2)))
    assert values["bimanual_dexterity"] == pytest.approx(1.0, abs=1e-9)


def test_hands_taking_turns_have_a_negative_bimanual_dexterity():
    # speeds |cos| and |sin|: one hand is fastest when the other stops. Over whole periods their
    # correlation is (1/pi - 4/pi^2) / (1/2 - 4/pi^2) = -0.918; the 6 Hz low-pass rounds the cusps
    # (-0.857 for 2 s reaches, -0.903 for 8 s ones, -0.910 for 16 s ones)
    time = np.arange(0.0, 24.0, 0.001)
    one, other = reach(8.0), reach(8.0, phase=np.pi / 2)
    value = metrics_of(two_hands(one, other, duration=24.0))["bimanual_dexterity"]
    first = UniformMotion.of(time, one(time), 100.0).speed
    second = UniformMotion.of(time, other(time), 100.0).speed
    assert value == pytest.approx(stats.pearsonr(first, second).statistic, abs=1e-12)
    analytic = (1 / np.pi - 4 / np.pi**2) / (0.5 - 4 / np.pi**2)
    assert value == pytest.approx(analytic, abs=0.02)


def test_an_assisting_hand_that_never_moves_has_no_bimanual_dexterity():
    values = metrics_of(two_hands(reach(2.0), lambda time: np.zeros((time.size, 3))))
    assert math.isnan(values["bimanual_dexterity"])


@settings(max_examples=15, deadline=None)
@given(
    first_period=st.floats(0.5, 3.0),
    second_period=st.floats(0.5, 3.0),
    phase=st.floats(0.0, 2 * np.pi),
    scale=st.floats(0.1, 10.0),
)
def test_bimanual_dexterity_is_symmetric_bounded_and_scale_free(first_period, second_period, phase, scale):
    one = reach(first_period)
    other = reach(second_period, phase, axis=1)
    value = metrics_of(two_hands(one, other))["bimanual_dexterity"]
    swapped = metrics_of(two_hands(other, one))["bimanual_dexterity"]
    scaled = metrics_of(two_hands(one, lambda time: scale * other(time)))["bimanual_dexterity"]
    assert -1.0 <= value <= 1.0
    assert swapped == pytest.approx(value, abs=1e-9) and scaled == pytest.approx(value, abs=1e-9)
