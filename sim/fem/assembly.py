"""Vectorised linear-tetrahedron stiffness, sparse assembly, strain and stress.

Degrees of freedom are node-major: (x, y, z) of node 0, then node 1, and so on.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray


def shape_gradients(points: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.float64]:
    """(M, 4, 3) gradients of the four linear shape functions of every element (1/m)."""
    edges = points[tets[:, 1:]] - points[tets[:, :1]]  # rows are p1-p0, p2-p0, p3-p0
    inverse = np.linalg.inv(edges)  # columns are grad N1..N3
    gradients = np.empty((len(tets), 4, 3))
    gradients[:, 1:, :] = np.swapaxes(inverse, 1, 2)
    gradients[:, 0, :] = -gradients[:, 1:, :].sum(axis=1)
    return gradients


def element_stiffness(
    gradients: NDArray[np.float64],
    volumes: NDArray[np.float64],
    lame_lambda: NDArray[np.float64],
    shear_modulus: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(M, 12, 12) element stiffness matrices (N/m).

    K[a i, b j] = V (lambda g_ai g_bj + mu g_aj g_bi + mu delta_ij g_a . g_b),
    the closed form of V B^T D B for isotropic linear elasticity.
    """
    lam = (lame_lambda * volumes)[:, None, None, None, None]
    mu = (shear_modulus * volumes)[:, None, None, None, None]
    k = lam * np.einsum("mai,mbj->maibj", gradients, gradients)
    k += mu * np.einsum("maj,mbi->maibj", gradients, gradients)
    dots = np.einsum("mak,mbk->mab", gradients, gradients)
    k += mu * dots[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
    return k.reshape(len(volumes), 12, 12)


class SparsityPattern:
    """The CSR structure of the global stiffness, computed once per mesh.

    The structure is found on node pairs (16 per element, 9x fewer than dof
    pairs) and expanded to 3x3 dof blocks; ``assemble`` then sums element
    matrices into it with one ``bincount``, so a material change re-assembles
    without re-sorting indices.
    """

    def __init__(self, tets: NDArray[np.int64], n_nodes: int) -> None:
        rows = np.repeat(tets, 4, axis=1).ravel()  # (M*16,) node a of each (a, b) pair
        cols = np.tile(tets, (1, 4)).ravel()  # node b
        unique, inverse = np.unique(rows * n_nodes + cols, return_inverse=True)
        node_ptr = np.searchsorted(unique // n_nodes, np.arange(n_nodes + 1))
        degree = np.diff(node_ptr)
        position = inverse - node_ptr[rows]  # index of b within node row a
        base = (9 * node_ptr[rows] + 3 * position).reshape(len(tets), 4, 1, 4, 1)
        row_step = (3 * degree[rows]).reshape(len(tets), 4, 1, 4, 1)
        axis = np.arange(3)
        slots = base + axis[None, None, :, None, None] * row_step + axis[None, None, None, None, :]
        self.shape = (3 * n_nodes, 3 * n_nodes)
        self._n_slots = 9 * len(unique)
        self._slot = slots.ravel().astype(np.int32 if self._n_slots < 2**31 else np.int64)
        dof_degree = np.repeat(3 * degree, 3)
        self.indptr = np.concatenate([[0], np.cumsum(dof_degree)]).astype(np.int64)
        # Column ids: dof row 3a+i holds the dofs 3b+j of every neighbour b of a, in order.
        block_cols = (3 * (unique % n_nodes)[:, None] + axis).ravel()
        self.indices = _expand_rows(block_cols, node_ptr, degree).astype(np.int32)

    def assemble(self, element_matrices: NDArray[np.float64]) -> sp.csr_matrix:
        """Sum (M, 12, 12) element matrices into a CSR matrix of this pattern."""
        data = np.bincount(self._slot, weights=element_matrices.ravel(), minlength=self._n_slots)
        return sp.csr_matrix((data, self.indices.copy(), self.indptr.copy()), shape=self.shape)


def _expand_rows(
    block_cols: NDArray[np.int64], node_ptr: NDArray[np.int64], degree: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Repeat each node row's 3*degree column ids three times (one per dof of the row node)."""
    offset_in_row = np.arange(len(block_cols)) - np.repeat(3 * node_ptr[:-1], 3 * degree)
    dof_row_start = np.repeat(9 * node_ptr[:-1], 3 * degree)
    width = np.repeat(3 * degree, 3 * degree)
    out = np.empty(3 * len(block_cols), dtype=np.int64)
    for axis in range(3):
        out[dof_row_start + axis * width + offset_in_row] = block_cols
    return out


def displacement_gradients(
    gradients: NDArray[np.float64], tets: NDArray[np.int64], displacement: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(M, 3, 3) displacement gradient du_i/dx_j per element."""
    return np.einsum("mai,maj->mij", displacement[tets], gradients)


def small_strain(grad_u: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 3, 3) infinitesimal strain tensor, sym(grad u)."""
    return 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))


def stress_tensor(
    strain: NDArray[np.float64], lame_lambda: NDArray[np.float64], shear_modulus: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(M, 3, 3) linear-elastic Cauchy stress (Pa): lambda tr(eps) I + 2 mu eps."""
    stress = 2 * shear_modulus[:, None, None] * strain
    stress += (lame_lambda * np.trace(strain, axis1=1, axis2=2))[:, None, None] * np.eye(3)
    return stress


def von_mises_of_stress(stress: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M,) von Mises equivalent stress (Pa): sqrt(3/2 s:s) of the deviator s."""
    deviator = stress - (np.trace(stress, axis1=1, axis2=2) / 3)[:, None, None] * np.eye(3)
    return np.sqrt(1.5 * np.einsum("mij,mij->m", deviator, deviator))


def von_mises_stress(
    strain: NDArray[np.float64], lame_lambda: NDArray[np.float64], shear_modulus: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(M,) von Mises equivalent stress (Pa) of the linear-elastic stress of each element."""
    return von_mises_of_stress(stress_tensor(strain, lame_lambda, shear_modulus))


def principal_stretches(grad_u: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 3) principal stretch ratios (length / original length), ascending."""
    deformation = grad_u + np.eye(3)
    right_cauchy_green = np.einsum("mki,mkj->mij", deformation, deformation)
    return np.sqrt(np.clip(np.linalg.eigvalsh(right_cauchy_green), 0.0, None))
