"""A supervisor watches a station's 3-D view live in the dashboard (Playwright + Debian Chromium).

A real-time session runs with its window on an Xvfb display (`vascsim run --realtime --view window`),
the dashboard runs under uvicorn over the same catalog, and the supervisor's browser shows the live
page: the scene's image updates while the session runs (two frames differ), beside the plots.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from recorder.layout import SAMPLES_JOURNAL
from recorder.remote.views import view_path
from sessions.catalog import Catalog
from sessions.catalog.accounts import create_user
from sessions.catalog.store import CatalogStore
from sessions.config import database_url
from tests.dashboard.conftest import PASSWORD, running_server
from tests.e2e.browser import chromium

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive

VASCSIM = str(Path(sys.executable).with_name("vascsim"))
SNAPSHOT = """() => {
  const image = document.getElementById("live-scene");
  if (!image.naturalWidth) return [0, 0];
  const canvas = document.createElement("canvas");
  canvas.width = image.naturalWidth;
  canvas.height = image.naturalHeight;
  const context = canvas.getContext("2d");
  context.drawImage(image, 0, 0);
  const pixels = context.getImageData(0, 0, canvas.width, canvas.height).data;
  let sum = 0;
  for (let i = 0; i < pixels.length; i += 3) sum = (sum * 31 + pixels[i]) >>> 0;
  return [Number(image.dataset.frames || 0), sum];
}"""


def frames_after(page, count: int, timeout: float) -> list[int]:
    """(frames shown, a checksum of the one on screen) once the page has shown ``count`` frames (polled
    from here: the page's content security policy allows no evaluated strings)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        shown = page.evaluate(SNAPSHOT)
        if shown[0] >= count:
            return shown
        time.sleep(0.05)
    raise AssertionError(f"the live page showed {shown[0]} frames of the scene, not {count}")


def signed_in_supervisor(browser, base: str):
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    page.goto(f"{base}/login")
    page.fill("input[name=username]", "supervisor")
    page.fill("input[name=password]", PASSWORD)
    page.click("#sign-in")
    page.wait_for_load_state("networkidle")
    return page


def course(home: Path) -> tuple[Catalog, CatalogStore]:
    """A catalog at ``home`` with study Course, trainee P1 and a supervisor's account."""
    catalog = Catalog(database_url(home))
    store = CatalogStore(catalog)
    store.create_study("Course")
    store.add_participant("Course", "P1", "trainee", "trainee")
    with catalog.session() as orm:
        create_user(orm, "supervisor", PASSWORD, "supervisor")
    return catalog, store


def station_process(display: str, home: Path, *extra: str, **environment: str) -> subprocess.Popen:
    """A trainee's keyboard-and-mouse session with its window (it runs until stopped, so the test's own
    pace never decides whether it is still running)."""
    skip = ("VTK_DEFAULT_OPENGL_WINDOW", "VASCSIM_DATABASE_URL")  # the window on screen; this catalog
    env = {k: v for k, v in os.environ.items() if k not in skip}
    env.update(DISPLAY=display, VASCSIM_HOME=str(home), **environment)
    return subprocess.Popen(
        [VASCSIM, "run", "--study", "Course", "--participant", "P1", "--task", "interrupted-stitch",
         "--device", "mouse", "--view", "window", *extra],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip


def scene_updates(page, screenshot: Path) -> None:
    """The page shows the scene, new frames keep coming and they differ, beside the plots."""
    first = frames_after(page, 3, 90.0)
    page.screenshot(path=str(screenshot))
    time.sleep(1.2)  # the strip's clock moves on: the next frames differ
    second = frames_after(page, first[0] + 4, 30.0)
    assert second[0] > first[0] and second[1] != first[1]  # new frames, and they differ
    assert page.locator("#live-plots .js-plotly-plot").count() == 3  # beside the plots


def stop(run: subprocess.Popen) -> str:
    """The station's Ctrl-C; its stderr once it has ended (exit status 0: the session is complete)."""
    os.killpg(run.pid, signal.SIGINT)
    _, err = run.communicate(timeout=120)
    assert run.returncode == 0, err
    return err


def kill(run: subprocess.Popen | None) -> None:
    if run is not None and run.poll() is None:
        os.killpg(run.pid, signal.SIGKILL)
        run.communicate()


@pytest.mark.slow
def test_a_supervisor_sees_the_station_scene_update_while_the_session_runs(display, tmp_path):
    """The supervisor signs in first; then a trainee's session starts; the live page shows its scene
    updating; Ctrl-C to the station ends the session, complete."""
    home = tmp_path / "home"
    catalog, store = course(home)
    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    run = None
    try:
        with running_server(app) as base, chromium() as browser:
            page = signed_in_supervisor(browser, base)
            run = station_process(display, home)
            uid = None
            deadline = time.monotonic() + 120
            while uid is None and time.monotonic() < deadline and run.poll() is None:
                running = store.sessions("Course", status="running")
                uid = running[0].uid if running else None
                time.sleep(0.1)
            assert uid is not None, run.communicate()[1] if run.poll() is not None else "no running session"
            page.goto(f"{base}/live/sessions/{uid}")
            scene_updates(page, tmp_path / "live-page.png")
        stop(run)
    finally:
        kill(run)
        catalog.close()
    assert not (home / "live" / f"{uid}.jpg").exists()  # the published view goes with the session


@pytest.mark.slow
def test_a_supervisor_sees_a_remote_station_scene_streamed_to_the_ingest(display, tmp_path):
    """A station with its own home streams to the dashboard's ingest (`--stream-to`, its token in the
    environment): the remote station's live page shows its scene updating beside the plots; when the
    trainee stops, the central recorder holds the session, complete, and its view is gone."""
    central, station_home = tmp_path / "central", tmp_path / "station"
    catalog, store = course(central)
    course(station_home)[0].close()  # the station's own catalog: the same study and trainee
    token = store.issue_station_token("bay-3")["token"]
    settings = DashboardSettings(home=central, database_url=catalog.url)
    app = create_app(settings, catalog)
    run = None
    try:
        with running_server(app) as base, chromium() as browser:
            page = signed_in_supervisor(browser, base)
            stream = ("--stream-to", f"{base}/ingest")
            run = station_process(display, station_home, *stream, VASCSIM_STATION_TOKEN=token)
            journals = []
            deadline = time.monotonic() + 120
            while not journals and time.monotonic() < deadline and run.poll() is None:
                journals = list(settings.ingest_root.glob(f"bay-3/*/{SAMPLES_JOURNAL}"))
                time.sleep(0.1)
            assert journals, run.communicate()[1] if run.poll() is not None else "nothing streamed"
            uid = journals[0].parent.name
            page.goto(f"{base}/live")
            page.click(f"a[href='/live/stations/bay-3/{uid}']")
            scene_updates(page, tmp_path / "live-station-page.png")
            err = stop(run)  # while the central recorder still runs
    finally:
        kill(run)
        catalog.close()
    assert "central recorder" not in err  # everything was taken
    header = json.loads((settings.ingest_root / "bay-3" / uid / "header.json").read_text())
    assert header["status"] == "complete" and header["participant_id"] == "P1"
    assert not view_path(settings.ingest_root, "bay-3", uid).exists()  # the view goes with the session
    assert not (station_home / "spool" / uid).exists()  # nothing left to send
