"""The package layering and the web-free core, checked on the real import graph."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["sim", "recorder", "metrics", "sessions", "dashboard"]


def imported_packages(package: str) -> set[str]:
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                found.add(node.module.split(".")[0])
    return found


def test_imports_point_one_way():
    for level, package in enumerate(ORDER):
        higher = set(ORDER[level + 1 :])
        assert not imported_packages(package) & higher, f"{package} imports a higher layer"


def test_core_imports_without_the_web_or_rendering_stack():
    code = (
        "import sys; import sim, sim.mesh, sim.fem, sim.experiments, recorder, metrics; "
        "bad = [m for m in ('vtk', 'pyvista', 'cv2', 'OpenImageIO', 'fastapi', 'starlette', 'sqlalchemy') "
        "if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
