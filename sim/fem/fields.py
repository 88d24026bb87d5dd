"""Tissue fields while the needle indents one triangle, as linear functions of the tip's displacement.

While the needle tip presses on a nominated triangle, the runtime drives the
triangle's nodes to intended displacements a_k = b_k d (b: barycentric weights of
the contact point, d: the tip's displacement from it). Each linear phase answers
linearly in d, so the stress of any element is S d for a fixed operator S built from
three unit solves; the biphase model only blends the two phases' answers with its
soft share, a scalar per tick. A whole indentation of thousands of ticks therefore
costs six sparse solves plus array arithmetic, and gives exactly what
``tissue.solve(..., fields=True)`` gives tick by tick.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import ModelError
from sim.fem import _local_stress as compiled
from sim.fem.assembly import displacement_gradients, small_strain, stress_tensor, von_mises_of_stress
from sim.fem.inverse.condensation import node_dofs
from sim.fem.model import TissueModel
from sim.fem.stress import von_mises_rows
from sim.fem.tissue import Tissue

_CHUNK = 512  # ticks per block: keeps the (ticks x elements x 3 x 3) temporaries small


def contact_depth(tissue: Tissue, nodes: NDArray[np.int64]) -> float:
    """Mean tissue depth h (m) under contact nodes, as the runtime's biphase contact uses it."""
    return tissue.depth_under(nodes)


def _phases(tissue: Tissue) -> list[TissueModel]:
    return list(tissue.models)


class IndentationStress:
    """Von Mises stress (Pa) of chosen elements while one triangle is indented.

    tissue: the (precomputed or on-demand) model the session ran on.
    nodes: (3,) the triangle's node ids; barycentric: (3,) weights of the contact point.
    elements: ids of the elements to evaluate (e.g. those near the contact).
    """

    def __init__(
        self,
        tissue: Tissue,
        nodes: ArrayLike,
        barycentric: ArrayLike,
        elements: ArrayLike,
    ) -> None:
        self.tissue = tissue
        self.nodes = np.asarray(nodes, dtype=np.int64).ravel()
        weights = np.asarray(barycentric, dtype=np.float64).ravel()
        self.elements = np.asarray(elements, dtype=np.int64).ravel()
        if weights.shape != self.nodes.shape or not np.all(np.isfinite(weights)):
            raise ModelError(
                f"barycentric weights {weights.tolist()} do not match nodes {self.nodes.tolist()}"
            )
        if self.elements.size == 0:
            raise ModelError("no elements to evaluate the indentation stress on")
        self.depth = contact_depth(tissue, self.nodes)
        mesh = tissue.mesh
        tets = mesh.tets[self.elements]
        # operators[p][a]: stress (E, 3, 3) of phase p for a unit tip displacement along axis a
        self.operators = []
        for model in _phases(tissue):
            lam, mu = model.lame
            per_axis = []
            for axis in range(3):
                unit = np.zeros(3)
                unit[axis] = 1.0
                solution = model.solve(
                    {int(n): w * unit for n, w in zip(self.nodes, weights, strict=True)}, full_field=True
                )
                grad = displacement_gradients(
                    model.element_gradients[self.elements], tets, solution.displacement
                )
                per_axis.append(stress_tensor(small_strain(grad), lam[self.elements], mu[self.elements]))
            self.operators.append(np.stack(per_axis))  # (3, E, 3, 3)

    def soft_share(
        self, tool_displacement: NDArray[np.float64], needle_speed: NDArray[np.float64]
    ) -> NDArray:
        """(T,) the soft phase's share per tick (1 for a single-phase model)."""
        p = self.tissue.biphase
        if p is None:
            return np.ones(len(tool_displacement))
        strain = np.linalg.norm(tool_displacement, axis=1) / self.depth
        ratio = np.minimum(np.clip(needle_speed, 0.0, None) / p.critical_speed, 1.0) ** p.speed_exponent
        limit = p.strain_limit * (1.0 - (1.0 - p.limit_floor) * ratio)
        return np.where(strain <= limit, 1.0, limit / np.maximum(strain, 1e-300))

    def von_mises(self, tool_displacement: ArrayLike, needle_speed: ArrayLike | None = None) -> NDArray:
        """(T, E) von Mises stress (Pa) of each element at each tick.

        tool_displacement: (T, 3) tip displacement from the contact point (m).
        needle_speed: (T,) tip speed (m/s), which lowers the biphase strain limit.
        """
        d = np.asarray(tool_displacement, dtype=np.float64).reshape(-1, 3)
        speed = np.zeros(len(d)) if needle_speed is None else np.asarray(needle_speed, dtype=np.float64)
        share = self.soft_share(d, np.nan_to_num(speed))
        out = np.empty((len(d), len(self.elements)))
        for start in range(0, len(d), _CHUNK):
            block = slice(start, start + _CHUNK)
            stress = np.einsum("ta,aeij->teij", d[block] * share[block, None], self.operators[0])
            if len(self.operators) == 2:
                stress += np.einsum("ta,aeij->teij", d[block] * (1.0 - share[block, None]), self.operators[1])
            out[block] = von_mises_of_stress(stress.reshape(-1, 3, 3)).reshape(len(stress), -1)
        return out


class TissueFieldReplay:
    """The whole tissue's displacement and surface stress for any drive the runtime applied.

    A drive is what the FEM layer sends the tissue each tick: contact nodes, their
    intended displacements (k, 3) and the needle speed; the tool displacement that
    sets the biphase strain is the intended displacements' sum (the runtime's own
    choice, indenting or pierced). Per contact set the full columns of each phase's
    K0^-1 at the contact dofs are solved once (one multi-right-hand-side solve) and
    kept, so a frame costs two small matrix products: replaying a session frame by
    frame gives exactly ``tissue.solve(..., full_field=True, fields=True)``.
    """

    def __init__(
        self,
        tissue: Tissue,
        cache_size: int = 16,
        elements: NDArray[np.int64] | None = None,
    ) -> None:
        """elements: replay only these elements' stress (:meth:`stress`; e.g. the wound's edge),
        reading only the rows of K0^-1's columns at their nodes; by default every exterior
        triangle's element (in the mesh's surface order) and the whole displacement
        (:meth:`state`)."""
        self.tissue = tissue
        self.mesh = tissue.mesh
        self._surface = self.mesh.surface_elements if elements is None else np.asarray(elements, np.int64)
        self._rows = None if elements is None else node_dofs(np.unique(self.mesh.tets[self._surface]))
        self._cache: dict[tuple[int, ...], list[tuple[object, NDArray, NDArray]]] = {}
        self._cache_size = cache_size
        # A phase whose K0 is s times the first one's (the biphase stiff phase with one Poisson
        # ratio) has columns G/s and a stress operator s*S: the same stress per unit reaction and
        # reactions s times the first phase's for the same drive, so it needs no arrays of its own.
        # _layout: per phase, (index of the arrays it uses in _part_models, its reaction scale).
        phases = _phases(tissue)
        self._part_models: list[TissueModel] = []
        self._layout: list[tuple[int, float]] = []
        for model in phases:
            source = model.inverse_source
            if source is not None and source[0] is phases[0]:
                self._layout.append((0, source[1]))
            else:
                self._layout.append((len(self._part_models), 1.0))
                self._part_models.append(model)
        operators = [surface_stress_operator(m, self._surface) for m in self._part_models]
        if self._rows is not None:  # the operator reads only the elements' own dofs
            operators = [operator.tocsc()[:, self._rows].tocsr() for operator in operators]
        self._stress_operators = operators

    def _phase_parts(self, nodes: NDArray[np.int64]) -> list[tuple[object, NDArray, NDArray]]:
        """Per model with arrays of its own: the contact handle, K0^-1 columns at the contact dofs
        (3N, 3k; only the elements' rows for a restricted replay), and the elements' stress per unit
        reaction (3k, F, 3, 3)."""
        key = tuple(int(n) for n in nodes)
        parts = self._cache.get(key)
        if parts is None:
            parts = []
            for model, operator in zip(self._part_models, self._stress_operators, strict=True):
                columns = model.node_columns(nodes, self._rows)
                unit_stress = (operator @ columns).T.reshape(columns.shape[1], len(self._surface), 3, 3)
                parts.append((model.contact(nodes), columns, unit_stress))
            if len(self._cache) >= self._cache_size:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = parts
        return parts

    def soft_share(
        self, nodes: NDArray[np.int64], intended: NDArray[np.float64], needle_speed: float
    ) -> float:
        p = self.tissue.biphase
        if p is None:
            return 1.0
        strain = float(np.linalg.norm(intended.sum(axis=0))) / self.tissue.depth_under(nodes)
        return p.soft_share(strain, p.strain_limit_at(max(float(needle_speed), 0.0)))

    def state(
        self,
        nodes: ArrayLike,
        intended: ArrayLike,
        needle_speed: float = 0.0,
        soft_share: float | None = None,
        grasp: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(N, 3) displacement of every node (m) and (F,) von Mises stress (Pa) under each exterior
        triangle, for contact ``nodes`` driven to ``intended`` (k, 3) at ``needle_speed`` (m/s).

        soft_share: the biphase split the runtime applied (the force kernel's, from its own strain);
        None or nan derives it from the drive (the barycentric rule's drive sums to the tip's).
        grasp: (nodes, forces (k, 3) N) of the subordinate hand's forceps on the tissue's base phase
        (:mod:`sim.forceps`), superposed: the stress is that of the summed displacement."""
        if self._rows is not None:
            raise ModelError("a replay of chosen elements has no whole displacement; use stress()")
        return self._replay(nodes, intended, needle_speed, soft_share, with_displacement=True, grasp=grasp)

    def stress(
        self,
        nodes: ArrayLike,
        intended: ArrayLike,
        needle_speed: float = 0.0,
        soft_share: float | None = None,
    ) -> NDArray[np.float64]:
        """(F,) von Mises stress (Pa) of the replay's elements for a drive (as :meth:`state`)."""
        return self._replay(nodes, intended, needle_speed, soft_share, with_displacement=False)[1]

    def _replay(
        self,
        nodes: ArrayLike,
        intended: ArrayLike,
        needle_speed: float,
        soft_share,
        with_displacement: bool,
        grasp: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        ids = np.asarray(nodes, dtype=np.int64).ravel()
        drive = np.asarray(intended, dtype=np.float64).reshape(-1, 3)
        displacement = np.zeros((self.mesh.n_nodes, 3)) if with_displacement else None
        stress = np.zeros((len(self._surface), 3, 3))
        if grasp is not None and len(grasp[0]):  # the forceps' loads on the base phase: G[:, P] f_P
            held = np.asarray(grasp[0], dtype=np.int64).ravel()
            pulls = np.asarray(grasp[1], dtype=np.float64).reshape(-1)
            _, columns, unit_stress = self._phase_parts(held)[0]
            if with_displacement:
                displacement += (columns @ pulls).reshape(-1, 3)
            stress += np.tensordot(pulls, unit_stress, axes=1)
        if ids.size == 0:
            return displacement, von_mises_of_stress(stress)
        known = soft_share is not None and np.isfinite(soft_share)
        share = float(soft_share) if known else self.soft_share(ids, drive, needle_speed)
        parts = self._phase_parts(ids)
        # per set of arrays: the reactions its displacement (G/s . sR) and its stress (S G . sR) take
        displacement_reactions: list = [None] * len(parts)
        stress_reactions: list = [None] * len(parts)
        for (index, scale), fraction in zip(self._layout, (share, 1.0 - share), strict=False):
            if fraction == 0.0:
                continue
            reactions = parts[index][0].reaction_forces(fraction * drive).reshape(-1)
            for sums, value in ((displacement_reactions, reactions), (stress_reactions, scale * reactions)):
                sums[index] = value if sums[index] is None else sums[index] + value
        for (_, columns, unit_stress), moved, stressed in zip(
            parts, displacement_reactions, stress_reactions, strict=True
        ):
            if moved is not None:
                if with_displacement:
                    displacement += (columns @ moved).reshape(-1, 3)
                stress += np.tensordot(stressed, unit_stress, axes=1)
        return displacement, von_mises_of_stress(stress)


def surface_stress_operator(model: TissueModel, elements: NDArray[np.int64]):
    """Sparse (9E, 3N) map from nodal displacements (m) to the linear-elastic stress tensors (Pa,
    row-major 3x3 per element) of ``elements``: sigma = lambda tr(eps) I + 2 mu eps, eps = sym(grad u),
    grad u = sum over the element's nodes of u_a (x) grad N_a."""
    import scipy.sparse as sp

    gradients = model.element_gradients[elements]  # (E, 4, 3): grad N_a per element node
    tets = model.mesh.tets[elements]
    lam, mu = (values[elements] for values in model.lame)
    base = np.arange(len(elements)) * 9
    eye = np.eye(3)
    rows, cols, vals = [], [], []
    for a in range(4):
        g = gradients[:, a, :]  # (E, 3)
        for k in range(3):  # displacement component k of node a
            # d(grad u)_ij / d u_ak = delta_ik g_j; eps_ij = (grad_ij + grad_ji) / 2; d tr(eps) = g_k
            for i in range(3):
                for j in range(3):
                    strain = 0.5 * (eye[i, k] * g[:, j] + eye[j, k] * g[:, i])
                    value = 2 * mu * strain + (lam * g[:, k] if i == j else 0.0)
                    rows.append(base + 3 * i + j)
                    cols.append(3 * tets[:, a] + k)
                    vals.append(value)
    shape = (9 * len(elements), 3 * model.mesh.n_nodes)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)


LOCAL_STRESS_RADIUS = 1e-3
"""Elements whose centroid lies within 1 mm of a contact (the needle's force kernel) are "local"."""

WOUND_EDGE_RADIUS = 3e-3
"""The wound-edge elements whose centroid lies within 3 mm of a contact are watched live (a bite is
1-2 mm from the edge; farther edge elements carry a fraction of the load)."""


def _decreasing(values: NDArray[np.float64]) -> NDArray[np.int64]:
    """Positions of ``values`` from the largest down, nan first (a nan is read, never skipped)."""
    return np.argsort(np.where(np.isnan(values), -np.inf, -values)).astype(np.int64)


def _reading_bounds(
    operator: NDArray, split: int, response: NDArray, rest: NDArray, rest_length: NDArray
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], float]:
    """What lets the compiled measures skip the elements and edges that cannot hold the largest
    stress or stretch (see sim/fem/_local_stress.c): (element order, (E, 1 + q) bounds in that order:
    each one's squared Frobenius norm then its column norms; edge order, (n, 3) bounds in that order:
    a_e = |D_e^T r_e| / L_e decreasing, the largest c from there on, c_e = |D_e|_F^2 / L_e; the
    largest |r_e|^2 / L_e). The local elements are ordered among themselves, then the watched ones."""
    q = operator.shape[1] if operator.ndim == 2 else 1
    elements, edges = np.empty((len(operator) // 6, 1 + q)), np.empty((len(rest_length), 2))
    base = compiled.measure_bounds(
        np.ascontiguousarray(operator, dtype=np.float64),
        q,
        np.ascontiguousarray(response, dtype=np.float64),
        np.ascontiguousarray(rest, dtype=np.float64),
        np.ascontiguousarray(rest_length, dtype=np.float64),
        elements,
        edges,
    )
    order = np.concatenate([_decreasing(elements[:split, 0]), split + _decreasing(elements[split:, 0])])
    edge_order = _decreasing(edges[:, 0])
    along, spread = edges[edge_order].T
    # a nan spread has a nan along (the same rows): it is read first, and the suffix maxima carry it
    beyond = np.maximum.accumulate(spread[::-1])[::-1] if len(spread) else spread
    element_bound = elements[order]
    edge_bound = np.column_stack([along, beyond, spread])
    return order, element_bound, edge_order, edge_bound, base


class LocalStress:
    """The largest von Mises stress (Pa) of the elements near a contact, for any load on its nodes.

    The load is q generalised forces f mapped to nodal forces R = M f on ``nodes`` (M: (3k, q); the
    identity for plain nodal forces, the kernel's weights for a force kernel). In the biphase model
    the stress of the superimposed phases is S_soft G_soft R_total (the stiff phase's S G is the soft
    one's when its K0 is a multiple), so one operator serves both phases: solved once per contact set
    (q right-hand sides), then each FEM step is a (6E x q) product and a maximum.
    """

    __slots__ = (
        "_bounds",
        "_operator",
        "_response",
        "_rest",
        "_rest_length",
        "_split",
        "elements",
        "watched",
    )

    def __init__(
        self,
        tissue: Tissue,
        nodes: ArrayLike,
        force_map: NDArray[np.float64],
        centres: ArrayLike,
        radius: float = LOCAL_STRESS_RADIUS,
        watched: ArrayLike | None = None,
    ) -> None:
        model = _phases(tissue)[0]
        mesh = model.mesh
        ids = np.asarray(nodes, dtype=np.int64).ravel()
        force_map = np.asarray(force_map, dtype=np.float64).reshape(3 * len(ids), -1)
        self.elements = model.elements_near(centres, radius)
        self.watched = np.zeros(0, dtype=np.int64)
        """Elements of ``watched`` (e.g. the wound's edge) within :data:`WOUND_EDGE_RADIUS` of the
        contact, whose stress :meth:`maxima` reports apart from the local elements'."""
        if watched is not None and len(watched):
            near = model.elements_near(centres, WOUND_EDGE_RADIUS)
            self.watched = np.intersect1d(near, np.asarray(watched, dtype=np.int64))
        self._split = len(self.elements)
        elements = np.concatenate([self.elements, self.watched])
        # displacement per unit generalised force, at the local elements' nodes only: rows of the
        # load nodes' cached K0^-1 columns (prefetched in real time), else one q-column solve
        local, tets = np.unique(mesh.tets[elements], return_inverse=True)
        response = model.load_response(ids, force_map, local)
        mu = model.lame[1][elements]
        corners = tets.reshape(-1, 4)
        self._operator = von_mises_rows(model.element_gradients[elements], mu, corners, response)
        # the local elements' edges, for the stretch of the displacement field these loads give
        pairs = (
            corners[: self._split][:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]]
            .reshape(-1, 2, 6)
            .transpose(0, 2, 1)
        )
        edges = (
            np.unique(np.sort(pairs.reshape(-1, 2), axis=1), axis=0) if self._split else np.zeros((0, 2), int)
        )
        self._rest = mesh.points[local[edges[:, 1]]] - mesh.points[local[edges[:, 0]]]
        self._rest_length = np.einsum("ij,ij->i", self._rest, self._rest)  # squared
        per_node = response.reshape(len(local), 3, -1)
        # each edge's change of length vector per unit generalised force: one product a step
        self._response = np.ascontiguousarray(
            (per_node[edges[:, 1]] - per_node[edges[:, 0]]).reshape(3 * len(edges), -1)
        )
        self._bounds = _reading_bounds(
            self._operator, self._split, self._response, self._rest, self._rest_length
        )

    def measures(self, forces: NDArray[np.float64], scale: float = 1.0) -> tuple[float, float, float]:
        """(local, watched, stretch) for the generalised forces (q,): :meth:`maxima` and
        :meth:`stretch` in one compiled pass (what each FEM step reads)."""
        forces = np.ascontiguousarray(forces, dtype=np.float64).reshape(-1)
        return compiled.measures(
            self._operator,
            self._split,
            self._response,
            self._rest,
            self._rest_length,
            forces,
            float(scale),
            *self._bounds,
        )

    def stretch(self, forces: NDArray[np.float64], scale: float = 1.0) -> float:
        """The largest stretch (deformed over rest length) of the local elements' edges in the
        displacement field ``scale`` x (the soft phase's response to the generalised forces (q,)):
        what the display draws around the contact (1.0 with no local elements)."""
        return self.measures(forces, scale)[2]

    def maximum(self, forces: NDArray[np.float64]) -> float:
        """The largest von Mises stress (Pa) of the local elements for the generalised forces (q,)."""
        return self.maxima(forces)[0]

    def maxima(self, forces: NDArray[np.float64]) -> tuple[float, float]:
        """(local, watched): the largest von Mises stress (Pa) of the local elements and of the
        watched ones (nan without any) for the generalised forces (q,)."""
        return self.measures(forces)[:2]
