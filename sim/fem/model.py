"""The tissue model: linear tetrahedral FEM with penalty-condensation (PAPER.md 3-4).

Fixed nodes are held by penalty springs C on their dofs, giving the SPD matrix
K0 = K + C sum_fixed e e^T. A contact set J (nodes driven to intended
displacements a) adds C at its dofs; with G = K0^-1 the exact response is

    R = C (I + C G_JJ)^-1 a        (reaction forces, R = -C (u_J - a))
    u = G[:, J] R                  (displacement anywhere)

so only columns of K0^-1 at contact dofs are ever needed. ``precompute()`` gets
the block of K0^-1 over every contact-candidate dof at once (condensation);
without it, columns are solved when a node first becomes a contact and kept in
a memory-bounded cache (on-demand mode).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from sim.errors import ModelError
from sim.fem import checks, stress
from sim.fem.assembly import (
    SparsityPattern,
    element_stiffness,
    shape_gradients,
)
from sim.fem.checks import fixed_nodes_of
from sim.fem.inverse import cache
from sim.fem.inverse.columns import ColumnCache
from sim.fem.inverse.condensation import node_dofs, sparse_cholesky, superposed_reactions
from sim.fem.inverse.precomputation import Precomputation, condensed, woodbury_composite
from sim.fem.inverse.reads import ColumnReads
from sim.fem.inverse.sharing import stiffness_scale
from sim.fem.material import Material, MaterialSpec, describe_materials, element_lame
from sim.fem.solution import ContactHandle, ContactSolution, PrescribedHandle
from sim.fem.surface import SurfaceGeometry
from sim.mesh.tetmesh import TetMesh

# Penalty constant C = factor x the largest diagonal entry of K. The constraint
# error of a penalty spring is about (local stiffness / C), i.e. ~1e-5 relative.
DEFAULT_PENALTY_FACTOR = 1e5
# Memory budget of the on-demand column cache.
DEFAULT_COLUMN_CACHE_BYTES = 1024 * 2**20


class TissueModel(ColumnReads):
    """Linear tetrahedral tissue with penalty-condensation.

    mesh: the tetrahedral mesh (metres).
    material: one :class:`Material`, or a map of region id or name -> Material.
    fixed_nodes: node ids held in place (all three dofs) by penalty springs.
    penalty: the penalty constant C (N/m) for fixed and contact dofs; default
        ``penalty_factor`` x the largest diagonal entry of the stiffness.
    fixed_dofs: extra individual dofs held (node-major ids, 3*node + axis), e.g. rollers.
    contact_nodes: contact candidates, also the rows of the condensed surface
        displacement; default every exterior node that is not fixed.
    """

    def __init__(
        self,
        mesh: TetMesh,
        material: MaterialSpec,
        fixed_nodes: ArrayLike = (),
        penalty: float | None = None,
        *,
        fixed_dofs: ArrayLike = (),
        contact_nodes: ArrayLike | None = None,
        penalty_factor: float = DEFAULT_PENALTY_FACTOR,
        column_cache_bytes: int = DEFAULT_COLUMN_CACHE_BYTES,
    ) -> None:
        self.mesh = mesh
        self.material = material
        self._lame = element_lame(mesh.regions, mesh.region_names, material)
        nodes = checks.node_ids(fixed_nodes, mesh.n_nodes, "fixed_nodes")
        extra = checks.ids(fixed_dofs, 3 * mesh.n_nodes, "fixed_dofs")
        self.fixed_dofs = np.union1d(node_dofs(nodes), extra)
        if self.fixed_dofs.size == 0:
            raise ModelError(
                "no fixed nodes or dofs: the tissue would float freely; fix at least "
                "the nodes the vessel is held by (e.g. mesh.node_sets['z0'])"
            )
        checks.check_rigid_motion_fixed(mesh.points, self.fixed_dofs)
        self.clamped_nodes = np.flatnonzero(np.bincount(self.fixed_dofs // 3, minlength=mesh.n_nodes) == 3)
        """Nodes held on all three axes."""
        if contact_nodes is None:
            candidates = np.setdiff1d(mesh.surface_nodes, self.clamped_nodes)
        else:
            candidates = checks.node_ids(contact_nodes, mesh.n_nodes, "contact_nodes")
        if candidates.size == 0:
            raise ModelError("the model has no contact-candidate nodes (every surface node is fixed)")
        self.contact_nodes = candidates
        self._candidate_row = np.full(mesh.n_nodes, -1, dtype=np.int64)
        self._candidate_row[candidates] = np.arange(len(candidates))
        self._penalty_factor = penalty_factor
        self._requested_penalty = penalty
        self._precomputed: Precomputation | None = None
        # solve_columns looked up at each solve, not bound now (a test or a worker may replace it)
        self._column_cache = ColumnCache(
            lambda nodes: self.solve_columns(nodes), node_dofs(candidates), column_cache_bytes
        )
        self._inverse_of: tuple[TissueModel, float] | None = None  # (base, s): K0 = s K0_base
        self.surface = SurfaceGeometry(mesh)
        """The surface's normals, element lookup and the tissue depth under each surface node."""

    # -- assembly --------------------------------------------------------------
    @cached_property
    def element_gradients(self) -> NDArray[np.float64]:
        """(E, 4, 3): the gradient of each element's four linear shape functions (constant per element)."""
        return shape_gradients(self.mesh.points, self.mesh.tets)

    @cached_property
    def _pattern(self) -> SparsityPattern:
        return SparsityPattern(self.mesh.tets, self.mesh.n_nodes)

    @cached_property
    def _stiffness(self) -> sp.csr_matrix:
        lam, mu = self._lame
        elements = element_stiffness(self.element_gradients, self.mesh.element_volumes, lam, mu)
        return self._pattern.assemble(elements)

    def stiffness_matrix(self) -> sp.csr_matrix:
        """Assembled global stiffness K (N/m) before any penalty; node-major dofs."""
        return self._stiffness.copy()

    @cached_property
    def penalty(self) -> float:
        """The penalty constant C (N/m) on fixed and contact dofs."""
        if self._inverse_of is not None and self._requested_penalty is None:
            base, scale = self._inverse_of
            return scale * base.penalty  # = penalty_factor x the largest diagonal entry of s K_base
        if self._requested_penalty is not None:
            if not (np.isfinite(self._requested_penalty) and self._requested_penalty > 0):
                raise ModelError(f"penalty must be a positive number of N/m; got {self._requested_penalty}")
            return float(self._requested_penalty)
        return float(self._penalty_factor * self._stiffness.diagonal().max())

    def penalised_stiffness(self) -> sp.csc_matrix:
        """K0 = K + C on the fixed dofs (N/m), SPD when rigid motion is prevented."""
        springs = np.zeros(self._stiffness.shape[0])
        springs[self.fixed_dofs] = self.penalty
        return (self._stiffness + sp.diags(springs)).tocsc()

    @cached_property
    def _factor(self):
        if self._inverse_of is not None:
            base, scale = self._inverse_of
            return lambda rhs: base._factor(rhs) / scale
        return sparse_cholesky(self.penalised_stiffness())

    def factorize(self) -> None:
        """Factorise K0 now (on-demand mode does it lazily on the first contact otherwise)."""
        self._factor  # noqa: B018 - the cached property does the work
        if self._inverse_of is not None:
            self._inverse_of[0].factorize()

    def share_inverse_with(self, base: TissueModel) -> float | None:
        """Take K0^-1 from ``base`` when this model's K0 is a positive multiple s of base's.

        That holds when both share the mesh, the fixed dofs, the contact candidates and the
        penalty rule, and every element's Lame parameters are base's times one common s (e.g.
        the biphase model's two phases: the same Poisson ratio, E2 = s E1). Then K0^-1 =
        K0_base^-1 / s exactly, so this model neither factorises nor solves columns of its own:
        it divides base's. Returns s, or None (nothing shared) when the models are not so related.
        """
        scale = stiffness_scale(self, base)
        if scale is None or "_factor" in self.__dict__ or "penalty" in self.__dict__:
            return None
        self._inverse_of = (base, scale)
        return scale

    @property
    def inverse_source(self) -> tuple[TissueModel, float] | None:
        """(base, s) when this model takes K0^-1 as base's divided by s (:meth:`share_inverse_with`)."""
        return self._inverse_of

    def needs_solve(self, node: int, full: bool = False) -> bool:
        """Whether a contact on ``node`` would need its columns solved (not precomputed, not cached).
        ``full``: whether its whole (3N) columns would (what the local-stress operator reads: the
        precomputed matrix holds only the candidates' rows)."""
        if self._inverse_of is not None:
            return self._inverse_of[0].needs_solve(node, full)
        precomputed = not full and self._precomputed is not None and self._candidate_row[node] >= 0
        return not precomputed and node not in self._column_cache

    def surface_von_mises(self, displacement: NDArray[np.float64]) -> NDArray[np.float64]:
        """See :func:`sim.fem.stress.surface_von_mises`."""
        return stress.surface_von_mises(self.mesh, self.element_gradients, self._lame, displacement)

    def surface_von_mises_of_gradients(self, gradients: NDArray[np.float64]) -> NDArray[np.float64]:
        """See :func:`sim.fem.stress.surface_von_mises_of_gradients`."""
        return stress.surface_von_mises_of_gradients(self.mesh, self._lame, gradients)

    def surface_gradient_map(self, columns: NDArray[np.float64]) -> NDArray[np.float64]:
        """See :func:`sim.fem.stress.surface_gradient_map`."""
        return stress.surface_gradient_map(self.mesh, self.element_gradients, columns)

    # -- precomputation ----------------------------------------------------------
    def cache_key(self) -> str:
        """Identifies the precomputation: mesh, materials, fixed dofs, candidates, penalty."""
        return cache.cache_key(
            self.mesh.content_hash,
            describe_materials(self.material),
            checks.array_hash(self.fixed_dofs),
            checks.array_hash(self.contact_nodes),
            repr(self.penalty),
        )

    def precompute(self, cache_dir: str | Path | None = None, use_cache: bool = True) -> Precomputation:
        """Condensed inverse over all contact candidates (the paper's composite matrix, exactly).

        With ``use_cache`` the result is read from / written to ``cache_dir``
        (default :func:`sim.fem.inverse.cache.default_cache_dir`), verified by checksum.
        """
        if self._inverse_of is not None:
            base, scale = self._inverse_of
            start = time.perf_counter()
            source = base._precomputed or base.precompute(cache_dir, use_cache)
            self._precomputed = Precomputation(
                self.contact_nodes,
                source.matrix / scale,
                {"derived": time.perf_counter() - start},
                source.from_cache,
            )
            return self._precomputed
        directory = Path(cache_dir) if cache_dir is not None else cache.default_cache_dir()
        self._precomputed = condensed(
            self.penalised_stiffness, self.contact_nodes, self.cache_key(), directory if use_cache else None
        )
        return self._precomputed

    @property
    def precomputation(self) -> Precomputation | None:
        """The precomputed condensed inverse, or ``None`` in on-demand mode."""
        return self._precomputed

    def composite_matrix(self) -> NDArray[np.float64]:
        """The paper's composite matrix Phi (3n x 3n over the contact candidates).

        Column block j is (K0 + C E_j E_j^T)^-1 E_j restricted to candidate rows,
        derived from the condensed inverse by the exact 3x3 Woodbury update
        Phi_j = G_:j (I + C G_jj)^-1.
        """
        return woodbury_composite(self._require_precomputed().matrix, self.penalty)

    def _require_precomputed(self) -> Precomputation:
        if self._precomputed is None:
            raise ModelError("the model is not precomputed; call precompute() first")
        return self._precomputed

    # -- solving -------------------------------------------------------------------------
    @property
    def lame(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per-element Lame parameters (lambda, mu) in Pa."""
        return self._lame

    @property
    def vertex_normals(self) -> NDArray[np.float64]:
        """(N, 3) area-weighted outward normals at the nodes (zero off the exterior surface)."""
        return self.surface.vertex_normals

    def compliance_block(self, nodes: ArrayLike) -> NDArray[np.float64]:
        """(3k, 3k) block of K0^-1 (m/N) at the nodes' dofs: displacement per unit nodal force
        (precomputed where the nodes are candidates, solved on demand and cached otherwise)."""
        ids = checks.contact_ids(nodes, self.mesh.n_nodes)
        return self._contact_columns(ids)[1]

    def contact(self, nodes: ArrayLike) -> ContactHandle:
        """A per-tick handle for a fixed contact set (e.g. a triangle's 3 nodes)."""
        ids = checks.contact_ids(nodes, self.mesh.n_nodes)
        columns, block, rows = self._contact_columns(ids)
        return ContactHandle(ids, self.penalty, block, columns, rows)

    def prescribed(self, nodes: ArrayLike, at_nodes: ArrayLike | None = None) -> PrescribedHandle:
        """A per-tick handle for nodes held exactly where they are put (a grasp), answering the
        displacement of ``at_nodes`` (default: the contact candidates) (:class:`PrescribedHandle`)."""
        ids = checks.contact_ids(nodes, self.mesh.n_nodes)
        if at_nodes is None:
            columns, block, rows = self._contact_columns(ids)
            return PrescribedHandle(ids, block, columns, rows)
        rows = checks.node_ids(at_nodes, self.mesh.n_nodes, "at_nodes")
        block = self._nodes_columns(ids, node_dofs(ids))
        # the held nodes' own rows when asked for them alone: the block (no second gather)
        same = rows.size == ids.size and np.array_equal(rows, ids)
        columns = block if same else self._nodes_columns(ids, node_dofs(rows))
        return PrescribedHandle(ids, block, columns, rows)

    def field_contact(self, nodes: ArrayLike) -> ContactHandle:
        """A handle for a fixed contact set whose displacement answer is the whole field: every
        node, in mesh order. Its K0^-1 columns are solved once (one multi-right-hand-side solve
        with this model's own factor); each use is then two small products, where
        ``solve(..., full_field=True)`` costs a sparse solve every time (17 ms on the 10k
        artery). For the display layer, which shows one contact set for many frames."""
        ids = checks.contact_ids(nodes, self.mesh.n_nodes)
        columns = self.solve_columns(ids)
        every_node = np.arange(self.mesh.n_nodes)
        return ContactHandle(ids, self.penalty, columns[node_dofs(ids)], columns, every_node)

    def solve(
        self,
        contacts: Mapping[int, ArrayLike],
        *,
        method: str = "exact",
        full_field: bool = False,
        fields: bool = False,
        prescribed: Mapping[int, ArrayLike] | None = None,
    ) -> ContactSolution:
        """Respond to contact nodes driven to intended displacements.

        contacts: node id -> intended displacement (3,) in metres.
        method: ``"exact"`` solves the multi-point penalty contact through the
            small capacitance system; ``"superposition"`` adds the single-node
            solutions as the paper did: each reaction from its own node's solution,
            displacements summed (ignores how neighbouring contacts interact).
        full_field: displacement of every node (one sparse solve).
        fields: also element von Mises stress, principal stretch and volume change.
        prescribed: node id -> displacement (3,) in metres at which the node is held exactly (a
            grasp), solved jointly with ``contacts`` (which may then be empty): with N the penalty
            contacts and P the held nodes, [[I + C G_NN, C G_NP], [G_PN, G_PP]] [f_N; f_P] =
            [C a_N; a_P]. The solution lists the contacts first, then the held nodes.
        """
        if method not in ("exact", "superposition"):
            raise ModelError(f"method must be 'exact' or 'superposition'; got {method!r}")
        if prescribed:
            if method != "exact":
                raise ModelError("held (prescribed) nodes are solved exactly; use method='exact'")
            held, held_at = checks.parse_contacts(prescribed, self.mesh.n_nodes)
            if contacts:
                pressed, pressed_at = checks.parse_contacts(contacts, self.mesh.n_nodes)
            else:
                pressed, pressed_at = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
            nodes = checks.contact_ids(np.concatenate([pressed, held]), self.mesh.n_nodes)
            intended = np.concatenate([pressed_at, held_at])
        else:
            nodes, intended = checks.parse_contacts(contacts, self.mesh.n_nodes)
        columns, block, rows = self._contact_columns(nodes)
        a = intended.reshape(-1)
        c = self.penalty
        if prescribed:
            n = 3 * len(pressed)  # rows of the penalty contacts; the held nodes' rows follow
            system = block.copy()
            system[:n] *= c
            system[:n, :n] += np.eye(n)
            rhs = a.copy()
            rhs[:n] *= c
            reactions = np.linalg.solve(system, rhs)
        elif method == "exact":
            reactions = c * np.linalg.solve(np.eye(len(a)) + c * block, a)
        else:
            reactions = superposed_reactions(block, a, c)
        full_field = full_field or fields
        if full_field:
            rhs = np.zeros(3 * self.mesh.n_nodes)
            rhs[node_dofs(nodes)] = reactions
            displacement = self._factor(rhs).reshape(-1, 3)
            shown = np.arange(self.mesh.n_nodes)
        else:
            displacement = (columns @ reactions).reshape(-1, 3)
            shown = rows
        extra = self.element_fields(displacement) if fields else {}
        if fields:
            largest = float(np.linalg.norm(intended, axis=1).max())
            extra["stretch_ratio"] = 1.0 + largest / self.tissue_depth(int(nodes[0]))
        return ContactSolution(nodes, intended, reactions.reshape(-1, 3), shown, displacement, **extra)

    def element_fields(self, displacement: NDArray[np.float64]) -> dict[str, object]:
        """See :func:`sim.fem.stress.element_fields`."""
        return stress.element_fields(self.mesh, self.element_gradients, self._lame, displacement)

    # -- surface geometry and depth (sim.fem.surface), through the facade ---------------
    def warm_contact_caches(self) -> None:
        """Build the surface geometry a first contact needs (normals, bounding spheres for the
        tissue-depth cast), so the first contact of a run does not pay for it (a few ms at 10k nodes)."""
        self.surface.warm()

    def elements_near(self, points: ArrayLike, radius: float) -> NDArray[np.int64]:
        """See :meth:`sim.fem.surface.SurfaceGeometry.elements_near`."""
        return self.surface.elements_near(points, radius)

    def tissue_depth(self, node: int) -> float:
        """Thickness of tissue (m) under a surface node, along its inward normal; cached per node
        (the column prefetcher casts ahead of contact, so a contact change rarely pays for it)."""
        return self.surface.tissue_depth(node)

    def depth_under(self, nodes: NDArray[np.int64]) -> float:
        """Mean tissue depth (m) under contact nodes (:meth:`tissue_depth`, cached per node)."""
        return self.surface.depth_under(nodes)

    def knows_depth(self, node: int) -> bool:
        """Whether :meth:`tissue_depth` of ``node`` is cached."""
        return self.surface.knows_depth(node)

    def cast_depths(self, nodes: Iterable[int]) -> None:
        """See :meth:`sim.fem.surface.SurfaceGeometry.cast_depths`."""
        self.surface.cast_depths(nodes)

    # -- the Tissue protocol (sim.fem.tissue): one phase -----------------------------------
    @property
    def models(self) -> tuple[TissueModel, ...]:
        """The linear models this tissue superimposes: this one."""
        return (self,)

    @property
    def base(self) -> TissueModel:
        """The model depths are cast and force kernels built on: this one."""
        return self

    @property
    def biphase(self) -> None:
        """The biphase law's parameters: none for one linear phase."""
        return None


__all__ = ["Material", "Precomputation", "TissueModel", "fixed_nodes_of"]
