"""The tasks a session can run: a scenario (mesh, materials, fixed nodes) and where the stitch goes."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

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
    more_bites: tuple = ()
    """Further bites after the first, in the order they are made: (entry, normal, bite_direction)."""
    access: dict | None = None
    """Restricted access: ``approach`` (unit vector from the entry point: the only direction the
    hand can come from) and ``tilt_deg`` (its angle from the wall's normal); None: open access."""
    time_budget_s: float = 60.0
    """The time a course allows for the task (s): chosen at about ten times a scripted expert's."""

    @property
    def stitch_count(self) -> int:
        """The stitches the task asks for (one per target entry mark; one without marks)."""
        return len(self.placement["entry_targets"]) if self.placement else 1

    @property
    def primary_metrics(self) -> tuple[str, ...]:
        """The metrics a study of this task analyses unless it declares others, chosen before any data:
        the source paper's proposed needle velocity near the insertion point (before and after
        piercing), its perpendicular-entry criterion, the hand's smoothness (the wrist should turn the
        needle smoothly), and, where the task marks targets, where the bite went against its mark. A
        short declared list keeps the multiple-comparison correction from diluting what matters."""
        needle = ("tip_speed_before_pierce", "tip_speed_after_pierce", "entry_angle_error_deg")
        hand = ("spectral_arc_length",)
        placement = ("entry_to_target",) if self.placement else ()
        return needle + hand + placement

    def bites(self) -> list[tuple]:
        """Every bite of the task, in order: (entry, normal, bite_direction) each (m, unit vectors)."""
        return [(self.entry, self.normal, self.bite_direction), *self.more_bites]


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


# The interrupted stitch: a 90 deg patch of a porcine artery (inner radius 4 mm, wall 1.5 mm,
# 10 mm long) held on its four cut sides, with a 6 mm arteriotomy along the axis at angle 0 that
# gapes 0.15 mm at mid-length. One bite through the wound's b edge (positive angles) at mid-length:
# in through the adventitia 1.5 mm from the edge, radially through the wall, out through the intima.
_VESSEL = {"inner": 0.004, "wall": 0.0015, "length": 0.01, "arc_deg": 90.0, "gap": 1.5e-4}
_OUTER = _VESSEL["inner"] + _VESSEL["wall"]
_EDGE = 0.5 * _VESSEL["gap"] / _OUTER  # the b edge's angle on the adventitia at mid-length (rad)
_BITE = 0.0015
_ENTRY_ANGLE = _EDGE + float(np.arcsin(_BITE / _OUTER))  # 1.5 mm from the edge's plane


def _on_cylinder(radius: float, angle: float, z: float) -> list[float]:
    return [radius * float(np.cos(angle)), radius * float(np.sin(angle)), z]


def _interrupted_stitch() -> TaskSpec:
    z = 0.5 * _VESSEL["length"]
    radial = (float(np.cos(_ENTRY_ANGLE)), float(np.sin(_ENTRY_ANGLE)), 0.0)
    towards_wound = (float(np.sin(_ENTRY_ANGLE)), -float(np.cos(_ENTRY_ANGLE)), 0.0)
    entry = _on_cylinder(_OUTER, _ENTRY_ANGLE, z)
    return TaskSpec(
        "interrupted-stitch",
        "vessel_patch",
        "One bite through an arteriotomy's edge on a porcine artery (inner radius 4 mm, wall 1.5 mm): "
        "in through the adventitia 1.5 mm from the wound edge, out through the intima; a 90 deg patch "
        "of the vessel held on its cut sides, 0.3 mm cells.",
        tuple(entry),
        radial,
        towards_wound,
        {
            "inner_radius_m": _VESSEL["inner"],
            "wall_m": _VESSEL["wall"],
            "length_m": _VESSEL["length"],
            "arc_deg": _VESSEL["arc_deg"],
            "divisions": [30, 5, 34],  # circumferential, radial, axial: <= 0.3 mm cells
            "wound": {"angle_deg": 0.0, "z_m": [0.002, 0.008], "gap_m": _VESSEL["gap"]},
            "stitch_region": {"angle_deg": [0.0, 35.0], "z_m": [0.003, 0.007]},
            "fixed": ["end0", "end1", "side0", "side1"],
            "model": "biphase",
            "tissue": "porcine-artery",
        },
        placement={
            # the b edge's plane through the axis; its normal points from the tissue into the gap
            "wound_point": _on_cylinder(_OUTER, _EDGE, z),
            "wound_normal": [float(np.sin(_EDGE)), -float(np.cos(_EDGE)), 0.0],
            "target_bite_m": _BITE,
            # straight through the wall: on the intima the same bite is 4/5.5 of it from the edge
            "target_exit_bite_m": _VESSEL["inner"] * float(np.sin(_ENTRY_ANGLE - _EDGE)),
            "entry_targets": [entry],
            "exit_targets": [_on_cylinder(_VESSEL["inner"], _ENTRY_ANGLE, z)],
            "far_normal": [-radial[0], -radial[1], 0.0],  # the lumen faces the axis
        },
    )


TASKS["interrupted-stitch"] = _interrupted_stitch()


def _closure_row(spacing: float = 0.0015, count: int = 3) -> TaskSpec:
    """Interrupted stitches in a row along the same arteriotomy edge, ``spacing`` apart at mid-length:
    each bite as the interrupted stitch's, so spacing and its regularity count too."""
    single = _interrupted_stitch()
    middle = 0.5 * _VESSEL["length"]
    heights = [middle + spacing * (k - (count - 1) / 2) for k in range(count)]
    entries = [_on_cylinder(_OUTER, _ENTRY_ANGLE, z) for z in heights]
    exits = [_on_cylinder(_VESSEL["inner"], _ENTRY_ANGLE, z) for z in heights]
    bites = tuple((tuple(e), single.normal, single.bite_direction) for e in entries)
    return TaskSpec(
        "arteriotomy-closure",
        "vessel_patch",
        f"A row of {count} interrupted stitches {1e3 * spacing:g} mm apart along an arteriotomy's edge on a "
        "porcine artery (the interrupted stitch's vessel): each bite in 1.5 mm from the edge and out "
        "through the intima; spacing and its regularity are scored.",
        *bites[0],
        dict(single.parameters),
        placement={
            **single.placement,
            "entry_targets": entries,
            "exit_targets": exits,
            "wound_direction": [0.0, 0.0, 1.0],
            "target_spacing_m": spacing,
        },
        more_bites=bites[1:],
        time_budget_s=60.0 * count,
    )


TASKS["arteriotomy-closure"] = _closure_row()


def _diseased_wall() -> TaskSpec:
    """The closure row through a diseased wall: a calcified plaque through the whole wall under the
    row's second and third bites (angles 3-35 deg, z 4.25-7.25 mm), four times stiffer with a
    puncture at the band's top (the ``calcified`` preset); the first bite is through healthy wall."""
    row = _closure_row()
    parameters = {
        **row.parameters,
        "calcification": {"angle_deg": [3.0, 35.0], "z_m": [0.00425, 0.00725], "layers": [0, 1, 2, 3, 4]},
        "region_tissue": {"calcified": "calcified"},
    }
    return TaskSpec(
        "diseased-wall",
        "vessel_patch",
        "The arteriotomy closure through a diseased wall: the row's second and third bites go through a "
        "calcified plaque (four times stiffer, puncture at 1500 mN instead of 800 mN), where a decisive "
        "needle at a square angle matters most.",
        row.entry,
        row.normal,
        row.bite_direction,
        parameters,
        placement=row.placement,
        more_bites=row.more_bites,
        time_budget_s=row.time_budget_s + 60.0,
    )


TASKS["diseased-wall"] = _diseased_wall()


def _restricted_access(tilt_deg: float = 45.0) -> TaskSpec:
    """The interrupted stitch at the bottom of a deep, narrow wound: the hand can only come in
    ``tilt_deg`` off the wall's normal, along the vessel's axis, yet the needle must still meet the
    wall square and be turned along its curve, so the wrist must turn further."""
    single = _interrupted_stitch()
    normal = np.asarray(single.normal)
    tilt = np.radians(tilt_deg)
    approach = np.cos(tilt) * normal + np.sin(tilt) * np.array([0.0, 0.0, 1.0])
    return TaskSpec(
        "restricted-access",
        "vessel_patch",
        f"The interrupted stitch through an arteriotomy deep in a narrow wound: the needle holder can "
        f"only come in {tilt_deg:g} deg off the wall's normal, along the vessel, so entering square and "
        "turning the needle along its curve take a further turn of the wrist.",
        single.entry,
        single.normal,
        single.bite_direction,
        dict(single.parameters),
        placement=single.placement,
        access={"approach": [float(x) for x in approach], "tilt_deg": tilt_deg},
        time_budget_s=90.0,
    )


TASKS["restricted-access"] = _restricted_access()


# -- tasks added from a mesh (`vascsim tasks add`): VASCSIM_HOME/tasks/NAME/{task.json,mesh.vtu} ------
USER_TASK_FILE = "task.json"
USER_MESH_FILE = "mesh.vtu"


def user_tasks_dir() -> Path:
    from sessions.config import data_home

    return data_home() / "tasks"


def _read_user_task(path: Path) -> TaskSpec:
    try:
        data = json.loads(path.read_text())
        return TaskSpec(
            **{
                **data,
                "entry": tuple(data["entry"]),
                "normal": tuple(data["normal"]),
                "bite_direction": tuple(data["bite_direction"]),
            }
        )
    except (OSError, ValueError, TypeError, KeyError) as error:
        raise VascsimError(
            f"task file {path} cannot be read ({error}); remove its folder or fix it"
        ) from error


def user_tasks() -> dict[str, TaskSpec]:
    """Tasks added from a mesh, read from the data directory (each checked as it is read)."""
    folder = user_tasks_dir()
    if not folder.is_dir():
        return {}
    specs = (_read_user_task(path) for path in sorted(folder.glob(f"*/{USER_TASK_FILE}")))
    return {spec.name: spec for spec in specs}


def all_tasks() -> dict[str, TaskSpec]:
    """The built-in tasks and those added from meshes."""
    return {**TASKS, **user_tasks()}


def known_task(name: str) -> bool:
    return name in TASKS or (user_tasks_dir() / name / USER_TASK_FILE).is_file()


def task_spec(name: str) -> TaskSpec:
    if name in TASKS:
        return TASKS[name]
    path = user_tasks_dir() / name / USER_TASK_FILE
    if not path.is_file():  # only a miss lists them all
        raise VascsimError(f"unknown task {name!r}; known tasks: {', '.join(all_tasks())}")
    return _read_user_task(path)


def add_mesh_task(
    name: str,
    mesh,
    entry: Sequence[float],
    tissue: str = "porcine-artery",
    fixed: Sequence[str] = ("end0", "end1"),
    stitch_radius: float = 0.003,
    bite_direction: Sequence[float] | None = None,
    description: str = "",
    time_budget_s: float = 60.0,
    region_tissue: dict[str, str] | None = None,
) -> TaskSpec:
    """Store ``mesh`` (a :class:`sim.mesh.TetMesh`) as task ``name``: one bite at ``entry`` (m), the
    nearest point of its outer surface, in along the inward normal there; contact candidates are
    the outer surface's nodes within ``stitch_radius``; ``fixed`` names the node sets held."""
    import re

    from sim.calibration.presets import tissue_preset
    from sim.mesh import save_mesh

    if not re.fullmatch(r"[a-z0-9][a-z0-9-]{1,40}", name):
        raise VascsimError(f"task name {name!r}: 2-41 lower-case letters, digits and dashes")
    if name in TASKS or (user_tasks_dir() / name).exists():
        raise VascsimError(f"task {name!r} already exists")
    tissue_preset(tissue)  # an unknown preset is refused before anything is written
    check_task_mesh(mesh, fixed, entry, stitch_radius)
    outer = mesh.node_sets.get("outer", mesh.surface_nodes)
    point, normal = _surface_point(mesh, np.asarray(entry, dtype=np.float64), outer)
    if bite_direction is None:
        axis = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        bite = np.cross(normal, axis)
    else:
        bite = np.asarray(bite_direction, dtype=np.float64)
        bite = bite - (bite @ normal) * normal
    bite = bite / np.linalg.norm(bite)
    folder = user_tasks_dir() / name
    folder.mkdir(parents=True)
    save_mesh(mesh, folder / USER_MESH_FILE)
    spec = TaskSpec(
        name,
        "mesh_file",
        description or f"One bite into a meshed vessel wall ({mesh.n_nodes} nodes), tissue {tissue}.",
        tuple(float(v) for v in point),
        tuple(float(-v) for v in normal),  # the task's normal points out of the wall, as the built-ins'
        tuple(float(v) for v in bite),
        {
            "mesh_file": USER_MESH_FILE,
            "fixed": list(fixed),
            "stitch_radius_m": float(stitch_radius),
            "model": "biphase",
            "tissue": tissue,
            **({"region_tissue": dict(region_tissue)} if region_tissue else {}),
        },
        time_budget_s=time_budget_s,
    )
    (folder / USER_TASK_FILE).write_text(json.dumps(dataclasses.asdict(spec), indent=1))
    return spec


# A vessel wall model spans between these (m): a mesh outside was written in other units, or is no
# vessel (a 1e-30 m cube meshed fine and then gave a singular wall).
MESH_SPAN_M = (1e-3, 1.0)
# Contact needs a patch of free outer-surface nodes about the entry, not one element's corners.
MIN_CONTACT_NODES = 4


def check_task_mesh(mesh, fixed: Sequence[str], entry: Sequence[float], stitch_radius: float) -> None:
    """VascsimError, in one line naming what to change, unless ``mesh`` can carry a one-bite task:
    a vessel's size in metres, held on at least one named node set that pins it in space (3 nodes
    not on one line), and at least :data:`MIN_CONTACT_NODES` outer-surface nodes within
    ``stitch_radius`` of ``entry`` that are not held (the needle's contact candidates)."""
    span = float(np.linalg.norm(np.ptp(mesh.points, axis=0)))
    low, high = MESH_SPAN_M
    if not low <= span <= high:
        raise VascsimError(
            f"the mesh spans {span:.3g} m corner to corner; a vessel wall spans {low * 1e3:g} mm to "
            f"{high:g} m (tetrahedral meshes are read in metres: rescale the file)"
        )
    if not fixed:
        sets = ", ".join(mesh.node_sets) or "none"
        raise VascsimError(
            "the mesh has no node set to hold (point data 'set:end0', 'set:end1', ...: the cut ends); "
            f"a wall held on nothing floats away (its sets: {sets})"
        )
    missing = [k for k in fixed if k not in mesh.node_sets]
    if missing:
        raise VascsimError(
            f"the mesh has no node set {', '.join(missing)}; its sets: {', '.join(mesh.node_sets) or 'none'}"
        )
    held = np.unique(np.concatenate([np.asarray(mesh.node_sets[k], dtype=np.int64) for k in fixed]))
    if held.size < 3 or np.linalg.matrix_rank(mesh.points[held] - mesh.points[held[0]], tol=1e-9 * span) < 2:
        raise VascsimError(
            f"the held node sets ({', '.join(fixed)}) have {held.size} node(s) on one line; the wall "
            "would turn about them: hold at least three nodes not on a line"
        )
    outer = np.asarray(mesh.node_sets.get("outer", mesh.surface_nodes))
    distance = np.linalg.norm(mesh.points[outer] - np.asarray(entry, dtype=np.float64), axis=1)
    if distance.min() > stitch_radius:
        raise VascsimError(
            f"the entry point is {distance.min() * 1e3:.3g} mm from the mesh's outer surface; give a "
            f"point within {stitch_radius * 1e3:g} mm of it (--entry, in mm)"
        )
    free = np.setdiff1d(outer[distance <= stitch_radius], held)
    if free.size < MIN_CONTACT_NODES:
        raise VascsimError(
            f"only {free.size} free outer-surface node(s) lie within {stitch_radius * 1e3:g} mm of the "
            f"entry; the needle needs {MIN_CONTACT_NODES} or more: refine the mesh there (edges of about "
            "0.5 mm) or move the entry away from the held ends"
        )


def _surface_point(mesh, entry: NDArray[np.float64], candidates) -> tuple[NDArray, NDArray]:
    """The candidate surface node nearest ``entry`` and the inward unit normal there (the mean of its
    exterior faces' outward normals, negated)."""
    node = int(candidates[np.argmin(np.linalg.norm(mesh.points[candidates] - entry, axis=1))])
    touching = np.any(mesh.surface_triangles == node, axis=1)
    outward = mesh.surface_normals[touching].mean(axis=0)
    return mesh.points[node], -outward / np.linalg.norm(outward)


def task_mesh(spec: TaskSpec):
    """The task's mesh: for a patch, ``stitch_cell_m`` cells over the stitch region (x and y) and
    through the wall, graded to ``cell_m`` elsewhere, so the needle's force kernel spans 3 cells;
    for a vessel patch, a wall segment with its arteriotomy at uniform divisions."""
    from sim.mesh import Calcification, Wound, grid_box_mesh, refined_coordinates, vessel_mesh

    p = spec.parameters
    if spec.scenario == "mesh_file":
        from sim.mesh import load_mesh

        return load_mesh(user_tasks_dir() / spec.name / p["mesh_file"])
    if spec.scenario == "vessel_patch":
        wound = p["wound"]
        plaque = p.get("calcification")
        return vessel_mesh(
            inner_radius=p["inner_radius_m"],
            wall_thickness=p["wall_m"],
            length=p["length_m"],
            arc_deg=p["arc_deg"],
            circumferential_divisions=p["divisions"][0],
            radial_divisions=p["divisions"][1],
            axial_divisions=p["divisions"][2],
            wound=Wound(wound["angle_deg"], *wound["z_m"], gap=wound["gap_m"]),
            calcification=None
            if plaque is None
            else Calcification(tuple(plaque["angle_deg"]), tuple(plaque["z_m"]), tuple(plaque["layers"])),
        )
    (length, width, thickness), coarse, fine = p["size_m"], p["cell_m"], p["stitch_cell_m"]
    (x0, x1), (y0, y1) = p["stitch_region_m"]
    return grid_box_mesh(
        refined_coordinates(length, coarse, fine, x0, x1),
        refined_coordinates(width, coarse, fine, y0, y1),
        refined_coordinates(thickness, coarse, fine, 0.0, thickness),
    )


def stitch_region_nodes(spec: TaskSpec, mesh) -> np.ndarray:
    """Surface nodes in the task's stitch region (a patch: an x, y box at every depth; a vessel
    patch: an angle and z range of the adventitia): the contact candidates."""
    points = mesh.points[mesh.surface_nodes]
    if spec.scenario == "mesh_file":
        outer = mesh.node_sets.get("outer", mesh.surface_nodes)
        near = (
            np.linalg.norm(mesh.points[outer] - np.asarray(spec.entry), axis=1)
            <= spec.parameters["stitch_radius_m"]
        )
        return np.asarray(outer)[near]
    if spec.scenario == "vessel_patch":
        region = spec.parameters["stitch_region"]
        angle = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
        (a0, a1), (z0, z1) = region["angle_deg"], region["z_m"]
        inside = (angle >= a0) & (angle <= a1) & (points[:, 2] >= z0 - 1e-9) & (points[:, 2] <= z1 + 1e-9)
        outer = np.isin(mesh.surface_nodes, mesh.node_sets["outer"])
        return mesh.surface_nodes[inside & outer]
    (x0, x1), (y0, y1) = spec.parameters["stitch_region_m"]
    inside = (points[:, 0] >= x0 - 1e-9) & (points[:, 0] <= x1 + 1e-9)
    inside &= (points[:, 1] >= y0 - 1e-9) & (points[:, 1] <= y1 + 1e-9)
    return mesh.surface_nodes[inside]


def task_preset(task: str):
    """The task's tissue preset (:mod:`sim.calibration.presets`): biphase parameters and needle forces."""
    from sim.calibration.presets import tissue_preset

    return tissue_preset(task_spec(task).parameters.get("tissue", "paper"))


def region_presets(task: str) -> dict:
    """Mesh region name -> tissue preset for the task's regions that differ from its wall (e.g. a
    calcified plaque); empty for a uniform wall."""
    from sim.calibration.presets import tissue_preset

    return {
        region: tissue_preset(name)
        for region, name in task_spec(task).parameters.get("region_tissue", {}).items()
    }


def region_forces(task: str, mesh) -> dict:
    """Mesh region id -> the needle forces of that region's preset (see :func:`region_presets`)."""
    ids = {name: rid for rid, name in mesh.region_names.items()}
    return {ids[region]: preset.forces for region, preset in region_presets(task).items()}


@cache
def tissue_for(task: str, cache_dir: Path | None = None):
    """The task's precomputed tissue model (built once per process, cached on disk): the preset's
    biphase wall on the task mesh, its condensed inverse over the stitch region's surface nodes."""
    from sim.fem import BiphaseTissue

    spec = task_spec(task)
    mesh = task_mesh(spec)
    if spec.scenario == "mesh_file":  # a stored task file can be edited by hand after `tasks add`
        check_task_mesh(mesh, spec.parameters["fixed"], spec.entry, spec.parameters["stitch_radius_m"])
    fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters["fixed"]])
    candidates = np.setdiff1d(stitch_region_nodes(spec, mesh), fixed)
    regions = {region: preset.biphase for region, preset in region_presets(task).items()}
    tissue = BiphaseTissue.build(
        mesh, fixed, task_preset(task).biphase, region_parameters=regions, contact_nodes=candidates
    )
    tissue.precompute(cache_dir=cache_dir)
    return tissue


def session_tissue(streams, cache_dir: Path | None = None):
    """The tissue model a recorded session ran on (from its header's ``task``), or None for
    sessions of other origins (imported data, unknown tasks)."""
    task = streams.attributes.get("task")
    return tissue_for(task, cache_dir) if task is not None and known_task(task) else None


def edge_grasps(spec: TaskSpec) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per bite, where the subordinate hand takes the wound edge and the way it lifts it
    (:func:`sim.devices.assisting.edge_grasp`: the rim beside the entry); none without a wound."""
    from sim.devices.assisting import edge_grasp

    placement = spec.placement or {}
    if placement.get("wound_point") is None:
        return []
    wound = placement["wound_point"], placement["wound_normal"]
    return [edge_grasp(entry, normal, *wound) for entry, normal, _ in spec.bites()]


def grasp_sites(spec: TaskSpec) -> np.ndarray:
    """(k, 3) points (m) where the subordinate hand takes the wound edge for the task's bites
    (:func:`edge_grasps`), (0, 3) on a task without a wound."""
    return np.asarray([rim for rim, _ in edge_grasps(spec)], dtype=np.float64).reshape(-1, 3)


def task_simulation(task: str, device, cache_dir: Path | None = None, **options):
    """A :class:`sim.runtime.Simulation` of ``task`` driven by ``device``: the task's tissue, the
    curved needle, its preset's needle forces and its regions' own (a calcified plaque pierces at
    its own threshold). ``options`` go to the Simulation (e.g. ``settings``)."""
    from sim.needle import Needle
    from sim.runtime import Simulation

    tissue = tissue_for(task, cache_dir)
    if options.get("subordinate") is not None and "grasp_sites" not in options:
        options["grasp_sites"] = grasp_sites(task_spec(task))
    return Simulation(
        tissue,
        Needle.curved(),
        device,
        forces=task_preset(task).forces,
        region_forces=region_forces(task, tissue.mesh),
        **options,
    )
