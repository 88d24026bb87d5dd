"""Issue 43, item 5: is the overstress decision converged with mesh refinement?

Run:  .venv/bin/python benchmarks/damage_convergence.py [--cells 0.5,0.35,0.25,0.18]
          [--nonlocal LENGTH_MM,DEPTH_MM,LIMIT_MPA] [--whole-patch]

The wall-stitch patch (porcine-artery preset) is rebuilt with its stitch region at each cell size (mm)
and a straight needle is, through the runtime's own interaction:

1. pressed perpendicular into the wall (puncture lifted) until the local stress (largest von Mises
   stress within 1 mm, what ``overstress`` watches) reaches the preset's ``damage_stress``: that
   depth;
2. pierced at 0.8 N and levered sideways across itself in the wall until the local stress reaches it:
   that sideways offset (the way levering trainees fire the event).

Prints both per cell size and the relative difference between the two finest meshes (target <= 5 %),
and why the lever's does not converge: the levering kernel's compliance along and across the wall,
and the von Mises stress per newton of sideways load of the elements next to the surface (within
0.12 mm of the kernel's point and 0.1 mm deep) against those half-way through the 1.5 mm wall.

``--nonlocal`` measures a candidate criterion instead of the simulator's (the largest element stress
within 1 mm): the non-local stress of integral damage models (Pijaudier-Cabot and Bazant 1987), the
local elements' von Mises stress averaged with Gaussian weights of length LENGTH_MM (times each
element's volume) round each kernel's point moved DEPTH_MM into the wall (towards the local elements'
centroid), against LIMIT_MPA. The interaction's local stress is replaced by it in this process only.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path = [p for p in sys.path if Path(p).resolve() != Path(__file__).resolve().parent]

import numpy as np  # noqa: E402

from sessions.tasks import stitch_region_nodes, task_mesh, task_preset, task_spec  # noqa: E402
from sim.calibration.indentation import PressedNeedle  # noqa: E402
from sim.fem import BiphaseTissue, fields  # noqa: E402
from sim.needle import Needle, Pose, rotation_aligning  # noqa: E402
from sim.needle.interaction import NeedleInteraction  # noqa: E402


def wall_at(cell: float, whole_patch: bool = False) -> BiphaseTissue:
    """The wall-stitch patch with its stitch region at ``cell`` (m); ``whole_patch``: the coarse cell
    outside it refined in the same proportion (1 mm at the task's 0.3 mm)."""
    spec = task_spec("wall-stitch")
    parameters = dataclasses.replace(spec.parameters, stitch_cell_m=cell)
    if whole_patch:
        coarse = spec.parameters.cell_m * cell / spec.parameters.stitch_cell_m
        parameters = dataclasses.replace(parameters, cell_m=coarse)
    refined = dataclasses.replace(spec, parameters=parameters)
    mesh = task_mesh(refined)
    fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters.fixed])
    region = np.setdiff1d(stitch_region_nodes(refined, mesh), fixed)
    near = region[np.linalg.norm(mesh.points[region] - np.asarray(spec.entry), axis=1) <= 2.5e-3]
    tissue = BiphaseTissue.build(
        mesh, fixed, task_preset(task_spec("wall-stitch")).biphase, contact_nodes=near
    )
    tissue.precompute(use_cache=False)
    return tissue


def crossing(xs: list[float], stresses: list[float], limit: float) -> float:
    """The first x at which the stress reaches ``limit`` (linear between samples; nan if never)."""
    values = np.asarray(stresses)
    above = np.flatnonzero(values >= limit)
    if not above.size:
        return float("nan")
    k = int(above[0])
    if k == 0:
        return xs[0]
    return float(np.interp(limit, [values[k - 1], values[k]], [xs[k - 1], xs[k]]))


def press_depth(tissue: BiphaseTissue, limit: float) -> float:
    spec, forces = task_spec("wall-stitch"), task_preset(task_spec("wall-stitch")).forces
    pressed = PressedNeedle(tissue, forces, spec.entry, spec.normal, step=1e-5)
    pressed.press_to(0.0, 0.004)
    depths, stresses = [], []
    for depth in np.arange(0.02e-3, 1.45e-3, 0.02e-3):
        pressed.press_to(float(depth), 0.004)
        depths.append(float(depth))
        stresses.append(pressed.interaction.local_stress)
    print(
        f"  press: largest local stress {max(stresses) / 1e6:.3f} MPa at {depths[-1] * 1e3:.2f} mm",
        flush=True,
    )
    return crossing(depths, stresses, limit)


def diagnose(
    tissue: BiphaseTissue, interaction: NeedleInteraction, normal: np.ndarray, sideways: np.ndarray
) -> None:
    """The levering kernel's compliance, and the stress per newton of sideways load near the surface
    and half-way through the wall (see the module docstring)."""
    operator, load = interaction._stress, interaction._load  # what the FEM step reads
    elements = operator.elements
    rows = (operator._operator[: 6 * len(elements)] @ sideways).reshape(-1, 6)
    per_newton = np.sqrt((rows**2).sum(axis=1))
    kernel = load.kernels[0]
    offsets = tissue.mesh.points[tissue.mesh.tets[elements]].mean(axis=1) - kernel.point
    depth = -(offsets @ normal)
    across = np.linalg.norm(offsets + np.outer(depth, normal), axis=1)
    block = load.soft.compliance[:3, :3]
    third = np.cross(normal, sideways)
    surface = per_newton[np.hypot(depth - 0.1e-3, across) < 0.12e-3].mean()
    mid = per_newton[np.hypot(depth - 0.5e-3, across) < 0.12e-3].mean()
    print(
        f"  kernel ({kernel.radius * 1e3:.2f} mm, {len(kernel.nodes)} nodes) compliance "
        f"{normal @ block @ normal * 1e3:.2f} mm/N along the normal, {sideways @ block @ sideways * 1e3:.2f} "
        f"mm/N sideways, {third @ block @ third * 1e3:.2f} mm/N across both; stress per newton "
        f"sideways: largest {per_newton.max() / 1e6:.3f} MPa, next to the surface {surface / 1e6:.3f}, "
        f"0.5 mm deep {mid / 1e6:.3f}",
        flush=True,
    )


def lever_offset(tissue: BiphaseTissue, limit: float) -> float:
    spec, forces = task_spec("wall-stitch"), task_preset(task_spec("wall-stitch")).forces
    needle = Needle.straight(0.01)
    interaction = NeedleInteraction(tissue, needle, forces=forces.with_(tear_force=None))
    normal = np.asarray(spec.normal, dtype=np.float64)
    rotation = rotation_aligning([1.0, 0.0, 0.0], -normal)
    sideways = np.asarray(spec.bite_direction, dtype=np.float64)
    now = 0.0

    def place(depth: float, offset: float) -> None:
        nonlocal now
        now += 0.002
        tip = np.asarray(spec.entry) - depth * normal + offset * sideways
        interaction.hold(now, Pose(tip - rotation @ needle.vertices[0], rotation), True)
        interaction.fem_step(now)

    place(-1e-4, 0.0)
    depth = 0.0
    while interaction.state == "contact" or depth == 0.0:
        depth += 1e-5
        place(depth, 0.0)
        if depth > 1.4e-3:
            raise SystemExit("set-up failed: the needle did not pierce")
    place(depth + 0.2e-3, 0.0)  # in the wall, not yet through it
    place(depth + 0.2e-3, 0.5e-3)
    diagnose(tissue, interaction, normal, sideways)
    offsets, stresses = [], []
    for offset in np.arange(0.01e-3, 1.0e-3, 0.01e-3):
        place(depth + 0.2e-3, float(offset))
        offsets.append(float(offset))
        stresses.append(interaction.local_stress)
    print(
        f"  lever: largest local stress {max(stresses) / 1e6:.3f} MPa at {offsets[-1] * 1e3:.2f} mm, "
        f"state {interaction.state}; pierced at {depth * 1e3:.3f} mm, levered from "
        f"{(depth + 0.2e-3) * 1e3:.3f} mm deep; stress before levering {stresses[0] / 1e6:.3f} MPa",
        flush=True,
    )
    return crossing(offsets, stresses, limit)


def use_nonlocal_stress(length: float, depth: float) -> None:
    """Replace, in this process, the local stress every :class:`sim.fem.fields.LocalStress` reports by
    the non-local stress described in the module docstring (length and depth in m)."""
    weights: dict[int, np.ndarray] = {}
    build, measure = fields.LocalStress.__init__, fields.LocalStress.measures

    def init(self, tissue, nodes, force_map, centres, radius=fields.LOCAL_STRESS_RADIUS, watched=None):
        build(self, tissue, nodes, force_map, centres, radius, watched)
        mesh = tissue.mesh
        corners = mesh.points[mesh.tets[self.elements]]
        middle = corners.mean(axis=1)
        edges = corners[:, 1:] - corners[:, :1]
        volume = np.abs(np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2]))) / 6
        points = np.atleast_2d(np.asarray(centres, dtype=np.float64))
        if depth and len(middle):
            inward = middle.mean(axis=0) - points.mean(axis=0)
            points = points + depth * inward / np.linalg.norm(inward)
        w = np.exp(-((middle[None] - points[:, None]) ** 2).sum(axis=-1) / (2 * length**2)) * volume
        weights[id(self)] = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)

    def measures(self, forces, scale=1.0):
        _, watched, stretch = measure(self, forces, scale)
        count = len(self.elements)
        if not count:
            return 0.0, watched, stretch
        rows = (self._operator[: 6 * count] @ np.asarray(forces, dtype=np.float64).reshape(-1)).reshape(-1, 6)
        return float((weights[id(self)] @ np.sqrt((rows**2).sum(axis=1))).max()), watched, stretch

    fields.LocalStress.__init__, fields.LocalStress.measures = init, measures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", default="0.5,0.35,0.25,0.18", help="stitch-region cell sizes in mm")
    parser.add_argument(
        "--nonlocal",
        dest="nonlocal_stress",
        metavar="LENGTH_MM,DEPTH_MM,LIMIT_MPA",
        help="measure the non-local stress criterion (module docstring) against LIMIT_MPA instead",
    )
    parser.add_argument(
        "--whole-patch", action="store_true", help="refine the coarse cell outside the stitch region too"
    )
    args = parser.parse_args()
    cells = [float(c) * 1e-3 for c in args.cells.split(",")]
    limit = task_preset(task_spec("wall-stitch")).forces.damage_stress
    if args.nonlocal_stress:
        length, depth, limit = (float(v) for v in args.nonlocal_stress.split(","))
        use_nonlocal_stress(length * 1e-3, depth * 1e-3)
        limit *= 1e6
    rows = []
    for cell in cells:
        began = time.perf_counter()
        tissue = wall_at(cell, args.whole_patch)
        depth, offset = press_depth(tissue, limit), lever_offset(tissue, limit)
        rows.append((cell, depth, offset))
        print(
            f"cell {cell * 1e3:.2f} mm ({tissue.mesh.n_nodes} nodes): overstress at press depth "
            f"{depth * 1e3:.3f} mm, at lever offset {offset * 1e3:.3f} mm "
            f"({time.perf_counter() - began:.0f} s)",
            flush=True,
        )
    (_, d1, o1), (_, d2, o2) = rows[-2], rows[-1]
    print(
        f"two finest meshes: press depth differs by {abs(d2 - d1) / d2:.1%}, lever offset by "
        f"{abs(o2 - o1) / o2:.1%} (target <= 5 %)"
    )


if __name__ == "__main__":
    main()
