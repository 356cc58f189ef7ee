"""Constants of the compiled particle-filter steps and the NumPy form of their ``exp`` (no backend imports).

The compiled steps are :mod:`.particle_numba`; the NumPy twins they are held to are the array code of
:mod:`workbench.particle_core` and :mod:`workbench.resampling`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["INV_LN2", "LN2_HI", "LN2_LO", "EXP_COEFFS", "EXP_UNDERFLOW", "poly_exp"]

# exp(x) = 2^n exp(r), n = round(x / ln 2), r = x - n ln2 with ln2 split in a high and a low part
# (Cody-Waite), so that n * LN2_HI is exact for |n| < 2^20.
INV_LN2 = 1.4426950408889634
LN2_HI = 0.6931471803691238
LN2_LO = 1.9082149292705877e-10
#: Taylor coefficients 1/k!, k = 13 ... 0 (Horner order): on |r| <= ln2 / 2 the truncation is below 1e-17,
#: so the result is within a few ulp of the library's exp.
EXP_COEFFS = tuple(1.0 / math.factorial(k) for k in range(13, -1, -1))
#: Below this argument the result is 0 (exp(-708) is about the smallest normal double): a zero weight stays
#: exactly zero, as -inf does.
EXP_UNDERFLOW = -708.0


def poly_exp(x: np.ndarray) -> np.ndarray:
    """The compiled steps' ``exp`` for ``x <= 0`` in NumPy (same steps), for tests and documentation.

    Shapes: any -> same.
    """
    x = np.asarray(x, dtype=float)
    y = np.maximum(x, EXP_UNDERFLOW)
    n = np.round(y * INV_LN2)
    r = (y - n * LN2_HI) - n * LN2_LO
    p = np.full_like(r, EXP_COEFFS[0])
    for c in EXP_COEFFS[1:]:
        p = p * r + c
    # 2^n: the biased exponent n + 1023 in bits 52..62 of an IEEE double
    with np.errstate(invalid="ignore"):  # a NaN argument: any bits, replaced below
        v = p * ((n.astype(np.int64) + 1023) << 52).view(np.float64)
    return np.where(x >= EXP_UNDERFLOW, v, np.where(x < EXP_UNDERFLOW, 0.0, x))
