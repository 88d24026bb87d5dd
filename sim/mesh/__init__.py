"""Tetrahedral meshes: the container, generators, validation and file I/O."""

from sim.mesh.generators import (
    Calcification,
    Wound,
    box_mesh,
    grid_box_mesh,
    refined_coordinates,
    vessel_mesh,
)
from sim.mesh.io import load_mesh, save_mesh
from sim.mesh.tetmesh import TetMesh, triangle_normals

__all__ = [
    "Calcification",
    "TetMesh",
    "Wound",
    "box_mesh",
    "grid_box_mesh",
    "load_mesh",
    "refined_coordinates",
    "save_mesh",
    "triangle_normals",
    "vessel_mesh",
]
