"""Collision-detection figures of issue 3.

Run:  .venv/bin/python benchmarks/collision.py

Global CD per graphics frame (a 16-segment 3/8-circle needle pressed into an
artery's outer wall) against ~10k and ~100k exterior triangles; the collision
mesh update after a subordinate-hand deformation; local CD per FEM tick
(penetration test and barycentric distribution against the nominated triangle)
and the whole FEM-rate contact step including the force. Medians of repeats.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from sim.collision.mesh import CollisionMesh
from sim.fem import Material, TissueModel
from sim.mesh import vessel_mesh
from sim.needle import Needle, Pose, rotation_aligning
from sim.needle.interaction import NeedleInteraction


def per_call(function: Callable[[], object], calls: int, repeats: int = 7) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            function()
        samples.append((time.perf_counter() - start) / calls)
    return float(np.median(samples))


def pressing_pose(needle: Needle, depth: float = 2e-4) -> Pose:
    """Needle tip pointing at the artery's axis, ``depth`` inside its outer surface at z = 15 mm."""
    rotation = rotation_aligning(needle.vertices[0] - needle.vertices[1], [-1.0, 0.0, 0.0])
    tip = np.array([0.0055 - depth, 0.0, 0.015])
    return Pose(tip - rotation @ needle.vertices[0], rotation)


def main() -> None:
    needle = Needle.curved(segments=16)
    pose = pressing_pose(needle)
    for n_theta, n_axial in ((64, 40), (160, 156)):
        mesh = vessel_mesh(
            circumferential_divisions=n_theta, radial_divisions=1, axial_divisions=n_axial, length=0.03
        )
        collision = CollisionMesh(mesh)
        vertices = needle.world_vertices(pose)
        hits = collision.query(vertices)
        frame_ms = 1e3 * per_call(lambda c=collision, v=vertices: c.query(v), 50)
        lifted = mesh.node_sets["outer"][:200]
        lifts = iter(np.arange(1, 10_000) * 1e-7)  # a new displacement each call, as a moving hand gives
        update_ms = 1e3 * per_call(
            lambda c=collision, n=lifted, k=lifts: c.deform(n, np.array([0.0, 0.0, next(k)])), 5
        )
        print(
            f"triangles={len(collision.triangles)}  segments={needle.segment_count}  hits={len(hits)}  "
            f"global_cd_frame_ms={frame_ms:.3f}  collision_mesh_update_ms={update_ms:.2f}",
            flush=True,
        )

    mesh = vessel_mesh(circumferential_divisions=64, radial_divisions=3, axial_divisions=40, length=0.03)
    fixed = np.union1d(mesh.node_sets["end0"], mesh.node_sets["end1"])
    model = TissueModel(mesh, Material(20e3, 0.45), fixed, contact_nodes=mesh.node_sets["outer"])
    model.precompute(use_cache=False)
    interaction = NeedleInteraction(model, needle)
    interaction.hold(0.0, pose, True)
    interaction.fem_step(0.0)  # the continuous test meets the wall: a contact (issue 43)
    if interaction.state != "contact":
        raise SystemExit(f"benchmark set-up failed: needle state {interaction.state}, expected contact")
    contact = interaction.contacts[0]
    tip = interaction.needle_vertices()[0]

    def local_cd() -> None:
        if contact.penetration(tip) > 0:
            np.outer(contact.barycentric, tip - contact.point)

    local_us = 1e6 * per_call(local_cd, 20000)
    step_us = 1e6 * per_call(lambda: interaction.fem_step(0.0), 5000)
    print(
        f"local_cd_tick_us={local_us:.2f}  fem_contact_step_us={step_us:.2f} (local CD + force, "
        f"{mesh.n_nodes}-node artery, precomputed)",
        flush=True,
    )


if __name__ == "__main__":
    main()
