"""The station's figures (issue 42): the live window's frame rate, motion to photon, and the haptic loop
with the window open, on the interrupted stitch's vessel patch under software rendering.

Run:  .venv/bin/python benchmarks/station.py [--seconds 30] [--sizes 960x540,1280x720]

Needs a display: the station's own, or (without DISPLAY) an Xvfb this script starts; Mesa's llvmpipe
renders either way on a machine without a GPU. For each window size:

1. the reference in the same run: a bare PyVista window of the task's surface (its 5,760 triangles,
   no needle, no strip, no simulation), rendered as fast as it goes, frames/s;
2. the station's live window (sessions.running.window.LiveWindow) on a real-time run of all layers
   (haptic 1 kHz in its own process, FEM 500 Hz, graphics 30 Hz, display 30 Hz in its own process),
   a scripted hand placing the closure row's three bites twice: display frames/s and the interval
   between swaps (p50, p99), motion to photon (a device sample's time to the swap of the first frame
   that shows its needle: p50, p95, p99), the haptic loop's rate and p99 period, contact-change p99.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

# this folder holds a metrics.py of its own: the package, not it
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests.xvfb

TASK = "interrupted-stitch"


def start_display() -> subprocess.Popen | None:
    """An Xvfb when there is no display; None when there is one."""
    if os.environ.get("DISPLAY"):
        return None
    from tests.xvfb import start_virtual_display

    server, os.environ["DISPLAY"] = start_virtual_display("1920x1080")
    return server


def bare_window_fps(mesh, size: tuple[int, int], seconds: float = 5.0) -> float:
    """Frames/s of a bare PyVista window showing the task's surface, re-rendered in a loop."""
    import pyvista as pv

    faces = np.hstack([np.full((len(mesh.surface_triangles), 1), 3), mesh.surface_triangles]).ravel()
    plotter = pv.Plotter(window_size=size, title="bare", lighting="none")
    plotter.add_light(pv.Light(light_type="headlight"))
    plotter.disable_anti_aliasing()
    plotter.add_mesh(pv.PolyData(mesh.points.copy(), faces), color="pink")
    plotter.show(auto_close=False, interactive_update=True)
    frames, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        plotter.render_window.Render()
        frames += 1
    rate = frames / (time.perf_counter() - start)
    plotter.close()
    return rate


def station_run(size: tuple[int, int] | None, seconds: float, delay_frames: int) -> dict:
    from sessions.config import cache_dir, data_home
    from sessions.running.hud import HudLimits
    from sessions.running.runner import LIVE_SETTINGS
    from sessions.running.scene import scene_facts
    from sessions.running.window import LiveWindow, ViewSettings
    from sessions.tasks import task_preset, task_simulation, task_spec, tissue_for
    from sim.devices import ScriptedDevice, SuturingPass
    from sim.devices.scripted import sequence_of_passes
    from sim.needle import Needle

    spec = task_spec(TASK)
    tissue = tissue_for(task_spec(TASK), cache_dir(data_home()))
    row = task_spec("arteriotomy-closure").bites()  # three bites on the same vessel patch
    passes = [SuturingPass(Needle.curved(), *bite) for bite in row + row]
    trajectory, total = sequence_of_passes(passes)
    limits = HudLimits(
        spec.time_budget_s,
        spec.stitch_count,
        (0.8, 1.1),
        3.3,
        task_preset(task_spec(TASK)).forces.damage_stress,
    )
    log = Path(tempfile.mkdtemp()) / "latency.npy"
    window = None
    if size is not None:
        facts = scene_facts(spec, tissue.mesh, limits)
        window = LiveWindow(tissue, facts, ViewSettings(size=size), latency_log=log)
    settings = replace(LIVE_SETTINGS, display_delay_frames=delay_frames)  # as the station runs
    simulation = task_simulation(
        task_spec(TASK),
        ScriptedDevice(trajectory),
        cache_dir(data_home()),
        renderer=window,
        settings=settings,
    )
    if window is not None:
        window.simulation = simulation
    duration = min(seconds, total)
    result = simulation.run_realtime(duration)
    frames = np.load(log) if window is not None else np.full((3, 2), np.nan)
    simulation.close()
    shown = frames[np.isfinite(frames[:, 0])]
    latency = shown[:, 1] - shown[:, 0] if len(shown) else np.full(1, np.nan)
    intervals = np.diff(frames[:, 1])
    changes = simulation.contact_latencies["contact_start"] + simulation.contact_latencies["exit"]
    haptic, display = result.telemetry["haptic"], result.telemetry["display"]
    return {
        "duration": duration,
        "display_fps": len(frames) / (frames[-1, 1] - frames[0, 1]),
        "display_rate": display.rate_hz,
        "display_compute_p50": display.compute_p50,
        "display_compute_p99": display.compute_p99,
        "interval_p50": np.percentile(intervals, 50),
        "interval_p99": np.percentile(intervals, 99),
        "mtp_p50": np.percentile(latency, 50),
        "mtp_p95": np.percentile(latency, 95),
        "mtp_p99": np.percentile(latency, 99),
        "haptic_rate": haptic.rate_hz,
        "haptic_p99": haptic.period_p99,
        "haptic_over": (haptic.periods_over_2ms, haptic.periods_over_3ms),
        "contact_changes": len(changes),
        "contact_p99": np.percentile(changes, 99) if changes else float("nan"),
        "failed": [e.detail for e in result.events if e.kind == "layer_failed"],
        "layers": {
            layer: (
                result.telemetry[layer].rate_hz,
                result.telemetry[layer].compute_p50,
                result.telemetry[layer].compute_p99,
            )
            for layer in ("fem", "graphics")
        },
    }


def report(label: str, f: dict, bare: float | None) -> None:
    ms = {k: 1e3 * v for k, v in f.items() if k.startswith(("interval", "mtp", "haptic_p99", "contact_p99"))}
    if bare is not None:
        print(f"[{label}] bare window (reference, nothing else running): {bare:.1f} frames/s", flush=True)
        print(
            f"[{label}] station window, all layers, {f['duration']:.0f} s: {f['display_fps']:.1f} "
            f"frames/s (display layer {f['display_rate']:.1f} Hz), swap interval p50 "
            f"{ms['interval_p50']:.1f} ms p99 {ms['interval_p99']:.1f} ms; "
            f"ratio to the bare window {f['display_fps'] / bare:.2f}; a frame's work p50 "
            f"{1e3 * f['display_compute_p50']:.1f} ms p99 {1e3 * f['display_compute_p99']:.1f} ms",
            flush=True,
        )
        print(
            f"[{label}] motion to photon (device sample -> swap of the frame showing it): p50 "
            f"{ms['mtp_p50']:.1f} ms p95 {ms['mtp_p95']:.1f} ms p99 {ms['mtp_p99']:.1f} ms",
            flush=True,
        )
    print(
        f"[{label}] haptic loop: {f['haptic_rate']:.1f} Hz, p99 period {ms['haptic_p99']:.3f} ms, "
        f"periods over 2 / 3 ms: {f['haptic_over'][0]} / {f['haptic_over'][1]}; "
        f"contact changes n={f['contact_changes']} p99 {ms['contact_p99']:.2f} ms"
        + (f"; FAILED: {f['failed']}" if f["failed"] else ""),
        flush=True,
    )
    print(
        f"[{label}] "
        + "; ".join(
            f"{layer} {rate:.0f} Hz, compute p50 {1e3 * p50:.2f} ms p99 {1e3 * p99:.2f} ms"
            for layer, (rate, p50, p99) in f["layers"].items()
        ),
        flush=True,
    )


def one(size_text: str, delay: int, seconds: float) -> None:
    """One configuration in this (fresh) process: its caches start cold, as a station's first trial."""
    from sessions.config import cache_dir, data_home
    from sessions.tasks import task_spec, tissue_for

    mesh = tissue_for(task_spec(TASK), cache_dir(data_home())).mesh
    if size_text == "none":
        report("no window", station_run(None, seconds, delay), None)
        return
    size = tuple(int(v) for v in size_text.split("x"))
    bare = bare_window_fps(mesh, size)
    report(f"{size_text}, display {delay} frame(s) behind", station_run(size, seconds, delay), bare)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument(
        "--runs",
        default="none:0,960x540:0,960x540:1,1280x720:0",
        help="SIZE:FRAMES_BEHIND,... (none: no window)",
    )
    parser.add_argument("--one", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    server = start_display()
    os.environ.pop("VTK_DEFAULT_OPENGL_WINDOW", None)  # on screen
    try:
        if args.one is not None:
            size_text, delay = args.one.split(":")
            one(size_text, int(delay), args.seconds)
            return
        from sessions.config import cache_dir, data_home
        from sessions.tasks import task_spec, tissue_for

        mesh = tissue_for(task_spec(TASK), cache_dir(data_home())).mesh  # built (and cached on disk) once
        triangles = len(mesh.surface_triangles)
        print(f"{TASK}: {mesh.n_nodes} nodes, {triangles} surface triangles; DISPLAY {os.environ['DISPLAY']}")
        for run in args.runs.split(","):
            subprocess.run(
                [sys.executable, __file__, "--seconds", str(args.seconds), "--one", run], check=True
            )
    finally:
        if server is not None:
            server.terminate()
            server.wait(10)


if __name__ == "__main__":
    sys.exit(main())
