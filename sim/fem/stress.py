"""Stress and strain from a displacement field: per element, and at the exterior surface.

Linear elements have constant gradients, so every quantity here is a product of the elements'
shape-function gradients with the nodal displacements (or with a displacement basis, for the
surface gradient map the live local stress reads). The tissue model calls these with its own mesh,
gradients and Lame parameters.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.fem import _local_stress as compiled
from sim.fem.assembly import displacement_gradients, principal_stretches, small_strain, von_mises_stress
from sim.mesh.tetmesh import TetMesh, signed_volumes

Lame = tuple[NDArray[np.float64], NDArray[np.float64]]


def surface_von_mises_of_gradients(mesh: TetMesh, lame: Lame, gradients: NDArray[np.float64]) -> NDArray:
    """(F,) von Mises stress (Pa) of the elements under the exterior triangles, from their (F, 3, 3)
    displacement gradients."""
    elements = mesh.surface_elements
    lam, mu = lame
    return von_mises_stress(small_strain(gradients), lam[elements], mu[elements])


def surface_von_mises(
    mesh: TetMesh, shape_gradients: NDArray[np.float64], lame: Lame, displacement: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(F,) von Mises stress (Pa) of the element under each exterior triangle, from a full field."""
    elements = mesh.surface_elements
    gradients = displacement_gradients(shape_gradients[elements], mesh.tets[elements], displacement)
    return surface_von_mises_of_gradients(mesh, lame, gradients)


def surface_gradient_map(
    mesh: TetMesh, shape_gradients: NDArray[np.float64], columns: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(F * 9, c) map from weights of the columns of a (3N, c) displacement basis to the
    displacement gradients of the elements under the exterior triangles (row-major (F, 3, 3)):
    gradients are linear in the displacement, so a whole-field handle's gradients for any
    reactions are this map times them (one product instead of a gather and an einsum)."""
    elements = mesh.surface_elements
    basis = columns.reshape(mesh.n_nodes, 3, columns.shape[1])[mesh.tets[elements]]
    gradients = np.einsum("maic,maj->mijc", basis, shape_gradients[elements])
    return np.ascontiguousarray(gradients.reshape(-1, columns.shape[1]))


def element_fields(
    mesh: TetMesh, shape_gradients: NDArray[np.float64], lame: Lame, displacement: NDArray[np.float64]
) -> dict[str, object]:
    """Element strain, von Mises stress (Pa), largest principal stretch, relative volume change."""
    grad_u = displacement_gradients(shape_gradients, mesh.tets, displacement)
    lam, mu = lame
    deformed = signed_volumes(mesh.points + displacement, mesh.tets).sum()
    strain = small_strain(grad_u)
    return {
        "element_strain": strain,
        "von_mises": von_mises_stress(strain, lam, mu),
        "max_stretch": principal_stretches(grad_u)[:, -1],
        "volume_change": float(deformed / mesh.volume - 1.0),
    }


def von_mises_rows(
    shape_gradients: NDArray[np.float64],
    mu: NDArray[np.float64],
    local_tets: NDArray[np.int64],
    response: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(6E, q) rows whose product with q generalised forces f gives, per element, six components
    whose norm is the element's von Mises stress (Pa): sqrt(3/2) (s00, s11, s22, sqrt2 s01,
    sqrt2 s02, sqrt2 s12) of the deviatoric stress s = 2 mu dev(sym grad u) (lambda multiplies the
    trace, which the deviator removes). ``shape_gradients`` (E, 4, 3) and ``mu`` (E,) (Pa) are the
    elements'; ``local_tets`` (E, 4) index the rows of ``response`` (3L, q), the displacement (m)
    of L nodes' dofs per unit generalised force. One compiled pass (:mod:`sim.fem._local_stress`)."""
    q = response.shape[1]
    out = np.empty((6 * len(mu), q))
    compiled.von_mises_rows(
        np.ascontiguousarray(response, dtype=np.float64),
        np.ascontiguousarray(local_tets, dtype=np.int64),
        np.ascontiguousarray(shape_gradients, dtype=np.float64),
        np.ascontiguousarray(mu, dtype=np.float64),
        out,
    )
    return out
