"""Named meshes with their supports and contact candidates, for the benchmarks.

``paper_table2_*`` are tissue slabs clamped at two opposite ends, sized like the
paper's Table 2 models (nodes within 0.8 %, contact candidates exactly as the
paper's N_free). ``vessel_10k`` and ``vessel_50k`` are arterial tubes held at
both cut ends, with an arteriotomy (wound); their contact candidates are the
adventitial surface and the wound edges, where needle and forceps touch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.calibration.indentation import paper_cube
from sim.devices.scripted import SuturingPass
from sim.errors import ModelError
from sim.mesh import TetMesh, Wound, box_mesh, vessel_mesh


@dataclass(frozen=True)
class Scenario:
    """A mesh, the nodes it is held by, and its contact candidates."""

    name: str
    mesh: TetMesh
    fixed_nodes: NDArray[np.int64]
    contact_nodes: NDArray[np.int64]
    description: str
    paper_seconds: float | None = None


def _slab(name: str, cells: tuple[int, int, int], candidates: int, paper_seconds: float) -> Scenario:
    mesh = box_mesh(np.array(cells) * 1e-3, cells)
    fixed = np.union1d(mesh.node_sets["x0"], mesh.node_sets["x1"])
    free = np.setdiff1d(mesh.surface_nodes, fixed)
    chosen = np.sort(free[np.argsort(-mesh.points[free, 2], kind="stable")[:candidates]])
    text = f"slab {cells[0]}x{cells[1]}x{cells[2]} mm clamped at both x ends"
    return Scenario(name, mesh, fixed, chosen, text, paper_seconds)


def _vessel(name: str, n_theta: int, n_axial: int) -> Scenario:
    length = 0.03
    mesh = vessel_mesh(
        inner_radius=0.004,
        wall_thickness=0.0015,
        length=length,
        circumferential_divisions=n_theta,
        radial_divisions=4,
        axial_divisions=n_axial,
        wound=Wound(angle_deg=90.0, z_start=0.3 * length, z_end=0.7 * length, gap=1e-4),
    )
    fixed = np.union1d(mesh.node_sets["end0"], mesh.node_sets["end1"])
    touchable = np.concatenate([mesh.node_sets[s] for s in ("outer", "wound_a", "wound_b")])
    text = f"artery r=4 mm, wall 1.5 mm, 30 mm long, {n_theta}x4x{n_axial} cells, arteriotomy 12 mm"
    return Scenario(name, mesh, fixed, np.setdiff1d(touchable, fixed), text)


def _paper_cube() -> Scenario:
    mesh, fixed = paper_cube()
    return Scenario(
        "paper_cube",
        mesh,
        fixed,
        np.setdiff1d(mesh.surface_nodes, fixed),
        "the paper's 10 mm test cube held on its base",
    )


SCENARIOS: dict[str, Callable[[], Scenario]] = {
    "paper_cube": _paper_cube,
    "paper_table2_792": lambda: _slab("paper_table2_792", (10, 11, 5), 286, 554.1),
    "paper_table2_1286": lambda: _slab("paper_table2_1286", (17, 17, 3), 633, 9658.8),
    "paper_table2_2283": lambda: _slab("paper_table2_2283", (25, 21, 3), 1152, 112108.9),
    "vessel_10k": lambda: _vessel("vessel_10k", 64, 32),
    "vessel_50k": lambda: _vessel("vessel_50k", 128, 78),
}


def scenario(name: str) -> Scenario:
    """Build a named scenario (see ``SCENARIOS``)."""
    if name not in SCENARIOS:
        raise ModelError(f"unknown scenario {name!r}; choose one of {', '.join(SCENARIOS)}")
    return SCENARIOS[name]()


def practice_passes(case: Scenario, needle, count: int) -> list:
    """``count`` scripted suturing passes laid out over a scenario's working surface, for benchmarks:
    on the cube's top face a 3 x 3 grid of entry points 2 mm apart; on an artery entry points around
    its outer surface (angles 200-325 deg, 8-20 mm along it), bites along its axis."""
    import math

    if case.name == "paper_cube":
        spots = [(0.003 + 0.002 * (k % 3), 0.003 + 0.002 * ((k // 3) % 3)) for k in range(count)]
        return [SuturingPass(needle, [x, y, 0.01], [0, 0, 1], [1, 0, 0]) for x, y in spots]
    if not case.name.startswith("vessel"):
        raise ModelError(f"no practice passes are laid out for scenario {case.name!r}")
    outer_radius = np.hypot(case.mesh.points[:, 0], case.mesh.points[:, 1]).max()
    passes = []
    for k in range(count):
        angle = math.radians(200 + 25 * (k % 6))
        normal = np.array([math.cos(angle), math.sin(angle), 0.0])
        passes.append(
            SuturingPass(needle, outer_radius * normal + [0, 0, 0.008 + 0.003 * (k % 5)], normal, [0, 0, 1])
        )
    return passes
