"""Metrics figures of issue 6.

Run:  .venv/bin/python benchmarks/metrics.py

- all registered metrics of one 10-minute session at 1 kHz (600,000 samples, synthetic
  streams with tool, tip, force, needle state, subordinate hand and events): median of 5;
  target <= 0.5 s;
- the study report of a 1000-session synthetic study (100 experts x 4 sessions, 75
  trainees x 7 practice + 1 retention): construct validity with 2000-resample bootstraps,
  LOPO composite, benchmarks, learning curves, HTML/Markdown/CSV/PNG/SVG: median of 3;
  target <= 30 s on 2 cores. The per-session metrics of those 1000 sessions (60 s each
  at 100 Hz) are timed separately and printed.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from metrics import compute_session_metrics, metrics_of  # noqa: E402
from metrics.reading.report import write_report  # noqa: E402
from metrics.study.analysis import StudySettings, analyse_study  # noqa: E402
from metrics.synthetic import synthetic_session, synthetic_study  # noqa: E402


def one_long_session(repeats: int = 5) -> None:
    streams = synthetic_session("long", "P", "trainee", 1, 0.5, duration=600.0, rate=1000.0, seed=1)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        values = metrics_of(streams)
        times.append(time.perf_counter() - start)
    computed = sum(not np.isnan(v) for v in values.values())
    print(
        f"one 10-min 1 kHz session ({streams.time.size} samples, "
        f"{computed}/{len(values)} metrics with values): "
        f"median {np.median(times):.3f} s, min {min(times):.3f} s over {repeats} runs (target <= 0.5 s)"
    )


def study_report(repeats: int = 3) -> None:
    start = time.perf_counter()
    table = compute_session_metrics(
        synthetic_study(
            experts=100, expert_sessions=4, trainees=75, trainee_sessions=7, duration=60.0, rate=100.0
        )
    )
    elapsed = time.perf_counter() - start
    print(f"per-session metrics of {len(table)} synthetic sessions (60 s at 100 Hz): {elapsed:.1f} s")
    times = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            analysis = analyse_study(table, StudySettings(n_boot=2000))
            write_report(analysis, folder)
            times.append(time.perf_counter() - start)
    print(
        f"study report of {len(table)} sessions / {table['participant_id'].nunique()} participants: "
        f"median {np.median(times):.2f} s, min {min(times):.2f} s over {repeats} runs (target <= 30 s)"
    )


if __name__ == "__main__":
    one_long_session()
    study_report()
