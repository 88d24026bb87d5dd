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


TASKS = {
    "wall-stitch": TaskSpec(
        "wall-stitch",
        "wall_patch",
        "One stitch through a 1.5 mm vessel-wall patch (12 x 10 mm, biphase elastin/collagen, held on three "
        "sides) near its free wound edge.",
        (0.0105, 0.0051, 0.0015),
        (0.0, 0.0, 1.0),
        (1.0, 0.0, 0.0),
        {
            "size_m": [0.012, 0.01, 0.0015],
            "cells": [12, 10, 3],
            "fixed": ["x0", "y0", "y1"],
            "model": "biphase",
        },
    )
}


def task_spec(name: str) -> TaskSpec:
    if name not in TASKS:
        raise VascsimError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    return TASKS[name]


@cache
def tissue_for(task: str, cache_dir: Path | None = None):
    """The task's precomputed tissue model (built once per process, cached on disk)."""
    from sim.fem import BiphaseTissue
    from sim.mesh import box_mesh

    spec = task_spec(task)
    mesh = box_mesh(tuple(spec.parameters["size_m"]), tuple(spec.parameters["cells"]))
    fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters["fixed"]])
    tissue = BiphaseTissue.build(mesh, fixed)
    tissue.precompute(cache_dir=cache_dir)
    return tissue


def session_tissue(streams, cache_dir: Path | None = None):
    """The tissue model a recorded session ran on (from its header's ``task``), or None for
    sessions of other origins (imported data, unknown tasks)."""
    task = streams.attributes.get("task")
    return tissue_for(task, cache_dir) if task in TASKS else None
