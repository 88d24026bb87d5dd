"""Stitch-placement cost (issue 22): what scoring a session's placement adds, per stitch.

Run:  .venv/bin/python benchmarks/placement.py [--repeats 200]

One scripted arteriotomy-closure session (three stitches) is recorded through the runner's device
(simulated time); then, medians of ``--repeats``:
- deriving its stitch points on the tissue mesh (``metrics.signals.placement.stitch_points``);
- how the needle went through the wall (``metrics.signals.passage.passage_columns``: track offset and swept
  area from the scene, wound-edge stress through the tissue model), cold (a fresh process: the
  kernel nodes' K0^-1 columns solved) and warm (columns cached, as right after recording);
- the registered placement metrics from them (``metrics_of`` restricted to the placement group);
- the per-stitch table that is stored (``metrics.signals.placement.stitch_table``);
and, for scale, the whole registry on the same session.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from metrics import REGISTRY, from_recorded, metrics_of  # noqa: E402
from metrics.signals.passage import passage_columns  # noqa: E402
from metrics.signals.placement import stitch_points, stitch_table  # noqa: E402
from metrics.signals.tissue import with_tissue_fields  # noqa: E402
from recorder import SessionWriter, open_session  # noqa: E402
from recorder.runtime import RuntimeRecorder  # noqa: E402
from sessions.running.runner import SessionPlan, open_device  # noqa: E402
from sessions.synthetic import pass_parameters  # noqa: E402
from sessions.tasks import forget_tissues, task_preset, task_simulation, task_spec, tissue_for  # noqa: E402


def median_us(function, repeats: int) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return 1e6 * float(np.median(samples))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    task = "arteriotomy-closure"
    spec, forces = task_spec(task), task_preset(task_spec(task)).forces
    with tempfile.TemporaryDirectory() as folder:
        plan = SessionPlan("b", "p", task, 1)
        device, duration, _ = open_device("scripted", plan, None, pass_parameters(0.5, 3))
        header = {"session_id": "bench", "task": task, "placement": spec.placement,
                  "needle_forces": forces.as_dict()}  # fmt: skip
        writer = SessionWriter(Path(folder) / "s", header, flush_interval=0.1)
        RuntimeRecorder(writer).attach(task_simulation(task_spec(task), device)).run_simulated(duration)
        writer.close()
        recorded = from_recorded(open_session(Path(folder) / "s"))
    wall = fresh_tissue(task)  # no columns cached: what scoring in a new process meets
    started = time.perf_counter()
    streams = with_tissue_fields(recorded, wall)
    cold = time.perf_counter() - started
    names = [m.name for m in REGISTRY if m.group == "placement"]
    stitches, events = len(streams.stitches), len(streams.events)
    print(f"session: {streams.time.size} samples, {stitches} stitch(es), {events} events")
    points = median_us(lambda: stitch_points(streams.events, wall.mesh), args.repeats)
    print(f"stitch points on the mesh: {points:.0f} us ({points / stitches:.0f} us per stitch)")
    print(f"all tissue streams of the session, cold (columns solved): {cold:.2f} s")
    frames = streams.needle_frames
    passage = median_us(lambda: passage_columns(streams.stitches, frames, wall), max(3, args.repeats // 40))
    print(f"passage (track, swept area, wound-edge stress), warm: {passage / 1e3:.0f} ms "
          f"({passage / 1e3 / stitches:.0f} ms per stitch)")  # fmt: skip
    placement = median_us(lambda: metrics_of(streams, names), args.repeats)
    print(f"placement metrics ({len(names)}): {placement:.0f} us")
    print(f"per-stitch table: {median_us(lambda: stitch_table(streams), args.repeats):.0f} us")
    whole = median_us(lambda: metrics_of(streams), max(5, args.repeats // 20))
    print(f"whole registry ({len(REGISTRY)} metrics), for scale: {whole / 1e3:.1f} ms")


def fresh_tissue(task: str):
    """The task's model as a new process loads it (from the disk cache, no columns solved yet)."""
    forget_tissues()
    return tissue_for(task_spec(task), None)


if __name__ == "__main__":
    main()
