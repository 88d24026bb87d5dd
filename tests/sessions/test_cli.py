import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from sessions.cli import main
from sim.experiments import indentation_curve

VASCSIM = Path(sys.executable).with_name("vascsim")


def test_indentation_json_matches_the_core():
    result = CliRunner().invoke(main, ["indentation", "--steps", "5", "--max-strain", "0.4", "--json"])
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
        [str(VASCSIM), "indentation", "--steps", "3"],
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
    assert "729 nodes" in demo_help.output and "--max-strain" in demo_help.output
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
