import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from sessions.cli import main
from sim.calibration.indentation import indentation_curve

VASCSIM = Path(sys.executable).with_name("vascsim")


def test_indentation_json_matches_the_core():
    arguments = ["indentation", "--tissue", "paper", "--steps", "5", "--max-strain", "0.4", "--json"]
    result = CliRunner().invoke(main, arguments)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    curve = indentation_curve(np.linspace(0, 0.4, 5))
    np.testing.assert_allclose(data["force_biphase"], curve.force_biphase, rtol=1e-12)
    np.testing.assert_allclose(data["strain"], [0, 0.1, 0.2, 0.3, 0.4])
    forces = np.array(data["force_biphase"])
    assert np.all(np.diff(forces) > 0)  # deeper press, more force
    assert data["force_biphase"][-1] > data["force_linear"][-1]  # stiff phase above 0.2


def test_indentation_prints_table_through_the_console_script():
    env = dict(os.environ, COLUMNS="160")
    result = subprocess.run(
        [str(VASCSIM), "indentation", "--tissue", "paper", "--steps", "3"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "729 nodes, 3072 elements" in result.stdout
    assert "precompute" in result.stdout
    assert "force biphase" in result.stdout


def test_calibrated_indentation_is_the_runtime_kernel_and_pierces_in_the_published_band(tmp_path):
    """The default curve: the porcine-artery wall-stitch patch through the force kernel; its force at
    each depth is what the kernel computes, and the wall gives at 0.7-1.1 mm under 0.8 N."""
    from sessions.tasks import task_preset, task_spec, tissue_for
    from sim.calibration.indentation import kernel_indentation_curve

    env = dict(os.environ, VASCSIM_HOME=str(tmp_path))
    result = CliRunner(env=env).invoke(main, ["indentation", "--steps", "13", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["tissue"] == "porcine-artery" and data["puncture_force"] == 0.8
    assert 0.7e-3 <= data["pierce_depth"] <= 1.1e-3
    spec = task_spec("wall-stitch")
    again = kernel_indentation_curve(
        tissue_for(task_spec("wall-stitch"), None),
        task_preset(task_spec("wall-stitch")).forces,
        spec.entry,
        spec.normal,
        np.linspace(0, 1.2e-3, 13),
        needle_speed=0.004,
    )
    np.testing.assert_allclose(data["force"], again.force, rtol=1e-9, atol=1e-12)
    assert np.all(np.diff(data["force"][1:]) > 0)
    printed = subprocess.run(
        [str(VASCSIM), "indentation", "--steps", "4"],
        capture_output=True,
        text=True,
        env=dict(env, COLUMNS="80"),
        timeout=300,
        check=False,
    )
    assert printed.returncode == 0, printed.stderr
    assert "force (mN)" in printed.stdout and "pierces at" in printed.stdout


def test_indentation_at_a_speed_with_its_unloading_branch_and_work(tmp_path):
    """``--speed`` presses at that speed; ``--unload`` draws the needle back out and reports the work
    put in and given back, which never exceeds what went in (issue 43: the wall returned 1.69x)."""
    from sessions.tasks import task_preset, task_spec, tissue_for
    from sim.calibration.indentation import load_cycle

    env = dict(os.environ, VASCSIM_HOME=str(tmp_path))
    arguments = ["indentation", "--steps", "7", "--max-depth", "0.6", "--speed", "10", "--unload", "--json"]
    result = CliRunner(env=env).invoke(main, arguments)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["speed_mm_s"] == 10.0
    cycle = data["cycle"]
    assert 0 < cycle["work_out"] <= cycle["work_in"]
    spec = task_spec("wall-stitch")
    again = load_cycle(
        tissue_for(task_spec("wall-stitch"), None),
        task_preset(task_spec("wall-stitch")).forces,
        spec.entry,
        spec.normal,
        0.6e-3,
        0.01,
        0.01,
    )
    assert cycle["work_in"] == again.work_in and cycle["work_out"] == again.work_out
    printed = CliRunner(env=dict(env, COLUMNS="100")).invoke(main, arguments[:-1])
    assert printed.exit_code == 0, printed.output
    assert "unloading" in printed.output and "work put in" in printed.output and "mJ" in printed.output


def test_bad_option_is_one_line_and_nonzero():
    result = subprocess.run(
        [str(VASCSIM), "indentation", "--steps", "1"], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 2
    assert "Invalid value for '--steps'" in result.stderr
    assert "Traceback" not in result.stderr


def test_help_explains_commands():
    result = CliRunner().invoke(main, ["--help"])
    assert result.exit_code == 0
    assert "demo" in result.output
    demo_help = CliRunner().invoke(main, ["indentation", "--help"])
    assert "porcine-artery" in demo_help.output and "10 mm cube" in demo_help.output
    assert "--max-strain" in demo_help.output and "--max-depth" in demo_help.output
    assert "synthetic study" in CliRunner().invoke(main, ["demo", "--help"]).output


def test_devices_lists_the_always_available_drivers():
    result = CliRunner().invoke(main, ["devices", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    drivers = {row["driver"]: row["status"] for row in rows}
    assert drivers["scripted"] == "ready" and drivers["replay"] == "ready"
    assert drivers["openhaptics"].startswith("not installed")
    table = CliRunner().invoke(main, ["devices"])
    assert "scripted" in table.output


def test_tasks_list_and_show_describe_the_task_library():
    """Issue 22: the task library described from the CLI, at 80 columns, with its target marks."""
    from click.testing import CliRunner

    from sessions.cli import main

    listed = CliRunner().invoke(main, ["tasks", "list"])
    assert listed.exit_code == 0 and "wall-stitch" in listed.output and "interrupted-stitch" in listed.output
    shown = CliRunner().invoke(main, ["tasks", "show", "wall-stitch"])
    assert shown.exit_code == 0 and "target bite  1.5 mm from the wound edge" in shown.output
    assert max(len(line) for line in listed.output.splitlines() + shown.output.splitlines()) <= 80
    from sessions.tasks import TASKS

    for name in TASKS:  # every task declares its stitches and time budget, and fits 80 columns
        text = CliRunner().invoke(main, ["tasks", "show", name]).output
        assert "asks for" in text and "(the course's time budget)" in text
        assert max(len(line) for line in text.splitlines()) <= 80, name
    diseased = CliRunner().invoke(main, ["tasks", "show", "diseased-wall"]).output
    assert "asks for     3 stitch(es) in 240 s" in diseased and "region       calcified" in diseased
    as_json = json.loads(CliRunner().invoke(main, ["tasks", "show", "wall-stitch", "--json"]).output)
    assert as_json["placement"]["target_bite_m"] == 0.0015
    unknown = CliRunner().invoke(main, ["tasks", "show", "nope"])
    assert (
        unknown.exit_code == 1
        and "unknown task 'nope'; known tasks: wall-stitch, interrupted-stitch, arteriotomy-closure, "
        in unknown.output
    )
