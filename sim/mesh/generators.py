"""Structured tetrahedral meshes: the paper's test cube and vessel-wall segments.

Both are built from a structured grid of hexahedral cells, each split into six
tetrahedra around the cell's main diagonal (the Kuhn/Freudenthal split), which
is conforming between neighbouring cells and yields 6 tets per hex as in the paper.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import MeshError
from sim.mesh.tetmesh import TetMesh, signed_volumes


def _kuhn_cell_tets() -> NDArray[np.int64]:
    """(6, 4, 3) index offsets of the six tets of a unit cell, walking 000 -> 111."""
    tets = []
    for order in itertools.permutations(range(3)):
        corner = np.zeros(3, dtype=np.int64)
        path = [corner.copy()]
        for axis in order:
            corner[axis] += 1
            path.append(corner.copy())
        tets.append(path)
    return np.array(tets)


KUHN_OFFSETS = _kuhn_cell_tets()


def structured_tets(cells: tuple[int, int, int]) -> NDArray[np.int64]:
    """Grid-index corners (C*6, 4, 3) of the Kuhn tets of an ``cells`` grid of hex cells."""
    base = np.stack(np.meshgrid(*(np.arange(n) for n in cells), indexing="ij"), axis=-1).reshape(-1, 3)
    return (base[:, None, None, :] + KUHN_OFFSETS[None]).reshape(-1, 4, 3)


def orient_positive(points: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.int64]:
    """Swap two nodes of every negatively oriented tet."""
    tets = tets.copy()
    negative = signed_volumes(points, tets) < 0
    tets[negative, 2], tets[negative, 3] = tets[negative, 3], tets[negative, 2].copy()
    return tets


def box_mesh(size: float | Sequence[float] = 0.01, divisions: int | Sequence[int] = 8) -> TetMesh:
    """An axis-aligned box from the origin, ``divisions`` hex cells per side, 6 tets per cell.

    ``box_mesh(0.01, 8)`` is the paper's test cube: 10 mm side, 729 nodes, 3072 elements.
    Node sets ``x0, x1, y0, y1, z0, z1`` name the six faces (``z0`` is the bottom).
    """
    lengths = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    cells = tuple(int(n) for n in np.broadcast_to(np.asarray(divisions), (3,)))
    if np.any(lengths <= 0) or not np.all(np.isfinite(lengths)):
        raise MeshError(f"box size must be positive and finite (m); got {tuple(lengths.tolist())}")
    if min(cells) < 1:
        raise MeshError(f"box divisions must be at least 1 per axis; got {cells}")
    return grid_box_mesh(*(np.arange(n + 1) * (length / n) for n, length in zip(cells, lengths, strict=True)))


def grid_box_mesh(xs: ArrayLike, ys: ArrayLike, zs: ArrayLike) -> TetMesh:
    """A box meshed on a tensor grid with the given node coordinates per axis (m, increasing), 6 tets
    per cell; e.g. with :func:`refined_coordinates` fine where a needle goes in, coarse elsewhere.
    Node sets ``x0, x1, y0, y1, z0, z1`` name the six faces."""
    axes = [np.asarray(v, dtype=np.float64).ravel() for v in (xs, ys, zs)]
    for name, values in zip("xyz", axes, strict=True):
        if values.size < 2 or not np.all(np.isfinite(values)) or np.any(np.diff(values) <= 0):
            raise MeshError(f"{name} coordinates must be at least two increasing finite numbers (m)")
    shape = tuple(len(v) for v in axes)
    cells = tuple(n - 1 for n in shape)
    grid = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), axis=-1).reshape(-1, 3)
    points = np.column_stack([axes[k][grid[:, k]] for k in range(3)])
    corners = structured_tets(cells)
    tets = np.ravel_multi_index(tuple(corners[..., k] for k in range(3)), shape)
    tets = orient_positive(points, tets)
    node_sets = {}
    for axis, name in enumerate("xyz"):
        node_sets[f"{name}0"] = np.flatnonzero(grid[:, axis] == 0)
        node_sets[f"{name}1"] = np.flatnonzero(grid[:, axis] == cells[axis])
    return TetMesh(points, tets, node_sets=node_sets, region_names={0: "tissue"})


def refined_coordinates(length: float, coarse: float, fine: float, start: float, stop: float) -> NDArray:
    """Node coordinates 0..length (m) with spacing at most ``fine`` on [start, stop] and growing by at
    most 1.5x per cell towards ``coarse`` outside it (a graded grid, no abrupt jump in cell size)."""
    if not 0 < fine <= coarse or not 0 <= start < stop <= length:
        raise MeshError(
            f"refinement needs 0 < fine <= coarse and 0 <= start < stop <= length; got fine={fine}, "
            f"coarse={coarse}, start={start}, stop={stop}, length={length}"
        )
    cells = max(1, math.ceil((stop - start) / fine - 1e-9))
    middle = np.linspace(start, stop, cells + 1)

    def graded(distance: float) -> list[float]:
        """Offsets from the refined zone outwards to ``distance``, spacing growing from fine."""
        offsets, step, at = [], fine, 0.0
        while distance - at > 1e-12:
            step = min(step * 1.5, coarse)
            remaining = distance - at
            at = distance if remaining < 1.5 * step else at + step
            offsets.append(at)
        return offsets

    below = [start - d for d in graded(start)][::-1]
    above = [stop + d for d in graded(length - stop)]
    return np.array(below + middle.tolist() + above)


@dataclass(frozen=True)
class Wound:
    """An incision through the full wall thickness, along the vessel axis.

    angle_deg: circumferential position (snapped to the nearest grid column).
    z_start, z_end: axial extent in metres (snapped to grid rings); the slit is
        closed at its ends (crack tips) unless it reaches the end of the segment.
    gap: opening at mid-length in metres; the two edges part with a sine profile.
    """

    angle_deg: float = 0.0
    z_start: float = 0.0
    z_end: float = 0.0
    gap: float = 0.0


@dataclass(frozen=True)
class Calcification:
    """A stiff plaque: elements of the given wall layers inside an angle and axial range."""

    angle_range_deg: tuple[float, float]
    z_range: tuple[float, float]
    layers: tuple[int, ...] = (1,)


def default_layer_names(radial_divisions: int) -> list[str]:
    """Intima innermost, adventitia outermost, media between (one layer: media)."""
    if radial_divisions == 1:
        return ["media"]
    names = ["media"] * radial_divisions
    names[0], names[-1] = "intima", "adventitia"
    return names


def vessel_mesh(
    inner_radius: float = 0.004,
    wall_thickness: float = 0.0015,
    length: float = 0.02,
    arc_deg: float = 360.0,
    circumferential_divisions: int = 48,
    radial_divisions: int = 3,
    axial_divisions: int = 20,
    layer_names: Sequence[str] | None = None,
    wound: Wound | None = None,
    calcification: Calcification | None = None,
) -> TetMesh:
    """A vessel-wall segment: a tube (``arc_deg=360``) or a patch of one, axis along z.

    Each radial cell layer is a region named by ``layer_names`` (default intima /
    media / adventitia). Node sets: ``inner`` (lumen), ``outer`` (adventitial
    surface), ``end0``/``end1`` (the cut ends), ``side0``/``side1`` (patch edges),
    and with a wound ``wound_a``/``wound_b`` (the two edges of the incision).
    """
    _check_vessel_args(
        inner_radius,
        wall_thickness,
        length,
        arc_deg,
        circumferential_divisions,
        radial_divisions,
        axial_divisions,
    )
    full_tube = math.isclose(arc_deg, 360.0)
    n_theta, n_r, n_z = circumferential_divisions, radial_divisions, axial_divisions
    theta_nodes = n_theta if full_tube else n_theta + 1
    shape = (theta_nodes, n_r + 1, n_z + 1)
    grid = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), axis=-1).reshape(-1, 3)
    arc = math.radians(arc_deg)
    theta = grid[:, 0] * (arc / n_theta) - (0.0 if full_tube else arc / 2)
    radius = inner_radius + grid[:, 1] * (wall_thickness / n_r)
    z = grid[:, 2] * (length / n_z)
    points = np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])

    corners = structured_tets((n_theta, n_r, n_z))
    if full_tube:
        corners[..., 0] %= n_theta
    tets = np.ravel_multi_index(tuple(corners[..., k] for k in range(3)), shape)
    cell_theta = corners[:, :, 0].min(axis=1)
    cell_theta = np.where(corners[:, :, 0].max(axis=1) - cell_theta > 1, n_theta - 1, cell_theta)
    cell_layer = corners[:, :, 1].min(axis=1)
    cell_z = corners[:, :, 2].min(axis=1)

    names = list(layer_names) if layer_names is not None else default_layer_names(n_r)
    if len(names) != n_r:
        raise MeshError(f"layer_names needs one name per radial division ({n_r}); got {len(names)}")
    region_ids = {name: i for i, name in enumerate(dict.fromkeys(names))}
    regions = np.array([region_ids[names[layer]] for layer in cell_layer], dtype=np.int32)
    if calcification is not None:
        regions = _calcify(
            regions,
            region_ids,
            calcification,
            cell_theta,
            cell_layer,
            cell_z,
            arc / n_theta,
            0.0 if full_tube else -arc / 2,
            length / n_z,
        )

    node_sets = {
        "inner": np.flatnonzero(grid[:, 1] == 0),
        "outer": np.flatnonzero(grid[:, 1] == n_r),
        "end0": np.flatnonzero(grid[:, 2] == 0),
        "end1": np.flatnonzero(grid[:, 2] == n_z),
    }
    if not full_tube:
        node_sets["side0"] = np.flatnonzero(grid[:, 0] == 0)
        node_sets["side1"] = np.flatnonzero(grid[:, 0] == n_theta)
    if wound is not None:
        points, tets, node_sets = _cut_wound(
            points, tets, node_sets, grid, cell_theta, wound, full_tube, arc, n_theta, length, n_z
        )
    tets = orient_positive(points, tets)
    return TetMesh(points, tets, regions, {i: n for n, i in region_ids.items()}, node_sets)


def _check_vessel_args(
    inner_radius: float,
    wall_thickness: float,
    length: float,
    arc_deg: float,
    n_theta: int,
    n_r: int,
    n_z: int,
) -> None:
    for name, value in (
        ("inner_radius", inner_radius),
        ("wall_thickness", wall_thickness),
        ("length", length),
    ):
        if not (math.isfinite(value) and value > 0):
            raise MeshError(f"vessel {name} must be positive and finite (m); got {value}")
    if not 0 < arc_deg <= 360:
        raise MeshError(f"vessel arc_deg must be in (0, 360]; got {arc_deg}")
    minimum = 3 if math.isclose(arc_deg, 360.0) else 1
    if n_theta < minimum or n_r < 1 or n_z < 1:
        raise MeshError(
            f"vessel divisions too small: circumferential {n_theta} (min {minimum}), "
            f"radial {n_r} (min 1), axial {n_z} (min 1)"
        )


def _calcify(
    regions: NDArray[np.int32],
    region_ids: dict[str, int],
    plaque: Calcification,
    cell_theta: NDArray,
    cell_layer: NDArray,
    cell_z: NDArray,
    dtheta: float,
    theta0: float,
    dz: float,
) -> NDArray[np.int32]:
    region_ids.setdefault("calcified", len(region_ids))
    angle = np.degrees(theta0 + (cell_theta + 0.5) * dtheta)
    z_mid = (cell_z + 0.5) * dz
    lo, hi = plaque.angle_range_deg
    z_lo, z_hi = plaque.z_range
    inside = (
        (angle >= lo) & (angle <= hi) & (z_mid >= z_lo) & (z_mid <= z_hi) & np.isin(cell_layer, plaque.layers)
    )
    if not inside.any():
        raise MeshError(f"calcification {plaque} selects no element; widen its ranges")
    regions = regions.copy()
    regions[inside] = region_ids["calcified"]
    return regions


def _cut_wound(
    points: NDArray,
    tets: NDArray,
    node_sets: dict[str, NDArray],
    grid: NDArray,
    cell_theta: NDArray,
    wound: Wound,
    full_tube: bool,
    arc: float,
    n_theta: int,
    length: float,
    n_z: int,
) -> tuple[NDArray, NDArray, dict[str, NDArray]]:
    """Duplicate the nodes on the incision so its two edges become separate surfaces."""
    theta0 = 0.0 if full_tube else -arc / 2
    column = round((math.radians(wound.angle_deg) - theta0) / (arc / n_theta))
    if full_tube:
        column %= n_theta
    elif not 0 < column < n_theta:
        raise MeshError(f"wound angle {wound.angle_deg} deg lies on the patch edge; place it inside the arc")
    k_start = round(wound.z_start / length * n_z)
    k_end = round(wound.z_end / length * n_z)
    if not 0 <= k_start < k_end <= n_z:
        raise MeshError(
            f"wound z range ({wound.z_start}, {wound.z_end}) m must lie inside the vessel length "
            f"{length} m and span at least one axial division ({length / n_z:.3g} m)"
        )
    lo = k_start if k_start == 0 else k_start + 1
    hi = k_end if k_end == n_z else k_end - 1
    on_slit = np.flatnonzero((grid[:, 0] == column) & (grid[:, 2] >= lo) & (grid[:, 2] <= hi))
    if on_slit.size == 0:
        raise MeshError("wound is too short to open: make it span at least two axial divisions")
    duplicates = np.arange(len(points), len(points) + len(on_slit))
    remap = np.arange(len(points))
    remap[on_slit] = duplicates
    side_b = cell_theta == column
    tets = tets.copy()
    tets[side_b] = remap[tets[side_b]]
    points = np.vstack([points, points[on_slit]])
    if wound.gap > 0:
        points = _open_wound(points, on_slit, duplicates, wound, arc / n_theta, length)
    node_sets = dict(node_sets)
    for name, ids in list(node_sets.items()):
        extra = duplicates[np.isin(on_slit, ids)]
        node_sets[name] = np.concatenate([ids, extra])
    node_sets["wound_a"], node_sets["wound_b"] = on_slit, duplicates
    return points, tets, node_sets


def _open_wound(
    points: NDArray, side_a: NDArray, side_b: NDArray, wound: Wound, dtheta: float, length: float
) -> NDArray:
    z = points[side_a, 2]
    closed_tips = [tip for tip in (wound.z_start, wound.z_end) if 0 < tip < length]
    half_span = 0.5 * (wound.z_end - wound.z_start)
    profile = np.ones_like(z)
    for tip in closed_tips:
        profile = np.minimum(profile, np.sin(0.5 * np.pi * np.clip(np.abs(z - tip) / half_span, 0, 1)))
    radius = np.hypot(points[side_a, 0], points[side_a, 1])
    half_angle = 0.5 * wound.gap * profile / radius
    limit = 0.45 * dtheta
    if np.any(half_angle > limit):
        widest = float(2 * limit * radius.min())
        raise MeshError(
            f"wound gap {wound.gap * 1e3:.3g} mm is wider than the grid allows ({widest * 1e3:.3g} mm); "
            "use more circumferential divisions or a smaller gap"
        )
    points = points.copy()
    for ids, sign in ((side_a, -1.0), (side_b, 1.0)):
        angle = np.arctan2(points[ids, 1], points[ids, 0]) + sign * half_angle
        points[ids, 0], points[ids, 1] = radius * np.cos(angle), radius * np.sin(angle)
    return points
