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
For the haptic layer: rate, period p50/p99/max, periods over 2 and 3 ms, and the compute of each
tick's force path (compiled) beside the whole step's.

``--trace`` (root): the haptic core is also traced with ftrace during each real-time run, and
every haptic period over 3 ms is put down to what the kernel saw (``benchmarks/kernel_trace.py``):
a timer interrupt handled late (the vCPU was not running), the haptic process woken on time but
run late (the tasks and interrupts that ran instead are named), or a long step.

``--instructions``: instead, the instructions one simulated stitch on the test cube
executes, counted by valgrind's callgrind (the same count whatever else the host is
doing, unlike the wall-clock ratio; about six minutes).
"""

from __future__ import annotations

import argparse
import contextlib
import mmap
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from kernel_trace import HapticCoreTrace, late_periods_explained

from sessions.config import prepare_rendering
from sim.calibration.indentation import paper_cube
from sim.calibration.presets import tissue_preset
from sim.calibration.scenarios import practice_passes, scenario
from sim.devices import ScriptedDevice
from sim.devices.scripted import sequence_of_passes
from sim.fem import BiphaseTissue
from sim.needle import Needle
from sim.runtime import RuntimeSettings, Simulation
from sim.runtime.cpu import stolen_seconds

LIVE_STRESS = RuntimeSettings().live_stress_in_real_time  # --live-stress / --no-live-stress
ARTERY = tissue_preset("porcine-artery").biphase  # the calibrated wall the default needle forces suit

STEAL_SAMPLER = """
import os, sys, time

os.sched_setaffinity(0, {int(sys.argv[2])})
os.nice(5)
prefix = "cpu" + sys.argv[1] + " "
with open(sys.argv[3], "w") as out:
    while True:
        with open("/proc/stat") as stat:
            steal = next(line for line in stat if line.startswith(prefix)).split()[8]
        out.write(f"{time.perf_counter()!r} {steal}\\n")
        out.flush()
        time.sleep(0.005)
"""
"""Every 5 ms: (perf_counter s, the haptic core's hypervisor steal in clock ticks) from /proc/stat,
sampled from another core."""


class StepClock:
    """Wraps a simulation's haptic step to keep, per step, its start (perf_counter s), wall time and
    the haptic thread's CPU time (s) in shared memory: the step runs in the forked haptic process.
    The guest kernel leaves hypervisor steal out of a thread's CPU time (paravirtual steal
    accounting), so a step whose wall time far exceeds its CPU time lost the vCPU to the host; a
    long step with CPU time close to its wall time ran slowly on the vCPU. Costs two clock reads a
    tick (about 1 us)."""

    def __init__(self, simulation: Simulation, capacity: int) -> None:
        self.rows = np.frombuffer(mmap.mmap(-1, 8 * 3 * capacity), dtype=np.float64).reshape(capacity, 3)
        self._count = np.frombuffer(mmap.mmap(-1, 8 * 2), dtype=np.int64)  # steps kept, haptic pid
        step, rows, count = simulation.haptic_step, self.rows, self._count
        started = simulation.on_haptic_start

        def note_pid() -> None:
            count[1] = os.getpid()
            if started is not None:
                started()

        simulation.on_haptic_start = note_pid

        def timed(now: float) -> None:
            wall, cpu = time.perf_counter(), time.thread_time()
            step(now)
            cpu, end = time.thread_time() - cpu, time.perf_counter()
            n = int(count[0])
            if n < capacity:
                rows[n] = (wall, end - wall, cpu)
                count[0] = n + 1

        simulation.haptic_step = timed  # type: ignore[method-assign]

    @property
    def steps(self) -> np.ndarray:
        return self.rows[: int(self._count[0])]

    @property
    def haptic_pid(self) -> int:
        return int(self._count[1])


def late_periods_by_cause(steps: np.ndarray, over: float = 3e-3) -> str:
    """The haptic periods over ``over`` s, by where the time went: a step that ran long on the vCPU
    (CPU time >= 70 % of its wall time), a step that lost the vCPU (less), or a late wake-up after
    a step of normal length (the sleep before the next deadline overran)."""
    walls, cpus = steps[:-1, 1], steps[:-1, 2]
    late = np.flatnonzero(np.diff(steps[:, 0]) > over)
    long_step = walls[late] > over - 1e-3
    ran_long = late[long_step & (cpus[late] >= 0.7 * walls[late])]
    stolen = late[long_step & (cpus[late] < 0.7 * walls[late])]
    woke_late = late[~long_step]

    def ms(indices: np.ndarray) -> str:
        return f"{len(indices)} (longest {1e3 * walls[indices].max():.1f} ms)" if len(indices) else "0"

    return (
        f"{len(late)} periods > {1e3 * over:.0f} ms: step ran long on the vCPU {ms(ran_long)}, "
        f"step lost the vCPU {ms(stolen)}, late wake-up after a normal step {len(woke_late)}"
    )


def run_measuring_steal(simulation: Simulation, duration: float, kernel_trace: bool = False):
    """A real-time run; the CPU time (s) the hypervisor took from each core during it; the haptic
    core's steal sampled every 5 ms as (perf_counter s, stolen s) arrays; the per-step clocks
    of the haptic layer (:class:`StepClock`); and, with ``kernel_trace``, the haptic core's
    ftrace (:class:`kernel_trace.CoreTrace`, else None)."""
    clock = StepClock(simulation, int(duration * 1200) + 2000)
    cores = sorted(os.sched_getaffinity(0))
    tracing = HapticCoreTrace(cores[-1]) if kernel_trace else contextlib.nullcontext()
    # in shared memory, not on disk: writing back a file raises disk interrupts on the haptic core
    with tempfile.NamedTemporaryFile("r", suffix=".steal", dir="/dev/shm") as trace:
        sampler = subprocess.Popen(
            [sys.executable, "-c", STEAL_SAMPLER, str(cores[-1]), str(cores[0]), trace.name]
        )
        try:
            before = stolen_seconds()
            with tracing:
                result = simulation.run_realtime(duration)
            after = stolen_seconds()
            stolen = [after[core] - before[core] for core in sorted(after)]
        finally:
            sampler.terminate()
            sampler.wait()
        samples = np.loadtxt(trace.name, ndmin=2)
    core_trace = tracing.parse(clock.haptic_pid) if kernel_trace else None
    steal = (samples[:, 0], samples[:, 1] / os.sysconf("SC_CLK_TCK"))
    return result, stolen, steal, clock.steps, core_trace


def stalls_against_steal(steps: np.ndarray, trace, over: float = 3e-3, draws: int = 20) -> str:
    """Whether the haptic core's late periods (> ``over`` s) coincide with the hypervisor taking
    that core: steal in the sampling windows around each late period, against windows of the same
    length at random times holding no late period. /proc/stat counts steal in 10 ms ticks of an
    exact running total, so a 4 ms stall moves it by one tick only sometimes; the sums tell."""
    times, steal = trace
    starts = steps[:, 0]  # perf_counter readings, the sampler's clock
    late = np.flatnonzero(np.diff(starts) > over)
    low = np.searchsorted(times, starts[late], side="right") - 1
    high = np.searchsorted(times, starts[late + 1], side="left")
    inside = (low >= 0) & (high < len(times))
    low, high, late = low[inside], high[inside], late[inside]
    if not len(late):
        return "no late period inside the steal trace"
    excess = float(np.sum(np.diff(starts)[late] - 1e-3))
    stolen = steal[high] - steal[low]
    spans = high - low
    busy = np.zeros(len(times), dtype=bool)
    for a, b in zip(low, high, strict=True):
        busy[a : b + 1] = True
    rng = np.random.default_rng(0)
    control_sum, control_hits = [], []
    for _ in range(draws):
        drawn = []
        for span in spans:
            for _attempt in range(100):
                a = int(rng.integers(0, len(times) - span))
                if not busy[a : a + span + 1].any():
                    drawn.append(steal[a + span] - steal[a])
                    break
        control_sum.append(sum(drawn))
        control_hits.append(sum(d > 0 for d in drawn))
    return (
        f"{len(late)} late periods ({1e3 * excess:.0f} ms past their deadlines in all); hypervisor steal "
        f"of the haptic core in the 5-ms-sample windows around them: {1e3 * stolen.sum():.0f} ms, in "
        f"{int(np.sum(stolen > 0))} of {len(late)} windows; in as many windows of the same lengths at "
        f"random times without a late period: {1e3 * np.mean(control_sum):.0f} ms, in "
        f"{np.mean(control_hits):.1f} (mean of {draws} draws)"
    )


def report(name: str, simulation: Simulation, result, stolen: list[float], trace, steps, core_trace) -> None:
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
    path = result.telemetry["haptic force path"]
    print(
        f"[{name}]   haptic tick's force path (holder publish, force at the delay, safety, log; "
        f"compiled): p50={1e6 * path.compute_p50:.1f} us p99={1e6 * path.compute_p99:.1f} us "
        f"max={1e6 * path.compute_max:.1f} us; the whole step (device read and write, FEM snapshot, "
        f"recording too): p50={1e6 * h.compute_p50:.0f} us p99={1e6 * h.compute_p99:.0f} us",
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
    builds = simulation.interaction.contact_builds
    dropped = simulation.interaction.tissue.evicted_columns

    def evicted(nodes) -> str:
        again = [n for n in nodes if n in dropped]
        return f"{len(again)} of them solved before and evicted" if again else "never solved before"

    if builds:
        seconds = 1e3 * np.array([b[2] for b in builds])
        waited = [b for b in builds if b[1]]
        print(
            f"[{name}]   contact handles built: n={len(builds)} p50={np.median(seconds):.2f} ms "
            f"max={seconds.max():.2f} ms; with columns solved on the spot: {len(waited)}"
            + "".join(
                f"; t={t:.2f} s, nodes {list(nodes)} ({evicted(nodes)}), {1e3 * s:.0f} ms"
                for t, nodes, s in waited
            ),
            flush=True,
        )
    if dropped:
        print(f"[{name}]   column cache: {len(dropped)} nodes' columns evicted (memory budget)", flush=True)
    for over in (3e-3, 2e-3):
        print(f"[{name}]   haptic {late_periods_by_cause(steps, over)}", flush=True)
        print(
            f"[{name}]   haptic periods > {1e3 * over:.0f} ms against steal: "
            f"{stalls_against_steal(steps, trace, over)}",
            flush=True,
        )
    if core_trace is not None:
        print(f"[{name}]   haptic {late_periods_explained(steps, core_trace)}", flush=True)
    kinds = [e.kind for e in result.events]
    print(f"[{name}]   events: " + ", ".join(f"{k}={kinds.count(k)}" for k in sorted(set(kinds))), flush=True)


def renderer_for(tissue, size, enabled):
    if not enabled:
        return None
    from sim.render import TissueRenderer
    from sim.runtime.display import DisplayScene

    # the live display: no multisampling, which quadruples a software-rendered frame (30.7 -> 7.0 ms
    # for the 10k artery on one core; replay videos, rendered offline, keep it)
    return DisplayScene(tissue, TissueRenderer(tissue.mesh, size=size, offscreen=True, anti_aliasing=False))


def main() -> None:
    prepare_rendering()  # offscreen EGL without a display, as the CLI
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--no-render", action="store_true")
    parser.add_argument(
        "--live-stress",
        action=argparse.BooleanOptionalAction,
        default=RuntimeSettings().live_stress_in_real_time,
        help="stream the local stress in real time (its operator is built at each contact change)",
    )
    parser.add_argument("--size", default="640x480")
    parser.add_argument(
        "--only", choices=["simulated", "cube", "artery", "artery-on-demand"], help="run one part only"
    )
    parser.add_argument(
        "--instructions",
        action="store_true",
        help="count the instructions of one simulated stitch under valgrind instead (host-independent)",
    )
    parser.add_argument(
        "--trace",
        action="store_true",
        help="trace the haptic core with ftrace (root) and say, from it, why each period over 3 ms was late",
    )
    parser.add_argument("--passes", type=int, default=None, help=argparse.SUPPRESS)  # under valgrind
    args = parser.parse_args()
    global LIVE_STRESS
    LIVE_STRESS = args.live_stress
    if args.passes is not None:
        simulated_passes(args.passes)
        return
    if args.instructions:
        instructions_per_stitch()
        return
    size = tuple(int(v) for v in args.size.split("x"))
    needle = Needle.curved()

    mesh, fixed = paper_cube()
    cube = BiphaseTissue.build(mesh, fixed, ARTERY)
    cube.precompute(use_cache=False)
    if args.only in (None, "simulated"):
        simulated_throughput(cube, needle)
    if args.only in (None, "cube"):
        realtime_cube(cube, needle, args.seconds, size, not args.no_render, args.trace)
    if args.only in (None, "artery"):
        realtime_artery(needle, args.seconds, size, not args.no_render, True, args.trace)
    if args.only in (None, "artery-on-demand"):
        realtime_artery(needle, args.seconds, size, not args.no_render, False, args.trace)


def interpreter_speed(iterations: int = 1_000_000) -> float:
    """Million iterations per second of a plain Python loop (sum of integers): how fast this vCPU
    runs interpreter code at the moment, printed beside the simulated-time figure, which is
    interpreter-bound (on these VMs the same loop varies by 40 % from one minute to the next)."""
    started = time.perf_counter()
    total = 0
    for i in range(iterations):
        total += i
    return iterations / (time.perf_counter() - started) / 1e6


def simulated_throughput(cube, needle) -> None:
    one = practice_passes(scenario("paper_cube"), needle, 1)[0]
    ratios, speeds = [], []
    for _ in range(3):
        speeds.append(interpreter_speed())
        simulation = Simulation(cube, needle, ScriptedDevice(one.pose_and_grip))
        result = simulation.run_simulated(one.duration)
        ratios.append(one.duration / result.wall_seconds)
    print(
        f"[simulated, test cube] one pass of {one.duration:.2f} s simulated: median "
        f"{np.median(ratios):.1f}x real time (runs: {', '.join(f'{r:.1f}' for r in ratios)}); "
        f"a plain Python loop just before each run: {', '.join(f'{v:.0f}' for v in speeds)} M iterations/s",
        flush=True,
    )


def simulated_passes(count: int) -> None:
    """Set up the test cube and run ``count`` simulated stitches (what valgrind counts)."""
    needle = Needle.curved()
    mesh, fixed = paper_cube()
    cube = BiphaseTissue.build(mesh, fixed, ARTERY)
    cube.precompute(use_cache=False)
    one = practice_passes(scenario("paper_cube"), needle, 1)[0]
    for _ in range(count):
        Simulation(cube, needle, ScriptedDevice(one.pose_and_grip)).run_simulated(one.duration)


def instructions_per_stitch() -> None:
    """callgrind's instruction count of set-up plus one stitch, minus set-up alone (both cores used).
    One BLAS thread and a fixed hash seed keep the count repeatable."""
    import shutil

    if shutil.which("valgrind") is None:
        sys.exit("--instructions needs valgrind (apt-get install valgrind)")
    environment = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONHASHSEED="0")
    command = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, __file__]
    runs = [
        subprocess.Popen(
            [*command, "--passes", str(count)], env=environment, stderr=subprocess.PIPE, text=True
        )
        for count in (0, 1)
    ]
    counts = []
    for run in runs:
        _, log = run.communicate()
        found = [line for line in log.splitlines() if "refs:" in line]
        if run.returncode or not found:
            sys.exit(f"valgrind run failed (exit {run.returncode}):\n{log[-2000:]}")
        counts.append(int(found[-1].split("refs:")[1].replace(",", "")))
    one = practice_passes(scenario("paper_cube"), Needle.curved(), 1)[0]
    stitch = counts[1] - counts[0]
    print(
        f"[instructions, test cube] one simulated stitch of {one.duration:.2f} s: {stitch / 1e9:.3f} G "
        f"instructions ({stitch / one.duration / 1e6:.0f} M per simulated second; set-up "
        f"{counts[0] / 1e9:.3f} G); 20x real time needs {20 * stitch / one.duration / 1e9:.1f} G "
        "instructions per wall second",
        flush=True,
    )


def realtime_cube(cube, needle, seconds, size, render, kernel_trace) -> None:
    trajectory, total = sequence_of_passes(practice_passes(scenario("paper_cube"), needle, 20))
    duration = min(seconds, total)
    settings = RuntimeSettings(fem_rate=500.0, live_stress_in_real_time=LIVE_STRESS)
    simulation = Simulation(
        cube, needle, ScriptedDevice(trajectory), settings, renderer=renderer_for(cube, size, render)
    )
    name = f"real time, test cube, {duration:.0f} s"
    report(name, simulation, *run_measuring_steal(simulation, duration, kernel_trace))


def realtime_artery(needle, seconds, size, render, precomputed, kernel_trace) -> None:
    case = scenario("vessel_10k")
    artery = BiphaseTissue.build(case.mesh, case.fixed_nodes, ARTERY, contact_nodes=case.contact_nodes)
    if precomputed:
        artery.precompute(use_cache=False)
    trajectory, total = sequence_of_passes(practice_passes(case, needle, 20))
    duration = min(seconds, total)
    settings = RuntimeSettings(fem_rate=500.0, live_stress_in_real_time=LIVE_STRESS)
    simulation = Simulation(
        artery, needle, ScriptedDevice(trajectory), settings, renderer=renderer_for(artery, size, render)
    )
    mode = "precomputed" if precomputed else "on demand"
    name = f"real time, {case.mesh.n_nodes}-node artery {mode}, {duration:.0f} s"
    report(name, simulation, *run_measuring_steal(simulation, duration, kernel_trace))
    simulation.close()


if __name__ == "__main__":
    main()
