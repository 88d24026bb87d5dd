"""The tasks a session can run: a scenario (mesh, materials, fixed nodes) and where the stitch goes.

`spec` (the TaskSpec), `kinds` (one class per kind of task: how its parameters become a mesh and
contact candidates), `library` (the built-in tasks), `user` (tasks added from a mesh, and the
lookup by name), `build` (what a task becomes to run: mesh, tissue, grasp sites, simulation).
"""

from sessions.tasks.build import (
    edge_grasps,
    forget_tissues,
    grasp_sites,
    region_forces,
    region_presets,
    session_tissue,
    stitch_region_nodes,
    task_mesh,
    task_preset,
    task_simulation,
    tissue_for,
    warm_exit_columns,
)
from sessions.tasks.library import TASKS
from sessions.tasks.spec import TaskSpec
from sessions.tasks.user import (
    MESH_SPAN_M,
    MIN_CONTACT_NODES,
    USER_MESH_FILE,
    USER_TASK_FILE,
    add_mesh_task,
    all_tasks,
    check_task_mesh,
    known_task,
    task_spec,
    user_tasks,
    user_tasks_dir,
)

__all__ = [
    "MESH_SPAN_M",
    "MIN_CONTACT_NODES",
    "TASKS",
    "USER_MESH_FILE",
    "USER_TASK_FILE",
    "TaskSpec",
    "add_mesh_task",
    "all_tasks",
    "check_task_mesh",
    "edge_grasps",
    "forget_tissues",
    "grasp_sites",
    "known_task",
    "region_forces",
    "region_presets",
    "session_tissue",
    "stitch_region_nodes",
    "task_mesh",
    "task_preset",
    "task_simulation",
    "task_spec",
    "tissue_for",
    "user_tasks",
    "user_tasks_dir",
    "warm_exit_columns",
]
