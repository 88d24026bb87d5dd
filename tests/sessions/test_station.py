"""The station as a trainee uses it: a real window under Xvfb, driven by xdotool through its event loop.

Each test starts the real command (`vascsim station` or `vascsim run`) on a virtual display, waits for
its windows by title, presses keys and drags the mouse as a person would, and reads the catalog and
the recording afterwards. Screenshots of every screen are saved in the test's folder (the ones in
docs/station.md came from here).
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from recorder import open_session
from sessions.catalog import Catalog
from sessions.catalog.store import CatalogStore
from sessions.running.scene import START_HEIGHT_M, access_direction, start_pose, task_camera
from sessions.tasks import task_spec
from sim.devices.mouse import MouseMapping, needle_circle
from sim.needle import Needle, rotation_about

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive

TASK = "interrupted-stitch"
VASCSIM = str(Path(sys.executable).with_name("vascsim"))
WINDOW = (960, 540)
STATION = [
    VASCSIM,
    "station",
    "--study",
    "Course",
    "--participant",
    "P1",
    "--device",
    "mouse",
    "--trials",
    "1",
]


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    """A course with two experts and a trainee who each placed one scripted stitch (simulated time),
    so a trainee's trial at the station is judged against a standard; and P1, who has not started."""
    from sessions.config import database_url
    from sessions.running.runner import SessionPlan, run_session
    from sessions.synthetic import pass_parameters

    home = tmp_path_factory.mktemp("station-home")
    catalog = Catalog(database_url(home))
    store = CatalogStore(catalog)
    store.create_study("Course")
    for code, group, skill in (("E1", "expert", 0.95), ("E2", "expert", 0.9), ("T1", "trainee", 0.3)):
        store.add_participant("Course", code, group, group)
        plan = SessionPlan("Course", code, TASK, None)
        run_session(catalog, home, plan, lambda trial, s=skill: pass_parameters(s, seed=trial))
    store.add_participant("Course", "P1", "trainee", "trainee")
    catalog.close()
    return home


@pytest.fixture
def station_home(course, tmp_path):
    """A copy of the course for one test (a test's trials never reach another's)."""
    home = tmp_path / "home"
    shutil.copytree(course, home)
    from tests.conftest import repoint_session_folders

    repoint_session_folders(f"sqlite:///{home / 'catalog.sqlite'}", course, home)
    return home


def environment(display: str, home: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "VTK_DEFAULT_OPENGL_WINDOW"}  # on screen, not EGL
    env.update(DISPLAY=display, VASCSIM_HOME=str(home))
    env.pop("VASCSIM_DATABASE_URL", None)
    return env


def launch(command: list[str], display: str, home: Path, **options) -> subprocess.Popen:
    """The command on ``display`` with the data in ``home``, its output captured as text."""
    return subprocess.Popen(
        command,
        env=environment(display, home),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **options,
    )


class Person:
    """A trainee at the station: xdotool on ``display``, screenshots into ``folder``."""

    def __init__(self, display: str, folder: Path) -> None:
        self.env = dict(os.environ, DISPLAY=display)
        self.folder = folder

    def xdo(self, *args) -> str:
        done = subprocess.run(["xdotool", *map(str, args)], env=self.env, capture_output=True, text=True)
        return done.stdout.strip()

    def window(self, title: str, timeout: float = 120.0, process: subprocess.Popen | None = None) -> str:
        """The id of the first window whose title contains ``title``, once it is shown."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = self.xdo("search", "--onlyvisible", "--name", title)
            if found:
                return found.split()[0]
            if process is not None and process.poll() is not None:
                raise AssertionError(f"the program ended before a {title!r} window: {process.stderr.read()}")
            time.sleep(0.2)
        raise AssertionError(f"no window titled {title!r} after {timeout:.0f} s")

    def gone(self, window: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if window not in self.xdo("search", "--onlyvisible", "--name", "vascsim").split():
                return
            time.sleep(0.2)
        raise AssertionError(f"window {window} still open after {timeout:.0f} s")

    def screenshot(self, name: str) -> np.ndarray:
        """The screen as a PNG in the test's folder, and its pixels (the window's part)."""
        path = self.folder / f"{name}.png"
        subprocess.run(["import", "-window", "root", str(path)], env=self.env, check=True)
        from sim.render import read_image

        return read_image(path)[: WINDOW[1], : WINDOW[0]]

    def key(self, window: str, key: str) -> None:
        self.xdo("key", "--window", window, key)

    def hold(self, window: str, key: str, seconds: float) -> None:
        self.xdo("keydown", "--window", window, key)
        time.sleep(seconds)
        self.xdo("keyup", "--window", window, key)


class HandGeometry:
    """Where the needle holder is and how a mouse moves it: the station's own camera and mapping
    (sessions.running.scene, sim.devices.mouse), so the test's moves land where it means them to."""

    def __init__(self) -> None:
        spec = task_spec(TASK)
        self.spec = spec
        position, focal, up = (np.array(v) for v in task_camera(spec))
        self.camera = position
        self.into = (focal - position) / np.linalg.norm(focal - position)
        self.right = np.cross(self.into, up) / np.linalg.norm(np.cross(self.into, up))
        self.up = np.cross(self.right, self.into)
        self.start = start_pose(spec)
        self.step = MouseMapping().wheel_step_m

    def per_pixel(self, holder: np.ndarray) -> float:
        depth = float(np.dot(holder - self.camera, self.into))
        return 2 * depth * math.tan(math.radians(15.0)) / WINDOW[1]  # VTK's 30 deg view angle

    def move(self, person: Person, window: str, holder: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Move the holder by ``delta`` (m): wheel notches along the view, then a drag across it."""
        notches = int(round(float(np.dot(delta, self.into)) / self.step))
        for _ in range(abs(notches)):
            person.xdo("click", "--window", window, 4 if notches > 0 else 5)
            time.sleep(0.01)
        holder = holder + notches * self.step * self.into
        across = delta - np.dot(delta, self.into) * self.into
        scale = self.per_pixel(holder)
        dx, dy = np.dot(across, self.right) / scale, np.dot(across, self.up) / scale
        x0, y0 = 300, 300
        person.xdo("mousemove", "--window", window, x0, y0)
        time.sleep(0.1)
        person.xdo("mousedown", 1)
        for k in range(1, 11):
            person.xdo("mousemove", "--window", window, round(x0 + dx * k / 10), round(y0 - dy * k / 10))
            time.sleep(0.03)
        person.xdo("mouseup", 1)
        time.sleep(0.1)
        return holder + across


def events_of(home: Path, uid: str) -> list[str]:
    return open_session(home / "sessions" / uid).events_frame()["kind"].tolist()


def stop_reason(home: Path, uid: str) -> str:
    """Why the recorded session ended (its ``stopped`` event)."""
    events = open_session(home / "sessions" / uid).events_frame()
    return events.loc[events["kind"] == "stopped", "detail"].iloc[-1]


def session_row(home: Path, uid: str):
    catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    try:
        facts = CatalogStore(catalog).session_facts(uid)
        return facts.session.status, facts.metrics
    finally:
        catalog.close()


def only_uid(home: Path) -> str:
    sessions = sorted(p.name for p in (home / "sessions").iterdir())
    mine = p1_sessions(home)
    assert len(mine) == 1 and mine[0] in sessions
    return mine[0]


@pytest.mark.slow
def test_a_trainee_places_a_whole_stitch_with_keyboard_and_mouse(display, station_home, tmp_path):
    """Instructions, space, a countdown, the live view; approach with the wheel and a drag, turn the
    wrist with D until the needle is through, release with G, drag the jaws to the tip, grasp, turn
    on to pull it through: the task is done, the feedback screen gives the verdict, Q quits."""
    person, hand = Person(display, tmp_path), HandGeometry()
    station = launch(STATION, display, station_home)
    try:
        instructions = person.window("vascsim: instructions", process=station)
        time.sleep(0.5)
        person.screenshot("1-instructions")
        person.key(instructions, "space")
        live = person.window(f"vascsim: {TASK}", process=station)
        time.sleep(1.0)
        before = person.screenshot("2-live-start")
        approach = access_direction(hand.spec)
        holder = hand.move(person, live, hand.start.position, -(START_HEIGHT_M + 2e-4) * approach)
        time.sleep(0.5)
        person.screenshot("3-live-touching")
        turn_seconds = 2.0
        person.hold(live, "d", turn_seconds)  # the wrist turns the needle through the wall
        time.sleep(0.4)
        through = person.screenshot("4-live-through")
        person.key(live, "g")  # open the jaws: the needle stays in the wall
        time.sleep(0.3)
        # the jaws go to the needle's tip, where the turn took it
        vertices = Needle.curved().world_vertices(hand.start)
        centre, axis = needle_circle(vertices)
        shift = holder - hand.start.position
        turned = rotation_about(axis, turn_seconds * math.radians(MouseMapping().turn_rate_deg_s))
        tip = centre + shift + turned @ (vertices[0] - centre)
        jaws = centre + shift + turned @ (hand.start.position - centre)
        hand.move(person, live, jaws, tip - jaws)
        person.key(live, "g")  # grasp the tip
        time.sleep(0.3)
        person.hold(live, "d", 3.0)  # and pull the needle through along its curve
        feedback = person.window("vascsim: feedback", process=station)
        time.sleep(0.5)
        person.screenshot("5-feedback")
        person.key(feedback, "q")
        out, err = station.communicate(timeout=60)
    finally:
        if station.poll() is None:
            station.kill()
        station.communicate()  # reaps it and closes its pipes, also when it ended by itself
    assert station.returncode == 0, err
    assert "Traceback" not in err
    assert "1 trial(s) recorded and scored" in out
    uid = only_uid(station_home)
    status, metrics = session_row(station_home, uid)
    assert status == "complete" and metrics["task_time"] > 1.0
    kinds = events_of(station_home, uid)
    for kind in ("contact_start", "pierce", "release", "regrab", "pull_through"):
        assert kind in kinds, kinds
    assert np.abs(through.astype(int) - before.astype(int)).max() > 50  # the scene moved on screen


@pytest.mark.slow
def test_escape_mid_session_keeps_a_complete_scored_session(display, station_home, tmp_path):
    person = Person(display, tmp_path)
    station = launch(STATION, display, station_home)
    try:
        person.key(person.window("vascsim: instructions", process=station), "space")
        live = person.window(f"vascsim: {TASK}", process=station)
        time.sleep(2.0)
        person.key(live, "Escape")
        feedback = person.window("vascsim: feedback", process=station)
        time.sleep(0.5)
        shown = person.screenshot("feedback-after-escape")
        person.key(feedback, "q")
        out, err = station.communicate(timeout=60)
    finally:
        if station.poll() is None:
            station.kill()
        station.communicate()  # reaps it and closes its pipes, also when it ended by itself
    assert station.returncode == 0 and "Traceback" not in err, err
    uid = only_uid(station_home)
    status, metrics = session_row(station_home, uid)
    assert status == "complete" and 1.0 < metrics["task_time"] < 30.0
    assert stop_reason(station_home, uid) == "stopped_by_trainee"
    assert shown.std() > 10  # the feedback screen has something on it


@pytest.mark.slow
def test_ctrl_c_in_the_terminal_ends_the_run_complete_with_no_traceback(display, station_home):
    """`vascsim run --device mouse` with no --duration (a live device runs until stopped) opens the
    window; Ctrl-C (SIGINT to the terminal's process group) ends it complete and scored, and the
    terminal's last lines are the verdict and what to work on."""
    person = Person(display, station_home)
    run = launch(
        [VASCSIM, "run", "--study", "Course", "--participant", "P1", "--task", TASK, "--device", "mouse"],
        display,
        station_home,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    try:
        person.window(f"vascsim: {TASK}", process=run)
        time.sleep(2.0)
        os.killpg(run.pid, signal.SIGINT)
        out, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
        run.communicate()  # reaps it and closes its pipes, also when it ended by itself
    assert run.returncode == 0, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    uid = only_uid(station_home)
    status, _ = session_row(station_home, uid)
    assert status == "complete"
    lines = out.strip().splitlines()
    assert lines[0].startswith(f"session {uid} (P1, trial 1) complete and scored")
    assert lines[1].startswith("verdict: ")
    assert any(line.startswith("work on") for line in lines) and lines[-1].startswith("all metrics:")
    assert stop_reason(station_home, uid) == "interrupted"


class RecordedReports:
    """A SpaceMouse's HID handle that plays report bytes (report id first, the documented formats) at
    their times from its first read: what the live decoder reads from a real device."""

    def __init__(self, reports: list[tuple[float, bytes]]) -> None:
        self.reports, self.first = list(reports), None

    def read(self, size: int) -> list[int]:
        now = time.perf_counter()
        self.first = self.first if self.first is not None else now
        if self.reports and now - self.first >= self.reports[0][0]:
            return list(self.reports.pop(0)[1][:size])
        return []

    def close(self) -> None:
        """Nothing to close."""


def test_the_spacemouse_button_starts_the_trial_once_released(display, monkeypatch):
    """The instruction screen's start on the device in hand: SpaceMouse report bytes (a button pressed
    at 0.3 s, released at 0.9 s) through the live decoder, read while the screen's event loop runs; it
    starts on the release (a held second button would stop the trial it started) and lets go of the
    device before the trial opens it again. A device that cannot be opened leaves the space bar."""
    from sessions.running.screens import Screen
    from sessions.running.station import _wait_to_start, instruction_lines
    from sessions.running.window import ViewSettings
    from sim.devices.base import DeviceError
    from sim.devices.spacemouse import SpaceMouse

    monkeypatch.setenv("DISPLAY", display)
    monkeypatch.delenv("VTK_DEFAULT_OPENGL_WINDOW", raising=False)
    reports = [
        (0.3, bytes([3]) + (2).to_bytes(4, "little")),  # the right button down
        (0.9, bytes([3]) + (0).to_bytes(4, "little")),  # up
    ]
    handle = RecordedReports(reports)
    closed = []
    handle.close = lambda: closed.append(True)
    screen = Screen(ViewSettings(), "instructions")
    try:
        screen.show(instruction_lines(task_spec(TASK), "spacemouse", "P1"))
        began = time.perf_counter()
        assert _wait_to_start(screen, lambda: SpaceMouse(source=handle)) == "start"
        assert time.perf_counter() - began >= 0.85 and closed == [True]  # on the release, then let go

        def unplugged():
            raise DeviceError("no SpaceMouse found")

        window = "$(xdotool search --onlyvisible --name vascsim | head -1)"
        pressing = f"sleep 1; xdotool key --window {window} space"
        presser = subprocess.Popen(["sh", "-c", pressing], env=dict(os.environ))
        assert _wait_to_start(screen, unplugged) == "start"  # the space bar, as without a device
        presser.wait(10)
    finally:
        screen.close()


def test_a_display_nobody_serves_is_named_in_one_line_not_a_crash(station_home):
    """DISPLAY names an X display with no server behind it (as after a remote session ended): the
    station says which display it could not reach and exits 2; the window library is never asked
    (it ends the process with a segmentation fault when its connection is refused)."""
    env = environment(":987", station_home)
    done = subprocess.run(STATION, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "cannot connect to the X display ':987'" in done.stderr
    assert "Traceback" not in done.stderr and "vtk" not in done.stderr.lower()
    assert p1_sessions(station_home) == []  # no trial was started


def p1_sessions(home: Path) -> list[str]:
    catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    try:
        return [r.uid for r in CatalogStore(catalog).sessions("Course") if r.participant == "P1"]
    finally:
        catalog.close()


@pytest.mark.slow
def test_spacemouse_reports_drive_the_needle_in_the_window(display, course, tmp_path, monkeypatch):
    """Report bytes of a SpaceMouse (jaws closed, then the cap pushed along z for a second, then let go)
    go through the live decoder in the haptic process; the needle moves on screen and in the log."""
    import struct

    from sessions.config import cache_dir
    from sessions.running.live import LiveView
    from sessions.running.scene import mapped_onto_task
    from sessions.tasks import task_simulation
    from sim.devices.spacemouse import FULL_SCALE, SpaceMouse
    from sim.devices.workspace import view_axes

    monkeypatch.setenv("DISPLAY", display)
    monkeypatch.delenv("VTK_DEFAULT_OPENGL_WINDOW", raising=False)
    push = 100  # of +-350: 100 / 350 x 20 mm/s = 5.7 mm/s
    reports = [
        (0.0, bytes([3]) + (1).to_bytes(4, "little")),  # button 1 down: the jaws hold the needle
        (1.5, bytes([1]) + struct.pack("<6h", 0, 0, push, 0, 0, 0)),  # 13-byte report: push along z
        (2.5, bytes([1]) + struct.pack("<6h", 0, 0, 0, 0, 0, 0)),  # let go
    ]
    spec = task_spec(TASK)
    device = mapped_onto_task(SpaceMouse(source=RecordedReports(reports)), spec)  # as the station does
    catalog = Catalog(f"sqlite:///{course / 'catalog.sqlite'}")
    try:
        window = LiveView().window(spec, device, catalog, course, (1, 1))
    finally:
        catalog.close()
    simulation = task_simulation(task_spec(TASK), device, cache_dir(course), renderer=window)
    window.simulation = simulation
    person = Person(display, tmp_path)
    shots: dict[str, np.ndarray] = {}

    def watch() -> None:
        person.window(f"vascsim: {TASK}")
        time.sleep(0.6)
        shots["before"] = person.screenshot("spacemouse-before")
        time.sleep(2.2)
        shots["after"] = person.screenshot("spacemouse-after")

    import threading

    watcher = threading.Thread(target=watch)
    watcher.start()
    result = simulation.run_realtime(3.6)  # the reports' clock starts at the haptic set-up's first read
    watcher.join(30)
    failures = [e.detail for e in result.events if e.kind == "layer_failed"]
    assert "after" in shots, f"no window: {failures}"
    log = result.haptic
    start = start_pose(spec).position  # the integration starts there, at the warm read (t = 0)
    moved = log.position[-1] - start
    # the reports' clock starts at the haptic set-up's first (warm) read; the loop starts after the
    # display is up (0.1-1.5 s later, by host), so the loop sees the last part of the 1-s push or all
    # of it. Rate control: the holder moves at the push's speed for as long as the loop saw it.
    path = np.vstack([start, log.position])
    ticks = np.diff(np.concatenate([[0.0], log.time]))
    pushed_s = float(ticks[np.linalg.norm(np.diff(path, axis=0), axis=1) > 0].sum())
    assert 0.3 < pushed_s < 1.0 + 0.01, pushed_s
    expected = push / FULL_SCALE * 0.02 * pushed_s  # m: that speed for that long
    towards_you = view_axes(*task_camera(spec))[:, 2]  # the cap's z: out of the screen, towards the user
    assert np.linalg.norm(moved) == pytest.approx(expected, rel=0.05)
    assert np.dot(moved, towards_you) / np.linalg.norm(moved) > 0.9999
    changed = np.abs(shots["after"].astype(int) - shots["before"].astype(int))[80:].max(axis=2) > 60
    assert changed.sum() > 300  # the needle (and its shadow) moved on screen, below the strip
    assert "display" not in {e.layer for e in result.events if e.kind == "layer_failed"}


def test_spacemouse_reports_drive_the_forceps_that_lift_the_wound_edge():
    """A second hand at the station (--sub-device spacemouse): SpaceMouse report bytes (the cap's
    button closes the jaws, a gentle push towards the user lifts the edge, the button let go opens
    them) go through the live decoder in the haptic process beside the needle hand's device; the
    forceps grasp the edge where they start, lift it and let it go, and the FEM layer holds it."""
    import struct

    from sessions.running.hands import forceps_on
    from sessions.tasks import task_simulation
    from sim.devices.mouse import MouseDevice
    from sim.devices.spacemouse import FULL_SCALE, SpaceMouse
    from sim.devices.workspace import view_axes

    push = 20  # of +-350: 20 / 350 x 20 mm/s = 1.1 mm/s, for 0.4 s: a 0.46 mm lift
    reports = [
        # the reports' clock starts at the haptic set-up's warm read, the loop up to ~1.5 s later
        (1.5, bytes([3]) + (1).to_bytes(4, "little")),  # button 1 down: the jaws close on the edge
        (1.8, bytes([1]) + struct.pack("<6h", 0, 0, push, 0, 0, 0)),  # push towards the user
        (2.2, bytes([1]) + struct.pack("<6h", 0, 0, 0, 0, 0, 0)),  # let go of the cap
        (2.8, bytes([3]) + (0).to_bytes(4, "little")),  # button up: the jaws open
    ]
    spec = task_spec(TASK)
    forceps = forceps_on(SpaceMouse(source=RecordedReports(reports)), spec)  # as the station maps it
    needle = MouseDevice(start_pose(spec))  # the needle hand waits above the first mark
    simulation = task_simulation(task_spec(TASK), needle, subordinate=forceps)
    held = []
    simulation.on_graphics = lambda now, fem: held.append((now, fem.grasp_force, fem.grasp_displacement))
    result = simulation.run_realtime(3.4)
    kinds = [event.kind for event in result.events]
    assert kinds.count("grasp") == 1 and kinds.count("release_grasp") == 1, kinds
    assert "edge_torn" not in kinds
    lifts = np.array([d for _, f, d in held if f is not None and np.any(f != 0)])
    towards_you = view_axes(*task_camera(spec))[:, 2]
    largest = lifts[np.argmax(np.linalg.norm(lifts, axis=1))]
    expected = push / FULL_SCALE * 0.02 * 0.4  # m: the push's speed for its 0.4 s
    assert np.linalg.norm(largest) == pytest.approx(expected, rel=0.1)
    assert np.dot(largest, towards_you) / np.linalg.norm(largest) > 0.999
    forces = np.array([np.linalg.norm(f) for _, f, _ in held if f is not None and np.any(f != 0)])
    assert 0.01 < forces.max() < 1.35  # lifting the edge half a millimetre, short of tearing it
    assert not np.any(held[-1][1])  # let go: the tissue is back at rest, the forceps hold nothing


STEREO_SCRIPT = """
import json, sys, time
import numpy as np
from sessions.running.hud import HudLimits
from sessions.running.scene import scene_facts
from sessions.running.window import LiveWindow, ViewSettings
from sessions.tasks import task_spec, tissue_for

tissue = tissue_for(task_spec("interrupted-stitch"))
facts = scene_facts(task_spec("interrupted-stitch"), tissue.mesh, HudLimits(60, 1))
drawn = {}
for mode in (None, sys.argv[1]):
    window = LiveWindow(tissue, facts, ViewSettings(stereo=mode))
    window.prepare(lambda *_: None, time.perf_counter)
    window.idle()
    drawn[mode] = window._renderer.read_pixels().astype(int)
    window.finish()
mono, both = drawn[None], drawn[sys.argv[1]]
print(json.dumps({
    "largest_change": int(np.abs(both - mono).max()),
    "green_blue_mono": float(np.abs(mono[..., 1] - mono[..., 2]).mean()),
    "green_blue_stereo": float(np.abs(both[..., 1] - both[..., 2]).mean()),
}))
"""


@pytest.mark.parametrize("stereo", ["anaglyph", "split"])
def test_a_stereo_mode_draws_two_eyes(display, course, stereo):
    """--stereo: anaglyph draws the two eyes in red and cyan, split side by side; both differ from the
    mono view (drawn by a process of its own, whose X connection ends with it)."""
    import json

    from sessions.running.window import ViewSettings, WindowError

    env = environment(display, course)
    done = subprocess.run(
        [sys.executable, "-c", STEREO_SCRIPT, stereo], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["largest_change"] > 100
    if stereo == "anaglyph":  # each eye in its own colour: green and blue no longer track each other
        assert seen["green_blue_stereo"] != seen["green_blue_mono"]
    with pytest.raises(WindowError, match="stereo must be one of anaglyph, split, crystal-eyes; got 'vr'"):
        ViewSettings(stereo="vr")
