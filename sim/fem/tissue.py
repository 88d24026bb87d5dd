"""What every tissue the simulator can run on offers: one linear model or the biphase pair.

:class:`sim.fem.TissueModel` and :class:`sim.fem.BiphaseTissue` both satisfy :class:`Tissue`, so
the runtime, the needle load and the field replays ask the tissue, never which kind it is.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from sim.fem.biphase import BiphaseParameters
    from sim.fem.model import TissueModel
    from sim.mesh.tetmesh import TetMesh


@runtime_checkable
class Tissue(Protocol):
    """A tissue: its mesh, the linear models it superimposes, contact and depth."""

    @property
    def mesh(self) -> TetMesh: ...

    @property
    def models(self) -> tuple[TissueModel, ...]:
        """The linear models it superimposes (one, or the soft and stiff phases, soft first)."""
        ...

    @property
    def base(self) -> TissueModel:
        """The model depths are cast and force kernels built on (the soft phase of a pair)."""
        ...

    @property
    def biphase(self) -> BiphaseParameters | None:
        """The biphase law's parameters, or None for one linear phase."""
        ...

    @property
    def spot_solved(self) -> list[int]: ...

    def precompute(self, cache_dir: str | Path | None = None, use_cache: bool = True) -> object: ...

    def contact(self, nodes: ArrayLike) -> object: ...

    def needs_solve(self, node: int) -> bool: ...

    def depth_under(self, nodes: NDArray[np.int64]) -> float: ...

    def cast_depths(self, nodes: Iterable[int]) -> None: ...

    def warm_contact_caches(self) -> None: ...
