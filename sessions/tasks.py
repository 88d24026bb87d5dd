"""The tasks a session can run: a scenario (mesh, materials, fixed nodes) and where the stitch goes."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from sim.errors import VascsimError


@dataclass(frozen=True)
class TaskSpec:
    name: str
    scenario: str
    description: str
    entry: tuple[float, float, float]
    normal: tuple[float, float, float]
    bite_direction: tuple[float, float, float]
    parameters: dict
    placement: dict | None = None
    """The wound edge and target marks placement metrics score against (SI units; see
    :class:`metrics.placement.PlacementTargets`); recorded in each session's header."""


TASKS = {
    "wall-stitch": TaskSpec(
        "wall-stitch",
        "wall_patch",
        "One stitch through a 1.5 mm porcine arterial-wall patch (12 x 10 mm, biphase elastin/collagen, "
        "held on three sides) near its free wound edge; 0.3 mm cells in the 3.5 x 4 mm stitch region.",
        (0.0105, 0.0051, 0.0015),
        (0.0, 0.0, 1.0),
        (1.0, 0.0, 0.0),
        {
            "size_m": [0.012, 0.01, 0.0015],
            "cell_m": 0.001,
            "stitch_cell_m": 0.0003,
            "stitch_region_m": [[0.0085, 0.012], [0.0031, 0.0071]],
            "fixed": ["x0", "y0", "y1"],
            "model": "biphase",
            "tissue": "porcine-artery",
        },
        placement={
            # the free x1 edge is the wound: its plane x = 12 mm, normal pointing into the gap
            "wound_point": [0.012, 0.0, 0.0015],
            "wound_normal": [1.0, 0.0, 0.0],
            "target_bite_m": 0.0015,
            "entry_targets": [[0.0105, 0.0051, 0.0015]],  # on the adventitia, 1.5 mm from the edge
            "exit_targets": [[0.0105, 0.0051, 0.0]],  # straight through: on the intima beneath
            "far_normal": [0.0, 0.0, -1.0],  # the luminal (intimal) surface faces -z
        },
    )
}


def task_spec(name: str) -> TaskSpec:
    if name not in TASKS:
        raise VascsimError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    return TASKS[name]


def task_mesh(spec: TaskSpec):
    """The task's patch mesh: ``stitch_cell_m`` cells over the stitch region (x and y) and through
    the wall, graded to ``cell_m`` elsewhere, so the needle's force kernel spans 3 cells."""
    from sim.mesh import grid_box_mesh, refined_coordinates

    p = spec.parameters
    (length, width, thickness), coarse, fine = p["size_m"], p["cell_m"], p["stitch_cell_m"]
    (x0, x1), (y0, y1) = p["stitch_region_m"]
    return grid_box_mesh(
        refined_coordinates(length, coarse, fine, x0, x1),
        refined_coordinates(width, coarse, fine, y0, y1),
        refined_coordinates(thickness, coarse, fine, 0.0, thickness),
    )


def stitch_region_nodes(spec: TaskSpec, mesh) -> np.ndarray:
    """Surface nodes in the task's stitch region (x, y box; every depth): the contact candidates."""
    (x0, x1), (y0, y1) = spec.parameters["stitch_region_m"]
    points = mesh.points[mesh.surface_nodes]
    inside = (points[:, 0] >= x0 - 1e-9) & (points[:, 0] <= x1 + 1e-9)
    inside &= (points[:, 1] >= y0 - 1e-9) & (points[:, 1] <= y1 + 1e-9)
    return mesh.surface_nodes[inside]


def task_preset(task: str):
    """The task's tissue preset (:mod:`sim.tissue_presets`): biphase parameters and needle forces."""
    from sim.tissue_presets import tissue_preset

    return tissue_preset(task_spec(task).parameters.get("tissue", "paper"))


@cache
def tissue_for(task: str, cache_dir: Path | None = None):
    """The task's precomputed tissue model (built once per process, cached on disk): the preset's
    biphase wall on the task mesh, its condensed inverse over the stitch region's surface nodes."""
    from sim.fem import BiphaseTissue

    spec = task_spec(task)
    mesh = task_mesh(spec)
    fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters["fixed"]])
    candidates = np.setdiff1d(stitch_region_nodes(spec, mesh), fixed)
    tissue = BiphaseTissue.build(mesh, fixed, task_preset(task).biphase, contact_nodes=candidates)
    tissue.precompute(cache_dir=cache_dir)
    return tissue


def session_tissue(streams, cache_dir: Path | None = None):
    """The tissue model a recorded session ran on (from its header's ``task``), or None for
    sessions of other origins (imported data, unknown tasks)."""
    task = streams.attributes.get("task")
    return tissue_for(task, cache_dir) if task in TASKS else None
