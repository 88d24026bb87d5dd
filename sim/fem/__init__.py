"""Linear tetrahedral FEM with penalty-condensation and the biphase model."""

from sim.fem.biphase import BiphaseContact, BiphaseParameters, BiphaseSolution, BiphaseTissue
from sim.fem.material import STABLE_POISSON_LIMIT, Material, PoissonRatioWarning
from sim.fem.model import Precomputation, TissueModel, fixed_nodes_of
from sim.fem.solution import ContactHandle, ContactSolution
from sim.fem.tissue import Tissue

__all__ = [
    "STABLE_POISSON_LIMIT",
    "BiphaseContact",
    "BiphaseParameters",
    "BiphaseSolution",
    "BiphaseTissue",
    "ContactHandle",
    "ContactSolution",
    "Material",
    "PoissonRatioWarning",
    "Precomputation",
    "Tissue",
    "TissueModel",
    "fixed_nodes_of",
]
