"""Which device holds which instrument at a station (--device, --sub-device, --handedness) and where
the forceps start (issue 46)."""

import pytest

from sessions.catalog import CatalogError
from sessions.running.hands import SUB_DEVICES, Instruments, forceps_start, instruments
from sessions.tasks import task_spec, tissue_for
from sim.collision.mesh import CollisionMesh
from sim.forceps import Forceps
from sim.forceps.jaws import closest_surface_point


@pytest.mark.parametrize(
    ("device", "sub_device", "handedness", "expected"),
    [
        ("openhaptics", "spacemouse", "right", Instruments("openhaptics", "spacemouse")),
        ("openhaptics", "spacemouse", "left", Instruments("spacemouse", "openhaptics")),
        ("mouse", "spacemouse", "right", Instruments("mouse", "spacemouse")),
        ("mouse", "none", "left", Instruments("mouse", None)),
        ("mouse", None, "right", Instruments("mouse", None)),
        ("scripted", "none", "left", Instruments("scripted", None)),
    ],
)
def test_the_instruments_go_to_the_devices_the_trainee_holds_them_in(
    device, sub_device, handedness, expected
):
    assert instruments(device, sub_device, handedness) == expected


@pytest.mark.parametrize(
    ("device", "sub_device", "handedness", "says"),
    [
        ("mouse", "spacemouse", "left", "keyboard and mouse drive the needle holder only"),
        ("scripted", "spacemouse", "right", "brings its own assisting hand"),
        ("mouse", "joystick", "right", "unknown second device 'joystick'"),
    ],
)
def test_a_choice_that_cannot_work_is_refused_in_one_line(device, sub_device, handedness, says):
    with pytest.raises(CatalogError, match=says) as refused:
        instruments(device, sub_device, handedness)
    assert "\n" not in str(refused.value)
    assert SUB_DEVICES[0] == "none"


@pytest.mark.parametrize("task", ["interrupted-stitch", "restricted-access"])
def test_the_jaws_start_open_within_reach_of_the_wound_edge(task):
    """Closing the jaws where they start takes the edge: the wall is within the forceps' reach there."""
    spec = task_spec(task)
    start = forceps_start(spec)
    found = closest_surface_point(
        CollisionMesh(tissue_for(task_spec(task)).mesh), start.position, Forceps().grasp_reach
    )
    assert found is not None


def test_a_task_without_a_wound_has_no_place_for_the_forceps():
    from dataclasses import replace

    with pytest.raises(CatalogError, match="no wound edge"):
        forceps_start(replace(task_spec("wall-stitch"), placement=None))
