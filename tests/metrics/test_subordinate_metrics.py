"""The subordinate hand's metrics on hand-built streams with known answers."""

import math

import numpy as np
import pandas as pd
import pytest

from metrics import SessionStreams, metrics_of


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
    ):
        assert math.isnan(values[name]), name
