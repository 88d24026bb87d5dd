"""The built-in tasks: a wall patch and the arteriotomy of a porcine artery (one stitch, a closure
row, a diseased wall, restricted access)."""

from __future__ import annotations

import dataclasses

import numpy as np

from sessions.tasks.parameters import (
    ArcRegion,
    Plaque,
    VesselPatchParameters,
    WallPatchParameters,
    WoundCut,
)
from sessions.tasks.spec import EvertedBite, TaskSpec

TASKS = {
    "wall-stitch": TaskSpec(
        "wall-stitch",
        "wall_patch",
        "One stitch through a 1.5 mm porcine arterial-wall patch (12 x 10 mm, biphase elastin/collagen, "
        "held on three sides) near its free wound edge; 0.3 mm cells in the 3.5 x 4 mm stitch region.",
        (0.0105, 0.0051, 0.0015),
        (0.0, 0.0, 1.0),
        (1.0, 0.0, 0.0),
        WallPatchParameters(
            fixed=("x0", "y0", "y1"),
            tissue="porcine-artery",
            size_m=(0.012, 0.01, 0.0015),
            cell_m=0.001,
            stitch_cell_m=0.0003,
            stitch_region_m=((0.0085, 0.012), (0.0031, 0.0071)),
        ),
        placement={
            # the free x1 edge is the wound: its plane x = 12 mm, normal pointing into the gap
            "wound_point": [0.012, 0.0, 0.0015],
            "wound_normal": [1.0, 0.0, 0.0],
            "target_bite_m": 0.0015,
            "entry_targets": [[0.0105, 0.0051, 0.0015]],  # on the adventitia, 1.5 mm from the edge
            "exit_targets": [[0.0105, 0.0051, 0.0]],  # straight through: on the intima beneath
            "far_normal": [0.0, 0.0, -1.0],  # the luminal (intimal) surface faces -z
        },
    )
}


# The interrupted stitch: a 90 deg patch of a porcine artery (inner radius 4 mm, wall 1.5 mm,
# 10 mm long) held on its four cut sides, with a 6 mm arteriotomy along the axis at angle 0 that
# gapes 0.15 mm at mid-length. One bite through the wound's b edge (positive angles) at mid-length:
# in through the adventitia 1.5 mm from the edge, radially through the wall, out through the intima.
_VESSEL = {"inner": 0.004, "wall": 0.0015, "length": 0.01, "arc_deg": 90.0, "gap": 1.5e-4}
_OUTER = _VESSEL["inner"] + _VESSEL["wall"]
_EDGE = 0.5 * _VESSEL["gap"] / _OUTER  # the b edge's angle on the adventitia at mid-length (rad)
_BITE = 0.0015
_ENTRY_ANGLE = _EDGE + float(np.arcsin(_BITE / _OUTER))  # 1.5 mm from the edge's plane


def _on_cylinder(radius: float, angle: float, z: float) -> list[float]:
    return [radius * float(np.cos(angle)), radius * float(np.sin(angle)), z]


def _interrupted_stitch() -> TaskSpec:
    z = 0.5 * _VESSEL["length"]
    radial = (float(np.cos(_ENTRY_ANGLE)), float(np.sin(_ENTRY_ANGLE)), 0.0)
    towards_wound = (float(np.sin(_ENTRY_ANGLE)), -float(np.cos(_ENTRY_ANGLE)), 0.0)
    entry = _on_cylinder(_OUTER, _ENTRY_ANGLE, z)
    return TaskSpec(
        "interrupted-stitch",
        "vessel_patch",
        "One bite through an arteriotomy's edge on a porcine artery (inner radius 4 mm, wall 1.5 mm): "
        "in through the adventitia 1.5 mm from the wound edge, out through the intima; a 90 deg patch "
        "of the vessel held on its cut sides, 0.3 mm cells.",
        tuple(entry),
        radial,
        towards_wound,
        VesselPatchParameters(
            fixed=("end0", "end1", "side0", "side1"),
            tissue="porcine-artery",
            inner_radius_m=_VESSEL["inner"],
            wall_m=_VESSEL["wall"],
            length_m=_VESSEL["length"],
            arc_deg=_VESSEL["arc_deg"],
            divisions=(30, 5, 34),  # circumferential, radial, axial: <= 0.3 mm cells
            wound=WoundCut(0.0, (0.002, 0.008), _VESSEL["gap"]),
            stitch_region=ArcRegion((0.0, 35.0), (0.003, 0.007)),
        ),
        placement={
            # the b edge's plane through the axis; its normal points from the tissue into the gap
            "wound_point": _on_cylinder(_OUTER, _EDGE, z),
            "wound_normal": [float(np.sin(_EDGE)), -float(np.cos(_EDGE)), 0.0],
            "target_bite_m": _BITE,
            # straight through the wall: on the intima the same bite is 4/5.5 of it from the edge
            "target_exit_bite_m": _VESSEL["inner"] * float(np.sin(_ENTRY_ANGLE - _EDGE)),
            "entry_targets": [entry],
            "exit_targets": [_on_cylinder(_VESSEL["inner"], _ENTRY_ANGLE, z)],
            "far_normal": [-radial[0], -radial[1], 0.0],  # the lumen faces the axis
        },
    )


TASKS["interrupted-stitch"] = _interrupted_stitch()


def _closure_row(spacing: float = 0.0015, count: int = 3) -> TaskSpec:
    """Interrupted stitches in a row along the same arteriotomy edge, ``spacing`` apart at mid-length:
    each bite as the interrupted stitch's, so spacing and its regularity count too."""
    single = _interrupted_stitch()
    middle = 0.5 * _VESSEL["length"]
    heights = [middle + spacing * (k - (count - 1) / 2) for k in range(count)]
    entries = [_on_cylinder(_OUTER, _ENTRY_ANGLE, z) for z in heights]
    exits = [_on_cylinder(_VESSEL["inner"], _ENTRY_ANGLE, z) for z in heights]
    bites = tuple((tuple(e), single.normal, single.bite_direction) for e in entries)
    return TaskSpec(
        "arteriotomy-closure",
        "vessel_patch",
        f"A row of {count} interrupted stitches {1e3 * spacing:g} mm apart along an arteriotomy's edge on a "
        "porcine artery (the interrupted stitch's vessel): each bite in 1.5 mm from the edge and out "
        "through the intima; spacing and its regularity are scored.",
        *bites[0],
        single.parameters,
        placement={
            **single.placement,
            "entry_targets": entries,
            "exit_targets": exits,
            "wound_direction": [0.0, 0.0, 1.0],
            "target_spacing_m": spacing,
        },
        more_bites=bites[1:],
        time_budget_s=60.0 * count,
    )


TASKS["arteriotomy-closure"] = _closure_row()


def _diseased_wall() -> TaskSpec:
    """The closure row through a diseased wall: a calcified plaque through the whole wall under the
    row's second and third bites (angles 3-35 deg, z 4.25-7.25 mm), four times stiffer with a
    puncture at the band's top (the ``calcified`` preset); the first bite is through healthy wall."""
    row = _closure_row()
    parameters = dataclasses.replace(
        row.parameters,
        calcification=Plaque((3.0, 35.0), (0.00425, 0.00725), (0, 1, 2, 3, 4)),
        region_tissue={"calcified": "calcified"},
    )
    return TaskSpec(
        "diseased-wall",
        "vessel_patch",
        "The arteriotomy closure through a diseased wall: the row's second and third bites go through a "
        "calcified plaque (four times stiffer, puncture at 1500 mN instead of 800 mN), where a decisive "
        "needle at a square angle matters most.",
        row.entry,
        row.normal,
        row.bite_direction,
        parameters,
        placement=row.placement,
        more_bites=row.more_bites,
        time_budget_s=row.time_budget_s + 60.0,
    )


TASKS["diseased-wall"] = _diseased_wall()


def _restricted_access(tilt_deg: float = 45.0) -> TaskSpec:
    """The interrupted stitch at the bottom of a deep, narrow wound: the hand can only come in
    ``tilt_deg`` off the wall's normal, along the vessel's axis, yet the needle must still meet the
    wall square and be turned along its curve, so the wrist must turn further."""
    single = _interrupted_stitch()
    normal = np.asarray(single.normal)
    tilt = np.radians(tilt_deg)
    approach = np.cos(tilt) * normal + np.sin(tilt) * np.array([0.0, 0.0, 1.0])
    return TaskSpec(
        "restricted-access",
        "vessel_patch",
        f"The interrupted stitch through an arteriotomy deep in a narrow wound: the needle holder can "
        f"only come in {tilt_deg:g} deg off the wall's normal, along the vessel, so entering square and "
        "turning the needle along its curve take a further turn of the wrist.",
        single.entry,
        single.normal,
        single.bite_direction,
        single.parameters,
        placement=single.placement,
        access={"approach": [float(x) for x in approach], "tilt_deg": tilt_deg},
        time_budget_s=90.0,
    )


TASKS["restricted-access"] = _restricted_access()


def _inside_edge() -> TaskSpec:
    """The interrupted stitch where the edge must be everted to be met square (PAPER.md section 2:
    the subordinate hand gives access inside the wound's edge, "sufficient to allow perpendicular
    entry of a curved needle"): the approach stops the wrist 7 deg short of square to the resting wall,
    and the forceps lifting the rim 0.38 mm turn the wall 7.6 deg to meet it (the rim's 48 nodes; the
    entry rises 0.18 mm; 128 mN on the forceps, well short of the 1.9 mm lift that tears the edge)."""
    single = _interrupted_stitch()
    return TaskSpec(
        "inside-edge",
        "vessel_patch",
        "The interrupted stitch where the wrist cannot reach square: the approach stops it 7 deg short "
        "of square to the resting wall, so the subordinate hand must evert the edge (lift it about "
        "0.4 mm with the forceps) to turn the wall to meet the needle, as inside a wound's edge.",
        single.entry,
        single.normal,
        single.bite_direction,
        single.parameters,
        placement=single.placement,
        time_budget_s=90.0,
        eversion=EvertedBite(short_deg=7.0, lift_m=0.38e-3, turn_deg=7.61),
    )


TASKS["inside-edge"] = _inside_edge()
