"""The display layer's scene: the tissue as the needle deforms it, coloured by von Mises stress."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim.fem import Tissue
from sim.fem.solution import ContactHandle
from sim.render import RenderFrame, TissueRenderer

SOLVE_EVERY = 2
"""With the same loaded nodes, the display solves every this many frames and scales the last field by
the loads in between (a frame's solve is a third of its cost under software rendering)."""


class DisplayScene:
    """Turns graphics snapshots into rendered frames (a ``Simulation`` renderer callback).

    Two ways to the deformation shown, both the soft phase's full-field response:

    - the FEM step's nodal loads (``snapshot.loads``: what a real-time display process gets): one
      right-hand-side solve (7 ms on the interrupted stitch's 6.6k-node patch) when the loaded nodes
      change, or every :data:`SOLVE_EVERY` frames while they stay (the field scaled by the loads in
      between), so a contact whose nodes change every frame (a needle sliding through the wall)
      costs no more than one that stays; above the biphase strain limit the loads are divided by
      the phases' combined stiffness (soft share s: s + (1 - s) E2/E1), so the wall is drawn where
      it is, not where the soft phase alone would put it;
    - the drive (``snapshot.contact``: nodes and intended displacements, in-process runs): a
      whole-field handle kept while the contact set stays the same (``TissueModel.field_contact``),
      exact for a linear model and for the biphase model's displacement.

    ``frames`` counts renders.
    """

    def __init__(self, tissue: Tissue, renderer: TissueRenderer | None) -> None:
        self.model = tissue.base
        # Factorise here, in the parent: CHOLMOD's OpenMP pool does not survive fork, so a
        # forked display process must only solve, never factorise.
        self.model.factorize()
        parameters = getattr(tissue, "parameters", None)
        self._stiffness_ratio = (
            parameters.stiff_modulus / parameters.soft_modulus if parameters is not None else 1.0
        )
        self.renderer = renderer
        self.mesh = self.model.mesh
        self._every_node = np.arange(self.mesh.n_nodes)
        self._rest_stress = np.zeros(len(self.mesh.surface_triangles))
        self._field: ContactHandle | None = None  # the whole-field handle of the contact shown
        self._gradient_map = np.zeros((0, 0))  # its surface elements' gradients per unit reaction
        self._solved: tuple | None = None  # (nodes, loads, displacement, stress) of the last solve
        self._since_solve = 0
        self.frames = 0
        self.last_image: np.ndarray | None = None

    def __call__(self, snapshot) -> None:
        self.last_image = self.renderer.render(self.frame_of(snapshot))
        self.frames += 1

    def frame_of(self, snapshot) -> RenderFrame:
        """What the graphics ``snapshot`` shows: the deformed wall, its surface stress, the needle."""
        loads = getattr(snapshot, "loads", None)
        if loads is not None and len(loads[0]):
            frame = self._under_loads(snapshot.needle_vertices, *loads)
            return dataclasses.replace(frame, forceps=getattr(snapshot, "jaws", None))
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
        jaws = getattr(snapshot, "jaws", None)
        return RenderFrame(points, stress, snapshot.needle_vertices, marker, forceps=jaws)

    def _under_loads(self, needle, nodes, forces, soft_share: float) -> RenderFrame:
        share = soft_share if math.isfinite(soft_share) else 1.0
        loads = forces.reshape(-1) / (share + (1.0 - share) * self._stiffness_ratio)
        last = self._solved
        if last is not None and self._since_solve < SOLVE_EVERY and np.array_equal(last[0], nodes):
            # the same loaded nodes: the field scaled by the loads' projection on the solved ones
            self._since_solve += 1
            scale = float(np.dot(loads, last[1]) / max(np.dot(last[1], last[1]), 1e-30))
            displacement, stress = scale * last[2], abs(scale) * last[3]
        else:
            response = self.model.load_response(nodes, loads.reshape(-1, 1), self._every_node)
            displacement = response.reshape(-1, 3)
            stress = self.model.surface_von_mises(displacement)
            self._solved, self._since_solve = (np.array(nodes), loads, displacement, stress), 1
        points = self.mesh.points + displacement
        return RenderFrame(points, stress, needle, points[nodes].mean(axis=0))


def instruments_now(frame: RenderFrame, snapshot, fem) -> tuple[RenderFrame, float]:
    """``frame`` (the wall as the graphics ``snapshot`` left it: at most a frame old, as in the paper)
    with the instruments where the hands have them now, in the newest FEM step ``fem`` (at most 2 ms
    old) when it is not older than the snapshot and holds the whole needle (the shared slot gives
    only the tip of a needle too long for it); and the time of the device sample they follow (what
    motion to photon is measured from). A frame's render is most of a person's motion to photon, so
    the instruments are not kept a graphics frame behind as well (docs/station.md)."""
    if fem is None or fem.time < snapshot.time or len(fem.needle_vertices) < 2:
        return frame, snapshot.holder_time
    return dataclasses.replace(
        frame, needle=np.asarray(fem.needle_vertices), forceps=fem.jaws
    ), fem.holder_time
