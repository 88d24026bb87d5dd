"""The dashboard's live 3-D view (issue 42): frames/s in a supervisor's browser and bytes/s per watched
station, and what the station pays to publish; beside it, the size of the alternative transport (the
scene's state for the browser to render).

Run:  .venv/bin/python benchmarks/live_view.py [--seconds 8] [--station local|remote]

A real-time scripted session of the arteriotomy closure (three stitches, about 15 s) with its window on
an Xvfb display this script starts, the dashboard under uvicorn on the same catalog, headless Chromium
(Playwright) on the session's live page as a supervisor; the page's image loads are counted for
--seconds while the session runs. ``--station remote``: the session runs on a station with its own
home streaming to the dashboard's ingest (``--stream-to``), and the page is the remote station's.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

TASK = "arteriotomy-closure"


def start_display() -> subprocess.Popen:
    from tests.xvfb import start_virtual_display

    server, os.environ["DISPLAY"] = start_virtual_display()
    return server


def scene_state_bytes() -> int:
    """One frame of the alternative: the wall's surface node positions and each surface triangle's
    stress as float32, plus the needle (what a vtk.js view would be sent each frame)."""
    from sessions.tasks import task_spec, tissue_for

    mesh = tissue_for(task_spec(TASK)).mesh
    surface_nodes = np.unique(mesh.surface_triangles)
    return 4 * (3 * len(surface_nodes) + len(mesh.surface_triangles) + 3 * 17)


def publish_cost(repeats: int = 30) -> float:
    """Median seconds the window spends publishing one frame (read back from the front buffer, JPEG)."""
    from sessions.running.hud import HudLimits
    from sessions.running.scene import scene_facts
    from sessions.running.window import LiveWindow
    from sessions.tasks import task_spec, tissue_for

    spec = task_spec(TASK)
    tissue = tissue_for(task_spec(TASK))
    target = Path(tempfile.mkdtemp()) / "view.jpg"
    window = LiveWindow(tissue, scene_facts(spec, tissue.mesh, HudLimits(60, 3)), published=target)
    window.prepare(lambda *_: None, time.perf_counter)
    window.idle()
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        window._publish()
        times.append(time.perf_counter() - began)
    window.finish()
    return float(np.median(times))


def watched(page, base: str, address: str, run: subprocess.Popen, seconds: float, received=None):
    """(frames the page loaded, the seconds watched, views the ingest received) on the live page at
    ``address`` while ``run`` records; ``received``: the file the ingest keeps a remote view in."""
    sizes: list[int] = []
    distinct: set[int] = set()

    def on_response(response) -> None:
        if "/view.jpg" in response.url and response.status == 200:
            body = response.body()
            sizes.append(len(body))
            distinct.add(hash(body))

    page.on("response", on_response)
    page.goto(f"{base}{address}")
    while not sizes and run.poll() is None:  # the window's first published frame
        page.wait_for_timeout(100)
    sizes.clear()
    distinct.clear()
    views, seen = [], None
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        page.wait_for_timeout(10)
        if received is not None:  # each new view the ingest keeps
            try:
                facts = received.stat()
            except FileNotFoundError:
                continue
            if (facts.st_mtime_ns, facts.st_size) != seen:
                seen = (facts.st_mtime_ns, facts.st_size)
                views.append(facts.st_size)
    return list(sizes), time.perf_counter() - start, views, len(distinct)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument(
        "--station",
        choices=["local", "remote"],
        default="local",
        help="a session on this machine's catalog, or a station with its own home streaming to the "
        "dashboard's ingest (--stream-to)",
    )
    args = parser.parse_args()
    server = start_display()
    os.environ.pop("VTK_DEFAULT_OPENGL_WINDOW", None)
    cost = publish_cost()
    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from recorder.layout import SAMPLES_JOURNAL
    from recorder.remote.views import view_path
    from tests.dashboard.conftest import running_server
    from tests.e2e.browser import chromium
    from tests.e2e.test_live_scene import course, signed_in_supervisor

    home = Path(tempfile.mkdtemp()) / "home"
    catalog, store = course(home)
    settings = DashboardSettings(home=home, database_url=catalog.url)
    app = create_app(settings, catalog)
    station_home, extra = home, []
    env = dict(os.environ)
    env.pop("VASCSIM_DATABASE_URL", None)
    if args.station == "remote":
        station_home = home.parent / "station"
        course(station_home)[0].close()
        env["VASCSIM_STATION_TOKEN"] = store.issue_station_token("bay-1")["token"]
    env["VASCSIM_HOME"] = str(station_home)
    vascsim = str(Path(sys.executable).with_name("vascsim"))
    run = None
    try:
        with running_server(app) as base, chromium() as browser:
            if args.station == "remote":
                extra = ["--stream-to", f"{base}/ingest"]
            run = subprocess.Popen(
                [vascsim, "run", "--study", "Course", "--participant", "P1", "--task", TASK, "--device",
                 "scripted", "--realtime", "--view", "window", *extra],
                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )  # fmt: skip
            address = received = None
            while address is None and run.poll() is None:
                if args.station == "local":
                    running = store.sessions("Course", status="running")
                    address = f"/live/sessions/{running[0].uid}" if running else None
                else:
                    journals = list(settings.ingest_root.glob(f"bay-1/*/{SAMPLES_JOURNAL}"))
                    if journals:
                        uid = journals[0].parent.name
                        address = f"/live/stations/bay-1/{uid}"
                        received = view_path(settings.ingest_root, "bay-1", uid)
                time.sleep(0.1)
            page = signed_in_supervisor(browser, base)
            frames, seconds, views, different = watched(page, base, address, run, args.seconds, received)
            run.wait(120)
    finally:
        if run is not None and run.poll() is None:
            run.kill()
        catalog.close()
        server.terminate()
    jpeg = float(np.median(frames)) if frames else float("nan")
    print(
        f"publishing at the station: {1e3 * cost:.1f} ms a published frame (every second frame drawn: "
        f"{1e3 * cost / 2:.1f} ms a frame on average), one file whatever the number of viewers"
    )
    if received is not None:
        print(
            f"remote station to the ingest, {seconds:.1f} s: {len(views) / seconds:.1f} views/s kept, "
            f"{sum(views) / seconds / 1e3:.0f} kB/s uploaded (once, whatever the number of viewers)"
        )
    state = scene_state_bytes()
    print(
        f"live page ({args.station} station), one supervisor, {seconds:.1f} s: "
        f"{len(frames) / seconds:.1f} frames/s loaded in the browser ({different / seconds:.1f}/s of them "
        f"different: new views), {sum(frames) / seconds / 1e3:.0f} kB/s for "
        f"the watched station (median frame {jpeg / 1e3:.1f} kB, 960x540 JPEG at quality 75)"
    )
    print(
        f"the alternative, the scene's state for vtk.js (surface nodes, triangle stress, needle, float32): "
        f"{state / 1e3:.1f} kB a frame ({state / jpeg:.1f}x the JPEG), before the browser renders it"
    )


if __name__ == "__main__":
    main()
