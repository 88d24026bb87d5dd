"""Calibrated tissue presets: the biphase wall and the needle's puncture and passage forces, with sources.

Each value says where it comes from (docs/tissue-model.md has the full table): a published
measurement, or "chosen" with the published force it was chosen to reproduce. The linear
phases are a phenomenological force law; the stress they give near the needle is not a
physical stress (a linear model cannot be valid at a needle's tip).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sim.errors import ModelError
from sim.fem.biphase import BiphaseParameters
from sim.needle_forces import NeedleForces


@dataclass(frozen=True)
class TissuePreset:
    """A named tissue: its biphase parameters, the needle forces in it, and the source of each value."""

    name: str
    description: str
    biphase: BiphaseParameters
    forces: NeedleForces
    sources: dict[str, str] = field(default_factory=dict)


_PAPER = TissuePreset(
    "paper",
    "The source paper's soft tissue (E1 = 20 kPa, E2 = 40 kPa) and needle (barycentric rule, 100 kPa "
    "tip stress): for reproducing its Table 1 and figures, not for assessment.",
    BiphaseParameters(),
    NeedleForces.paper(),
    {
        "soft_modulus, stiff_modulus, strain_limit": "PAPER.md section 6 (20 kPa, 40 kPa, 0.2)",
        "load, puncture": "PAPER.md: three-node barycentric drive; puncture stress chosen to pierce at "
        "about 0.65 mm on a 1.5 mm patch",
    },
)

_ARTERY = TissuePreset(
    "porcine-artery",
    "Porcine arterial wall as used on bench courses: elastin phase 300 kPa, collagen phase 4.5 MPa "
    "beyond 15 % indentation strain; puncture 0.8 N, emergence 0.4 N, cutting 0.2 N, friction "
    "0.03 N/mm.",
    BiphaseParameters(soft_modulus=300e3, stiff_modulus=6e6, poisson_ratio=0.45, strain_limit=0.12),
    NeedleForces(damage_stress=8e5, edge_damage_stress=6e5),
    {
        "soft_modulus": "chosen: the low-strain (elastin) modulus of arterial wall is of the order of "
        "100-500 kPa in uniaxial tests; 300 kPa with the stiff phase puts 0.8 N at about 1 mm depth",
        "stiff_modulus": "within the porcine aortic moduli at 1 MPa stress, 1.3 MPa radial to 7.8 MPa "
        "circumferential (review table, PMC6948849 Table 3)",
        "strain_limit": "chosen with the moduli so the puncture force is reached at 0.7-1.1 mm",
        "poisson_ratio": "0.45: nearly incompressible wall within the paper's stable range (<= 0.47)",
        "puncture_force": "chosen in the 0.3-1.5 N band of suture-needle puncture: taper needles "
        "puncture cartilage at 0.61-0.90 N (Maloney et al. 2025, Ann Plast Surg 95:423); the source "
        "paper's VESTA forces are typically < 2 N and students applied 2-2.5 N (O'Toole et al.)",
        "emergence_force": "chosen at half the entry peak: Frick et al. 2001 (J Biomech 34:1335) "
        "measured a second, emergence peak through the underside",
        "cutting_force, friction_per_length": "chosen to give a 0.1-0.3 N pull-through plateau, the "
        "Okamura/Simone 2004 cutting + friction decomposition (IEEE TBME 51:1707)",
        "viscous_coefficient": "small: Frick et al. 2001 found no effect of speed (1-10 mm/s)",
        "damage_stress": "chosen: about twice the largest local stress of a perpendicular expert pass "
        "(0.42 MPa), so a well-made stitch never crosses it and levering (1.8 MPa) or a 25 deg entry "
        "(1.2 MPa) does; a relative threshold of this force law, not a measured tissue strength",
        "edge_damage_stress": "chosen: about twice the wound-edge stress of an expert bite 1.5 mm from "
        "the edge (0.28 MPa), so bites 0.6-1.0 mm from it (0.37-0.48 MPa) do not cross it and "
        "levering (0.91 MPa; 2.1 MPa 0.6 mm from the edge) does; below the 1-2 MPa circumferential "
        "tensile strength reported for porcine arteries, as a tear starts before the wall fails",
    },
)

_CALCIFIED = TissuePreset(
    "calcified",
    "A calcified wall region: four times the artery's moduli, puncture at the band's top (1.5 N), "
    "harder emergence and cutting.",
    BiphaseParameters(soft_modulus=1.2e6, stiff_modulus=24e6, poisson_ratio=0.45, strain_limit=0.12),
    NeedleForces(
        puncture_force=1.5,
        emergence_force=0.7,
        cutting_force=0.35,
        friction_per_length=120.0,
        damage_stress=1.6e6,
        edge_damage_stress=1.2e6,
    ),
    {
        "moduli": "chosen: calcified plaque is reported from tens of MPa upwards, beyond what a linear "
        "phase can carry; four times the artery keeps the E2/E1 ratio (one shared factorisation)",
        "puncture_force": "chosen at the top of the 0.3-1.5 N band",
        "damage_stress, edge_damage_stress": "chosen: twice the artery's, as its puncture force is "
        "about twice",
    },
)

PRESETS: dict[str, TissuePreset] = {p.name: p for p in (_ARTERY, _CALCIFIED, _PAPER)}
DEFAULT_PRESET = "porcine-artery"


def tissue_preset(name: str) -> TissuePreset:
    """The preset called ``name`` (see ``PRESETS``)."""
    if name not in PRESETS:
        raise ModelError(f"unknown tissue preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]
