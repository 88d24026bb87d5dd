"""Replay and bench-video figures of issue 8.

Run:  .venv/bin/python benchmarks/replay.py [--repeats 3]

- replay export at 1280x720, 30 frames/s, H.264, ghost mode against an expert (the
  session itself, so alignment and the ghost are exercised), of a ~24 s recorded
  session on the paper's test cube and on the ~10k-node artery (vessel_10k, on-demand
  columns): median of repeats, frames per second of the whole export (reading the
  session, alignment, tissue state per frame, rendering, HUD, encoding) and of the
  render-and-encode loop alone, with a freshly built tissue model (cold) and with one
  already used (warm); target >= 30 frames/s (real time). The reference is a
  naive PyVista screenshot loop at 10-20 frames/s, measured here in the same process;
- ArUco tracking of a synthetic 1920x1080 bench video (10 s, 30 frames/s): frames per
  second on decoded frames, and including H.264 decoding; target >= 30 frames/s.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from metrics.bench.tracking import track_frames  # noqa: E402
from metrics.replay.export import ReplaySettings, export_replay  # noqa: E402
from recorder import SessionWriter, open_session  # noqa: E402
from recorder.runtime import RuntimeRecorder  # noqa: E402
from sessions.config import prepare_rendering  # noqa: E402
from sim.calibration.presets import tissue_preset  # noqa: E402
from sim.calibration.scenarios import practice_passes, scenario  # noqa: E402
from sim.devices import ScriptedDevice  # noqa: E402
from sim.devices.scripted import sequence_of_passes  # noqa: E402
from sim.fem import BiphaseTissue  # noqa: E402
from sim.needle import Needle  # noqa: E402
from sim.runtime import Simulation  # noqa: E402
from sim.tracking.camera import Camera  # noqa: E402
from sim.tracking.synthetic import default_camera_matrix, write_bench_video  # noqa: E402
from sim.tracking.video import read_video  # noqa: E402

ARTERY = tissue_preset("porcine-artery").biphase  # the calibrated wall the default needle forces suit


def record(case_name: str, folder: Path, precompute: bool):
    case = scenario(case_name)
    tissue = BiphaseTissue.build(case.mesh, case.fixed_nodes, ARTERY, contact_nodes=case.contact_nodes)
    if precompute:
        tissue.precompute(use_cache=False)
    needle = Needle.curved()
    trajectory, duration = sequence_of_passes(practice_passes(case, needle, 4))
    writer = SessionWriter(folder, {"session_id": case_name, "task": case_name}, flush_interval=0.1)
    started = time.perf_counter()
    RuntimeRecorder(writer).attach(Simulation(tissue, needle, ScriptedDevice(trajectory))).run_simulated(
        duration
    )
    writer.close()
    took = time.perf_counter() - started
    print(f"[{case_name}] {case.mesh.n_nodes} nodes, recorded {duration:.1f} s in {took:.1f} s")
    return tissue, open_session(folder)


def naive_screenshot_fps(tissue, frames: int = 60) -> float:
    """The reference: PyVista's own screenshot per frame with its defaults (4x MSAA)."""
    from sim.render import RenderFrame, TissueRenderer

    mesh = tissue.mesh
    renderer = TissueRenderer(mesh, size=(1280, 720), offscreen=True)
    needle = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.001]])
    stress = np.zeros(len(mesh.surface_triangles))
    renderer.render(RenderFrame(mesh.points, stress, needle))
    started = time.perf_counter()
    for k in range(frames):
        renderer.surface.points[:] = mesh.points + 1e-6 * k
        renderer.surface.Modified()
        renderer.plotter.render()
        renderer.plotter.screenshot(return_img=True)
    elapsed = time.perf_counter() - started
    renderer.close()
    return frames / elapsed


def fresh_model(case_name: str, precompute: bool):
    case = scenario(case_name)
    tissue = BiphaseTissue.build(case.mesh, case.fixed_nodes, ARTERY, contact_nodes=case.contact_nodes)
    if precompute:
        tissue.precompute(use_cache=False)
    return tissue


def replay_figures(repeats: int) -> None:
    with tempfile.TemporaryDirectory() as folder:
        for case_name, precompute in (("paper_cube", True), ("vessel_10k", False)):
            tissue, session = record(case_name, Path(folder) / case_name, precompute)
            print(f"[{case_name}] naive PyVista screenshot loop: {naive_screenshot_fps(tissue):.1f} frames/s")
            for state in ("cold", "warm"):
                totals, loops, frames = [], [], 0
                for k in range(repeats):
                    # cold: a freshly built model, as `vascsim replay` has in a new process (factorisation
                    # and contact columns solved during the export); warm: the model of a process that
                    # already replayed (a server replaying many sessions)
                    model = fresh_model(case_name, precompute) if state == "cold" else tissue
                    out = Path(folder) / f"{case_name}{state}{k}.mp4"
                    result = export_replay(session, model, out, [session], ReplaySettings(mode="ghost"))
                    frames = result.frames
                    totals.append(result.seconds)
                    loops.append(result.timings["render"])
                total, loop = float(np.median(totals)), float(np.median(loops))
                print(
                    f"[{case_name}] replay export ({state} model) 1280x720 30 fps H.264, {frames} frames "
                    f"({frames / 30:.1f} s): median {total:.2f} s over {repeats} = "
                    f"{frames / total:.1f} frames/s whole export ({frames / total / 30:.2f}x real time); "
                    f"render loop {frames / loop:.1f} frames/s (target >= 30)"
                )


def tracking_figures(repeats: int) -> None:
    with tempfile.TemporaryDirectory() as folder:
        video = Path(folder) / "bench.mp4"
        write_bench_video(video, duration_s=10.0, fps=30)
        camera = Camera(default_camera_matrix(), np.zeros(5), (1920, 1080))
        frames, fps, _ = read_video(video)
        decoded = list(frames)
        on_frames, with_decoding = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            track_frames(decoded, fps, camera)
            on_frames.append(time.perf_counter() - started)
            started = time.perf_counter()
            stream, fps, _ = read_video(video)
            track_frames(stream, fps, camera)
            with_decoding.append(time.perf_counter() - started)
        n = len(decoded)
        print(
            f"[aruco] 1920x1080 tracking, {n} frames: {n / np.median(on_frames):.0f} frames/s on decoded "
            "frames, "
            f"{n / np.median(with_decoding):.0f} frames/s including H.264 decoding, median of {repeats} "
            f"(target >= 30)"
        )


def main() -> None:
    prepare_rendering()  # offscreen EGL without a display, as the CLI
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=("tracking", "replay"), default=None, help="Run one part only.")
    args = parser.parse_args()
    if args.only != "replay":
        tracking_figures(args.repeats)
    if args.only != "tracking":
        replay_figures(args.repeats)


if __name__ == "__main__":
    main()
