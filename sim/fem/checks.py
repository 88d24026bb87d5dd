"""The tissue model's input checks: ids in range, contacts well formed, rigid motion prevented.

Each raises :class:`sim.errors.ModelError` naming the input and what to do; the model calls them
before any numerics, so a bad argument never reaches a factorisation.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import ModelError
from sim.mesh.tetmesh import TetMesh


def check_rigid_motion_fixed(points: NDArray[np.float64], fixed_dofs: NDArray[np.int64]) -> None:
    """Raise unless the fixed dofs stop all six rigid-body modes (else K0 is singular)."""
    nodes, axes = fixed_dofs // 3, fixed_dofs % 3
    centred = points[nodes] - points[nodes].mean(axis=0)
    scale = max(float(np.abs(centred).max()), 1e-300)
    modes = np.zeros((len(fixed_dofs), 6))
    modes[np.arange(len(fixed_dofs)), axes] = 1.0
    for k in range(3):  # rotation about axis k: (e_k x x) at each fixed dof
        modes[:, 3 + k] = np.cross(np.eye(3)[k], centred / scale)[np.arange(len(fixed_dofs)), axes]
    rank = np.linalg.matrix_rank(modes, tol=1e-8 * max(1.0, np.sqrt(len(fixed_dofs))))
    if rank < 6:
        raise ModelError(
            f"the fixed nodes/dofs leave {6 - rank} rigid-body mode(s) free, so the tissue can move "
            "without deforming; fix at least three non-collinear nodes (e.g. a face or the vessel ends)"
        )


def ids(values: ArrayLike, limit: int, name: str) -> NDArray[np.int64]:
    array = np.asarray(values).ravel()
    if array.size == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.issubdtype(array.dtype, np.integer):
        raise ModelError(f"{name} must be integer ids; got dtype {array.dtype}")
    bad = array[(array < 0) | (array >= limit)]
    if bad.size:
        raise ModelError(f"{name} contains id {bad[0]} outside 0..{limit - 1}")
    return np.unique(array.astype(np.int64))


def node_ids(values: ArrayLike, n_nodes: int, name: str) -> NDArray[np.int64]:
    return ids(values, n_nodes, name)


def contact_ids(nodes: ArrayLike, n_nodes: int) -> NDArray[np.int64]:
    array = np.asarray(nodes, dtype=np.int64).ravel()
    distinct = ids(array, n_nodes, "contact nodes")
    if len(distinct) != len(array):
        raise ModelError(f"contact nodes must be distinct; got {array.tolist()}")
    return array


def parse_contacts(contacts: Mapping[int, ArrayLike], n_nodes: int) -> tuple[NDArray, NDArray]:
    if not contacts:
        raise ModelError("contacts is empty: give at least one node id -> intended displacement")
    nodes = contact_ids(list(contacts), n_nodes)
    intended = np.array([np.asarray(contacts[k], dtype=np.float64) for k in contacts])
    if intended.shape != (len(nodes), 3):
        raise ModelError(f"each intended displacement must be 3 numbers (m); got shape {intended.shape[1:]}")
    if not np.all(np.isfinite(intended)):
        raise ModelError("intended displacements must be finite numbers (m)")
    return nodes, intended


def array_hash(array: NDArray) -> str:
    """SHA-256 of an array's bytes (cache keys)."""
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def fixed_nodes_of(mesh: TetMesh, names: Sequence[str]) -> NDArray[np.int64]:
    """Union of named node sets, e.g. ``fixed_nodes_of(mesh, ["end0", "end1"])``."""
    missing = [n for n in names if n not in mesh.node_sets]
    if missing:
        raise ModelError(f"mesh has no node set {missing[0]!r} (sets: {sorted(mesh.node_sets)})")
    return np.unique(np.concatenate([mesh.node_sets[n] for n in names]))
