"""Robust orientation predicate, vectorised, exact where floating point is unsure.

``orient3d(a, b, c, d) = det[a - d, b - d, c - d]`` (six times the signed volume of
the tetrahedron abcd). Computed in floating point with Shewchuk's static error
bound; the few cases whose sign the bound cannot certify (including exact zeros,
the degenerate cases) are recomputed in exact rational arithmetic.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

_EPSILON = 2.0**-53
# Shewchuk, "Adaptive precision floating-point arithmetic and fast robust
# geometric predicates" (1997): orient3d's first error bound.
ORIENT3D_BOUND = (7.0 + 56.0 * _EPSILON) * _EPSILON


def orient3d_fast(a: NDArray, b: NDArray, c: NDArray, d: NDArray) -> tuple[NDArray, NDArray]:
    """Floating-point orient3d over broadcast (..., 3) inputs and its error bound."""
    # Columns taken once and each 2x2 product computed once, for the determinant and its
    # permanent alike: the same floating-point operations as the textbook form, a third fewer
    # array operations (which is what a call costs for the few pairs the global CD tests).
    ad, bd, cd = a - d, b - d, c - d
    adx, ady, adz = ad[..., 0], ad[..., 1], ad[..., 2]
    bdx, bdy, bdz = bd[..., 0], bd[..., 1], bd[..., 2]
    cdx, cdy, cdz = cd[..., 0], cd[..., 1], cd[..., 2]
    b_c, c_b = bdy * cdz, bdz * cdy
    c_a, a_c = cdy * adz, cdz * ady
    a_b, b_a = ady * bdz, adz * bdy
    det = adx * (b_c - c_b) + bdx * (c_a - a_c) + cdx * (a_b - b_a)
    abs_ = np.abs
    permanent = (
        abs_(adx) * (abs_(b_c) + abs_(c_b))
        + abs_(bdx) * (abs_(c_a) + abs_(a_c))
        + abs_(cdx) * (abs_(a_b) + abs_(b_a))
    )
    return det, ORIENT3D_BOUND * permanent


def orient3d_exact(a: NDArray, b: NDArray, c: NDArray, d: NDArray) -> Fraction:
    """Exact orient3d of four points given as float (3,) arrays."""
    pa, pb, pc, pd = ([Fraction(float(x)) for x in p] for p in (a, b, c, d))
    ad = [pa[i] - pd[i] for i in range(3)]
    bd = [pb[i] - pd[i] for i in range(3)]
    cd = [pc[i] - pd[i] for i in range(3)]
    return (
        ad[0] * (bd[1] * cd[2] - bd[2] * cd[1])
        + bd[0] * (cd[1] * ad[2] - cd[2] * ad[1])
        + cd[0] * (ad[1] * bd[2] - ad[2] * bd[1])
    )


def orient3d(
    a: NDArray, b: NDArray, c: NDArray, d: NDArray, relative_accuracy: float = 1e-9
) -> tuple[NDArray, NDArray]:
    """(value, sign) of orient3d over broadcast (K, 3) inputs; the sign is exact.

    ``sign`` is -1, 0 or +1 exactly. ``value`` is the floating-point determinant,
    recomputed exactly (then rounded) wherever its error bound exceeds
    ``relative_accuracy`` of its magnitude: near-degenerate configurations, where
    cancellation would otherwise spoil ratios such as barycentric coordinates.
    """
    det, bound = orient3d_fast(a, b, c, d)
    sign = np.sign(det).astype(np.int8)
    (unsure,) = np.nonzero(~(np.abs(det) * relative_accuracy > bound))
    if unsure.size:
        a, b, c, d = np.broadcast_arrays(a, b, c, d)
        for k in unsure:
            exact = orient3d_exact(a[k], b[k], c[k], d[k])
            det[k] = float(exact)
            sign[k] = (exact > 0) - (exact < 0)
    return det, sign
