"""The dashboard's live 3-D view (issue 42): frames/s in a supervisor's browser and bytes/s per watched
station, and what the station pays to publish; beside it, the size of the alternative transport (the
scene's state for the browser to render).

Run:  .venv/bin/python benchmarks/live_view.py [--seconds 8]

A real-time scripted session of the arteriotomy closure (three stitches, about 15 s) with its window on
an Xvfb display this script starts, the dashboard under uvicorn on the same catalog, headless Chromium
(Playwright) on the session's live page as a supervisor; the page's image loads are counted for
--seconds while the session runs.
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


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=8.0)
    args = parser.parse_args()
    server = start_display()
    os.environ.pop("VTK_DEFAULT_OPENGL_WINDOW", None)
    cost = publish_cost()
    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from sessions.catalog import Catalog
    from sessions.catalog.accounts import create_user
    from sessions.catalog.store import CatalogStore
    from sessions.config import database_url
    from tests.dashboard.conftest import PASSWORD, running_server
    from tests.e2e.browser import chromium

    home = Path(tempfile.mkdtemp()) / "home"
    catalog = Catalog(database_url(home))
    store = CatalogStore(catalog)
    store.create_study("Course")
    store.add_participant("Course", "P1", "trainee", "trainee")
    with catalog.session() as orm:
        create_user(orm, "supervisor", PASSWORD, "supervisor")
    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    env = dict(os.environ, VASCSIM_HOME=str(home))
    env.pop("VASCSIM_DATABASE_URL", None)
    vascsim = str(Path(sys.executable).with_name("vascsim"))
    run = subprocess.Popen(
        [vascsim, "run", "--study", "Course", "--participant", "P1", "--task", TASK, "--device", "scripted",
         "--realtime", "--view", "window"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        uid = None
        while uid is None and run.poll() is None:
            running = store.sessions("Course", status="running")
            uid = running[0].uid if running else None
            time.sleep(0.1)
        sizes: list[int] = []
        with running_server(app) as base, chromium() as browser:
            page = browser.new_page(viewport={"width": 1366, "height": 768})
            page.goto(f"{base}/login")
            page.fill("input[name=username]", "supervisor")
            page.fill("input[name=password]", PASSWORD)
            page.click("#sign-in")
            page.wait_for_load_state("networkidle")

            def on_response(response) -> None:
                if "/view.jpg" in response.url and response.status == 200:
                    sizes.append(len(response.body()))

            page.on("response", on_response)
            page.goto(f"{base}/live/sessions/{uid}")
            while not sizes and run.poll() is None:  # the window's first published frame
                page.wait_for_timeout(100)
            sizes.clear()
            start = time.perf_counter()
            page.wait_for_timeout(1000 * args.seconds)
            seconds = time.perf_counter() - start
            frames = list(sizes)
        run.wait(120)
    finally:
        if run.poll() is None:
            run.kill()
        catalog.close()
        server.terminate()
    jpeg = float(np.median(frames)) if frames else float("nan")
    print(
        f"publishing at the station: {1e3 * cost:.1f} ms a published frame (every second frame drawn: "
        f"{1e3 * cost / 2:.1f} ms a frame on average), one file whatever the number of viewers"
    )
    state = scene_state_bytes()
    print(
        f"live page, one supervisor, {seconds:.1f} s: {len(frames) / seconds:.1f} frames/s in the browser, "
        f"{sum(frames) / seconds / 1e3:.0f} kB/s for the watched station (median frame {jpeg / 1e3:.1f} kB, "
        f"960x540 JPEG at quality 75)"
    )
    print(
        f"the alternative, the scene's state for vtk.js (surface nodes, triangle stress, needle, float32): "
        f"{state / 1e3:.1f} kB a frame ({state / jpeg:.1f}x the JPEG), before the browser renders it"
    )


if __name__ == "__main__":
    main()
