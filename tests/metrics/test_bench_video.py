"""Bench-model video: ChArUco calibration and ArUco tracking on synthetic video with a known camera and a
known marker trajectory; the tracked path through the same motion metrics; the catalog import."""

import numpy as np
import pytest

from metrics import SessionStreams, metrics_of
from metrics.bench.tracking import smooth_path, track_frames
from metrics.errors import MetricsError
from sim.errors import TrackingError
from sim.tracking.camera import Camera, calibrate_charuco
from sim.tracking.synthetic import default_camera_matrix
from sim.tracking.video import read_video

MOTION = ("task_time", "path_length", "economy_of_motion", "log_dimensionless_jerk", "spectral_arc_length")


def test_charuco_calibration_recovers_the_camera(bench_calibration, tmp_path):
    camera, saved = bench_calibration
    truth = default_camera_matrix()
    assert camera.rms < 0.2  # pixels
    np.testing.assert_allclose(camera.matrix, truth, rtol=2e-3, atol=1.5)  # focal and centre within ~1 px
    again = Camera.load(saved)
    np.testing.assert_array_equal(again.matrix, camera.matrix)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(TrackingError, match="is not readable"):
        Camera.load(bad)


def test_too_few_board_views_is_a_clear_error():
    blank = [np.full((480, 640), 128, np.uint8)] * 4
    with pytest.raises(TrackingError, match="found in 0 of 4 images"):
        calibrate_charuco(blank)


@pytest.mark.slow
def test_tracked_path_within_half_a_millimetre_and_metrics_within_two_percent(bench_calibration, bench_video):
    camera, _ = bench_calibration
    path, time, truth = bench_video
    frames, fps, _ = read_video(path)
    tracked = track_frames(frames, fps, camera)
    assert tracked.found.all()
    np.testing.assert_allclose(tracked.time, time)
    error = np.linalg.norm(tracked.tip - truth, axis=1)
    assert np.sqrt(np.mean(error**2)) <= 0.5e-3, np.sqrt(np.mean(error**2))
    measured = metrics_of(tracked.to_streams("bench"))
    expected = metrics_of(SessionStreams("truth", time, truth))
    for name in MOTION:
        if name == "log_dimensionless_jerk":
            # Per-movement LDLJ (issue 20) carries the tracked path's in-band error (0.34 mm RMS,
            # varying over ~0.5 s) into the jerk: -7.78 against -7.47 here. The whole-session form
            # agreed within 2 % mostly because it measured ln(task time), which both paths share.
            assert measured[name] == pytest.approx(expected[name], abs=0.4), name
            continue
        assert measured[name] == pytest.approx(expected[name], rel=0.02), name
    # The tracked path's error halved when corners moved onto fitted edges (0.36 -> 0.19 mm RMS), but
    # where the hand stops for 0.3 s (the truth's speed falls to 0.04 mm/s) the marker, face-on there,
    # wobbles the smoothed path at up to 4.4 mm/s, over the 2 mm/s movement threshold: one extra
    # submovement (3 against 2; equal with the detector's corners). Noted on issue 47.
    assert abs(measured["movement_count"] - expected["movement_count"]) <= 1
    assert np.isnan(measured["peak_force"])  # a video has no force


def test_a_lost_marker_is_bridged_briefly_and_refused_when_long():
    time = np.arange(90) / 30.0
    path = np.column_stack([np.sin(time), np.cos(time), time]) * 0.01
    short = path.copy()
    short[40:46] = np.nan  # 0.2 s
    np.testing.assert_allclose(smooth_path(time, short), smooth_path(time, path), atol=2e-4)
    long = path.copy()
    long[30:60] = np.nan  # 1 s
    with pytest.raises(MetricsError, match=r"lost for 1\.00 s"):
        smooth_path(time, long)
