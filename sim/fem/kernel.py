"""The needle's load on the tissue as a force kernel around the tip, with the needle's analytic near field.

A point load on a 3-D continuum has no finite stiffness: driving the three nodes of
the triangle under the tip (the paper's barycentric rule) gives a needle stiffness
proportional to the element size. Here the tip's load is spread over every surface
node within ``radius`` r of the contact point, with weights

    w_i = (1 - (rho_i / r)^2)^2 A_i / sum_j (...)        (biweight x nodal area)

so nodal forces are F_i = w_i F. The kernel's compliance is then the weighted
mean displacement per unit force, C_kernel = W^T G_JJ W (3 x 3; G = K0^-1 at the
kernel's dofs), which converges with mesh refinement once a few elements span r.
What a kernel of radius r cannot see is the needle's own near field: the wire
(radius a) presses like a flat punch, whose half-space compliance is 1 / (2 a E*),
while the half-space compliance of the biweight distribution itself is
beta / (E* r) (beta = 0.7665, from the Hankel transform of the distribution; see
:func:`biweight_halfspace_factor`). The needle's compliance along the contact
normal is therefore

    1 / k = n^T C_kernel n + 1 / (2 a E*) - beta / (E* r)

and its stiffness the inverse of C_kernel plus that correction on n n^T. On a
half-space the FEM kernel term tends to beta / (E* r), so the needle stiffness
tends to the flat punch's 2 a E* (Sneddon 1965); on a thin wall the kernel term
carries the wall's bending. Kernels from the needle's entry and exit through a
wall are coupled through G (one 3m x 3m system for m kernels).

The tissue is linear in each phase, so a kernel set's stiffness is solved once
when the set is made (the k-node block gather and a small inverse) and each tick
is a 3m x 3m product. The nodal forces W F define an equivalent penalty drive
a = G_JJ R + R / C (exactly what driving those nodes by the penalty method would
need to produce the same reactions), so the display, the scene log and the replay,
which replay penalty drives, show the same field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from sim.errors import ModelError
from sim.fem.model import TissueModel


@cache
def biweight_halfspace_factor() -> float:
    """beta in C = beta / (E* r): the weighted-mean normal displacement per unit force of a biweight
    pressure (1 - rho^2/r^2)^2 on an elastic half-space (E* = E / (1 - nu^2)).

    With the normalised Hankel transform H(k) = (24 / pi) J3(kr) / (kr)^3 of the pressure, the mean
    displacement weighted by the same pressure is (4 pi / E*) int_0^inf H(k)^2 dk =
    (2304 / pi) / (E* r) int_0^inf J3(t)^2 t^-6 dt, and that integral is the Weber-Schafheitlin value
    Gamma(6) Gamma(1/2) / (2^6 Gamma(7/2)^2 Gamma(13/2)).
    """
    integral = math.gamma(6) * math.gamma(0.5) / (2**6 * math.gamma(3.5) ** 2 * math.gamma(6.5))
    return 2304.0 / math.pi * integral


def flat_punch_stiffness(wire_radius: float, effective_modulus: float) -> float:
    """Normal stiffness (N/m) of a rigid flat punch of radius a on a half-space: 2 a E*."""
    return 2.0 * wire_radius * effective_modulus


@dataclass(frozen=True)
class ForceKernel:
    """Where one needle crossing loads the tissue: surface nodes, their weights (sum 1), the point
    (m) and outward unit normal it is centred on, and the tissue's E* (Pa) there."""

    nodes: NDArray[np.int64]
    weights: NDArray[np.float64]
    point: NDArray[np.float64]
    normal: NDArray[np.float64]
    effective_modulus: float
    radius: float


def kernel_at(
    tissue: TissueModel,
    point: ArrayLike,
    normal: ArrayLike,
    radius: float,
    fallback: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    element: int | None = None,
) -> ForceKernel:
    """The force kernel of radius ``radius`` (m) centred on a surface ``point`` with outward ``normal``.

    Nodes: free (not clamped) surface nodes within ``radius`` whose vertex normal faces the same way
    (cosine >= 0.5, so the far side of a thin wall or the other face of an edge is not loaded).
    With none there (a mesh coarser than the kernel), ``fallback`` (nodes, weights), typically the
    contact triangle's nodes and barycentric weights, is the kernel. ``element``: the element under
    the contact, whose material gives E* (default: the nearest surface element).
    """
    if not radius > 0:
        raise ModelError(f"kernel radius must be positive (m); got {radius}")
    centre = np.asarray(point, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    geometry = _surface_geometry(tissue)
    # the tree finds the few nodes near the point (a scan of every surface node took about 1 ms on
    # a 119k-node wall); a hair wider, then the exact test, so the chosen nodes are the scan's
    near = np.sort(np.asarray(geometry.tree.query_ball_point(centre, radius * (1.0 + 1e-9)), dtype=np.int64))
    offsets = geometry.points[near] - centre
    distance = np.sqrt(np.einsum("ij,ij->i", offsets, offsets))
    inside = (distance < radius) & (geometry.normals[near] @ n >= 0.5)
    chosen = near[inside]
    ids = geometry.nodes[chosen]
    if ids.size:
        s = distance[inside] / radius
        weights = (1.0 - s * s) ** 2 * geometry.areas[chosen]
    elif fallback is not None:
        ids, weights = (np.asarray(v) for v in fallback)
    else:
        raise ModelError(f"no free surface node within {radius * 1e3:.2f} mm of the contact point")
    weights = np.asarray(weights, dtype=np.float64)
    keep = weights > 0
    ids, weights = ids[keep].astype(np.int64), weights[keep]
    if ids.size == 0:
        raise ModelError("the force kernel has no node with positive weight")
    modulus = _effective_modulus(tissue, centre, element)
    return ForceKernel(ids, weights / weights.sum(), centre, n, modulus, radius)


def near_field_compliance(kernel: ForceKernel, wire_radius: float) -> float:
    """Compliance (m/N) the kernel misses: the flat punch's 1/(2 a E*) less the half-space
    compliance of the kernel's own distribution, beta / (E* r); zero when the wire is not smaller
    than the kernel."""
    if wire_radius >= kernel.radius:
        return 0.0
    extra = 1.0 / (2.0 * wire_radius) - biweight_halfspace_factor() / kernel.radius
    return max(extra, 0.0) / kernel.effective_modulus


def normal_near_field(kernel: ForceKernel, wire_radius: float) -> NDArray[np.float64]:
    """(3, 3) near-field compliance of a needle pressing on the surface: along the normal only."""
    return near_field_compliance(kernel, wire_radius) * np.outer(kernel.normal, kernel.normal)


def lateral_near_field(
    kernel: ForceKernel, wire_radius: float, tangent: NDArray[np.float64], scale: float = 1.0
) -> NDArray[np.float64]:
    """(3, 3) near-field compliance of a wire bearing sideways on the wall it passes through: the
    punch's scalar in the plane across the needle (a chosen calibration, divided by ``scale``)."""
    t = tangent / np.linalg.norm(tangent)
    return near_field_compliance(kernel, wire_radius) / scale * (np.eye(3) - np.outer(t, t))


class KernelContact:
    """Per-tick needle forces for a fixed set of kernels in one linear tissue phase.

    ``stiffness`` maps the kernels' stacked displacements d (3m,) to the forces on the tissue
    F (3m,); ``nodal_forces(F)`` spreads them on the nodes (k, 3) and ``kernel_drive(F)`` gives the
    penalty drive that produces them.
    """

    __slots__ = ("_block_map", "_map", "compliance", "kernels", "nodes", "penalty", "stiffness")

    def __init__(
        self, tissue: TissueModel, kernels: list[ForceKernel], near_field: list[NDArray[np.float64]]
    ) -> None:
        self.kernels = kernels
        self.nodes = np.unique(np.concatenate([k.nodes for k in kernels]))
        position = np.searchsorted(self.nodes, np.concatenate([k.nodes for k in kernels]))
        weights = np.concatenate([k.weights for k in kernels])
        owner = np.repeat(np.arange(len(kernels)), [len(k.nodes) for k in kernels])
        # (k, m) node weight per kernel; the (3k, 3m) map from kernel forces to nodal forces
        per_node = np.zeros((len(self.nodes), len(kernels)))
        np.add.at(per_node, (position, owner), weights)
        self._map = np.kron(per_node, np.eye(3))
        self.penalty = tissue.penalty
        # G_JJ M (3k, 3m): the nodes' displacement per unit kernel force, for the drive each step
        self._block_map = np.ascontiguousarray(tissue.compliance_block(self.nodes) @ self._map)
        compliance = self._map.T @ self._block_map
        for i, extra in enumerate(near_field):
            compliance[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += extra
        self.compliance = np.ascontiguousarray(compliance)
        """(3m, 3m) the kernels' displacements (m) per unit kernel force (N), near field included."""
        self.stiffness = np.ascontiguousarray(np.linalg.inv(compliance))

    @property
    def force_map(self) -> NDArray[np.float64]:
        """(3k, 3m) nodal forces per unit kernel force."""
        return self._map

    def nodal_forces(self, kernel_forces: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, 3) forces on the kernel nodes (N) for the kernels' stacked forces (3m,)."""
        return self._map.dot(kernel_forces).reshape(-1, 3)

    def kernel_drive(self, kernel_forces: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, 3) intended displacements (m) whose penalty response is the nodal forces R = M F of the
        kernels' stacked forces F (3m,): a = G_JJ R + R / C, from R = C (I + C G_JJ)^-1 a, with G_JJ M
        formed once for the kernel set (a (3k x 3m) product a step, not (3k x 3k))."""
        f = np.asarray(kernel_forces, dtype=np.float64).reshape(-1)
        return (self._block_map.dot(f) + self._map.dot(f) / self.penalty).reshape(-1, 3)


@dataclass(frozen=True)
class _SurfaceGeometry:
    nodes: NDArray[np.int64]
    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    areas: NDArray[np.float64]
    tree: cKDTree  # over points


def warm_kernel_geometry(tissue: TissueModel) -> None:
    """Build the free surface nodes' positions, normals and areas now, so a first touch does not
    (about 5 ms on the 10k artery)."""
    _surface_geometry(tissue)


def _surface_geometry(tissue: TissueModel) -> _SurfaceGeometry:
    """Free surface nodes with their positions, unit vertex normals and nodal areas (a third of each
    adjacent exterior triangle's area); cached on the model."""
    cached = tissue.__dict__.get("_kernel_geometry")
    if cached is not None:
        return cached
    mesh = tissue.mesh
    corners = mesh.points[mesh.surface_triangles]
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    nodal = np.zeros(mesh.n_nodes)
    np.add.at(nodal, mesh.surface_triangles.ravel(), np.repeat(areas / 3.0, 3))
    free = np.setdiff1d(mesh.surface_nodes, tissue.clamped_nodes)
    normals = tissue.vertex_normals[free]
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    points = mesh.points[free]
    geometry = _SurfaceGeometry(
        free, points, normals / np.where(lengths > 0, lengths, 1.0), nodal[free], cKDTree(points)
    )
    tissue.__dict__["_kernel_geometry"] = geometry
    return geometry


def _effective_modulus(tissue: TissueModel, point: NDArray[np.float64], element: int | None) -> float:
    """E* = E / (1 - nu^2) = 2 mu / (1 - nu) of the element under the contact (Pa)."""
    if element is None:
        mesh = tissue.mesh
        centres = mesh.points[mesh.surface_triangles].mean(axis=1)
        element = int(mesh.surface_elements[np.argmin(np.linalg.norm(centres - point, axis=1))])
    lam, mu = (float(values[element]) for values in tissue.lame)
    poisson = lam / (2.0 * (lam + mu))
    return 2.0 * mu / (1.0 - poisson)
