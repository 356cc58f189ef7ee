"""The select-only ``atan2`` the compiled particle kernels share (the bootstrap filter's range-bearing likelihood in
:mod:`.particle_numba`, the CRPF step of the ``crpf`` filter plugin): its coefficients and the NumPy twin
:func:`atan2_poly` the compiled ``atan2`` is held to."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ATAN_C", "TAN_PI_8", "atan2_poly", "atan_reduced"]


#: atan(t) = t + t z P(z), z = t^2, on |t| <= tan(pi/8): P of degree 10, ``ATAN_C[k]`` the coefficient of z^k.
#: A least-squares fit of ``(atan(sqrt z) - sqrt z) / z^1.5`` at 200 Chebyshev nodes of [0, tan(pi/8)^2], in
#: 50-digit arithmetic (mpmath): 9.4e-17 relative on P, so the rounding of the evaluation (about an ulp) is the
#: error.  (A polynomial in place of Cephes' rational P/Q: one division fewer per call.)
ATAN_C = (-0.3333333333333333, 0.19999999999995652, -0.1428571428469138, 0.11111111017100327,
          -0.0909090464769568, 0.07692184699371778, -0.06664531369805009, 0.05858311810501153,
          -0.05086254885823143, 0.039253696320618564, -0.01920252926841228)
TAN_PI_8 = 0.41421356237309504880


c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10 = ATAN_C


def atan_reduced(t):
    """``atan t`` for ``|t| <= tan(pi/8)``: ``t + t z P(z)``, P by Estrin's scheme (a short dependency chain).
    Plain arithmetic, so the one expression serves NumPy arrays here and the Numba kernels (compiled from this
    function: :func:`workbench.kernels.particle_numba.atan2`), the same operations in the same order."""
    z = t * t
    z2 = z * z
    z4 = z2 * z2
    z8 = z4 * z4
    p = (((c0 + c1 * z) + (c2 + c3 * z) * z2) + ((c4 + c5 * z) + (c6 + c7 * z) * z2) * z4
         + ((c8 + c9 * z) + c10 * z2) * z8)
    return t + t * z * p


def atan2_poly(y, x):
    """``atan2(y, x)`` by range reduction and :func:`atan_reduced`, written with selects only.

    The NumPy twin of the Numba kernels' ``atan2`` (a library ``atan2`` call per particle does not vectorise; this
    does), the same operations in the same order.  Reduction: with ``mx = max(|x|, |y|)``, ``mn = min(|x|, |y|)``,
    ``t = mn / mx``, or where ``mn > tan(pi/8) mx``, ``t = (mn - mx) / (mn + mx)`` and ``atan(mn / mx) = pi/4 +
    atan t`` (one division either way), so ``|t| <= tan(pi/8)``; then the octant (``pi/2 - .``), the half plane
    (``pi - .``) and the sign of ``y``, signed zeros as the library's atan2.
    """
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    ax, ay = np.abs(x), np.abs(y)
    swap = ay > ax
    mx = np.where(swap, ay, ax)
    mn = np.where(swap, ax, ay)
    big = mn > TAN_PI_8 * mx
    num = np.where(big, mn - mx, mn)
    den = np.where(big, mn + mx, mx)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = num / np.where(den > 0.0, den, 1.0)
    r = atan_reduced(t) + np.where(big, 0.25 * math.pi, 0.0)
    r = np.where(swap, 0.5 * math.pi - r, r)
    r = np.where(np.signbit(x), math.pi - r, r)  # signbit: atan2(+-0, -0) = +-pi, as the library's
    return np.copysign(r, y)
