"""The select-only ``atan2`` the compiled particle kernels share (the bootstrap filter's range-bearing likelihood in
:mod:`.particle_numba`, the CRPF step of the ``crpf`` filter plugin): Cephes' coefficients and the NumPy twin
:func:`atan2_poly` the compiled ``atan2`` is held to."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ATAN_P", "ATAN_Q", "TAN_PI_8", "atan2_poly"]


#: Cephes' rational approximation of atan on |t| <= 0.66: atan(t) = t + t z P(z) / Q(z), z = t^2
#: (Q monic); about 1 ulp in float64.
ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
          -1.228866684490136173410e2, -6.485021904942025371773e1)
ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
          4.853903996359136964868e2, 1.945506571482613964425e2)
TAN_PI_8 = 0.41421356237309504880


def atan2_poly(y, x):
    """``atan2(y, x)`` by range reduction and :data:`ATAN_P` / :data:`ATAN_Q`, written with selects only.

    The NumPy twin of the Numba kernel's ``atan2`` (a library ``atan2`` call per particle does not
    vectorise; this does).  Reduction: ``a = min(|x|, |y|) / max(|x|, |y|)`` in [0, 1]; above
    tan(pi/8), ``t = (a - 1) / (a + 1)`` and ``atan a = pi/4 + atan t``, so ``|t| <= tan(pi/8)``; then
    the octant (``pi/2 - .``), the half plane (``pi - .``) and the sign of ``y``, signed zeros as the library's atan2.
    """
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    ax, ay = np.abs(x), np.abs(y)
    swap = ay > ax
    mx = np.where(swap, ay, ax)
    mn = np.where(swap, ax, ay)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = mn / np.where(mx > 0.0, mx, 1.0)
        big = a > TAN_PI_8
        t = np.where(big, a - 1.0, a) / np.where(big, a + 1.0, 1.0)
    z = t * t
    p0, p1, p2, p3, p4 = ATAN_P
    q0, q1, q2, q3, q4 = ATAN_Q
    r = t + t * z * ((((p0 * z + p1) * z + p2) * z + p3) * z + p4) / (((((z + q0) * z + q1) * z + q2) * z + q3) * z + q4)
    r = r + np.where(big, 0.25 * math.pi, 0.0)
    r = np.where(swap, 0.5 * math.pi - r, r)
    r = np.where(np.signbit(x), math.pi - r, r)  # signbit: atan2(+-0, -0) = +-pi, as the library's
    return np.copysign(r, y)
