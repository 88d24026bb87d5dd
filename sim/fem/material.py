"""Linear isotropic materials and their assignment to mesh regions."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.errors import MaterialError, VascsimWarning

# Above this Poisson's ratio the paper saw the inverted, penalised model go unstable.
STABLE_POISSON_LIMIT = 0.47


class PoissonRatioWarning(VascsimWarning):
    """Poisson's ratio above the paper's stability limit (0.47)."""


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic material.

    youngs_modulus: Young's modulus E in pascals (soft tissue: 1-200 kPa).
    poisson_ratio: nu, 0 <= nu < 0.5; above 0.47 the paper's model went unstable,
        so a :class:`PoissonRatioWarning` is issued.
    """

    youngs_modulus: float
    poisson_ratio: float = 0.45

    def __post_init__(self) -> None:
        e, nu = self.youngs_modulus, self.poisson_ratio
        if not (isinstance(e, int | float) and math.isfinite(e) and e > 0):
            raise MaterialError(f"youngs_modulus must be a positive finite number of pascals; got {e!r}")
        if not (isinstance(nu, int | float) and math.isfinite(nu) and 0 <= nu < 0.5):
            raise MaterialError(f"poisson_ratio must satisfy 0 <= nu < 0.5; got {nu!r}")
        if nu > STABLE_POISSON_LIMIT:
            warnings.warn(
                f"poisson_ratio {nu} is above {STABLE_POISSON_LIMIT}, where the paper's penalised "
                "model became unstable",
                PoissonRatioWarning,
                stacklevel=3,
            )

    @property
    def lame_lambda(self) -> float:
        """First Lame parameter (Pa)."""
        e, nu = self.youngs_modulus, self.poisson_ratio
        return e * nu / ((1 + nu) * (1 - 2 * nu))

    @property
    def shear_modulus(self) -> float:
        """Second Lame parameter mu (Pa)."""
        return self.youngs_modulus / (2 * (1 + self.poisson_ratio))

    def scaled(self, factor: float) -> Material:
        """The same material with Young's modulus multiplied by ``factor``."""
        return Material(self.youngs_modulus * factor, self.poisson_ratio)


MaterialSpec = Material | Mapping[int | str, Material]


def element_lame(
    regions: NDArray[np.int32], region_names: Mapping[int, str], materials: MaterialSpec
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-element (lambda, mu) from one material or a map of region id/name -> material."""
    if isinstance(materials, Material):
        n = len(regions)
        return np.full(n, materials.lame_lambda), np.full(n, materials.shear_modulus)
    by_id = resolve_region_materials(regions, region_names, materials)
    ids = np.unique(regions)
    lam = np.empty(len(regions))
    mu = np.empty(len(regions))
    for region in ids:
        mask = regions == region
        lam[mask] = by_id[int(region)].lame_lambda
        mu[mask] = by_id[int(region)].shear_modulus
    return lam, mu


def resolve_region_materials(
    regions: NDArray[np.int32], region_names: Mapping[int, str], materials: Mapping[int | str, Material]
) -> dict[int, Material]:
    """Map every region present in the mesh to its material; name the missing ones."""
    ids_by_name = {name: rid for rid, name in region_names.items()}
    resolved: dict[int, Material] = {}
    for key, material in materials.items():
        if not isinstance(material, Material):
            raise MaterialError(
                f"material for region {key!r} must be a Material; got {type(material).__name__}"
            )
        if isinstance(key, str):
            if key not in ids_by_name:
                raise MaterialError(
                    f"material given for region {key!r}, which the mesh does not have "
                    f"(regions: {sorted(ids_by_name)})"
                )
            key = ids_by_name[key]
        resolved[int(key)] = material
    missing = [int(r) for r in np.unique(regions) if int(r) not in resolved]
    if missing:
        names = ", ".join(f"{r} ({region_names.get(r, '?')})" for r in missing)
        raise MaterialError(f"no material for mesh region(s) {names}")
    return resolved


def describe_materials(materials: MaterialSpec) -> str:
    """A stable text form of the materials, used in cache keys and session headers."""
    if isinstance(materials, Material):
        return repr(materials)
    return repr(sorted((str(k), repr(v)) for k, v in materials.items()))
