"""The condensed inverse over the contact candidates: computed, or read back from the disk cache.

``precompute`` (PAPER.md 4) inverts K0 over every contact-candidate dof at once; the result is keyed
by everything it depends on (mesh, materials, fixed dofs, candidates, penalty) and stored with a
checksum (:mod:`sim.fem.inverse.cache`), so a second run on the same tissue loads it in milliseconds. The
paper's composite matrix follows from it by an exact 3 x 3 Woodbury update per node.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from sim.fem.inverse import cache
from sim.fem.inverse.condensation import condensed_inverse, node_dofs


@dataclass
class Precomputation:
    """The condensed inverse over the contact candidates, and how it was obtained."""

    nodes: NDArray[np.int64]
    matrix: NDArray[np.float64]
    seconds: dict[str, float] = field(default_factory=dict)
    from_cache: bool = False

    @property
    def nbytes(self) -> int:
        return int(self.matrix.nbytes)


def condensed(
    assemble: Callable[[], sp.spmatrix], candidates: NDArray[np.int64], key: str, directory: Path | None
) -> Precomputation:
    """K0^-1 (``assemble()`` gives K0) over the candidates' dofs: read from ``directory`` under
    ``key`` when there (and of the right shape), else computed and, with a ``directory``, stored."""
    start = time.perf_counter()
    matrix = cache.load_cached(directory, key) if directory is not None else None
    if matrix is not None and matrix.shape == (3 * len(candidates),) * 2:
        return Precomputation(candidates, matrix, {"load": time.perf_counter() - start}, True)
    start = time.perf_counter()
    penalised = assemble()
    timings = {"assembly": time.perf_counter() - start}
    start = time.perf_counter()
    inverse = condensed_inverse(penalised, node_dofs(candidates), timings)
    timings["condensation"] = time.perf_counter() - start
    if directory is not None:
        cache.store_cached(directory, key, inverse)
    return Precomputation(candidates, inverse, timings)


def woodbury_composite(g: NDArray[np.float64], penalty: float) -> NDArray[np.float64]:
    """The paper's composite matrix Phi (3n x 3n over the candidates) from the condensed inverse G:
    column block j is (K0 + C E_j E_j^T)^-1 E_j on the candidates' rows, Phi_j = G_:j (I + C G_jj)^-1."""
    n = g.shape[0] // 3
    diagonal = g.reshape(n, 3, n, 3)[np.arange(n), :, np.arange(n), :]  # (n, 3, 3) G_jj
    correction = np.linalg.inv(np.eye(3) + penalty * diagonal)  # (n, 3, 3)
    blocks = np.einsum("rjk,jkl->rjl", g.reshape(3 * n, n, 3), correction)
    return blocks.reshape(3 * n, 3 * n)
