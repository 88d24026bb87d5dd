"""The cache of K0^-1 columns a contact needs: per node, least recently used first out of a byte budget.

On-demand mode (no precomputed candidates) and the live local stress (whole columns, for every
row of the field) read a node's three columns of K0^-1 when it becomes a contact. They are solved
once, in one multi-right-hand-side solve for all the nodes that lack them, kept with their rows at
the contact candidates cut out beside them, and dropped least recently used first when the cache
outgrows its budget. A prefetcher fills it ahead of contact (``ahead``); what a contact had to solve
itself is logged (:attr:`ColumnCache.spot_solved`), as is what the budget evicted.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from sim.fem.inverse.condensation import node_dofs

Solver = Callable[[NDArray[np.int64]], NDArray[np.float64]]


class CachedColumns(NamedTuple):
    """One node's three K0^-1 columns (3N, 3), and their rows at the contact candidates' dofs."""

    full: NDArray[np.float64]
    at_candidates: NDArray[np.float64]

    @classmethod
    def of(cls, columns: NDArray[np.float64], candidate_dofs: NDArray[np.int64]) -> CachedColumns:
        full = np.ascontiguousarray(columns)
        at_candidates = np.ascontiguousarray(full[candidate_dofs])
        full.flags.writeable = at_candidates.flags.writeable = False
        return cls(full, at_candidates)

    @property
    def nbytes(self) -> int:
        return self.full.nbytes + self.at_candidates.nbytes


class ColumnCache:
    """Columns of K0^-1 per node within ``budget`` bytes; ``solve`` gives (3N, 3k) columns for k
    nodes, ``candidate_dofs`` are the rows kept beside each (the contact candidates' dofs)."""

    def __init__(self, solve: Solver, candidate_dofs: NDArray[np.int64], budget: int) -> None:
        self._solve = solve
        self._candidate_dofs = candidate_dofs
        self._budget = budget
        self._columns: OrderedDict[int, CachedColumns] = OrderedDict()
        self._lock = threading.Lock()
        self.solver: Solver | None = None
        """Solves in place of ``solve`` when set (e.g. a column worker in another process)."""
        self.spot_solved: list[int] = []
        """Nodes whose columns a contact had to solve when it needed them (not solved ahead)."""
        self.evicted: set[int] = set()
        """Nodes whose cached columns were dropped for the memory budget (telemetry: a contact that
        must solve one of these again was prefetched, then evicted before it was used)."""

    def __contains__(self, node: int) -> bool:
        return node in self._columns

    def __len__(self) -> int:
        """How many nodes' columns are cached."""
        return len(self._columns)

    def clear(self) -> None:
        """Forget every cached column (benchmarks time a contact change from cold)."""
        with self._lock:
            self._columns.clear()

    def columns(
        self,
        nodes: NDArray[np.int64],
        rows: NDArray[np.int64] | None = None,
        *,
        at_candidates: bool = False,
        ahead: bool = False,
    ) -> NDArray[np.float64]:
        """(3N, 3k) columns at the nodes' dofs, only their ``rows`` (dof ids), or only the candidates'
        dofs: cached ones reused, the rest solved together. A contact change so copies (3n, 3k)
        rows, never whole (3N, 3k) blocks. Nodes solved for a contact (not ``ahead`` of it, as
        prefetching does) are logged in :attr:`spot_solved`."""
        with self._lock:
            known = {int(n): self._columns[int(n)] for n in nodes if int(n) in self._columns}
            for n in known:
                self._columns.move_to_end(n)
        missing = [int(n) for n in nodes if int(n) not in known]
        if missing:
            if not ahead:
                self.spot_solved.extend(missing)
            solved = (self.solver or self._solve)(np.array(missing, dtype=np.int64))
            with self._lock:
                for i, node in enumerate(missing):
                    known[node] = self._columns[node] = CachedColumns.of(
                        solved[:, 3 * i : 3 * i + 3], self._candidate_dofs
                    )
                self._evict()
        if at_candidates:
            return np.hstack([known[int(n)].at_candidates for n in nodes])
        if rows is None:
            return np.hstack([known[int(n)].full for n in nodes])
        return np.hstack([known[int(n)].full[rows] for n in nodes])

    def cached_whole(self, nodes: NDArray[np.int64]) -> list[NDArray[np.float64]] | None:
        """Each node's whole (3N, 3) columns when every one is cached (marked recently used), else
        None: what a contact's local-stress operator reads without solving."""
        with self._lock:
            found = [self._columns.get(int(n)) for n in nodes]
            if any(c is None for c in found):
                return None
            for n in nodes:
                self._columns.move_to_end(int(n))
        return [c.full for c in found]

    def _evict(self) -> None:
        """Drop least recently used columns beyond the budget (lock held)."""
        used = sum(c.nbytes for c in self._columns.values())
        while len(self._columns) > 1 and used > self._budget:
            node, dropped = self._columns.popitem(last=False)
            used -= dropped.nbytes
            self.evicted.add(node)


def mixed_columns(
    g: NDArray[np.float64],
    nodes: NDArray[np.int64],
    rows: NDArray[np.int64],
    on_demand: Callable[..., NDArray[np.float64]],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(columns at the candidates' rows, G_JJ block) for a contact set of candidate nodes (``rows``:
    their row in the precomputed G, -1 for a node that is not a candidate) and others (e.g. an exit
    through a face that is not a contact candidate), whose columns ``on_demand(nodes, dofs)`` or
    ``on_demand(nodes, at_candidates=True)`` gives; exact either way."""
    inside = rows >= 0
    in_pos, out_pos = node_dofs(np.flatnonzero(inside)), node_dofs(np.flatnonzero(~inside))
    outside = nodes[~inside]  # their columns of K0^-1, at the candidates' and the contact's dofs
    columns = np.empty((g.shape[0], 3 * len(nodes)))
    columns[:, in_pos] = g[:, node_dofs(rows[inside])]
    columns[:, out_pos] = on_demand(outside, at_candidates=True)
    block = np.empty((3 * len(nodes), 3 * len(nodes)))
    block[:, out_pos] = on_demand(outside, node_dofs(nodes))
    block[np.ix_(in_pos, in_pos)] = columns[np.ix_(node_dofs(rows[inside]), in_pos)]
    block[np.ix_(out_pos, in_pos)] = block[np.ix_(in_pos, out_pos)].T
    return columns, block
