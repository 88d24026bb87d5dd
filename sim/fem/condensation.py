"""Sparse Cholesky and the condensed inverse behind penalty-condensation.

The paper's composite matrix needs, for every contact-candidate node j, the
columns of (K0 + C E_j E_j^T)^-1 at node j's dofs, restricted to surface rows.
Everything follows from one block of the inverse of the fixed-only penalised
stiffness K0:  G = [K0^-1]_{cc}  (c: the candidates' dofs). We get G exactly as
the inverse of the Schur complement of K0 onto c:

    S = K_cc - K_ci K_ii^-1 K_ic,    G = S^-1,

with one sparse Cholesky (CHOLMOD) of the interior block, a multi-right-hand-side
solve, and a dense LAPACK Cholesky inverse (potrf + potri, BLAS-3, all cores).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg import lapack

from sim.errors import SolverError
from sim.fem.lapack import potri_lower

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


def solve_blocks(factor, rhs: sp.spmatrix | NDArray[np.float64]) -> NDArray[np.float64]:
    """Solve A X = B for many columns, in blocks, returning a dense Fortran-ordered X."""
    n_cols = rhs.shape[1]
    out = np.empty((rhs.shape[0], n_cols), order="F")
    for start in range(0, n_cols, SOLVE_BLOCK_COLUMNS):
        block = rhs[:, start : start + SOLVE_BLOCK_COLUMNS]
        block = block.toarray() if sp.issparse(block) else np.asarray(block)
        out[:, start : start + block.shape[1]] = factor(np.asfortranarray(block))
    return out


def schur_complement(matrix: sp.csc_matrix, kept: NDArray[np.int64]) -> NDArray[np.float64]:
    """Dense Schur complement of a sparse SPD matrix onto the ``kept`` dofs."""
    n = matrix.shape[0]
    eliminated = np.setdiff1d(np.arange(n), kept)
    csr = matrix.tocsr()
    k_cc = csr[kept][:, kept].toarray()
    if eliminated.size == 0:
        return k_cc
    k_ic = csr[eliminated][:, kept].tocsc()
    k_ci = k_ic.T.tocsr()
    factor = sparse_cholesky(csr[eliminated][:, eliminated].tocsc(), "interior stiffness block")
    schur = k_cc
    # Only the eliminated dofs coupled to the kept ones contribute; solve in column blocks.
    for start in range(0, len(kept), SOLVE_BLOCK_COLUMNS):
        stop = min(start + SOLVE_BLOCK_COLUMNS, len(kept))
        y = factor(np.asfortranarray(k_ic[:, start:stop].toarray()))
        schur[:, start:stop] -= k_ci @ y
    return schur


def inverse_spd(matrix: NDArray[np.float64], what: str = "condensed stiffness") -> NDArray[np.float64]:
    """Inverse of a dense SPD matrix by LAPACK potrf + potri (symmetric result)."""
    a = np.asfortranarray(matrix)
    factor, info = lapack.dpotrf(a, lower=1, overwrite_a=1, clean=0)
    if info != 0:
        raise SolverError(f"the {what} is not positive definite (LAPACK dpotrf info={info})")
    inverse, info = lapack.dpotri(factor, lower=1, overwrite_c=1)
    if info != 0:
        raise SolverError(f"the {what} could not be inverted (LAPACK dpotri info={info})")
    return _symmetrize_lower(inverse)


def trailing_cholesky(matrix: sp.csc_matrix, kept: NDArray[np.int64]) -> NDArray[np.float64]:
    """Dense lower Cholesky factor L_kk of the Schur complement of ``matrix`` onto ``kept``.

    The eliminated dofs are ordered first (fill-reducing order of their own
    block) and the kept dofs last; CHOLMOD's supernodal factor of that
    permutation then holds S = L_kk L_kk^T in its trailing block, the Schur
    update having been done with BLAS-3 inside CHOLMOD.
    """
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze, cholesky

    n = matrix.shape[0]
    eliminated = np.setdiff1d(np.arange(n), kept)
    csr = matrix.tocsr()
    order = kept
    if eliminated.size:
        interior_order = analyze(csr[eliminated][:, eliminated].tocsc()).P()
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


def condensed_inverse(matrix: sp.csc_matrix, kept: NDArray[np.int64]) -> NDArray[np.float64]:
    """[A^-1]_{kept, kept} of a sparse SPD matrix, exactly: (Schur complement)^-1.

    Equivalent to :func:`condensed_inverse_multi_rhs` at a fraction of the cost:
    the Schur complement's Cholesky factor comes from one CHOLMOD factorisation
    and its inverse from LAPACK potri, both BLAS-3 on all cores.
    """
    factor = trailing_cholesky(matrix, kept)
    inverse, info = potri_lower(factor)
    if info != 0:
        raise SolverError(f"the condensed stiffness could not be inverted (LAPACK dpotri info={info})")
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
