"""The kinds of task (sessions.tasks.kinds): every task names one, and one that is unknown is refused
with the task's name and the kinds there are."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sessions.tasks import TASKS, stitch_region_nodes, task_mesh
from sessions.tasks.kinds import KINDS, MeshFile, VesselPatch, WallPatch, kind_of
from sim.errors import VascsimError


def test_every_built_in_task_is_of_a_kind_and_says_its_geometry_in_millimetres():
    for spec in TASKS.values():
        kind = kind_of(spec)
        assert kind is KINDS[spec.scenario]
        assert "held on" in kind.geometry(spec) and "mm" in kind.geometry(spec)
    assert isinstance(kind_of(TASKS["wall-stitch"]), WallPatch)
    assert isinstance(kind_of(TASKS["interrupted-stitch"]), VesselPatch)
    assert set(KINDS) == {"wall_patch", "vessel_patch", "mesh_file"}
    assert isinstance(KINDS["mesh_file"], MeshFile)


def test_a_wall_patch_builds_its_graded_mesh_and_finds_its_stitch_region():
    spec = TASKS["wall-stitch"]
    mesh = task_mesh(spec)
    (x0, x1), (y0, y1) = spec.parameters.stitch_region_m
    nodes = stitch_region_nodes(spec, mesh)
    points = mesh.points[nodes]
    assert len(nodes) > 0 and np.isin(nodes, mesh.surface_nodes).all()
    assert (points[:, 0] >= x0 - 1e-9).all() and (points[:, 0] <= x1 + 1e-9).all()
    assert (points[:, 1] >= y0 - 1e-9).all() and (points[:, 1] <= y1 + 1e-9).all()
    # the stitch region is graded finer than the rest of the patch
    xs = np.unique(np.round(mesh.points[:, 0], 9))
    steps = np.diff(xs)
    assert steps.min() == pytest.approx(spec.parameters.stitch_cell_m, rel=0.05)
    assert steps.max() > 1.5 * spec.parameters.stitch_cell_m


def test_a_task_of_an_unknown_kind_is_refused_naming_it_and_the_kinds():
    spec = dataclasses.replace(TASKS["wall-stitch"], name="my-task", scenario="lung_patch")
    with pytest.raises(
        VascsimError, match=r"task 'my-task' is of kind 'lung_patch'.*wall_patch, vessel_patch"
    ):
        task_mesh(spec)
