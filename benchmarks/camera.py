"""Issue 47's figures: instruments tracked by a camera, measured on rendered video with known poses.

Run:  .venv/bin/python benchmarks/camera.py [--repeats 3]
          [--part cost|accuracy|jitter|latency|stitch|realtime|all]

- cost: per frame, detection + pose + filter of the needle holder's marker cube, on one core
  (OpenCV and BLAS held to one thread), at 640x480 and 1280x720 (a 6 s wrist-roll video at 30 cm);
  median and p95 over the frames, the median over ``--repeats``; the pose rate is 1 / median;
- accuracy: the same videos: the tip's RMS error at the frames (raw pose, filtered estimate) and at
  1 kHz (the haptic pose, extrapolated between frames), the orientation's RMS error, for both filters;
- jitter: a still instrument (the cube held 3 s at 30 cm): the haptic pose's RMS about its mean, raw
  poses and after each filter;
- latency: from a frame's capture to the haptic pose that follows it: the frame's processing time
  (p95) plus the wait for the next 1 kHz tick, plus the filter and prediction's lag (the time shift
  that best aligns the haptic pose with the truth on the wrist-roll video; negative = ahead). The
  camera's own exposure and readout come on top (a 30 frames/s webcam: up to one frame, 33 ms);
- stitch: scripted wall stitches (skills 0.9 and 0.3) filmed at 1280x720, 30 frames/s and played back
  through ``camera:FILE`` on a simulated clock: the five motion metrics against the scripted session's;
- realtime: the expert stitch's video played through ``camera:FILE`` on the real-time clock: the share
  of haptic samples measured / predicted / held on this machine (the tracking process shares the cores
  with the FEM and haptic processes).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This folder holds scripts named like our packages (metrics.py, recorder.py): keep it off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from metrics import from_recorded, metrics_of  # noqa: E402
from recorder import open_session  # noqa: E402
from sessions.catalog import Catalog  # noqa: E402
from sessions.running.filmed import film_scripted_pass  # noqa: E402
from sessions.running.runner import SessionPlan, run_session  # noqa: E402
from sessions.synthetic import pass_parameters  # noqa: E402
from sim.tracking.camera import Camera  # noqa: E402
from sim.tracking.channel import PoseEstimator, PosePredictor  # noqa: E402
from sim.tracking.filters import rotation_vector  # noqa: E402
from sim.tracking.markers import NEEDLE_HOLDER  # noqa: E402
from sim.tracking.pose import BodyTracker  # noqa: E402
from sim.tracking.synthetic import (  # noqa: E402
    FACING_CAMERA,
    default_camera_matrix,
    rotation_xyz,
    wrist_motion,
    write_instrument_video,
)
from sim.tracking.video import VideoFile  # noqa: E402

FPS = 30
SIZES = ((640, 480), (1280, 720))
MOTION = ("task_time", "path_length", "economy_of_motion", "log_dimensionless_jerk", "spectral_arc_length")


def camera_for(size) -> Camera:
    return Camera(default_camera_matrix(size, focal_px=size[0] * 0.9), np.zeros(5), size)


def wrist_video(folder: Path, size, seconds: float = 6.0):
    """The wrist roll over ``seconds`` (6 s: the tip's peak speed 0.28 m/s, a brisk suturing hand)."""
    path = folder / f"wrist-{size[0]}.mp4"
    time_s = np.arange(0, seconds, 1 / FPS)
    rotations, origins = wrist_motion(time_s)
    write_instrument_video(path, rotations, origins, NEEDLE_HOLDER, FPS, size, camera_for(size).matrix)
    tips = np.einsum("nij,j->ni", rotations, np.asarray(NEEDLE_HOLDER.tip_offset_m)) + origins
    return path, time_s, rotations, tips


def frames_of(path):
    return [frame for _, frame in VideoFile(path)]


def cost(folder: Path, repeats: int) -> None:
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    print("per frame on one core: detection + pose + filter (ms)")
    for size in SIZES:
        path, time_s, *_ = wrist_video(folder, size)
        frames = frames_of(path)
        medians, p95s = [], []
        for _ in range(repeats):
            tracker, estimator = BodyTracker(camera_for(size), NEEDLE_HOLDER), PoseEstimator()
            spent = []
            with threadpool_limits(1):
                for t, frame in zip(time_s, frames, strict=False):
                    began = time.perf_counter()
                    estimator.update(t, tracker.locate(frame))
                    spent.append(time.perf_counter() - began)
            medians.append(np.median(spent))
            p95s.append(np.percentile(spent, 95))
        median, p95 = float(np.median(medians)) * 1e3, float(np.median(p95s)) * 1e3
        print(
            f"  {size[0]}x{size[1]}: median {median:.2f} ms, p95 {p95:.2f} ms (budget 8 ms); "
            f"pose rate {1e3 / median:.0f} poses/s"
        )


def haptic_path(frames, time_s, size, kind: str, ticks):
    """The haptic pose at ``ticks`` from the frames (simulated clock), and the filtered estimates."""
    tracker, estimator = BodyTracker(camera_for(size), NEEDLE_HOLDER), PoseEstimator(kind)
    predictor = PosePredictor(1 / FPS)
    poses = [tracker.locate(frame) for frame in frames]
    out, k, estimates = [], 0, []
    for tick in ticks:
        while k < len(frames) and time_s[k] <= tick:
            estimates.append(estimator.update(time_s[k], poses[k]))
            k += 1
        out.append(predictor.at(tick, estimator.estimate)[0])
    estimates += [estimator.update(time_s[j], poses[j]) for j in range(k, len(frames))]
    return np.array(out), estimates, poses


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.sum(np.atleast_2d(values) ** 2, axis=-1))))


def accuracy(folder: Path) -> None:
    print("accuracy on the wrist roll at 30 cm (tip 120 mm from the cube): RMS error")
    for size in SIZES:
        path, time_s, rotations, tips = wrist_video(folder, size)
        frames = frames_of(path)
        ticks = np.arange(0.0, time_s[-1], 0.001)
        truth = np.column_stack([np.interp(ticks, time_s, tips[:, k]) for k in range(3)])
        for kind in ("kalman", "one-euro"):
            out, estimates, poses = haptic_path(frames, time_s, size, kind, ticks)
            raw = np.array([p.tip for p in poses])
            filtered = np.array([e.position for e in estimates])
            angle = [
                np.degrees(np.linalg.norm(rotation_vector(p.rotation @ r.T)))
                for p, r in zip(poses, rotations, strict=True)
            ]
            print(
                f"  {size[0]}x{size[1]} {kind:>8}: tip at frames raw {rms(raw - tips) * 1e3:.2f} mm, "
                f"filtered {rms(filtered - tips) * 1e3:.2f} mm; haptic pose at 1 kHz "
                f"{rms(out - truth) * 1e3:.2f} mm "
                f"(max {np.linalg.norm(out - truth, axis=1).max() * 1e3:.1f} mm, largest step between ticks "
                f"{np.linalg.norm(np.diff(out, axis=0), axis=1).max() * 1e3:.2f} mm); orientation "
                f"{np.sqrt(np.mean(np.square(angle))):.2f} deg (budget: tip 1 mm, orientation 2 deg)"
            )


def jitter(folder: Path) -> None:
    print("still instrument at 30 cm, 3 s: RMS of the haptic pose about its mean (budget 0.1 mm)")
    for size in SIZES:
        for noise in (2.0, 6.0):  # sensor noise (grey levels RMS): a lit bench, a dim room
            path = folder / f"still-{size[0]}-{noise:g}.mp4"
            count = 3 * FPS
            rotation = FACING_CAMERA @ rotation_xyz(np.array([0.25, np.radians(35.0), 0.1]))
            rotations = np.repeat(rotation[None], count, axis=0)
            origins = np.repeat(np.array([[0.0, -0.02, 0.30]]), count, axis=0)
            matrix = camera_for(size).matrix
            write_instrument_video(path, rotations, origins, NEEDLE_HOLDER, FPS, size, matrix, 7, noise)
            frames, time_s = frames_of(path), np.arange(count) / FPS
            ticks = np.arange(0.5, time_s[-1], 0.001)  # after the filters settle
            for kind in ("kalman", "one-euro"):
                out, _, poses = haptic_path(frames, time_s, size, kind, ticks)
                raw = np.array([p.tip for p in poses])
                still, haptic = rms(raw - raw.mean(axis=0)), rms(out - out.mean(axis=0))
                print(
                    f"  {size[0]}x{size[1]} noise {noise:g} {kind:>8}: raw poses {still * 1e3:.3f} mm, "
                    f"haptic pose {haptic * 1e3:.3f} mm"
                )


def latency(folder: Path, repeats: int) -> None:
    print("camera frame to haptic pose (the camera's exposure and readout come on top: <= 33 ms at 30 fps)")
    size = (1280, 720)
    path, time_s, _, tips = wrist_video(folder, size)
    frames = frames_of(path)
    tracker, estimator = BodyTracker(camera_for(size), NEEDLE_HOLDER), PoseEstimator()
    spent = []
    for _ in range(repeats):
        for t, frame in zip(time_s, frames, strict=False):
            began = time.perf_counter()
            estimator.update(t, tracker.locate(frame))
            spent.append(time.perf_counter() - began)
    processing = float(np.percentile(spent, 95)) + 0.001  # + the wait for the next 1 kHz tick
    ticks = np.arange(0.3, time_s[-1] - 0.3, 0.001)
    for kind in ("kalman", "one-euro"):
        out, _, _ = haptic_path(frames, time_s, size, kind, ticks)
        shifts = np.arange(-0.05, 0.1, 0.001)
        errors = [
            rms(out - np.column_stack([np.interp(ticks - s, time_s, tips[:, k]) for k in range(3)]))
            for s in shifts
        ]
        lag = float(shifts[int(np.argmin(errors))])
        print(
            f"  {kind:>8}: processing p95 + tick {processing * 1e3:.1f} ms, filter and prediction lag "
            f"{lag * 1e3:+.0f} ms: total {(processing + max(lag, 0.0)) * 1e3:.1f} ms (budget 40 ms)"
        )


def stitch(folder: Path, clock: str = "simulated") -> None:
    print(f"scripted wall stitches filmed and played through camera:FILE ({clock} clock): motion metrics")
    for skill in (0.9, 0.3):
        home = folder / f"home-{skill}-{clock}"
        home.mkdir()
        catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
        with catalog.session() as orm:
            catalog.add_participant(orm, catalog.study(orm, "S", create=True), "P", level="expert")
        parameters = pass_parameters(skill, 3)
        scripted = run_session(catalog, home, SessionPlan("S", "P", "wall-stitch", None), parameters)
        video = home / "stitch.mp4"
        _, matrix, _ = film_scripted_pass("wall-stitch", parameters, video)
        Camera(matrix, np.zeros(5), (1280, 720)).save(home / "camera.json")
        filmed = run_session(
            catalog, home, SessionPlan("S", "P", "wall-stitch", None, device=f"camera:{video}", clock=clock)
        )
        values = {}
        for uid in (scripted, filmed):
            with catalog.session() as orm:
                values[uid] = metrics_of(
                    from_recorded(open_session(catalog.recorded_session(orm, uid).directory))
                )
        parts = []
        for name in MOTION:
            truth, seen = values[scripted][name], values[filmed][name]
            parts.append(f"{name} {seen:.4g} vs {truth:.4g} ({(seen - truth) / abs(truth) * 100:+.1f} %)")
        print(f"  skill {skill}: " + "; ".join(parts))
        if clock == "realtime":
            with catalog.session() as orm:
                samples = open_session(catalog.recorded_session(orm, filmed).directory).samples_frame()
            shares = np.bincount(samples["tool_tracking"].to_numpy(), minlength=3) / len(samples)
            print(
                f"    haptic samples measured {shares[0] * 100:.0f} %, predicted {shares[1] * 100:.0f} %, "
                f"held {shares[2] * 100:.0f} % (on {len(os.sched_getaffinity(0))} cores)"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parts = ("cost", "accuracy", "jitter", "latency", "stitch", "realtime", "all")
    parser.add_argument("--part", choices=parts, default="all")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        if args.part in ("cost", "all"):
            cost(folder, args.repeats)
        if args.part in ("accuracy", "all"):
            accuracy(folder)
        if args.part in ("jitter", "all"):
            jitter(folder)
        if args.part in ("latency", "all"):
            latency(folder, args.repeats)
        if args.part in ("stitch", "all"):
            stitch(folder)
        if args.part in ("realtime", "all"):
            stitch(folder, "realtime")


if __name__ == "__main__":
    main()
