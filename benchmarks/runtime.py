"""Runtime figures of issue 4: real-time loop rates and latencies, simulated-time throughput.

Run:  .venv/bin/python benchmarks/runtime.py [--seconds 60] [--no-render] [--size 640x480]

1. Simulated time: one suturing pass on the paper's test cube (biphase,
   precomputed), all layers, no rendering: simulated seconds per wall second.
2. Real time, test cube: repeated stitches for --seconds, FEM at 500 Hz, global
   CD at 30 Hz, the display layer rendering offscreen (EGL) at 30 Hz.
3. Real time, ~10k-node artery, precomputed: the same loop, plus the
   contact-change latency (graphics frame that found the change -> end of the FEM step
   with exact forces for its triangle), for first touches and exits through the far wall.
4. The same artery in on-demand mode (columns solved when needed, prefetched by
   the graphics layer near the needle tip).
For the haptic layer: rate, period p50/p99/max, periods over 2 and 3 ms.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from sim.devices import ScriptedDevice
from sim.devices.scripted import sequence_of_passes
from sim.experiments import paper_cube
from sim.fem import BiphaseTissue
from sim.needle import Needle
from sim.runtime import RuntimeSettings, Simulation
from sim.scenarios import practice_passes, scenario


def stolen_seconds() -> list[float]:
    """CPU time each core has lost to the hypervisor since boot (s), from /proc/stat."""
    ticks = os.sysconf("SC_CLK_TCK")
    with open("/proc/stat") as stat:
        lines = [line.split() for line in stat if line.startswith("cpu") and line[3] != " "]
    return [int(fields[8]) / ticks for fields in lines]


def run_measuring_steal(simulation: Simulation, duration: float):
    """A real-time run, and the CPU time (s) the hypervisor took from each core during it."""
    before = stolen_seconds()
    result = simulation.run_realtime(duration)
    return result, [b - a for a, b in zip(before, stolen_seconds(), strict=True)]


def report(name: str, simulation: Simulation, result, stolen: list[float]) -> None:
    h = result.telemetry["haptic"]
    print(f"[{name}] stop={result.stop_reason} wall={result.wall_seconds:.1f}s", flush=True)
    print(
        f"[{name}]   hypervisor steal during the run: "
        + ", ".join(f"cpu{k} {1e3 * s:.0f} ms" for k, s in enumerate(stolen))
        + " (a stolen slice of the haptic core stalls the loop however it is scheduled)",
        flush=True,
    )
    print(
        f"[{name}]   haptic: rate={h.rate_hz:.1f} Hz period p50={1e3 * h.period_p50:.3f} ms "
        f"p99={1e3 * h.period_p99:.3f} ms max={1e3 * h.period_max:.3f} ms >2ms={h.periods_over_2ms} "
        f">3ms={h.periods_over_3ms} compute p99={1e6 * h.compute_p99:.0f} us",
        flush=True,
    )
    for layer in ("fem", "graphics", "display"):
        s = result.telemetry[layer]
        print(
            f"[{name}]   {layer}: rate={s.rate_hz:.1f} Hz compute p50={1e3 * s.compute_p50:.2f} ms "
            f"p99={1e3 * s.compute_p99:.2f} ms",
            flush=True,
        )
    changes = simulation.contact_latencies
    for label, latencies in (
        ("contact-change latency (all)", changes["contact_start"] + changes["exit"]),
        ("  first touch", changes["contact_start"]),
        ("  exit face", changes["exit"]),
    ):
        if latencies:
            ms = 1e3 * np.array(latencies)
            print(
                f"[{name}]   {label}: n={ms.size} p50={np.percentile(ms, 50):.2f} ms "
                f"p99={np.percentile(ms, 99):.2f} ms max={ms.max():.2f} ms",
                flush=True,
            )
    kinds = [e.kind for e in result.events]
    print(f"[{name}]   events: " + ", ".join(f"{k}={kinds.count(k)}" for k in sorted(set(kinds))), flush=True)


def renderer_for(tissue, size, enabled):
    if not enabled:
        return None
    from sim.render import TissueRenderer
    from sim.runtime.display import DisplayScene

    return DisplayScene(tissue, TissueRenderer(tissue.mesh, size=size, offscreen=True))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--no-render", action="store_true")
    parser.add_argument("--size", default="640x480")
    parser.add_argument(
        "--only", choices=["simulated", "cube", "artery", "artery-on-demand"], help="run one part only"
    )
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    needle = Needle.curved()

    mesh, fixed = paper_cube()
    cube = BiphaseTissue.build(mesh, fixed)
    cube.precompute(use_cache=False)
    if args.only in (None, "simulated"):
        simulated_throughput(cube, needle)
    if args.only in (None, "cube"):
        realtime_cube(cube, needle, args.seconds, size, not args.no_render)
    if args.only in (None, "artery"):
        realtime_artery(needle, args.seconds, size, not args.no_render, precomputed=True)
    if args.only in (None, "artery-on-demand"):
        realtime_artery(needle, args.seconds, size, not args.no_render, precomputed=False)


def simulated_throughput(cube, needle) -> None:
    one = practice_passes(scenario("paper_cube"), needle, 1)[0]
    ratios = []
    for _ in range(3):
        simulation = Simulation(cube, needle, ScriptedDevice(one.pose_and_grip))
        result = simulation.run_simulated(one.duration)
        ratios.append(one.duration / result.wall_seconds)
    print(
        f"[simulated, test cube] one pass of {one.duration:.2f} s simulated: median "
        f"{np.median(ratios):.1f}x real time (runs: {', '.join(f'{r:.1f}' for r in ratios)})",
        flush=True,
    )


def realtime_cube(cube, needle, seconds, size, render) -> None:
    trajectory, total = sequence_of_passes(practice_passes(scenario("paper_cube"), needle, 20))
    duration = min(seconds, total)
    settings = RuntimeSettings(fem_rate=500.0)
    simulation = Simulation(
        cube, needle, ScriptedDevice(trajectory), settings, renderer=renderer_for(cube, size, render)
    )
    report(f"real time, test cube, {duration:.0f} s", simulation, *run_measuring_steal(simulation, duration))


def realtime_artery(needle, seconds, size, render, precomputed) -> None:
    case = scenario("vessel_10k")
    artery = BiphaseTissue.build(case.mesh, case.fixed_nodes, contact_nodes=case.contact_nodes)
    if precomputed:
        artery.precompute(use_cache=False)
    trajectory, total = sequence_of_passes(practice_passes(case, needle, 20))
    duration = min(seconds, total)
    settings = RuntimeSettings(fem_rate=500.0)
    simulation = Simulation(
        artery, needle, ScriptedDevice(trajectory), settings, renderer=renderer_for(artery, size, render)
    )
    mode = "precomputed" if precomputed else "on demand"
    name = f"real time, {case.mesh.n_nodes}-node artery {mode}, {duration:.0f} s"
    report(name, simulation, *run_measuring_steal(simulation, duration))
    simulation.close()


if __name__ == "__main__":
    main()
