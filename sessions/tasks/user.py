"""Tasks added from a mesh (`vascsim tasks add`) beside the built-ins, and the lookup of any task
by name."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sessions.config import data_home
from sessions.tasks.library import TASKS
from sessions.tasks.parameters import MeshFileParameters, parameters_from
from sessions.tasks.spec import TaskSpec
from sim.calibration.presets import tissue_preset
from sim.errors import VascsimError
from sim.mesh import save_mesh

# -- tasks added from a mesh (`vascsim tasks add`): VASCSIM_HOME/tasks/NAME/{task.json,mesh.vtu} ------
USER_TASK_FILE = "task.json"
USER_MESH_FILE = "mesh.vtu"


def user_tasks_dir() -> Path:

    return data_home() / "tasks"


def _read_user_task(path: Path) -> TaskSpec:
    """The task stored at ``path`` (``tasks/NAME/task.json``: a file anyone with the data folder can
    edit), every field checked before it is used: VascsimError naming the file and the field."""
    try:
        data = json.loads(path.read_text())
        return _user_task(data, path.parent.name)
    except (OSError, ValueError) as error:
        raise VascsimError(
            f"task file {path} cannot be read ({error}); remove its folder or fix it"
        ) from error
    except VascsimError as error:
        raise VascsimError(f"task file {path}: {error}; remove its folder or fix it") from error


_USER_TASK_FIELDS = frozenset(
    {"name", "scenario", "description", "entry", "normal", "bite_direction", "parameters"}
    | {"placement", "more_bites", "access", "time_budget_s", "eversion"}
)


def _user_task(data, folder: str) -> TaskSpec:
    """A task added from a mesh, from its stored form: the mesh-file kind's fields only, each checked."""
    if not isinstance(data, dict):
        raise VascsimError("the task must be a JSON object")
    unknown = sorted(set(data) - _USER_TASK_FIELDS)
    if unknown:
        raise VascsimError(f"fields it cannot use: {', '.join(map(repr, unknown))}")
    if data.get("name") != folder:
        raise VascsimError(f"name {data.get('name')!r} is not its folder's, {folder!r}")
    if data.get("scenario") != MeshFileParameters.scenario:
        raise VascsimError(f"scenario {data.get('scenario')!r}: a task added from a mesh is 'mesh_file'")
    marked = any(data.get(key) is not None for key in ("placement", "access", "eversion"))
    if marked or data.get("more_bites"):
        raise VascsimError("a task added from a mesh has one bite and no placement marks, access or eversion")
    description = data.get("description", "")
    budget = data.get("time_budget_s", 60.0)
    if not isinstance(description, str):
        raise VascsimError("description must be text")
    if isinstance(budget, bool) or not isinstance(budget, (int, float)) or not 1.0 <= budget <= 7200.0:
        raise VascsimError(f"time_budget_s {budget!r} must be a number of seconds from 1 to 7200")
    return TaskSpec(
        folder,
        MeshFileParameters.scenario,
        description,
        _vector(data.get("entry"), "entry", 1.0),
        _unit(data.get("normal"), "normal"),
        _unit(data.get("bite_direction"), "bite_direction"),
        parameters_from(MeshFileParameters.scenario, data.get("parameters"), "parameters"),
        time_budget_s=float(budget),
    )


def _vector(value, name: str, bound: float) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise VascsimError(f"{name} must be a list of 3 numbers, not {value!r}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > bound:
            raise VascsimError(f"{name} must hold 3 finite numbers within {bound:g}, not {value!r}")
    return tuple(float(v) for v in value)


def _unit(value, name: str) -> tuple[float, float, float]:
    vector = _vector(value, name, 1.0 + 1e-6)
    if abs(math.hypot(*vector) - 1.0) > 1e-6:
        raise VascsimError(f"{name} must be a unit vector, not {list(vector)!r}")
    return vector


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
        MeshFileParameters(
            fixed=tuple(fixed),
            tissue=tissue,
            region_tissue=dict(region_tissue or {}),
            mesh_file=USER_MESH_FILE,
            stitch_radius_m=float(stitch_radius),
        ),
        time_budget_s=time_budget_s,
    )
    stored = {**dataclasses.asdict(spec), "parameters": spec.parameters.as_dict()}
    (folder / USER_TASK_FILE).write_text(json.dumps(stored, indent=1))
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
