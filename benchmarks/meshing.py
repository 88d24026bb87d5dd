"""Issue 27's meshing figures: a ~100k-node vessel wall from a surface, as a course would bring one.

Run:  .venv/bin/python benchmarks/meshing.py [--max-edge 0.4] [--touches 40]

A bent artery's lumen surface (inner radius 4 mm, 40 mm along a centreline of radius 30 mm, written
as STL in millimetres) becomes a task (`vascsim tasks add`'s path: TetGen, 1.5 mm wall, three
layers), then:
1. meshing time and the mesh's quality (radius-edge ratio, dihedral angles);
2. load to the first haptic tick: the task's tissue built and precomputed over its stitch region
   (nothing cached), the simulation made, its first haptic step taken;
3. the process's peak memory (ru_maxrss);
4. contact start on that wall with the columns near the needle prefetched, as the runtime's
   prefetcher does ahead of it (three nodes a solve), under the FEM layer's conditions in a run
   (``process_prepared``: frozen heap, freed memory kept; one BLAS thread): median and p99 over
   ``--touches`` first touches.
Targets: load to first tick < 60 s, memory < 8 GB, contact start p99 <= 5 ms.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

import numpy as np  # noqa: E402
import pyvista as pv  # noqa: E402


def bent_lumen(radius_mm=4.0, length_mm=40.0, bend_mm=30.0, around=160, along=160) -> pv.PolyData:
    theta = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    ring = np.stack([radius_mm * np.cos(theta), radius_mm * np.sin(theta), np.zeros_like(theta)], axis=1)
    rows = []
    for s in np.linspace(0.0, length_mm, along + 1):
        angle = s / bend_mm
        rows.append(
            np.stack(
                [
                    (bend_mm + ring[:, 0]) * np.cos(angle) - bend_mm,
                    ring[:, 1],
                    (bend_mm + ring[:, 0]) * np.sin(angle),
                ],
                axis=1,
            )
        )
    faces = []
    for j in range(along):
        for i in range(around):
            a, b = j * around + i, j * around + (i + 1) % around
            faces += [[3, a, b, b + around], [3, a, b + around, a + around]]
    return pv.PolyData(np.concatenate(rows), np.array(faces).ravel())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-edge", type=float, default=0.4, help="largest element edge (mm)")
    parser.add_argument("--touches", type=int, default=40)
    parser.add_argument(
        "--no-live-stress",
        action="store_true",
        help="contact start with the kernel stiffness only (no local-stress operator, columns not whole)",
    )
    parser.add_argument(
        "--within", type=float, default=1.5, help="touches within this distance (mm) of the task's entry"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        os.environ["VASCSIM_HOME"] = folder
        from threadpoolctl import threadpool_limits

        from sessions.tasks import add_mesh_task, stitch_region_nodes, task_spec, tissue_for
        from sim.calibration.presets import tissue_preset
        from sim.devices import ScriptedDevice
        from sim.mesh.surfaces import mesh_vessel_surface
        from sim.needle import Needle, Pose, rotation_aligning
        from sim.needle.interaction import NeedleInteraction
        from sim.runtime import Simulation
        from sim.runtime.osrt import process_prepared
        from sim.runtime.prefetch import SOLVE_CHUNK

        surface = Path(folder) / "lumen.stl"
        bent_lumen().save(surface)
        started = time.perf_counter()
        mesh, quality = mesh_vessel_surface(surface, thickness=1.5e-3, max_edge=args.max_edge * 1e-3)
        meshing = time.perf_counter() - started
        print(
            f"[meshing] {meshing:.1f} s for a {mesh.n_nodes}-node wall (max edge {args.max_edge} mm)",
            flush=True,
        )
        for line in quality.lines():
            print(f"  {line}", flush=True)
        # the entry: on the outer surface at mid-length, on the bend's outside (x > 0 side of the ring)
        mid = 20.0 / 30.0
        entry = np.array([(30.0 + 5.5) * np.cos(mid) - 30.0, 0.0, (30.0 + 5.5) * np.sin(mid)]) * 1e-3
        spec = add_mesh_task("bent-artery", mesh, entry, fixed=("end0", "end1"))
        started = time.perf_counter()
        tissue = tissue_for(spec, Path(folder) / "cache")
        needle = Needle.curved()
        forces = tissue_preset("porcine-artery").forces
        trajectory = lambda t: (Pose(np.array(spec.entry) + 0.01 * np.array(spec.normal), np.eye(3)), False)  # noqa: E731
        simulation = Simulation(tissue, needle, ScriptedDevice(trajectory), forces=forces)
        simulation.haptic_step(0.0)
        loaded = time.perf_counter() - started
        candidates = stitch_region_nodes(task_spec(spec.name), tissue.mesh)
        print(
            f"[load to first haptic tick] {loaded:.1f} s ({len(candidates)} stitch-region candidates "
            "precomputed, nothing cached; target < 60 s)",
            flush=True,
        )
        tissue.warm_contact_caches()  # as a run does before its clock starts
        starts = []
        run_conditions = contextlib.ExitStack()  # what the FEM layer runs under (sim.runtime)
        run_conditions.enter_context(process_prepared())
        run_conditions.enter_context(threadpool_limits(1))
        rng = np.random.default_rng(0)
        outer = tissue.mesh.node_sets["outer"]
        near = outer[np.linalg.norm(tissue.mesh.points[outer] - spec.entry, axis=1) < args.within * 1e-3]
        for node in rng.choice(near, size=min(args.touches, len(near)), replace=False):
            point = tissue.mesh.points[node]
            touching = np.any(tissue.mesh.surface_triangles == node, axis=1)
            normal = tissue.mesh.surface_normals[touching].mean(axis=0)
            normal /= np.linalg.norm(normal)
            interaction = NeedleInteraction(tissue, needle, forces=forces)
            interaction.live_stress = not args.no_live_stress
            rotation = rotation_aligning(needle.vertices[0] - needle.vertices[1], -normal)

            def press(depth, interaction=interaction, rotation=rotation, point=point, normal=normal):
                tip = point - depth * normal
                interaction.hold(0.0, Pose(tip - rotation @ needle.vertices[0], rotation), True)

            press(-1e-5)  # 10 um outside the wall: free
            interaction.fem_step(0.0)
            press(1e-5)
            surface_nodes = tissue.mesh.surface_nodes
            tip = interaction.needle_vertices()[0]
            close = surface_nodes[np.linalg.norm(tissue.mesh.points[surface_nodes] - tip, axis=1) <= 1.5e-3]
            for chunk in range(0, len(close), SOLVE_CHUNK):  # as the prefetcher does ahead of the
                tissue.soft.prefetch(close[chunk : chunk + SOLVE_CHUNK], full=not args.no_live_stress)
            tissue.cast_depths(close)  # needle: columns solved a triangle's worth at a time, depths cast
            press(2e-4)
            began = time.perf_counter()
            interaction.fem_step(0.001)  # the sweep meets the wall: nominates and builds the kernels
            starts.append(time.perf_counter() - began)
            if interaction.state != "contact":
                continue
        run_conditions.close()
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB -> bytes
        p50, p99 = np.percentile(starts, [50, 99]) if starts else (np.nan, np.nan)
        print(
            f"[contact start, prefetched] median {1e3 * p50:.2f} ms, p99 {1e3 * p99:.2f} ms over "
            f"{len(starts)} first touches, live stress {'off' if args.no_live_stress else 'on'} "
            "(target p99 <= 5 ms)",
            flush=True,
        )
        print(f"[peak memory] {peak / 1e9:.2f} GB = {peak / 2**30:.2f} GiB (target < 8 GB)", flush=True)
        simulation.close()


if __name__ == "__main__":
    main()
