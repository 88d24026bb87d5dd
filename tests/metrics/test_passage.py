"""How the needle went through the wall (issue 22): needle-curve following, swept tissue, wound-edge
stress, back-wall catches and extra punctures, on constructed needles and drives with known answers."""

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from metrics import metrics_of
from metrics.signals.passage import (
    WoundEdgeStress,
    nearest_on_curve,
    passage_columns,
    track_and_sweep,
)
from metrics.streams import NeedleFrames
from tests.metrics.test_placement import WALL, at_node, bite, event, streams_of

ENTRY = np.array([0.0105, 0.005, 0.0015])


def shifted(point, dx=0.0, dy=0.0, dz=0.0):
    return np.asarray(point, dtype=float) + np.array([dx, dy, dz])


def straight_needle(tip, direction=(0.0, 0.0, -1.0), length=0.01, vertices=21):
    """A straight needle's vertices, tip first, running back from ``tip`` against ``direction``."""
    direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.asarray(tip, dtype=float) - np.linspace(0.0, length, vertices)[:, None] * direction


def frames_of(needles, states, drives=None):
    n = len(needles)
    return NeedleFrames(
        np.arange(n) / 30.0,
        np.asarray(states, dtype=np.int8),
        np.asarray(needles, dtype=float),
        drives if drives is not None else [None] * n,
        np.full(n, 0.004),
    )


def test_nearest_point_on_the_needle_by_hand():
    needle = straight_needle((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), length=0.01, vertices=11)  # up the z axis
    distance, arc, past_tail = nearest_on_curve(needle, np.array([0.0003, 0.0, 0.004]))
    assert distance == pytest.approx(0.0003) and arc == pytest.approx(0.004) and not past_tail
    assert nearest_on_curve(needle, np.array([0.0, 0.0, 0.02]))[2]  # beyond the tail: pulled through


def test_a_needle_sliding_along_its_own_track_sweeps_nothing():
    """Pushed straight down through the entry point 0.1 mm a frame: offset 0, swept area 0."""
    needles = [straight_needle(shifted(ENTRY, dz=-1e-4 * k)) for k in range(1, 15)]
    offset, area = track_and_sweep(frames_of(needles, [2] * 14), slice(0, 14), ENTRY, 0.0015)
    assert offset == pytest.approx(0.0, abs=1e-12) and area == pytest.approx(0.0, abs=1e-15)


def test_a_levered_needle_is_off_its_track_and_sweeps_by_hand():
    """Tip 1 mm into the wall, the needle moved sideways 0.1 mm a frame for 5 frames (offsets 0, 0.1,
    ... 0.4 mm): mean offset 0.2 mm; swept area 4 x 0.1 mm x 1 mm inside = 0.4 mm^2."""
    tip = shifted(ENTRY, dz=-0.001)
    needles = [straight_needle(shifted(tip, 1e-4 * k)) for k in range(5)]
    offset, area = track_and_sweep(frames_of(needles, [2] * 5), slice(0, 5), ENTRY, 0.0015)
    assert offset == pytest.approx(0.0002, rel=1e-9)
    assert area == pytest.approx(4 * 1e-4 * 1e-3, rel=1e-9)
    free = track_and_sweep(frames_of(needles, [0] * 5), slice(0, 5), ENTRY, 0.0015)
    assert math.isnan(free[0]) and free[1] == 0.0  # never in the wall: no offset, nothing swept


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.01, 0.01), st.floats(-0.01, 0.01), st.floats(-0.01, 0.01), st.floats(0.0, 2 * math.pi))
def test_track_offset_and_swept_area_do_not_depend_on_where_the_wall_is(dx, dy, dz, angle):
    """Moving and turning the whole scene (needle and entry point) about the z axis changes nothing."""
    tip = shifted(ENTRY, dz=-0.001)
    needles = np.array([straight_needle(shifted(tip, 1e-4 * k, 5e-5 * k * k)) for k in range(6)])
    reference = track_and_sweep(frames_of(needles, [2] * 6), slice(0, 6), ENTRY, 0.0015)
    c, s = math.cos(angle), math.sin(angle)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([dx, dy, dz])
    moved = track_and_sweep(
        frames_of(needles @ turn.T + shift, [2] * 6), slice(0, 6), turn @ ENTRY + shift, 0.0015
    )
    assert moved == pytest.approx(reference, rel=1e-7, abs=1e-15)


def test_a_pierce_in_through_the_lumen_is_a_back_wall_catch_not_a_stitch():
    """A proper bite, then the needle's tip pierces the intima from the lumen side (a face whose
    outward normal is the far normal): one stitch, one back-wall catch, no extra puncture."""
    catch = [event(2.5, "pierce", *at_node(WALL, (0.008, 0.005, 0.0), (0, 0, -1)))]
    values = metrics_of(streams_of(bite((0.0105, 0.005, 0.0015), (0.0105, 0.005, 0.0)) + catch))
    assert values["back_wall_catches"] == 1.0 and values["extra_punctures"] == 0.0
    clean = metrics_of(streams_of(bite((0.0105, 0.005, 0.0015), (0.0105, 0.005, 0.0))))
    for name in ("entry_to_target", "exit_to_target", "bite_error_entry", "full_thickness_fraction"):
        assert values[name] == clean[name]  # the catch is not scored as a bite
    assert clean["back_wall_catches"] == 0.0


def test_a_second_hole_for_one_mark_is_an_extra_puncture():
    first = bite((0.010, 0.005, 0.0015))  # pierced, withdrawn
    again = [dict(e, time=e["time"] + 2.0) for e in bite((0.0105, 0.005, 0.0015), (0.0105, 0.005, 0.0))]
    assert metrics_of(streams_of(first + again))["extra_punctures"] == 1.0
    assert metrics_of(streams_of(again))["extra_punctures"] == 0.0
    assert math.isnan(metrics_of(streams_of(again, targets=None))["extra_punctures"])


@pytest.fixture(scope="module")
def wound_patch():
    """The interrupted stitch's artery patch with its arteriotomy (the task library's tissue)."""
    from sessions.tasks import task_spec, tissue_for

    return tissue_for(task_spec("interrupted-stitch"), None)


def test_wound_edge_stress_is_the_full_replay_at_the_cut_faces_and_grows_nearer_the_edge(wound_patch):
    """The edge-only replay equals the whole-surface replay (an independent path through the same
    solver) at the wound's cut-face triangles; the same push 1 mm nearer the edge loads it more."""
    from sim.fem.fields import TissueFieldReplay

    mesh = wound_patch.mesh
    edge = mesh.wound_edge_elements
    cut = np.isin(mesh.surface_triangles, np.r_[mesh.node_sets["wound_a"], mesh.node_sets["wound_b"]])
    assert edge.size and set(edge) == set(mesh.surface_elements[cut.all(axis=1)])
    outer = mesh.node_sets["outer"]
    angle = np.degrees(np.arctan2(mesh.points[outer, 1], mesh.points[outer, 0]))
    mid = np.abs(mesh.points[outer, 2] - 0.005) < 1e-4

    def node_at(degrees):
        return int(outer[mid][np.argmin(np.abs(angle[mid] - degrees))])

    push = np.array([[-3e-4, 0.0, 0.0]])
    full = TissueFieldReplay(wound_patch)
    stress = WoundEdgeStress(wound_patch)
    peaks = []
    for degrees in (27.0, 16.0):  # about 2.5 and 1.5 mm from the edge on the adventitia
        node = np.array([node_at(degrees)])
        frames = frames_of([straight_needle(mesh.points[node[0]])], [1], [(node, push, math.nan)])
        peak = stress.peak(frames, slice(0, 1))
        _, surface = full.state(node, push, 0.004)
        expected = surface[np.isin(mesh.surface_elements, edge)].max()
        assert peak == pytest.approx(expected, rel=1e-9)
        peaks.append(peak)
    assert peaks[1] > 1.5 * peaks[0] > 0


def test_passage_columns_follow_each_stitch_through_its_own_frames(wound_patch):
    """Two stitches: the first pushed straight through (offset 0), the second levered 0.1 mm a frame;
    each keeps its own offset, and only frames with a drive load the edge."""
    first = straight_needle(shifted(ENTRY, dz=-0.001))
    second_entry = shifted(ENTRY, dy=0.002)
    levered = [straight_needle(shifted(second_entry, 1e-4 * k, 0.0, -0.001)) for k in range(3)]
    needles = [first, first, straight_needle(shifted(ENTRY, dz=0.005)), *levered]
    frames = frames_of(needles, [2, 2, 0, 2, 2, 2])
    stitches = pd.DataFrame(
        {
            "pierce_time": [0.0, 3 / 30.0],
            "entry_x": [ENTRY[0], second_entry[0]],
            "entry_y": [ENTRY[1], second_entry[1]],
            "entry_z": [ENTRY[2], second_entry[2]],
            "exit_x": [np.nan, np.nan],
            "exit_y": [np.nan, np.nan],
            "exit_z": [np.nan, np.nan],
        }
    )
    table = passage_columns(stitches, frames, wound_patch)
    assert table["track_offset"].tolist() == pytest.approx([0.0, 1e-4], abs=1e-12)
    assert table["swept_area"].tolist() == pytest.approx([0.0, 2 * 1e-4 * 1e-3], abs=1e-15)
    assert table["wound_edge_stress"].isna().all()  # no frame drove the tissue
