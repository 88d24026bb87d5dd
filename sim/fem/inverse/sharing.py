"""When one tissue model may share another's condensed inverse: its stiffness a positive multiple
of the other's (:meth:`sim.fem.TissueModel.share_inverse_with`; the biphase model's two phases)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sim.fem.model import TissueModel


def stiffness_scale(model: TissueModel, base: TissueModel) -> float | None:
    """s with K0 = s K0_base (``model`` may then take its inverse from ``base``, divided by s), or
    None: both share the mesh, the fixed dofs and the contact candidates, every element's Lame
    parameters are base's times one s, and so is the penalty."""
    if base is model or base._inverse_of is not None:
        return None
    same_structure = (
        model.mesh is base.mesh
        and np.array_equal(model.fixed_dofs, base.fixed_dofs)
        and np.array_equal(model.contact_nodes, base.contact_nodes)
    )
    if not same_structure:
        return None
    (lam, mu), (base_lam, base_mu) = model._lame, base._lame
    scale = float(mu[0] / base_mu[0])
    if not (
        scale > 0
        and np.allclose(mu, scale * base_mu, rtol=1e-12, atol=0.0)
        and np.allclose(lam, scale * base_lam, rtol=1e-12, atol=0.0)
    ):
        return None
    if model._requested_penalty is None and base._requested_penalty is None:
        return scale if model._penalty_factor == base._penalty_factor else None
    if model._requested_penalty is not None and base._requested_penalty is not None:
        ratio = model._requested_penalty / base._requested_penalty
        return scale if abs(ratio - scale) <= 1e-12 * scale else None
    return None
