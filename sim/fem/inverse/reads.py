"""The tissue model's reads of K0^-1: the mixin of :class:`sim.fem.model.TissueModel` that answers
a contact's columns (precomputed at the candidates, else from the column cache, solved on demand or
by a prefetcher ahead of the needle), a load's response at chosen nodes, and the cache's telemetry.
The state it reads (the factor, the precomputation, the column cache, the candidates' rows, a shared
inverse) is the model's."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.fem import _local_stress as compiled
from sim.fem import checks
from sim.fem.inverse.columns import mixed_columns
from sim.fem.inverse.condensation import node_dofs


class ColumnReads:
    """Columns of K0^-1 as a contact, a prefetcher or the live stress reads them (see the module
    docstring)."""

    def _nodes_columns(
        self,
        nodes: NDArray[np.int64],
        rows: NDArray[np.int64] | None = None,
        *,
        at_candidates: bool = False,
        ahead: bool = False,
    ) -> NDArray[np.float64]:
        """(3N, 3k) columns of K0^-1 at the nodes' dofs, only their ``rows`` (dof ids), or only the
        candidates' dofs, from the column cache (:class:`sim.fem.inverse.columns.ColumnCache`; a model that
        shares its inverse reads its base's, divided by the scale)."""
        if self._inverse_of is not None:
            base, scale = self._inverse_of
            return base._nodes_columns(nodes, rows, at_candidates=at_candidates, ahead=ahead) / scale
        return self._column_cache.columns(nodes, rows, at_candidates=at_candidates, ahead=ahead)

    @property
    def column_solver(self) -> Callable[[NDArray[np.int64]], NDArray[np.float64]] | None:
        """Solves on-demand columns in place of :meth:`solve_columns` (e.g. in a worker process)."""
        return self._column_cache.solver

    @column_solver.setter
    def column_solver(self, solver: Callable[[NDArray[np.int64]], NDArray[np.float64]] | None) -> None:
        self._column_cache.solver = solver

    @property
    def spot_solved(self) -> list[int]:
        """Nodes whose columns a contact had to solve when it needed them (not solved ahead)."""
        return self._column_cache.spot_solved

    @property
    def cached_columns(self) -> int:
        """How many nodes' K0^-1 columns the column cache holds now."""
        return len(self._column_cache)

    def drop_cached_columns(self) -> None:
        """Empty the column cache (what a contact change costs from cold is then measurable)."""
        self._column_cache.clear()

    @property
    def evicted_columns(self) -> set[int]:
        """Nodes whose cached columns the memory budget dropped."""
        return self._column_cache.evicted

    def solve_columns(self, nodes: NDArray[np.int64]) -> NDArray[np.float64]:
        """(3N, 3k) columns of K0^-1 at the nodes' dofs, in one multi-right-hand-side solve."""
        rhs = np.zeros((3 * self.mesh.n_nodes, 3 * len(nodes)), order="F")
        rhs[node_dofs(np.asarray(nodes, dtype=np.int64)), np.arange(3 * len(nodes))] = 1.0
        return self._factor(rhs)

    def prefetch(self, nodes: ArrayLike, full: bool = False) -> None:
        """Solve and cache the on-demand columns of ``nodes`` ahead of contact (in precomputed
        mode only those of nodes outside the precomputed candidates are needed, unless ``full``:
        the whole columns the local-stress operator reads)."""
        ids = checks.node_ids(nodes, self.mesh.n_nodes, "nodes")
        if self._precomputed is not None and not full:
            ids = ids[self._candidate_row[ids] < 0]
        if ids.size:
            self._nodes_columns(ids, ahead=True)

    def load_response(self, nodes: ArrayLike, loads: ArrayLike, at_nodes: ArrayLike) -> NDArray[np.float64]:
        """(3L, q) displacement (m) of the dofs of ``at_nodes`` (L node ids; row 3l + i is dof i of
        node l) per unit of each of q generalised loads, ``loads`` (3k, q) mapping them to forces (N)
        on the k ``nodes``' dofs.

        From the nodes' whole cached K0^-1 columns when every one is cached (no solve: what the
        real-time prefetcher arranges; one compiled pass, :mod:`sim.fem._local_stress`), else one
        q-right-hand-side solve (cheaper than solving 3k whole columns that nothing else will read)."""
        ids, at = (np.asarray(v, dtype=np.int64).ravel() for v in (nodes, at_nodes))
        checks.node_ids(ids, self.mesh.n_nodes, "nodes")  # checked; the order given is the rows' order
        checks.node_ids(at, self.mesh.n_nodes, "at_nodes")
        loads = np.ascontiguousarray(loads, dtype=np.float64).reshape(3 * len(ids), -1)
        base, scale = self._inverse_of or (self, 1.0)
        whole = base._column_cache.cached_whole(ids)
        if whole is not None:
            out = np.empty((3 * len(at), loads.shape[1]))
            compiled.response(whole, loads, at, out)
            return out / scale if scale != 1.0 else out
        rhs = np.zeros((3 * self.mesh.n_nodes, loads.shape[1]), order="F")
        np.add.at(rhs, node_dofs(ids), loads)
        return np.ascontiguousarray(self._factor(rhs)[node_dofs(at)])

    def node_columns(self, nodes: ArrayLike, rows: ArrayLike | None = None) -> NDArray[np.float64]:
        """K0^-1's columns at the nodes' dofs, whole (3N, 3k) or only ``rows`` (dof ids), cached ones
        reused and the rest solved (unchecked ids: for callers holding ids the mesh gave them)."""
        ids = np.asarray(nodes, dtype=np.int64).ravel()
        return self._nodes_columns(ids, None if rows is None else np.asarray(rows, dtype=np.int64).ravel())

    def columns_at(self, nodes: ArrayLike, rows: ArrayLike) -> NDArray[np.float64]:
        """(len(rows), 3k) rows (dof ids) of K0^-1's columns at the nodes' dofs, in the order given:
        the displacement of those dofs per unit force on each node (m/N). Cached columns are
        reused; the rest are solved (by the column worker when one is attached) and cached."""
        ids, dofs = np.asarray(nodes).ravel(), np.asarray(rows).ravel()
        checks.node_ids(ids, self.mesh.n_nodes, "nodes")  # checked; the order given is the columns' order
        checks.ids(dofs, 3 * self.mesh.n_nodes, "rows")
        return self._nodes_columns(ids.astype(np.int64), dofs.astype(np.int64))

    def _contact_columns(self, nodes: NDArray[np.int64]) -> tuple[NDArray, NDArray, NDArray]:
        """(G rows x 3k columns, G_JJ block, ids of the rows) for a contact set."""
        if self._precomputed is not None:
            rows = self._candidate_row[nodes]
            if np.all(rows >= 0):
                dofs_local = node_dofs(rows)
                columns = self._precomputed.matrix[:, dofs_local]
                return columns, columns[dofs_local], self.contact_nodes
            mixed = mixed_columns(self._precomputed.matrix, nodes, rows, self._nodes_columns)
            return (*mixed, self.contact_nodes)
        columns = self._nodes_columns(nodes, at_candidates=True)
        block = self._nodes_columns(nodes, node_dofs(nodes))
        return columns, block, self.contact_nodes
