"""Results of a contact solve, and the fast per-tick handle for a fixed contact set."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class ContactSolution:
    """The tissue's response to driven contact nodes.

    contact_nodes: (k,) driven node ids, in the order of ``intended``.
    intended: (k, 3) intended (driven) displacement a of each contact node (m).
    reaction_forces: (k, 3) R = -C (u - a) per contact node (N): the force the tool
        applies to the tissue there; the force felt at the tool is ``-net_force``.
    displacement_nodes: ids of the nodes whose displacement is given.
    displacement: (len(displacement_nodes), 3) displacement (m); every node when the
        full field was requested, else the condensed surface nodes.
    von_mises, max_stretch: (M,) per-element von Mises stress (Pa) and largest
        principal stretch ratio, when fields were requested.
    element_strain: (M, 3, 3) small-strain tensor per element, when requested.
    volume_change: relative change of the deformed mesh volume, when requested.
    stretch_ratio: the paper's stretch statistic lambda = 1 + |a|max / h (h: tissue
        depth under the first contact node), when requested.
    """

    contact_nodes: NDArray[np.int64]
    intended: NDArray[np.float64]
    reaction_forces: NDArray[np.float64]
    displacement_nodes: NDArray[np.int64]
    displacement: NDArray[np.float64]
    von_mises: NDArray[np.float64] | None = None
    max_stretch: NDArray[np.float64] | None = None
    volume_change: float | None = None
    element_strain: NDArray[np.float64] | None = None
    stretch_ratio: float | None = None

    @property
    def net_force(self) -> NDArray[np.float64]:
        """Sum of the nodal reaction forces (N)."""
        return self.reaction_forces.sum(axis=0)

    def displacement_of(self, nodes: NDArray[np.int64]) -> NDArray[np.float64]:
        """Displacement (m) of given node ids, which must be among ``displacement_nodes``."""
        position = np.searchsorted(self.displacement_nodes, nodes)
        position = np.clip(position, 0, len(self.displacement_nodes) - 1)
        if np.any(self.displacement_nodes[position] != nodes):
            missing = np.asarray(nodes)[self.displacement_nodes[position] != nodes]
            raise KeyError(
                f"node(s) {missing.tolist()} have no displacement in this solution; "
                "solve with full_field=True"
            )
        return self.displacement[position]


class ContactHandle:
    """Everything needed to answer one contact set at haptic rate.

    Built once when a contact set (e.g. a triangle's three nodes) is nominated;
    then each tick is a (3k x 3k) matrix-vector product for the forces and a
    (rows x 3k) product for the condensed surface displacement.
    """

    __slots__ = ("_columns", "_stiffness", "nodes", "penalty", "surface_nodes")

    def __init__(
        self,
        nodes: NDArray[np.int64],
        penalty: float,
        contact_block: NDArray[np.float64],
        columns: NDArray[np.float64],
        surface_nodes: NDArray[np.int64],
    ) -> None:
        self.nodes = nodes
        self.penalty = penalty
        k = len(nodes)
        capacitance = np.eye(3 * k) + penalty * contact_block
        # R = C (I + C G_JJ)^-1 a: the exact effective stiffness seen by the driven dofs.
        self._stiffness = np.ascontiguousarray(penalty * np.linalg.inv(capacitance))
        self._columns = np.ascontiguousarray(columns)
        self.surface_nodes = surface_nodes

    def scaled(self, factor: float) -> ContactHandle:
        """The handle of a tissue whose K0 and penalty are both ``factor`` times this one's: the
        capacitance I + C G_JJ is unchanged, so the effective stiffness scales by ``factor`` and
        the displacement columns by 1 / ``factor`` (exact up to rounding)."""
        handle = object.__new__(ContactHandle)
        handle.nodes, handle.penalty, handle.surface_nodes = (
            self.nodes,
            factor * self.penalty,
            self.surface_nodes,
        )
        handle._stiffness = factor * self._stiffness
        handle._columns = self._columns / factor
        return handle

    @property
    def columns(self) -> NDArray[np.float64]:
        """(3 * rows, 3k) displacement of ``surface_nodes`` (m) per unit reaction force (N) at each
        driven dof."""
        return self._columns

    @property
    def stiffness(self) -> NDArray[np.float64]:
        """(3k, 3k) matrix mapping intended displacements (m) to reaction forces (N)."""
        return self._stiffness

    def reaction_forces(
        self, intended: NDArray[np.float64], tool_displacement: object = None, needle_speed: float = 0.0
    ) -> NDArray[np.float64]:
        """(k, 3) reaction forces R = -C(u - a) for intended displacements a (k, 3), in N. The tool's
        displacement and speed, which a biphase contact reads, do not change one linear phase."""
        return self._stiffness.dot(intended.reshape(-1)).reshape(-1, 3)

    def surface_displacement(self, reaction_forces: NDArray[np.float64]) -> NDArray[np.float64]:
        """(rows, 3) displacement of ``surface_nodes`` (m) under the given reaction forces."""
        return (self._columns @ reaction_forces.reshape(-1)).reshape(-1, 3)


class PrescribedHandle:
    """Nodes held exactly at prescribed displacements (a grasp: the forceps' jaws move the tissue
    they close on). With G = K0^-1 the nodal forces that put nodes J exactly at a are
    f = G_JJ^-1 a (the limit of the penalty contact as C grows), and the displacement anywhere is
    G[:, J] f: the same field as the FEM solve with those dofs prescribed (Dirichlet), since
    K0 u = f with u_J = a is that solve. Built once per grasp; each tick is one Cholesky solve
    of order 3k and one product."""

    __slots__ = ("_columns", "_factor", "nodes", "surface_nodes")

    def __init__(
        self,
        nodes: NDArray[np.int64],
        block: NDArray[np.float64],
        columns: NDArray[np.float64],
        surface_nodes: NDArray[np.int64],
    ) -> None:
        from scipy.linalg import cho_factor

        self.nodes = nodes
        self._factor = cho_factor(np.array(block, dtype=np.float64), lower=True)
        self._columns = np.ascontiguousarray(columns)
        self.surface_nodes = surface_nodes

    def forces(self, prescribed: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, 3) forces (N) the grasp applies to the tissue at its nodes to hold them at the
        prescribed displacements (k, 3) (m)."""
        from scipy.linalg import cho_solve

        return cho_solve(self._factor, np.reshape(prescribed, -1)).reshape(-1, 3)

    @property
    def columns(self) -> NDArray[np.float64]:
        """(3 * rows, 3k) displacement of ``surface_nodes`` (m) per unit force (N) at each held dof."""
        return self._columns

    def forces_of(self, displacements: NDArray[np.float64]) -> NDArray[np.float64]:
        """G_PP^-1 applied to each column of ``displacements`` (3k, q): the holding forces for q
        displacement patterns of the held dofs at once."""
        from scipy.linalg import cho_solve

        return cho_solve(self._factor, displacements)

    def surface_displacement(self, forces: NDArray[np.float64]) -> NDArray[np.float64]:
        """(rows, 3) displacement of ``surface_nodes`` (m) under the grasp's nodal forces."""
        return (self._columns @ np.reshape(forces, -1)).reshape(-1, 3)
