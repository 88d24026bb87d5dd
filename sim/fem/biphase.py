"""The biphase tissue model of PAPER.md section 6: a J-shaped response from two linear models.

Below the strain limit the soft model (E1, elastin) answers alone. Above it the
input f is split along its own direction f^ = f/|f|: the part up to the limit,
|f*| f^, goes to the soft model, the rest, (|f| - |f*|) f^, to the stiff model
(E2, collagen), and the two solutions are superimposed. At the limit the second
part is zero, so displacement and force are C0-continuous; above it the slope is
the stiff model's.

The strain statistic is the indentation strain |d| / h: the tool's displacement
magnitude over the tissue depth under the contact (PAPER.md's stretch ratio
lambda = 1 + |d| / h). The limit falls with needle speed v (a decisive needle
meets a stiffer wall sooner, cueing depth and letting it pierce):

    limit(v) = limit_0 * (1 - (1 - floor) * min(v / v_crit, 1) ** p)

with defaults limit_0 = 0.2, v_crit = 0.01 m/s, floor = 0.25, p = 2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import ModelError
from sim.fem.assembly import (
    displacement_gradients,
    principal_stretches,
    small_strain,
    stress_tensor,
    von_mises_of_stress,
)
from sim.fem.material import Material
from sim.fem.model import Precomputation, TissueModel
from sim.fem.solution import ContactHandle, ContactSolution
from sim.mesh.tetmesh import TetMesh, signed_volumes


@dataclass(frozen=True)
class BiphaseParameters:
    """Parameters of the biphase model, with the paper's defaults.

    soft_modulus, stiff_modulus: E1 and E2 in pascals (20 kPa, 40 kPa).
    poisson_ratio: shared by both phases (the paper's stable maximum is 0.47).
    strain_limit: indentation strain at which the stiff phase engages (0.2).
    critical_speed: needle speed (m/s) at which the limit reaches its floor.
    limit_floor: the limit at or above the critical speed, as a fraction of strain_limit.
    speed_exponent: shape of the fall of the limit with speed.
    """

    soft_modulus: float = 20e3
    stiff_modulus: float = 40e3
    poisson_ratio: float = 0.45
    strain_limit: float = 0.2
    critical_speed: float = 0.01
    limit_floor: float = 0.25
    speed_exponent: float = 2.0

    def __post_init__(self) -> None:
        if not 0 < self.strain_limit < 1:
            raise ModelError(f"strain_limit must be in (0, 1); got {self.strain_limit}")
        if not self.critical_speed > 0:
            raise ModelError(f"critical_speed must be positive (m/s); got {self.critical_speed}")
        if not 0 < self.limit_floor <= 1:
            raise ModelError(f"limit_floor must be in (0, 1]; got {self.limit_floor}")
        if not self.speed_exponent > 0:
            raise ModelError(f"speed_exponent must be positive; got {self.speed_exponent}")
        if not self.stiff_modulus >= self.soft_modulus:
            raise ModelError(
                f"stiff_modulus ({self.stiff_modulus} Pa) must be at least soft_modulus "
                f"({self.soft_modulus} Pa)"
            )

    def strain_limit_at(self, needle_speed: float) -> float:
        """The strain limit at a needle speed (m/s); equal to ``strain_limit`` at rest."""
        if not np.isfinite(needle_speed) or needle_speed < 0:
            raise ModelError(f"needle_speed must be a non-negative number of m/s; got {needle_speed}")
        ratio = min(needle_speed / self.critical_speed, 1.0) ** self.speed_exponent
        return self.strain_limit * (1.0 - (1.0 - self.limit_floor) * ratio)

    def soft_share(self, strain: float, limit: float) -> float:
        """Fraction of the input the soft phase takes: 1 up to the limit, limit/strain above."""
        return 1.0 if strain <= limit else limit / strain


@dataclass(frozen=True)
class BiphaseSolution:
    """Superimposed response of the two phases (same fields as :class:`ContactSolution`)."""

    soft: ContactSolution
    stiff: ContactSolution | None
    strain: float
    strain_limit: float
    soft_share: float
    reaction_forces: NDArray[np.float64] = field(repr=False)
    displacement: NDArray[np.float64] = field(repr=False)
    von_mises: NDArray[np.float64] | None = field(default=None, repr=False)
    max_stretch: NDArray[np.float64] | None = field(default=None, repr=False)
    volume_change: float | None = None

    @property
    def contact_nodes(self) -> NDArray[np.int64]:
        return self.soft.contact_nodes

    @property
    def displacement_nodes(self) -> NDArray[np.int64]:
        return self.soft.displacement_nodes

    @property
    def net_force(self) -> NDArray[np.float64]:
        return self.reaction_forces.sum(axis=0)

    @property
    def stretch_ratio(self) -> float:
        """lambda = 1 + strain: the paper's stretch statistic."""
        return 1.0 + self.strain

    @property
    def stiff_phase(self) -> bool:
        return self.soft_share < 1.0


class BiphaseTissue:
    """Two linear tissue models (soft E1, stiff E2) combined as PAPER.md section 6."""

    def __init__(
        self, soft: TissueModel, stiff: TissueModel, parameters: BiphaseParameters | None = None
    ) -> None:
        if soft.mesh is not stiff.mesh or not np.array_equal(soft.contact_nodes, stiff.contact_nodes):
            raise ModelError("the soft and stiff models must share one mesh and one set of contact nodes")
        self.soft, self.stiff = soft, stiff
        # with one Poisson ratio the stiff phase's K0 is (E2/E1) times the soft one's: its inverse
        # is the soft inverse scaled, so one factorisation and one set of column solves serve both
        stiff.share_inverse_with(soft)
        self.parameters = parameters or BiphaseParameters()

    @classmethod
    def build(
        cls,
        mesh: TetMesh,
        fixed_nodes: ArrayLike,
        parameters: BiphaseParameters | None = None,
        region_parameters: Mapping[str, BiphaseParameters] | None = None,
        **model_options: object,
    ) -> BiphaseTissue:
        """Both phases on one mesh from the parameters' moduli: uniform, or per mesh region where
        ``region_parameters`` names a region (e.g. ``{"calcified": ...}``). Only the moduli and
        Poisson ratio vary by region; the strain limit and its speed law are ``parameters``'.
        With one E2/E1 and Poisson ratio in every region the two phases still share one
        factorisation."""
        p = parameters or BiphaseParameters()
        by_region = dict(region_parameters or {})
        unknown = sorted(set(by_region) - set(mesh.region_names.values()))
        if unknown:
            raise ModelError(
                f"tissue parameters given for region(s) {', '.join(unknown)}, which the mesh does not "
                f"have (regions: {', '.join(sorted(mesh.region_names.values()))})"
            )

        def phase(modulus: Callable[[BiphaseParameters], float]) -> Material | dict[int, Material]:
            if not by_region:  # one material: the model (and its cache key) as a uniform wall's
                return Material(modulus(p), p.poisson_ratio)
            return {
                rid: Material(modulus(q), q.poisson_ratio)
                for rid, name in mesh.region_names.items()
                for q in [by_region.get(name, p)]
            }

        soft = TissueModel(mesh, phase(lambda q: q.soft_modulus), fixed_nodes, **model_options)
        stiff = TissueModel(mesh, phase(lambda q: q.stiff_modulus), fixed_nodes, **model_options)
        return cls(soft, stiff, p)

    @property
    def mesh(self) -> TetMesh:
        return self.soft.mesh

    # -- the Tissue protocol (sim.fem.tissue) ------------------------------------------------
    @property
    def models(self) -> tuple[TissueModel, ...]:
        """The two linear phases, soft first."""
        return (self.soft, self.stiff)

    @property
    def base(self) -> TissueModel:
        """The soft phase: depths are cast and force kernels built on it."""
        return self.soft

    @property
    def biphase(self) -> BiphaseParameters:
        """The biphase law's parameters (the same as :attr:`parameters`)."""
        return self.parameters

    def precompute(
        self, cache_dir: str | Path | None = None, use_cache: bool = True
    ) -> tuple[Precomputation, Precomputation]:
        """Precompute both phases (the paper's Phi1 and Phi2)."""
        return (self.soft.precompute(cache_dir, use_cache), self.stiff.precompute(cache_dir, use_cache))

    def needs_solve(self, node: int) -> bool:
        """Whether a contact on ``node`` would need columns solved in either phase."""
        return self.soft.needs_solve(node) or self.stiff.needs_solve(node)

    @property
    def spot_solved(self) -> list[int]:
        """Nodes whose columns a contact had to solve when it needed them (either phase)."""
        return self.soft.spot_solved + self.stiff.spot_solved

    @property
    def evicted_columns(self) -> set[int]:
        """Nodes whose cached columns either phase dropped for its memory budget."""
        return self.soft.evicted_columns | self.stiff.evicted_columns

    def warm_contact_caches(self) -> None:
        """See :meth:`TissueModel.warm_contact_caches` (depths are cast in the soft phase)."""
        self.soft.warm_contact_caches()

    def cast_depths(self, nodes: Iterable[int]) -> None:
        """See :meth:`TissueModel.cast_depths` (depths are cast in the soft phase)."""
        self.soft.cast_depths(nodes)

    def depth_under(self, nodes: NDArray[np.int64]) -> float:
        """Mean tissue depth (m) under contact nodes (cast in the soft phase, cached per node)."""
        return float(np.mean([self.soft.tissue_depth(int(n)) for n in nodes]))

    def strain_of(self, tool_displacement: NDArray[np.float64], depth: float) -> float:
        """Indentation strain |d| / h."""
        if not depth > 0:
            raise ModelError(f"tissue depth must be positive (m); got {depth}")
        return float(np.linalg.norm(tool_displacement)) / depth

    def solve(
        self,
        contacts: dict[int, ArrayLike],
        *,
        tool_displacement: ArrayLike | None = None,
        depth: float | None = None,
        needle_speed: float = 0.0,
        full_field: bool = False,
        fields: bool = False,
        method: str = "exact",
    ) -> BiphaseSolution:
        """Biphase response to driven contact nodes.

        tool_displacement: the tool's displacement d (m) whose magnitude defines the
            strain; default the intended nodal displacement of largest magnitude.
        depth: tissue depth h (m) under the contact; default from a ray cast.
        needle_speed: needle tip speed (m/s), which lowers the strain limit.
        """
        nodes = np.asarray(list(contacts), dtype=np.int64)
        intended = np.array([np.asarray(contacts[k], dtype=np.float64) for k in contacts])
        if tool_displacement is None:
            tool_displacement = intended[np.argmax(np.linalg.norm(intended, axis=-1))]
        h = self.depth_under(nodes) if depth is None else depth
        strain = self.strain_of(np.asarray(tool_displacement, dtype=np.float64), h)
        limit = self.parameters.strain_limit_at(needle_speed)
        share = self.parameters.soft_share(strain, limit)
        full = full_field or fields
        soft = self.soft.solve(
            {int(n): share * a for n, a in zip(nodes, intended, strict=True)}, method=method, full_field=full
        )
        stiff = None
        reactions, displacement = soft.reaction_forces, soft.displacement
        if share < 1.0:
            stiff = self.stiff.solve(
                {int(n): (1.0 - share) * a for n, a in zip(nodes, intended, strict=True)},
                method=method,
                full_field=full,
            )
            reactions = reactions + stiff.reaction_forces
            displacement = displacement + stiff.displacement
        extra = self._fields(soft, stiff) if fields else {}
        return BiphaseSolution(soft, stiff, strain, limit, share, reactions, displacement, **extra)

    def _fields(self, soft: ContactSolution, stiff: ContactSolution | None) -> dict[str, object]:
        mesh = self.mesh
        parts = [(self.soft, soft)] + ([(self.stiff, stiff)] if stiff is not None else [])
        stress = 0.0
        total = np.zeros_like(soft.displacement)
        for model, part in parts:
            grad = displacement_gradients(model.element_gradients, mesh.tets, part.displacement)
            lam, mu = model.lame
            stress = stress + stress_tensor(small_strain(grad), lam, mu)
            total += part.displacement
        grad_total = displacement_gradients(self.soft.element_gradients, mesh.tets, total)
        deformed = signed_volumes(mesh.points + total, mesh.tets).sum()
        return {
            "von_mises": von_mises_of_stress(stress),
            "max_stretch": principal_stretches(grad_total)[:, -1],
            "volume_change": float(deformed / mesh.volume - 1.0),
        }

    def contact(self, nodes: ArrayLike) -> BiphaseContact:
        """A per-tick handle for a fixed contact set in both phases."""
        ids = np.asarray(nodes, dtype=np.int64).ravel()
        soft = self.soft.contact(ids)
        shared = self.stiff.inverse_source
        if shared is not None and shared[0] is self.soft:
            stiff = soft.scaled(shared[1])  # K0 and C are s times the soft phase's: no second gather
        else:
            stiff = self.stiff.contact(ids)
        return BiphaseContact(soft, stiff, self.parameters, self.depth_under(ids))


class BiphaseContact:
    """Per-tick biphase forces for one contact set: one small matrix-vector product.

    Both phases' effective stiffnesses are stacked so a tick costs one (6k x 3k)
    product plus a blend; the strain limit law is evaluated in plain floats.
    """

    __slots__ = ("_floor_drop", "_stacked", "_three_k", "depth", "parameters", "soft", "stiff")

    def __init__(
        self, soft: ContactHandle, stiff: ContactHandle, parameters: BiphaseParameters, depth: float
    ) -> None:
        self.soft, self.stiff, self.parameters, self.depth = soft, stiff, parameters, depth
        self._stacked = np.ascontiguousarray(np.vstack([soft.stiffness, stiff.stiffness]))
        self._three_k = soft.stiffness.shape[0]
        self._floor_drop = 1.0 - parameters.limit_floor

    def reaction_forces(
        self, intended: NDArray[np.float64], tool_displacement: NDArray[np.float64], needle_speed: float = 0.0
    ) -> NDArray[np.float64]:
        """(k, 3) reaction forces (N) for intended nodal displacements (k, 3)."""
        p = self.parameters
        dx, dy, dz = tool_displacement.tolist()
        strain = math.sqrt(dx * dx + dy * dy + dz * dz) / self.depth
        ratio = min(needle_speed / p.critical_speed, 1.0) ** p.speed_exponent if needle_speed > 0 else 0.0
        limit = p.strain_limit * (1.0 - self._floor_drop * ratio)
        both = self._stacked.dot(intended.reshape(-1))
        n = self._three_k
        if strain <= limit:
            return both[:n].reshape(-1, 3)
        share = limit / strain
        return (share * both[:n] + (1.0 - share) * both[n:]).reshape(-1, 3)
