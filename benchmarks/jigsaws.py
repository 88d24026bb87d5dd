"""Issue 26: the JIGSAWS skill benchmark on one task (39 trials) in under 30 s on 2 cores.

Run:  .venv/bin/python benchmarks/jigsaws.py [--repeats 3] [--dir JIGSAWS/Suturing]

Without ``--dir`` the 39 trials are written in the data set's format with JIGSAWS-like lengths
(Suturing at 30 Hz: experts about 90 s, intermediates 120 s, novices 170 s; 8 surgeons, surgeon H
four trials), random smooth motion of both tools: the figure is the time vascsim takes, not a
result about skill. Timed: reading the kinematics and meta file, every metric of every trial, both
protocols (LOSO 5 folds, LOUO 8 folds; 3-class, 2-class, GRS) with 2,000 bootstrap draws each.
Prints the median of ``--repeats`` wall times.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This folder holds scripts named like our packages (metrics.py, recorder.py): keep it off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from metrics import compute_session_metrics  # noqa: E402
from metrics.datasets import jigsaws  # noqa: E402
from metrics.datasets.jigsaws_benchmark import run_benchmark  # noqa: E402

SURGEONS = {"B": "N", "C": "I", "D": "E", "E": "E", "F": "I", "G": "N", "H": "N", "I": "N"}
SECONDS = {"E": 90.0, "I": 120.0, "N": 170.0}


def smooth_walk(rng: np.random.Generator, frames: int, scale: float) -> np.ndarray:
    steps = rng.normal(scale=scale, size=(frames, 3))
    kernel = np.hanning(31) / np.hanning(31).sum()
    smooth = np.column_stack([np.convolve(steps[:, k], kernel, mode="same") for k in range(3)])
    return np.cumsum(smooth, axis=0)


def write_task(root: Path, seed: int = 0) -> tuple[Path, Path]:
    rng = np.random.default_rng(seed)
    folder = root / "Suturing" / "kinematics" / "AllGestures"
    folder.mkdir(parents=True)
    lines = []
    for surgeon, skill in SURGEONS.items():
        for trial in range(1, (4 if surgeon == "H" else 5) + 1):
            frames = int(SECONDS[skill] * 30 * rng.uniform(0.8, 1.2))
            rows = np.zeros((frames, jigsaws.N_COLUMNS))
            for manipulator, scale in (("slave_right", 2e-4), ("slave_left", 1e-4), ("master_right", 1e-3)):
                columns = jigsaws.manipulator_columns(manipulator)
                rows[:, columns["position"]] = smooth_walk(rng, frames, scale)
                rows[:, columns["rotation"]] = np.tile(np.eye(3).ravel(), (frames, 1))
                rows[:, columns["gripper_angle"]] = rng.uniform(-1, 1, (frames, 1))
            name = f"Suturing_{surgeon}00{trial}"
            np.savetxt(folder / f"{name}.txt", rows, fmt="%.6e", delimiter="    ", newline="\r\n")
            grs = {"E": 24, "I": 17, "N": 12}[skill] + int(rng.integers(-2, 3))
            lines.append(f"{name}\t\t{skill}\t{grs}\t\t" + "\t".join(["2"] * 5 + [str(grs - 10)]))
    meta = root / "Suturing" / "meta_file_Suturing.txt"
    meta.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return root / "Suturing", meta


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dir", type=Path, default=None, help="A real JIGSAWS task folder.")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        if args.dir is None:
            folder, meta = write_task(Path(scratch))
        else:
            folder, meta = args.dir, next(args.dir.glob("meta_file_*.txt"))
        times = []
        for _ in range(args.repeats):
            began = time.perf_counter()
            trials = jigsaws.load(folder, meta)
            table = compute_session_metrics(trials)
            result = run_benchmark(trials, folder.parent, draws=2000, table=table)
            times.append(time.perf_counter() - began)
            frames = sum(t.samples.shape[0] for t in trials)
            print(
                f"{len(trials)} trials, {frames} frames ({frames / 30 / 60:.1f} min at 30 Hz), "
                f"{len(result.metrics)} metrics: {times[-1]:.2f} s",
                flush=True,
            )
    print(f"JIGSAWS benchmark, one task: median {statistics.median(times):.2f} s of {len(times)} (bar: 30 s)")


if __name__ == "__main__":
    main()
