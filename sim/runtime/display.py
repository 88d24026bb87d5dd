"""The display layer's scene: the tissue as the needle deforms it, coloured by von Mises stress."""

from __future__ import annotations

import numpy as np

from sim.fem import Tissue
from sim.fem.solution import ContactHandle
from sim.render import RenderFrame, TissueRenderer


class DisplayScene:
    """Turns graphics snapshots into rendered frames (a ``Simulation`` renderer callback).

    The deformation shown is the soft phase's full-field response to the current
    contact (exact for a linear model; for the biphase model the displacement is
    the same when the phases differ only in stiffness), from a whole-field handle
    kept while the contact set stays the same (``TissueModel.field_contact``).
    ``frames`` counts renders.
    """

    def __init__(self, tissue: Tissue, renderer: TissueRenderer) -> None:
        self.model = tissue.base
        # Factorise here, in the parent: CHOLMOD's OpenMP pool does not survive fork, so a
        # forked display process must only solve, never factorise.
        self.model.factorize()
        self.renderer = renderer
        self.mesh = self.model.mesh
        self._rest_stress = np.zeros(len(self.mesh.surface_triangles))
        self._field: ContactHandle | None = None  # the whole-field handle of the contact shown
        self._gradient_map = np.zeros((0, 0))  # its surface elements' gradients per unit reaction
        self.frames = 0
        self.last_image: np.ndarray | None = None

    def __call__(self, snapshot) -> None:
        points, stress, marker = self.mesh.points, self._rest_stress, None
        if snapshot.contact is not None and len(snapshot.contact[0]):
            nodes, intended = snapshot.contact
            if self._field is None or not np.array_equal(self._field.nodes, nodes):
                self._field = self.model.field_contact(nodes)  # solved once per contact set
                self._gradient_map = self.model.surface_gradient_map(self._field.columns)
            reactions = self._field.reaction_forces(intended).reshape(-1)
            points = self.mesh.points + self._field.surface_displacement(reactions)
            gradients = self._gradient_map.dot(reactions).reshape(-1, 3, 3)
            stress = self.model.surface_von_mises_of_gradients(gradients)  # surface elements only
            marker = points[nodes].mean(axis=0)
        self.last_image = self.renderer.render(RenderFrame(points, stress, snapshot.needle_vertices, marker))
        self.frames += 1
