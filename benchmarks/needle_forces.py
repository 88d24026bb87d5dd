"""Needle-force figures of issue 21: the cost of the force kernel, passage forces and live stress.

Run:  .venv/bin/python benchmarks/needle_forces.py

1. Kernel force per tick: the 3m x 3m stiffness product, the nodal spread and the biphase blend,
   for a kernel of k nodes (k = 3 on a coarse mesh, up to ~40 on the refined stitch region).
2. FEM step on the ~10k-node artery (vessel_10k, porcine-artery preset, precomputed): a needle
   pressing on the wall (kernel + local stress) and one through it (lateral kernel, cutting,
   friction, emergence, local stress); median and p99 of repeats.
3. Contact start on the same artery: the FEM step whose continuous collision test meets the wall,
   building the kernel set's stiffness and its local-stress operator, at 40 entry points; median,
   p99, max. Before it, the cost of that test (issue 43) while the needle is carried to the wall.
4. The wall-stitch patch (0.3 mm cells in its stitch region) built and precomputed uncached.
5. The haptic and FEM layers' compute time during a whole simulated stitch on the wall-stitch
   task (kernel contact), from the runtime's own telemetry.
"""

from __future__ import annotations

import math
import time

import numpy as np

from sessions.tasks import forget_tissues, task_preset, task_spec, tissue_for
from sim.calibration.presets import tissue_preset
from sim.calibration.scenarios import scenario
from sim.devices import ScriptedDevice, SuturingPass
from sim.fem import BiphaseTissue
from sim.needle import Needle, Pose
from sim.needle.interaction import NeedleInteraction
from sim.runtime import Simulation


def percentiles(samples: list[float]) -> tuple[float, float, float]:
    values = np.asarray(samples)
    return float(np.median(values)), float(np.percentile(values, 99)), float(values.max())


def timed(function, repeats: int) -> list[float]:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return samples


def artery() -> tuple[BiphaseTissue, object]:
    case = scenario("vessel_10k")
    preset = tissue_preset("porcine-artery")
    tissue = BiphaseTissue.build(
        case.mesh, case.fixed_nodes, preset.biphase, contact_nodes=case.contact_nodes
    )
    started = time.perf_counter()
    tissue.precompute(use_cache=False)
    tissue.soft.factorize()
    tissue.warm_contact_caches()  # as a run does before its clock starts
    print(
        f"artery: {case.mesh.n_nodes} nodes, {len(case.contact_nodes)} candidates, precompute + factor "
        f"{time.perf_counter() - started:.1f} s",
        flush=True,
    )
    return tissue, case


def pressing(interaction: NeedleInteraction, outer: float, angle: float, z: float, depth: float) -> None:
    """Hold the needle's tip ``depth`` inside the artery's outer surface, pointing at its axis."""
    normal = np.array([math.cos(angle), math.sin(angle), 0.0])
    from sim.needle import rotation_aligning

    needle = interaction.needle
    rotation = rotation_aligning(needle.vertices[0] - needle.vertices[1], -normal)
    tip = (outer - depth) * normal + [0, 0, z]
    interaction.hold(0.0, Pose(tip - rotation @ needle.vertices[0], rotation), True)


def kernel_figures(tissue: BiphaseTissue, case, live_stress: bool = True, prefetched: bool = False) -> None:
    """``prefetched``: before each touch, the whole K0^-1 columns of the surface nodes within
    1.5 mm of it are cached (untimed), as the runtime's prefetcher does ahead of the needle."""
    forces = tissue_preset("porcine-artery").forces
    needle = Needle.curved(segments=16)
    outer = float(np.hypot(case.mesh.points[:, 0], case.mesh.points[:, 1]).max())
    starts, steps = [], []
    interaction = None
    for k in range(40):
        interaction = NeedleInteraction(tissue, needle, forces=forces)
        interaction.live_stress = live_stress
        angle, z = math.radians(200 + 3 * k), 0.011 + 0.0002 * k
        pressing(interaction, outer, angle, z, 1e-5)
        if prefetched:
            tip = interaction.needle_vertices()[0]
            surface = tissue.mesh.surface_nodes
            near = surface[np.linalg.norm(tissue.mesh.points[surface] - tip, axis=1) <= 1.5e-3]
            tissue.soft.prefetch(near, full=True)
        interaction.fem_step(0.0)  # 10 um in: does the needle meet the wall here? (a few do not)
        if interaction.state != "contact":
            continue
        interaction = NeedleInteraction(tissue, needle, forces=forces)  # again, timed from free
        interaction.live_stress = live_stress
        pressing(interaction, outer, angle, z, -1e-5)
        interaction.fem_step(0.0)  # 10 um outside: free
        pressing(interaction, outer, angle, z, 2e-4)
        began = time.perf_counter()
        interaction.fem_step(0.002)  # the sweep meets the wall: nominates, builds the kernels and operator
        starts.append(time.perf_counter() - began)
        if interaction.state != "contact":
            raise SystemExit(f"benchmark set-up failed: state {interaction.state} after the first touch")
        for k in range(200):  # pressing on, 0.1 um a step (a needle held still would skip the sweep)
            pressing(interaction, outer, angle, z, 2e-4 + 1e-7 * k)
            steps += timed(lambda i=interaction, t=0.004 + 0.002 * k: i.fem_step(t), 1)
    load = interaction._load
    print(f"kernel nodes at the last entry: {len(load.nodes)}", flush=True)
    d = np.array([[0.0, 0.0, -2e-4]])
    tick = timed(lambda: load.nodal_forces(load.elastic_forces(d, load.soft_share(d, 0.004))), 20000)
    p50, p99, _ = percentiles(tick)
    print(
        f"kernel_force_tick_us median={p50 * 1e6:.2f} p99={p99 * 1e6:.2f} (k={len(load.nodes)})", flush=True
    )
    p50, p99, top = percentiles(starts)
    what = "kernel stiffness (real-time default)"
    if live_stress:
        what = "kernel stiffness + local-stress operator" + (
            ", whole columns prefetched" if prefetched else ", columns solved at the touch"
        )
    print(
        f"contact_start_ms median={p50 * 1e3:.2f} p99={p99 * 1e3:.2f} max={top * 1e3:.2f} "
        f"({len(starts)} first touches on the 10k artery: {what})",
        flush=True,
    )
    p50, p99, _ = percentiles(steps)
    print(
        f"fem_step_pressing_us median={p50 * 1e6:.1f} p99={p99 * 1e6:.1f} (live stress {live_stress})",
        flush=True,
    )


def passage_figure(tissue: BiphaseTissue, case) -> None:
    """A needle through the artery wall: pierce, then step it forward a little each FEM step."""
    forces = tissue_preset("porcine-artery").forces
    needle = Needle.curved(segments=16)
    outer = float(np.hypot(case.mesh.points[:, 0], case.mesh.points[:, 1]).max())
    interaction = NeedleInteraction(tissue, needle, forces=forces)
    angle, z = math.radians(250), 0.015
    pressing(interaction, outer, angle, z, 1e-5)
    interaction.fem_step(0.0)  # the first touch
    depth, now = 1e-5, 0.0
    while interaction.state == "contact" and depth < 1.4e-3:
        depth += 2e-5
        now += 0.002
        pressing(interaction, outer, angle, z, depth)
        interaction.fem_step(now)
    if interaction.state != "pierced":
        raise SystemExit(f"benchmark set-up failed: needle state {interaction.state} at {depth * 1e3:.2f} mm")
    samples = []
    for _ in range(2000):
        depth += 1e-7
        now += 0.002
        pressing(interaction, outer, angle, z, depth)
        began = time.perf_counter()
        interaction.fem_step(now)
        samples.append(time.perf_counter() - began)
    p50, p99, _ = percentiles(samples)
    print(
        f"fem_step_pierced_us median={p50 * 1e6:.1f} p99={p99 * 1e6:.1f} (pierced at {depth * 1e3:.2f} mm: "
        f"lateral kernel, cutting, friction, emergence, local stress)",
        flush=True,
    )


def sweep_figure(tissue: BiphaseTissue, case) -> None:
    """Issue 43: the continuous collision test of the needle's swept path, per FEM step, on the 10k
    artery: a needle carried towards the wall (free) at 10, 100 and 500 mm/s, 500 Hz FEM; the test
    alone (``first_touch``) and the whole free FEM step it is part of."""
    from sim.needle.sweep import first_touch

    forces = tissue_preset("porcine-artery").forces
    needle = Needle.curved(segments=16)
    outer = float(np.hypot(case.mesh.points[:, 0], case.mesh.points[:, 1]).max())
    for speed in (0.01, 0.1, 0.5):
        sweeps, steps = [], []
        for k in range(20):
            angle, z = math.radians(200 + 3 * k), 0.011 + 0.0002 * k
            gap, now = 3e-3, 0.0
            interaction = NeedleInteraction(tissue, needle, forces=forces)
            while gap > speed * 0.002 and interaction.state == "free":
                pressing(interaction, outer, angle, z, -gap)
                before = interaction._swept_from
                after = interaction.needle_vertices()
                if before is not None:
                    collision = interaction.collision
                    sweeps += timed(lambda c=collision, b=before, a=after: first_touch(c, b, a), 1)
                began = time.perf_counter()
                interaction.fem_step(now)
                steps.append(time.perf_counter() - began)
                gap -= speed * 0.002
                now += 0.002
        sweep50, sweep99, _ = percentiles(sweeps)
        step50, step99, _ = percentiles(steps)
        print(
            f"sweep_us at {speed * 1e3:.0f} mm/s: test median={sweep50 * 1e6:.1f} p99={sweep99 * 1e6:.1f}; "
            f"free FEM step median={step50 * 1e6:.1f} p99={step99 * 1e6:.1f} ({len(steps)} steps, "
            "10k artery)",
            flush=True,
        )


def stitch_region_precompute() -> None:
    """The wall-stitch patch built and precomputed from nothing (no cache): the refined stitch region."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as cache:
        forget_tissues()
        started = time.perf_counter()
        tissue = tissue_for(task_spec("wall-stitch"), Path(cache))
        seconds = time.perf_counter() - started
    print(
        f"wall_stitch_precompute_s={seconds:.2f} ({tissue.mesh.n_nodes} nodes, "
        f"{len(tissue.soft.contact_nodes)} stitch-region candidates, 0.3 mm cells; uncached)",
        flush=True,
    )


def stitch_telemetry() -> None:
    tissue = tissue_for(task_spec("wall-stitch"), None)
    spec = task_spec("wall-stitch")
    needle = Needle.curved()
    suturing = SuturingPass(needle, spec.entry, spec.normal, spec.bite_direction)
    simulation = Simulation(
        tissue,
        needle,
        ScriptedDevice(suturing.pose_and_grip),
        forces=task_preset(task_spec("wall-stitch")).forces,
    )
    result = simulation.run_simulated(suturing.duration)
    for layer in ("haptic", "fem"):
        summary = result.telemetry[layer]
        print(
            f"wall_stitch_{layer}_compute_us median={summary.compute_p50 * 1e6:.1f} "
            f"p99={summary.compute_p99 * 1e6:.1f} ({summary.steps} steps, one simulated stitch)",
            flush=True,
        )


def main() -> None:
    tissue, case = artery()
    sweep_figure(tissue, case)
    kernel_figures(tissue, case)
    kernel_figures(tissue, case, prefetched=True)
    kernel_figures(tissue, case, live_stress=False)
    passage_figure(tissue, case)
    stitch_region_precompute()
    stitch_telemetry()


if __name__ == "__main__":
    main()
