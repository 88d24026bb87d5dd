"""Dense LAPACK calls through the same BLAS that CHOLMOD uses.

SciPy's wheels carry their own OpenBLAS; CHOLMOD links the system one. Two
thread pools on a 2-core machine spin against each other for ~0.1 s after each
call, so the dense inverse that follows a CHOLMOD factorisation runs ~30 %
slower through SciPy. We call ``dpotri`` from the system LAPACK (the library
CHOLMOD is linked to) when it can be loaded, and SciPy's otherwise.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import cache

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack as scipy_lapack


@cache
def _system_lapack() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("lapack")
    if name is None:
        return None
    try:
        library = ctypes.CDLL(name)
        library.dpotri_  # noqa: B018 - probe the symbol
    except (OSError, AttributeError):
        return None
    return library


def potri_lower(factor: NDArray[np.float64]) -> tuple[NDArray[np.float64], int]:
    """Inverse (lower triangle valid) of A = L L^T from its Fortran-ordered factor L, in place."""
    library = _system_lapack()
    if library is None or not factor.flags.f_contiguous or factor.dtype != np.float64:
        inverse, info = scipy_lapack.dpotri(factor, lower=1, overwrite_c=1)
        return inverse, int(info)
    n = ctypes.c_int(factor.shape[0])
    info = ctypes.c_int(0)
    library.dpotri_(
        ctypes.byref(ctypes.c_char(b"L")),
        ctypes.byref(n),
        factor.ctypes.data_as(ctypes.c_void_p),
        ctypes.byref(n),
        ctypes.byref(info),
    )
    return factor, info.value
