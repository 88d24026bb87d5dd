"""The station's countdown solves what a trial's first exit reads (sessions.tasks.warm_exit_columns)."""

import time

import numpy as np

from sessions.tasks import task_preset, task_spec, tissue_for, warm_exit_columns
from sim.collision.mesh import CollisionMesh
from sim.devices.suturing import planned_exits
from sim.needle import Needle
from sim.runtime.simulation import EXIT_REACH_KERNELS


def test_the_countdown_solves_the_exit_faces_whole_and_keeps_to_its_deadline():
    spec = task_spec("wall-stitch")
    tissue = tissue_for(spec, None)
    tissue.base.drop_cached_columns()
    mesh = tissue.mesh
    sites = planned_exits(Needle.curved(), CollisionMesh(mesh), spec.bites())
    reach = EXIT_REACH_KERNELS * task_preset(spec).forces.kernel_radius
    surface = np.setdiff1d(mesh.surface_nodes, tissue.base.clamped_nodes)
    wanted = np.unique(
        np.concatenate([surface[np.linalg.norm(mesh.points[surface] - s, axis=1) <= reach] for s in sites])
    )
    assert wanted.size and all(tissue.base.needs_solve(int(n), full=True) for n in wanted)
    solve = warm_exit_columns(spec, None)
    assert solve(time.monotonic() - 1.0) == 0  # no time left: nothing solved
    assert solve(time.monotonic() + 120.0) == wanted.size
    assert not any(model.needs_solve(int(n), full=True) for model in tissue.models for n in wanted)
    assert solve(time.monotonic() + 120.0) == 0  # solved once
