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
ORIENT3D_ACCURACY = 1e-9
"""orient3d recomputes a value exactly where its error bound exceeds this share of its magnitude."""


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


def orient3d_integer(a: NDArray, b: NDArray, c: NDArray, d: NDArray) -> tuple[int, int]:
    """Exact orient3d of four points given as float (3,) arrays, as ``(numerator, denominator)``
    Python integers (the value is their ratio; the denominator is positive).

    Every float is an integer times a power of two, so scaling all twelve coordinates by the
    largest of their denominators makes them integers, and the determinant of the differences is
    an integer over that scale cubed: exact, and about seven times faster than rationals.
    """
    ratios = [float(x).as_integer_ratio() for point in (a, b, c, d) for x in point]
    scale = max(denominator for _, denominator in ratios)  # powers of two: the largest is their lcm
    ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = (
        numerator * (scale // denominator) for numerator, denominator in ratios
    )
    adx, ady, adz = ax - dx, ay - dy, az - dz
    bdx, bdy, bdz = bx - dx, by - dy, bz - dz
    cdx, cdy, cdz = cx - dx, cy - dy, cz - dz
    determinant = (
        adx * (bdy * cdz - bdz * cdy) + bdx * (cdy * adz - cdz * ady) + cdx * (ady * bdz - adz * bdy)
    )
    return determinant, scale**3


def orient3d_exact(a: NDArray, b: NDArray, c: NDArray, d: NDArray) -> Fraction:
    """Exact orient3d of four points given as float (3,) arrays."""
    return Fraction(*orient3d_integer(a, b, c, d))


def orient3d(
    a: NDArray, b: NDArray, c: NDArray, d: NDArray, relative_accuracy: float = ORIENT3D_ACCURACY
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
            numerator, denominator = orient3d_integer(a[k], b[k], c[k], d[k])
            det[k] = numerator / denominator  # integer division rounds correctly
            sign[k] = (numerator > 0) - (numerator < 0)
    return det, sign
