"""What a task becomes to run: its mesh, contact candidates, tissue presets, the precomputed tissue,
the subordinate hand's grasp sites and the simulation."""

from __future__ import annotations

import json
import time as clock
from collections.abc import Callable
from pathlib import Path

import numpy as np

from sessions.tasks.kinds import kind_of
from sessions.tasks.spec import TaskSpec
from sessions.tasks.user import known_task, task_spec
from sim.calibration.presets import tissue_preset
from sim.collision.mesh import CollisionMesh
from sim.devices.assisting import edge_grasp
from sim.devices.suturing import planned_exits
from sim.fem import BiphaseTissue
from sim.needle import Needle
from sim.needle.reach import WristLimit, WristStop
from sim.runtime import Simulation
from sim.runtime.simulation import EXIT_REACH_KERNELS


def task_mesh(spec: TaskSpec):
    """The task's mesh, as its kind builds it (:mod:`sessions.tasks.kinds`)."""
    return kind_of(spec).mesh(spec)


def stitch_region_nodes(spec: TaskSpec, mesh) -> np.ndarray:
    """The surface nodes of the task's stitch region, as its kind finds them: the contact candidates."""
    return kind_of(spec).stitch_region_nodes(spec, mesh)


def task_preset(spec: TaskSpec):
    """The task's tissue preset (:mod:`sim.calibration.presets`): biphase parameters and needle forces."""

    return tissue_preset(spec.parameters.tissue)


def region_presets(spec: TaskSpec) -> dict:
    """Mesh region name -> tissue preset for the task's regions that differ from its wall (e.g. a
    calcified plaque); empty for a uniform wall."""

    return {region: tissue_preset(name) for region, name in spec.parameters.region_tissue.items()}


def region_forces(spec: TaskSpec, mesh) -> dict:
    """Mesh region id -> the needle forces of that region's preset (see :func:`region_presets`)."""
    ids = {name: rid for rid, name in mesh.region_names.items()}
    return {ids[region]: preset.forces for region, preset in region_presets(spec).items()}


_TISSUES: dict[tuple[str, str, str], object] = {}
"""Tissue models built in this process, by the task's name, what it is made of and the cache folder
(a task edited in place is a different key, so it is built again)."""


def tissue_for(spec: TaskSpec, cache_dir: Path | None = None):
    """The task's precomputed tissue model (built once per process, cached on disk): the preset's
    biphase wall on the task mesh, its condensed inverse over the stitch region's surface nodes."""
    key = (
        spec.name,
        json.dumps([spec.scenario, spec.parameters.as_dict()], sort_keys=True, default=str),
        str(cache_dir),
    )
    if key not in _TISSUES:
        _TISSUES[key] = _built_tissue(spec, cache_dir)
    return _TISSUES[key]


def forget_tissues() -> None:
    """Drop the tissue models built in this process (a benchmark timing a build from the disk cache)."""
    _TISSUES.clear()


def _built_tissue(spec: TaskSpec, cache_dir: Path | None):
    kind = kind_of(spec)
    mesh = kind.mesh(spec)
    kind.check(spec, mesh)  # a stored task's mesh file can be edited by hand after `tasks add`
    fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters.fixed])
    candidates = np.setdiff1d(stitch_region_nodes(spec, mesh), fixed)
    regions = {region: preset.biphase for region, preset in region_presets(spec).items()}
    tissue = BiphaseTissue.build(
        mesh, fixed, task_preset(spec).biphase, region_parameters=regions, contact_nodes=candidates
    )
    tissue.precompute(cache_dir=cache_dir)
    return tissue


def session_tissue(streams, cache_dir: Path | None = None):
    """The tissue model a recorded session ran on (from its header's ``task``), or None for
    sessions of other origins (imported data, unknown tasks)."""
    task = streams.attributes.get("task")
    return tissue_for(task_spec(task), cache_dir) if task is not None and known_task(task) else None


def edge_grasps(spec: TaskSpec) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per bite, where the subordinate hand takes the wound edge and the way it lifts it
    (:func:`sim.devices.assisting.edge_grasp`: the rim beside the entry); none without a wound."""

    placement = spec.placement or {}
    if placement.get("wound_point") is None:
        return []
    wound = placement["wound_point"], placement["wound_normal"]
    return [edge_grasp(entry, normal, *wound) for entry, normal, _ in spec.bites()]


def grasp_sites(spec: TaskSpec) -> np.ndarray:
    """(k, 3) points (m) where the subordinate hand takes the wound edge for the task's bites
    (:func:`edge_grasps`), (0, 3) on a task without a wound."""
    return np.asarray([rim for rim, _ in edge_grasps(spec)], dtype=np.float64).reshape(-1, 3)


def wrist_stop(spec: TaskSpec) -> WristStop | None:
    """Where the task's approach stops the needle hand's wrist (``spec.eversion``), None where it
    reaches square."""
    if spec.eversion is None:
        return None
    return WristStop.short_of_square(spec.normal, spec.bite_direction, spec.eversion.short_deg)


def task_simulation(spec: TaskSpec, device, cache_dir: Path | None = None, **options):
    """A :class:`sim.runtime.Simulation` of the task driven by ``device``: the task's tissue, the
    curved needle, its preset's needle forces and its regions' own (a calcified plaque pierces at
    its own threshold). ``options`` go to the Simulation (e.g. ``settings``)."""

    tissue = tissue_for(spec, cache_dir)
    if options.get("subordinate") is not None and "grasp_sites" not in options:
        options["grasp_sites"] = grasp_sites(spec)
    options.setdefault("bites", spec.bites())
    simulation = Simulation(
        tissue,
        Needle.curved(),
        device,
        forces=task_preset(spec).forces,
        region_forces=region_forces(spec, tissue.mesh),
        **options,
    )
    stop = wrist_stop(spec)
    if stop is not None:  # the approach stops the wrist short of square to the resting wall
        simulation.interaction.wrist = WristLimit(stop, simulation.interaction.needle)
    return simulation


def warm_exit_columns(spec: TaskSpec, cache_dir: Path | None) -> Callable[[float], int]:
    """``solve(until)``: solves, in this process's tissue model of the task (:func:`tissue_for`), the
    whole K0^-1 columns of the surface nodes round where a needle planned square on each bite comes out
    of the wall, nearest first, three at a time, until ``until`` (``time.monotonic()``) or all are
    solved; returns how many it solved. The nodes are found at its first call. The station calls it in
    its start countdown, where the process would only wait, so a trial's first exit finds them (a
    real-time run's column worker, sharing a core with the display, reaches them only after a fast
    hand's first exit)."""
    missing: list[int] | None = None

    def solve(until: float) -> int:
        nonlocal missing
        tissue = tissue_for(spec, cache_dir)
        models = [model for model in tissue.models if model.inverse_source is None]  # a shared one divides
        if missing is None:
            missing = [
                n for n in _exit_face_nodes(spec, tissue) if any(m.needs_solve(n, full=True) for m in models)
            ]
        solved = 0
        while missing and clock.monotonic() < until:
            chunk, missing = missing[:3], missing[3:]
            for model in models:
                model.prefetch(np.array(chunk), full=True)
            solved += len(chunk)
        return solved

    return solve


def _exit_face_nodes(spec: TaskSpec, tissue) -> list[int]:
    """The free surface nodes within the kernels' reach of the task's planned exits, nearest first."""
    mesh = tissue.mesh
    reach = EXIT_REACH_KERNELS * task_preset(spec).forces.kernel_radius
    surface = np.setdiff1d(mesh.surface_nodes, tissue.base.clamped_nodes)
    wanted: dict[int, None] = {}  # ordered, each once
    for site in planned_exits(Needle.curved(), CollisionMesh(mesh), spec.bites()):
        distance = np.linalg.norm(mesh.points[surface] - site, axis=1)
        close = distance <= reach
        wanted.update(dict.fromkeys(surface[close][np.argsort(distance[close])].tolist()))
    return list(wanted)
