"""The demo figure of issue 7: `vascsim demo` on a fresh data directory, end to end.

Run:  .venv/bin/python benchmarks/demo.py [--repeats 3]

Each repeat runs the installed `vascsim demo` command in a new, empty VASCSIM_HOME
(so the task models are built and cached inside the timed run, as on a fresh set-up)
with the embedded SQLite catalog: the two-task curriculum's 75 sessions through the
real simulator, recorder and catalog (two at once), all metrics, each task's
construct-validity report, the standard, learning curves and verdicts. Prints the
median wall time; target < 120 s on 2 cores (issue 44).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    command = Path(sys.executable).with_name("vascsim")
    times = []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as home:
            env = dict(os.environ, VASCSIM_HOME=home)
            env.pop("VASCSIM_DATABASE_URL", None)
            start = time.perf_counter()
            done = subprocess.run([str(command), "demo", "--json"], env=env, check=True, capture_output=True)
            times.append(time.perf_counter() - start)
            sessions = json.loads(done.stdout)["sessions"]
    print(
        f"vascsim demo, fresh VASCSIM_HOME, {sessions} sessions: median {np.median(times):.1f} s, "
        f"min {min(times):.1f} s over {args.repeats} runs (target < 120 s)"
    )


if __name__ == "__main__":
    main()
