"""The needle's load through force kernels in a one- or two-phase tissue, as the FEM layer applies it.

A :class:`KernelLoad` is made when the needle's contact set changes (first touch, pierce, exit):
it holds each phase's kernel stiffness (:class:`sim.fem.kernel.KernelContact`). Per FEM step it
turns the kernels' displacements d (where the needle is against where it met the wall) into the
forces on the tissue. In the biphase model (PAPER.md section 6) the soft phase answers up to the
strain limit and the stiff phase beyond it, split by the soft share of the indentation strain
max |d| / h: F = (share + (1 - share) s) K_soft d when the stiff phase's K0 is s times the soft
one's (one Poisson ratio), otherwise share K_soft d + (1 - share) K_stiff d.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.errors import ModelError
from sim.fem import BiphaseParameters, Tissue, TissueModel
from sim.fem.fields import LocalStress
from sim.fem.kernel import ForceKernel, KernelContact, kernel_at, lateral_near_field, normal_near_field
from sim.needle import _contact_law as compiled
from sim.needle.forces import NeedleForces

KernelFactory = Callable[[TissueModel], tuple[list[ForceKernel], list[NDArray[np.float64]]]]
"""Builds the kernels and their (3, 3) near-field compliances on one phase's model."""


def kernel_factory(
    forces: NeedleForces, wire_radius: float, contacts: list, tangent: NDArray[np.float64] | None = None
) -> KernelFactory:
    """Builds the force kernels of nominated contacts (each with ``point``, ``normal``, ``nodes``,
    ``barycentric`` and ``triangle``: a :class:`sim.collision.mesh.TriangleContact`) on one phase's
    model: a needle pressing on the surface (``tangent`` None: near field along the normal) or
    bearing sideways in the wall it passes through (near field across the needle's ``tangent``)."""

    def make(model: TissueModel) -> tuple[list[ForceKernel], list[NDArray[np.float64]]]:
        elements = model.mesh.surface_elements
        kernels, fields = [], []
        for contact in contacts:
            kernel = kernel_at(
                model,
                contact.point,
                contact.normal,
                forces.kernel_radius,
                fallback=(contact.nodes, contact.barycentric),
                element=int(elements[contact.triangle]),
            )
            if not forces.near_field:
                field = np.zeros((3, 3))
            elif tangent is None:
                field = normal_near_field(kernel, wire_radius)
            else:
                field = lateral_near_field(kernel, wire_radius, tangent, forces.lateral_scale)
            kernels.append(kernel)
            fields.append(field)
        return kernels, fields

    return make


def tissue_poisson_ratio(tissue: Tissue) -> float:
    """The tissue's Poisson ratio (a biphase tissue's shared one, else the largest of its regions')."""
    if tissue.biphase is not None:
        return float(tissue.biphase.poisson_ratio)
    material = tissue.base.material
    values = material.values() if isinstance(material, Mapping) else [material]
    return max(float(m.poisson_ratio) for m in values)


def mindlin_ratio(poisson_ratio: float) -> float:
    """Tangential over normal stiffness of a rigid flat circular punch bonded to an elastic half-space,
    2 (1 - nu) / (2 - nu) (Mindlin 1949, J Appl Mech 16:259; Johnson, Contact Mechanics, 1985, 7.2):
    0.71 at nu = 0.45. Both stiffnesses scale with the same modulus and radius, so the ratio carries
    the normal stiffness's convergence with mesh and kernel radius over to the tangential one."""
    return 2.0 * (1.0 - poisson_ratio) / (2.0 - poisson_ratio)


@dataclass(frozen=True)
class KernelStep:
    """One FEM step of the needle's load through its kernels (:func:`kernel_step`).

    kernel_forces: (m, 3) forces on the tissue (N) at the kernels, elastic plus explicit;
    share: the biphase soft share; indentation: the kernels' largest total displacement (m), what the
    next step compares with to know whether the wall is loading; shifts: (m, 3) how far (m) each
    kernel's hold on the needle moved (slid, or the wall gave way); torn: kernels that gave way.
    """

    kernel_forces: NDArray[np.float64]
    share: float
    indentation: float
    shifts: NDArray[np.float64]
    torn: tuple[int, ...]


def kernel_step(
    load: KernelLoad,
    displacements: NDArray[np.float64],
    extra_forces: NDArray[np.float64],
    speed: float,
    indentation: float,
    forces: NeedleForces,
    surface: NDArray[np.float64] | None = None,
    ratio: float = 1.0,
) -> KernelStep:
    """The contact law of one FEM step, the one place it is written (the runtime and the post-hoc
    derivation of recorded sessions both call it).

    displacements: (m, 3) where the needle is against where each kernel holds it (m); extra_forces:
    (m, 3) explicit forces on the tissue there (the passage's, N); speed: the tip's (m/s);
    indentation: the previous step's :attr:`KernelStep.indentation`.

    - ``surface`` ((m, 3) outward normals of a needle pressing on the surface at each kernel): each
      kernel's normal stiffness k_n, the tangential one ``ratio`` k_n (Mindlin) with the Coulomb
      limit (beyond it the hold slides after the needle and the wall carries the bound);
    - the tip's speed stiffens the wall only while it is loading (the kernels' displacement not
      shrinking): unloading follows the rest curve, so no cycle returns more work than it took;
    - a kernel whose elastic force would exceed ``forces.tear_force`` gives way: its hold follows the
      needle and it carries that force, no more.

    One compiled pass (:mod:`sim.needle._contact_law`; its NumPy reference, which it must equal, is
    in tests/sim/test_contact_law.py).
    """
    d = np.ascontiguousarray(displacements, dtype=np.float64).reshape(-1, 3)
    m = len(d)
    kernel_forces, shifts, torn = np.empty((m, 3)), np.empty((m, 3)), np.empty(m, dtype=np.int64)
    try:
        share, now, count = compiled.step(
            d,
            np.ascontiguousarray(extra_forces, dtype=np.float64),
            load.soft.compliance,
            load.soft.stiffness,
            _NONE if load._stiff is None else load._stiff.stiffness,
            load._stiff_scale,
            _NONE if surface is None else np.ascontiguousarray(surface, dtype=np.float64),
            ratio,
            forces.friction_coefficient,
            float(speed),
            float(indentation),
            load.depth,
            *biphase_limits(load.parameters),
            math.nan if forces.tear_force is None else forces.tear_force,
            kernel_forces,
            shifts,
            torn,
        )
    except ValueError as error:  # a speed that is not a number, or arrays that do not fit
        raise ModelError(str(error)) from None
    return KernelStep(kernel_forces, share, now, shifts, tuple(torn[:count].tolist()))


def biphase_limits(parameters: BiphaseParameters | None) -> tuple[float, float, float, float]:
    """(strain limit, critical speed, speed exponent, limit floor) as the compiled law reads them; a
    strain limit of nan for a one-phase tissue (its soft share is always 1)."""
    if parameters is None:
        return (math.nan, 1.0, 1.0, 1.0)
    p = parameters
    return (p.strain_limit, p.critical_speed, p.speed_exponent, p.limit_floor)


_NONE = np.zeros(0)
"""An empty array: no stiff phase of its own, or no surface normals (the needle is in the wall)."""


class KernelLoad:
    """Forces of a fixed set of force kernels on a :class:`TissueModel` or :class:`BiphaseTissue`."""

    __slots__ = ("_stiff", "_stiff_scale", "depth", "kernels", "nodes", "parameters", "soft")

    def __init__(self, tissue: Tissue, make_kernels: KernelFactory) -> None:
        biphase = tissue.biphase is not None
        soft_model = tissue.base
        kernels, near_field = make_kernels(soft_model)
        self.kernels = kernels
        self.soft = KernelContact(soft_model, kernels, near_field)
        self.nodes = self.soft.nodes
        self.parameters = tissue.biphase
        self._stiff: KernelContact | None = None
        self._stiff_scale = 1.0
        self.depth = math.inf
        if biphase:
            shared = tissue.stiff.inverse_source
            if shared is not None and shared[0] is tissue.soft:
                self._stiff_scale = shared[1]
            else:
                self._stiff = KernelContact(tissue.stiff, *make_kernels(tissue.stiff))
            self.depth = tissue.depth_under(self.nodes)

    def soft_share(self, displacements: NDArray[np.float64], speed: float) -> float:
        """The soft phase's share (1 in a one-phase tissue) at the kernels' total displacements (m, 3)
        (m): a wall stretched by friction meets its stiff phase as an indented one does."""
        p = self.parameters
        if p is None:
            return 1.0
        strain = float(np.sqrt(np.einsum("ij,ij->i", displacements, displacements).max())) / self.depth
        return p.soft_share(strain, p.strain_limit_at(max(speed, 0.0)))

    def elastic_forces(self, displacements: NDArray[np.float64], share: float) -> NDArray[np.float64]:
        """(m, 3) elastic forces on the tissue (N) at each kernel for displacements (m, 3) (m)."""
        d = displacements.reshape(-1)
        soft = self.soft.stiffness.dot(d)
        if share == 1.0:
            return soft.reshape(-1, 3)
        if self._stiff is None:
            return ((share + (1.0 - share) * self._stiff_scale) * soft).reshape(-1, 3)
        return (share * soft + (1.0 - share) * self._stiff.stiffness.dot(d)).reshape(-1, 3)

    def drive_scale(self, share: float) -> float:
        """share + (1 - share) s: the factor by which the two phases' penalty answer to one drive
        exceeds the soft phase's (what :meth:`kernel_drive` divides by)."""
        return share + (1.0 - share) * self._stiff_scale

    def local_stress(self, tissue: Tissue) -> LocalStress:
        """The local-stress operator of these kernels (within 1 mm of their points), per kernel force,
        watching the wound's edge elements near them too."""
        points = [k.point for k in self.kernels]
        return LocalStress(
            tissue, self.nodes, self.soft.force_map, points, watched=tissue.mesh.wound_edge_elements
        )

    def nodal_forces(self, kernel_forces: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, 3) forces (N) on :attr:`nodes` for the kernels' forces (m, 3)."""
        return self.soft.nodal_forces(kernel_forces.reshape(-1))

    def drive(self, kernel_forces: NDArray[np.float64], share: float) -> KernelDrive:
        """(nodes, :meth:`kernel_drive`) of this step's kernel forces, the drive worked out only when
        read (by the graphics layer, 30 times a second, not by each FEM step)."""
        return KernelDrive(self, kernel_forces, share)

    def kernel_drive(self, kernel_forces: NDArray[np.float64], share: float) -> NDArray[np.float64]:
        """(k, 3) penalty drive (m) of :attr:`nodes` that the tissue answers with the
        :meth:`nodal_forces` of ``kernel_forces`` (m, 3) when split between the phases by ``share``
        (what the display and the replay drive)."""
        return self.soft.kernel_drive(kernel_forces) / self.drive_scale(share)


class KernelDrive(Sequence):
    """(kernel nodes, their penalty drive (k, 3) m) of one FEM step's kernel forces, read as the pair
    it is (``nodes, intended = drive``); the drive is worked out on first reading. It keeps its own
    copy of the forces, so it can be handed to another thread as it is."""

    __slots__ = ("_forces", "_intended", "_load", "_share", "nodes")

    def __init__(self, load: KernelLoad, kernel_forces: NDArray[np.float64], share: float) -> None:
        self.nodes = load.nodes
        self._load, self._forces, self._share = load, np.array(kernel_forces, dtype=np.float64), share
        self._intended: NDArray[np.float64] | None = None

    @property
    def intended(self) -> NDArray[np.float64]:
        if self._intended is None:
            self._intended = self._load.kernel_drive(self._forces, self._share)
        return self._intended

    def __len__(self) -> int:
        return 2

    def __getitem__(self, index: int | slice):  # the pair's items, as a tuple's
        return (self.nodes, self.intended)[index]
