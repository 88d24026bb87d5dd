"""The station with a real needle holder tracked by a camera (issue 47), as a trainee uses it: a real
window under Xvfb, the instruments' video played through ``camera:FILE`` on the real-time clock.

The video is a scripted wall stitch filmed with a hand over the cube for half a second, so the trial
shows the needle following the instrument, the strip saying the camera lost it, and the feedback."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

from sessions.running.filmed import film_scripted_pass
from sessions.synthetic import pass_parameters
from sim.tracking.camera import Camera
from tests.sessions.test_station import VASCSIM, Person, events_of, launch, only_uid, session_row

pytestmark = pytest.mark.exclusive

TASK = "wall-stitch"
HIDDEN = (2.0, 2.6)


@pytest.fixture
def camera_home(tmp_path):
    from sessions.catalog import Catalog
    from sessions.catalog.store import CatalogStore
    from sessions.config import database_url

    home = tmp_path / "home"
    home.mkdir()
    catalog = Catalog(database_url(home))
    store = CatalogStore(catalog)
    store.create_study("Course")
    store.add_participant("Course", "P1", "trainee", "trainee")
    catalog.close()
    video = home / "holder.mp4"
    _, matrix, _ = film_scripted_pass(TASK, pass_parameters(0.9, 3), video, hidden=HIDDEN)
    Camera(matrix, np.zeros(5), (1280, 720)).save(home / "camera.json")
    return home, video


def test_a_trainee_sutures_with_a_tracked_needle_holder_at_the_station(display, camera_home, tmp_path):
    """Instructions naming the camera, space, the live view following the instrument, the strip saying
    when the camera loses the cube, the feedback screen; the recording holds the tracking's labels and
    its lost and regained events."""
    home, video = camera_home
    person = Person(display, tmp_path)
    command = [VASCSIM, "station", "--study", "Course", "--participant", "P1", "--task", TASK]
    station = launch([*command, "--device", f"camera:{video}", "--trials", "1"], display, home)
    try:
        instructions = person.window("vascsim: instructions", process=station)
        time.sleep(0.5)
        person.screenshot("1-instructions")
        person.key(instructions, "space")
        person.window(f"vascsim: {TASK}", process=station)
        for k in range(12):  # the trial as it goes (the cube is hidden 2.0-2.6 s into the video)
            time.sleep(0.05)
            person.screenshot(f"2-live-{k:02d}")
        feedback = person.window("vascsim: feedback", process=station)
        time.sleep(0.5)
        person.screenshot("4-feedback")
        person.key(feedback, "q")
        out, err = station.communicate(timeout=60)
    finally:
        if station.poll() is None:
            station.kill()
        station.communicate()
    assert station.returncode == 0, err
    assert "Traceback" not in err
    uid = only_uid(home)
    status, metrics = session_row(home, uid)
    assert status == "complete" and metrics["task_time"] > 1.0
    kinds = events_of(home, uid)
    assert "tracking_lost" in kinds and "tracking_regained" in kinds, kinds
    assert kinds.index("tracking_lost") < kinds.index("tracking_regained")


@pytest.fixture(scope="module")
def board_video(tmp_path_factory):
    """A video of the ChArUco board shown square-on and tilted each way, as a course calibrating live
    shows it (sim.tracking.synthetic)."""
    from sim.tracking.synthetic import board_views_video

    video = tmp_path_factory.mktemp("board") / "board.mp4"
    # each view held a second (a file is read as fast as the window draws, ~30 ms a frame): the window
    # stays up for several seconds, long enough for the test to see the picture change
    board_views_video(video, size=(960, 540), hold_frames=10)
    return video


def test_live_calibration_guides_on_screen_until_every_view_is_taken(display, board_video, tmp_path):
    """`vascsim calibrate --live` on a display opens a window: the camera's picture with the board's
    corners, the checklist of views and which way to turn the board next; the instruction changes as
    views are kept, and the calibration is written when they are all taken."""
    from sim.tracking.guided import KINDS

    home = tmp_path / "home"
    person = Person(display, tmp_path)
    command = [VASCSIM, "calibrate", "--live", "--source", f"camera:{board_video}", "--view", "window"]
    run = launch(command, display, home)
    person.window("camera calibration", process=run)
    shown = []
    while run.poll() is None and len(shown) < 60:
        shown.append(person.screenshot(f"calibration-{len(shown)}"))
        time.sleep(0.25)
    out, err = run.communicate(timeout=120)
    assert run.returncode == 0, err
    assert "reprojection error" in out and (home / "camera.json").exists()
    pictures = [s for s in shown if s.std() > 20]  # the camera's picture drawn, not an empty window
    changes = [np.abs(a.astype(int) - b).mean() for a, b in itertools.pairwise(pictures)]
    assert len(pictures) >= 3 and max(changes) > 2  # the picture moves as the board turns
    assert all(kind in err for kind in KINDS)  # the terminal said it too


def test_escape_in_the_calibration_window_gives_up_and_writes_nothing(display, board_video, tmp_path):
    home = tmp_path / "home"
    person = Person(display, tmp_path)
    command = [VASCSIM, "calibrate", "--live", "--source", f"camera:{board_video}", "--view", "window"]
    run = launch(command, display, home)
    window = person.window("camera calibration", process=run)
    person.key(window, "Escape")
    out, err = run.communicate(timeout=120)
    assert run.returncode == 1 and "given up in its window; nothing was written" in err, err
    assert "Traceback" not in err and not (home / "camera.json").exists()
