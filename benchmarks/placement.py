"""Stitch-placement cost (issue 22): what scoring a session's placement adds.

Run:  .venv/bin/python benchmarks/placement.py [--repeats 200]

One scripted wall-stitch session is recorded (simulated time); then, medians of ``--repeats``:
- deriving its stitch points on the tissue mesh (``metrics.placement.stitch_points``);
- the six registered placement metrics from them (``metrics_of`` restricted to the placement group);
- the per-stitch table that is stored (``metrics.placement.stitch_table``);
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
from metrics.placement import stitch_points, stitch_table  # noqa: E402
from metrics.tissue import with_tissue_fields  # noqa: E402
from recorder import SessionWriter, open_session  # noqa: E402
from recorder.runtime import RuntimeRecorder  # noqa: E402
from sessions.synthetic import pass_parameters  # noqa: E402
from sessions.tasks import task_preset, task_spec, tissue_for  # noqa: E402
from sim.devices import ScriptedDevice, SuturingPass  # noqa: E402
from sim.needle import Needle  # noqa: E402
from sim.runtime import Simulation  # noqa: E402


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
    spec, wall = task_spec("wall-stitch"), tissue_for("wall-stitch", None)
    forces = task_preset("wall-stitch").forces
    with tempfile.TemporaryDirectory() as folder:
        suturing = SuturingPass(
            Needle.curved(), spec.entry, spec.normal, spec.bite_direction, pass_parameters(0.5, 3)
        )
        header = {"session_id": "bench", "task": "wall-stitch", "placement": spec.placement,
                  "needle_forces": forces.as_dict()}  # fmt: skip
        writer = SessionWriter(Path(folder) / "s", header, flush_interval=0.1)
        simulation = Simulation(wall, Needle.curved(), ScriptedDevice(suturing.pose_and_grip), forces=forces)
        RuntimeRecorder(writer).attach(simulation).run_simulated(suturing.duration)
        writer.close()
        streams = with_tissue_fields(from_recorded(open_session(Path(folder) / "s")), wall)
    names = [m.name for m in REGISTRY if m.group == "placement"]
    stitches, events = len(streams.stitches), len(streams.events)
    print(f"session: {streams.time.size} samples, {stitches} stitch(es), {events} events")
    points = median_us(lambda: stitch_points(streams.events, wall.mesh), args.repeats)
    print(f"stitch points on the mesh: {points:.0f} us")
    placement = median_us(lambda: metrics_of(streams, names), args.repeats)
    print(f"placement metrics ({len(names)}): {placement:.0f} us")
    print(f"per-stitch table: {median_us(lambda: stitch_table(streams), args.repeats):.0f} us")
    whole = median_us(lambda: metrics_of(streams), max(5, args.repeats // 20))
    print(f"whole registry ({len(REGISTRY)} metrics), for scale: {whole / 1e3:.1f} ms")


if __name__ == "__main__":
    main()
