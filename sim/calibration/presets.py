"""Calibrated tissue presets: the biphase wall and the needle's puncture and passage forces, with sources.

Each value says where it comes from (docs/tissue-model.md has the full table): a published
measurement, or "chosen" with the published force it was chosen to reproduce. The linear
phases are a phenomenological force law; the stress they give near the needle is not a
physical stress (a linear model cannot be valid at a needle's tip).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from sim.errors import ModelError
from sim.fem.biphase import BiphaseParameters
from sim.needle.forces import NeedleForces


@dataclass(frozen=True)
class TissuePreset:
    """A named tissue: its biphase parameters, the needle forces in it, and the source of each value.

    ``sources`` maps parameter names (several joined by ", ") to what the value is and where it comes
    from; every parameter of ``biphase`` and ``forces`` has one (:func:`undocumented` lists any that
    do not). ``description`` is written from the values, so it cannot drift from them.
    """

    name: str
    summary: str
    biphase: BiphaseParameters
    forces: NeedleForces
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def description(self) -> str:
        return f"{self.summary} {describe(self.biphase, self.forces)}"


def describe(biphase: BiphaseParameters, forces: NeedleForces) -> str:
    """The preset's values in a surgeon-researcher's units, one sentence each."""
    walls = (
        f"Wall: E1 = {_pascals(biphase.soft_modulus)} (soft phase), E2 = {_pascals(biphase.stiff_modulus)} "
        f"beyond {biphase.strain_limit * 100:.0f} % indentation strain (nu = {biphase.poisson_ratio:.2f}); "
        f"faster than {biphase.critical_speed * 1e3:.0f} mm/s the stiff phase engages at "
        f"{biphase.limit_floor * 100:.0f} % of that strain, while loading only."
    )
    if forces.puncture_force is None:
        needle = "Needle: pierces by the paper's tip-stress rule"
    else:
        needle = f"Needle: pierces at {forces.puncture_force * 1e3:.0f} mN normal force"
    if forces.resists_passage:
        needle += (
            f", cutting {forces.cutting_force * 1e3:.0f} mN, "
            f"emergence {forces.emergence_force * 1e3:.0f} mN, "
            f"friction {forces.friction_per_length:.0f} mN/mm along the needle"
        )
    else:
        needle += ", no passage forces"
    needle += f"; surface friction coefficient {forces.friction_coefficient:.2f}"
    if forces.tear_force is not None:
        needle += f"; the wall tears at {forces.tear_force * 1e3:.0f} mN"
    needle += "."
    if forces.damage_stress is None:
        return f"{walls} {needle}"
    edge = (
        ""
        if forces.edge_damage_stress is None
        else f", {forces.edge_damage_stress / 1e6:.2f} MPa at a wound edge"
    )
    return f"{walls} {needle} Overstress above {forces.damage_stress / 1e6:.2f} MPa local stress{edge}."


def _pascals(value: float) -> str:
    return f"{value / 1e6:.1f} MPa" if value >= 1e6 else f"{value / 1e3:.0f} kPa"


def undocumented(preset: TissuePreset) -> list[str]:
    """The parameters of ``preset`` its sources do not cover."""
    covered = {name.strip() for key in preset.sources for name in key.split(",")}
    names = [f.name for f in fields(preset.biphase)] + [f.name for f in fields(preset.forces)]
    return [name for name in names if name not in covered]


_KERNEL_AND_PASSAGE = {
    "load, kernel_radius, near_field, lateral_scale": "the force kernel of sim/fem/kernel.py (a "
    "mesh-independent "
    "load over 1 mm with the 0.25 mm wire's flat-punch near field; the sideways stiffness of a pierced wall "
    "as the kernel gives it): model choices, converged with mesh refinement (docs/tissue-model.md)",
    "stick_speed, recoil_time": "numerical regularisation: a 0.1 mm/s Karnopp stick band for the friction "
    "along the needle, and a 30 ms time constant for the wall's recoil on a released needle (chosen)",
    "limit_floor, speed_exponent": "the biphase model's speed law (PAPER.md section 6): the strain "
    "limit falls "
    "to 25 % of itself, quadratically, as the needle approaches the critical speed (the paper's form)",
}

_PAPER = TissuePreset(
    "paper",
    "The source paper's soft tissue and needle, for reproducing its Table 1 and figures, not for assessment.",
    BiphaseParameters(),
    NeedleForces.paper(),
    {
        "soft_modulus, stiff_modulus, strain_limit, poisson_ratio, critical_speed, limit_floor, "
        "speed_exponent": (
            "PAPER.md section 6 (20 kPa, 40 kPa, 0.2, 0.45; the speed law's constants as the paper states it)"
        ),
        "load, puncture_force": "PAPER.md: three-node barycentric drive and a tip-stress puncture rule, "
        "its stress "
        "chosen to pierce at about 0.65 mm on a 1.5 mm patch",
        "kernel_radius, near_field, lateral_scale, emergence_force, emergence_ramp, cutting_force, "
        "friction_per_length, stick_speed, viscous_coefficient, damage_stress, edge_damage_stress, "
        "recoil_time, friction_coefficient, tear_force": "not in the paper: the barycentric rule ignores the "
        "kernel's; no passage forces, no damage events, no tearing",
    },
)

_ARTERY = TissuePreset(
    "porcine-artery",
    "Porcine arterial wall as used on bench courses.",
    BiphaseParameters(
        soft_modulus=300e3, stiff_modulus=6e6, poisson_ratio=0.45, strain_limit=0.12, critical_speed=0.1
    ),
    NeedleForces(damage_stress=8e5, edge_damage_stress=6e5, tear_force=1.9),
    {
        "soft_modulus": "fitted, not measured: with stiff_modulus and strain_limit, the linear soft "
        "phase that "
        "puts the 0.8 N puncture force at 0.7-1.1 mm indentation of a 1.5 mm wall. It is a stiffness of this "
        "force law, 4-5x the indentation modulus of porcine aorta (60-70 kPa, Hemmasizadeh et al. 2012, "
        "J Mech "
        "Behav Biomed Mater 15:199), which a linear model cannot use and still reach the measured forces",
        "stiff_modulus": "fitted with soft_modulus; of the order of porcine aortic tangent moduli in the "
        "collagen-recruited range, fitted slopes over a stress range of 1.3 MPa radial to 7.8 MPa "
        "circumferential (review table, PMC6948849 Table 3), not values at one stress",
        "strain_limit": "fitted with the moduli (the strain at which collagen takes over, 12 %)",
        "poisson_ratio": "chosen: 0.45, a nearly incompressible wall within the paper's stable range "
        "(<= 0.47, PAPER.md)",
        "critical_speed": "chosen at 100 mm/s so that between 1 and 10 mm/s the force at a depth changes by "
        "under 1 % (Frick et al. 2001, J Biomech 34:1335: no effect of speed between 1 and 10 mm/s); only "
        "stabs faster than about 30 mm/s meet the stiff phase sooner",
        "puncture_force": "in the 0.3-1.5 N band of suture-needle puncture: taper needles puncture cartilage "
        "at 0.61-0.90 N (Maloney et al. 2025, Ann Plast Surg 95:423); the source paper's VESTA forces are "
        "typically < 2 N and students applied 2-2.5 N (O'Toole et al.)",
        "emergence_force, emergence_ramp": "fitted: a second, emergence peak below the entry one as the tip "
        "tents the far surface over its last 0.3 mm (Frick et al. 2001 measured it through the underside)",
        "cutting_force, friction_per_length, viscous_coefficient": "fitted to a 0.1-0.3 N pull-through "
        "plateau, "
        "the cutting + friction decomposition of Okamura, Simone and O'Leary 2004 (IEEE TBME 51:1707); the "
        "viscous term small, as Frick et al. 2001 found no effect of speed",
        "friction_coefficient": "0.3: needle-tissue friction coefficients measured 0.12-0.34 (ASME MSEC "
        "2021, "
        "V001T03A008) and 0.33 for a bare steel needle (Chu et al. 2016, Sci Rep 6:31847)",
        "tear_force": "1.9 N: the suture retention strength of human saphenous vein, 196 gf (1.4 N for "
        "internal "
        "mammary artery, 138 gf; L'Heureux et al. 2006, Nat Med 12:361): the load at which a wire cuts out "
        "through a vessel wall",
        "damage_stress": "chosen: above the largest local stress of a scripted expert pass on every task and "
        "below that of a levering pass (docs/tissue-model.md); a relative threshold of this force law, not "
        "a measured tissue strength; the media's ultimate strength is 0.5-1.2 MPa (Teng et al. 2009, J "
        "Biomech 42:2535)",
        "edge_damage_stress": "chosen: about twice the wound-edge stress of an expert bite 1.5 mm from "
        "the edge "
        "(0.28 MPa), so bites 0.6-1.0 mm from it do not cross it and levering does; below the 1-2 MPa "
        "circumferential tensile strength reported for porcine arteries, as a tear starts before the "
        "wall fails",
        **_KERNEL_AND_PASSAGE,
    },
)

_CALCIFIED = TissuePreset(
    "calcified",
    "A calcified wall region.",
    BiphaseParameters(
        soft_modulus=1.2e6, stiff_modulus=24e6, poisson_ratio=0.45, strain_limit=0.12, critical_speed=0.1
    ),
    NeedleForces(
        puncture_force=1.5,
        tear_force=3.6,
        emergence_force=0.7,
        cutting_force=0.35,
        friction_per_length=120.0,
        damage_stress=1.6e6,
        edge_damage_stress=1.2e6,
    ),
    {
        "soft_modulus": "1.2 MPa: within the static circumferential tangent modulus of calcified human "
        "atherosclerotic tissue, 1.47 +- 1.28 MPa at physiological stress (Loree et al. 1994, J Biomech "
        "27:195); four times the artery's",
        "stiff_modulus": "fitted: 20x the soft phase, the artery's ratio, so both phases share one "
        "factorisation; calcifications themselves reach GPa (nanoindentation), beyond what a linear phase "
        "of a needle-scale wall can carry",
        "strain_limit, poisson_ratio, critical_speed, limit_floor, speed_exponent": "as the artery's",
        "puncture_force": "chosen at the top of the 0.3-1.5 N band of suture-needle puncture",
        "tear_force": "chosen: the artery's 1.9 N scaled as the puncture force (1.5 / 0.8)",
        "emergence_force, emergence_ramp, cutting_force, friction_per_length, viscous_coefficient": "fitted: "
        "the artery's passage forces raised about as the puncture force is",
        "friction_coefficient": "as the artery's (the needle's steel on a wall's surface)",
        "damage_stress, edge_damage_stress": "chosen: twice the artery's, as its puncture force is "
        "about twice",
        **_KERNEL_AND_PASSAGE,
    },
)

PRESETS: dict[str, TissuePreset] = {p.name: p for p in (_ARTERY, _CALCIFIED, _PAPER)}
DEFAULT_PRESET = "porcine-artery"


def tissue_preset(name: str) -> TissuePreset:
    """The preset called ``name`` (see ``PRESETS``)."""
    if name not in PRESETS:
        raise ModelError(f"unknown tissue preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]
