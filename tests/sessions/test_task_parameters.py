"""A task's parameters typed by its kind (sessions.tasks.parameters): the built-ins' stored form is
what it was, and a task file edited by hand is checked field by field before anything is built from
it (issue 48's typed parameters; a hostile task.json at the data folder's boundary)."""

from __future__ import annotations

import copy
import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sessions.tasks import TASKS, task_spec
from sessions.tasks.parameters import MeshFileParameters, VesselPatchParameters, parameters_from
from sessions.tasks.user import USER_TASK_FILE, _user_task
from sim.errors import VascsimError

STORED = {
    "name": "my-vessel",
    "scenario": "mesh_file",
    "description": "a vessel meshed elsewhere",
    "entry": [0.001, 0.002, 0.0055],
    "normal": [0.0, 0.0, 1.0],
    "bite_direction": [1.0, 0.0, 0.0],
    "parameters": {
        "mesh_file": "mesh.vtu",
        "fixed": ["end0", "end1"],
        "stitch_radius_m": 0.003,
        "model": "biphase",
        "tissue": "porcine-artery",
    },
    "placement": None,
    "more_bites": [],
    "access": None,
    "time_budget_s": 60.0,
}


@pytest.mark.parametrize("name", sorted(TASKS))
def test_each_built_in_reads_back_from_its_stored_form(name):
    spec = TASKS[name]
    stored = json.loads(json.dumps(spec.parameters.as_dict()))  # as the catalog holds it
    assert parameters_from(spec.scenario, stored, name) == spec.parameters


def test_the_diseased_wall_is_the_closure_with_a_plaque_typed():
    plaque = TASKS["diseased-wall"].parameters
    assert isinstance(plaque, VesselPatchParameters) and plaque.calcification.layers == (0, 1, 2, 3, 4)
    assert plaque.region_tissue == {"calcified": "calcified"}
    assert TASKS["arteriotomy-closure"].parameters.calcification is None


def test_a_stored_task_reads_as_typed_parameters(tmp_path, monkeypatch):
    monkeypatch.setenv("VASCSIM_HOME", str(tmp_path))
    (tmp_path / "tasks" / "my-vessel").mkdir(parents=True)
    (tmp_path / "tasks" / "my-vessel" / USER_TASK_FILE).write_text(json.dumps(STORED))
    spec = task_spec("my-vessel")
    assert spec.parameters == MeshFileParameters(
        fixed=("end0", "end1"), tissue="porcine-artery", mesh_file="mesh.vtu", stitch_radius_m=0.003
    )
    assert spec.entry == (0.001, 0.002, 0.0055) and spec.time_budget_s == 60.0


def edited(path: tuple, value) -> dict:
    data = copy.deepcopy(STORED)
    *parents, last = path
    place = data
    for key in parents:
        place = place[key]
    if value is KeyError:
        del place[last]
    else:
        place[last] = value
    return data


@pytest.mark.parametrize(
    ("path", "value", "said"),
    [
        (("parameters", "mesh_file"), "../../../etc/passwd", "must be a file name in the task's folder"),
        (("parameters", "mesh_file"), "..", "must be a file name"),
        (("parameters", "stitch_radius_m"), math.nan, "stitch_radius_m must be a number"),
        (("parameters", "stitch_radius_m"), -0.003, "outside"),
        (("parameters", "fixed"), ["end0", "../x"], "not a node set name"),
        (("parameters", "fixed"), [], "must be a list of node set names"),
        (("parameters", "tissue"), "granite", "tissue must be one of"),
        (("parameters", "region_tissue"), {"plaque": "granite"}, "maps 'plaque' to 'granite'"),
        (("parameters", "model"), "linear", "model must be one of biphase"),
        (("parameters", "shell"), 1, "fields it cannot use: 'shell'"),
        (("parameters", "mesh_file"), KeyError, "has no 'mesh_file'"),
        (("scenario",), "vessel_patch", "a task added from a mesh is 'mesh_file'"),
        (("name",), "other", "is not its folder's"),
        (("normal",), [0.0, 0.6, 0.6], "must be a unit vector"),
        (("entry",), [0.0, math.inf, 0.0], "3 finite numbers"),
        (("entry",), "0,0,0", "list of 3 numbers"),
        (("time_budget_s",), 0, "from 1 to 7200"),
        (("placement",), {"entry_targets": []}, "no placement marks"),
        (("extra",), True, "fields it cannot use: 'extra'"),
        (("parameters",), [1, 2], "must be an object"),
    ],
)
def test_a_task_file_edited_by_hand_is_refused_naming_the_field(tmp_path, monkeypatch, path, value, said):
    monkeypatch.setenv("VASCSIM_HOME", str(tmp_path))
    folder = tmp_path / "tasks" / "my-vessel"
    folder.mkdir(parents=True)
    (folder / USER_TASK_FILE).write_text(json.dumps(edited(path, value)))
    with pytest.raises(VascsimError, match="remove its folder or fix it") as refused:
        task_spec("my-vessel")
    assert said in str(refused.value) and str(folder / USER_TASK_FILE) in str(refused.value)


JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 5) | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(key=st.sampled_from([*sorted(STORED["parameters"]), "fixed", "region_tissue"]), value=JSON)
def test_any_value_in_any_parameter_is_read_or_refused_in_words(key, value):
    """Whatever a hand puts in a parameter, reading it ends in typed parameters or one VascsimError."""
    data = edited(("parameters", key), value)
    try:
        spec = _user_task(data, "my-vessel")
    except VascsimError:
        return
    assert isinstance(spec.parameters, MeshFileParameters)
    assert math.isfinite(spec.parameters.stitch_radius_m) and "/" not in spec.parameters.mesh_file
