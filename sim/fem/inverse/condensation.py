"""Sparse Cholesky and the condensed inverse behind penalty-condensation.

The paper's composite matrix needs, for every contact-candidate node j, the
columns of (K0 + C E_j E_j^T)^-1 at node j's dofs, restricted to surface rows.
Everything follows from one block of the inverse of the fixed-only penalised
stiffness K0:  G = [K0^-1]_{cc}  (c: the candidates' dofs). We get G exactly as
the inverse of the Schur complement of K0 onto c:

    S = K_cc - K_ci K_ii^-1 K_ic,    G = S^-1,

from one CHOLMOD supernodal factorisation with the kept dofs ordered last (its
trailing block is the Cholesky factor of S) and a dense LAPACK inverse (potri),
both BLAS-3 on all cores.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from sim.errors import SolverError
from sim.fem.inverse.lapack import potri_lower

# Columns per block in multi-right-hand-side solves: big enough for BLAS-3,
# small enough to bound the dense workspace.
SOLVE_BLOCK_COLUMNS = 1024


def sparse_cholesky(matrix: sp.spmatrix, what: str = "penalised stiffness"):
    """CHOLMOD factor of a symmetric positive definite matrix, or a clear :class:`SolverError`."""
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

    try:
        return cholesky(sp.csc_matrix(matrix), mode="supernodal")
    except CholmodNotPositiveDefiniteError as error:
        raise SolverError(
            f"the {what} is not positive definite ({error}); fix enough nodes to stop rigid-body "
            "motion and check the materials"
        ) from error


def trailing_cholesky(matrix: sp.csc_matrix, kept: NDArray[np.int64]) -> NDArray[np.float64]:
    """Dense lower Cholesky factor L_kk of the Schur complement of ``matrix`` onto ``kept``.

    The eliminated dofs are ordered first (fill-reducing order of their own
    block) and the kept dofs last; CHOLMOD's supernodal factor of that
    permutation then holds S = L_kk L_kk^T in its trailing block, the Schur
    update having been done with BLAS-3 inside CHOLMOD.
    """
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

    n = matrix.shape[0]
    eliminated = np.setdiff1d(np.arange(n), kept)
    csr = matrix.tocsr()
    order = kept
    if eliminated.size:
        interior_order = _fill_reducing_order(csr[eliminated][:, eliminated].tocsc())
        order = np.concatenate([eliminated[interior_order], kept])
    permuted = csr[order][:, order].tocsc()
    try:
        lower = cholesky(permuted, ordering_method="natural", mode="supernodal").L()
    except CholmodNotPositiveDefiniteError as error:
        raise SolverError(
            f"the penalised stiffness is not positive definite ({error}); fix enough "
            "nodes to stop rigid-body motion and check the materials"
        ) from error
    start = lower.indptr[eliminated.size]
    trailing = sp.csc_matrix(
        (
            lower.data[start:],
            lower.indices[start:] - eliminated.size,
            lower.indptr[eliminated.size :] - start,
        ),
        shape=(len(kept), len(kept)),
    )
    return trailing.toarray(order="F")


def _fill_reducing_order(matrix: sp.csc_matrix) -> NDArray[np.int64]:
    """METIS nested dissection (least fill and fastest Schur update measured here), else AMD."""
    from sksparse.cholmod import CholmodError, analyze

    try:
        return analyze(matrix, ordering_method="metis").P()
    except CholmodError:
        return analyze(matrix, ordering_method="amd").P()


def condensed_inverse(
    matrix: sp.csc_matrix, kept: NDArray[np.int64], timings: dict[str, float] | None = None
) -> NDArray[np.float64]:
    """[A^-1]_{kept, kept} of a sparse SPD matrix, exactly: (Schur complement)^-1.

    Equivalent to :func:`condensed_inverse_multi_rhs` at a fraction of the cost:
    the Schur complement's Cholesky factor comes from one CHOLMOD factorisation
    and its inverse from LAPACK potri, both BLAS-3 on all cores.
    """
    timings = {} if timings is None else timings
    start = time.perf_counter()
    factor = trailing_cholesky(matrix, kept)
    timings["schur_cholesky"] = time.perf_counter() - start
    inverse, info = potri_lower(factor)
    if info != 0:
        raise SolverError(f"the condensed stiffness could not be inverted (LAPACK dpotri info={info})")
    timings["potri"] = time.perf_counter() - start - timings["schur_cholesky"]
    return _symmetrize_lower(inverse)


def _symmetrize_lower(matrix: NDArray[np.float64], block: int = 256) -> NDArray[np.float64]:
    """Copy the lower triangle onto the upper, in place, in cache-sized blocks."""
    n = matrix.shape[0]
    for start in range(0, n, block):
        stop = min(start + block, n)
        # Rows below this block column, transposed into the block row to the right.
        matrix[start:stop, stop:] = matrix[stop:, start:stop].T
        tile = matrix[start:stop, start:stop]
        upper = np.triu_indices(stop - start, k=1)
        tile[upper] = tile.T[upper]
    return matrix


def condensed_inverse_multi_rhs(matrix: sp.csc_matrix, kept: NDArray[np.int64]) -> NDArray[np.float64]:
    """The same block by the straightforward route: solve A X = E_kept, keep the kept rows."""
    factor = sparse_cholesky(matrix)
    n = matrix.shape[0]
    selector = sp.csc_matrix((np.ones(len(kept)), (kept, np.arange(len(kept)))), shape=(n, len(kept)))
    out = np.empty((len(kept), len(kept)))
    for start in range(0, len(kept), SOLVE_BLOCK_COLUMNS):
        block = selector[:, start : start + SOLVE_BLOCK_COLUMNS].toarray()
        out[:, start : start + block.shape[1]] = factor(np.asfortranarray(block))[kept]
    return out


def node_dofs(nodes: NDArray[np.int64]) -> NDArray[np.int64]:
    """Node-major dof ids (3 per node) of the given nodes."""
    return (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()


def superposed_reactions(block: NDArray[np.float64], a: NDArray[np.float64], penalty: float) -> NDArray:
    """The paper's run-time superposition: each contact node's reaction from its own single-contact
    solution, R_j = C (I + C G_jj)^-1 a_j (``block``: G_JJ, ``a``: the intended displacements)."""
    k = len(a) // 3
    diagonal = block.reshape(k, 3, k, 3)[np.arange(k), :, np.arange(k), :]
    alone = penalty * np.linalg.solve(np.eye(3) + penalty * diagonal, a.reshape(k, 3, 1))
    return alone.reshape(-1)
