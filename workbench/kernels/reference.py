"""NumPy references that every compiled kernel of :mod:`workbench.kernels` is held to.

Written from the formulas with SciPy's own densities and ``logsumexp`` (not from the kernels'
algebra), and chunked over particles so that memory stays ``O(chunk * M)`` however large ``N`` is.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp
from scipy.stats import norm

__all__ = ["tbd_log_weight_sums_reference"]


def tbd_log_weight_sums_reference(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                                  sigma_p: np.ndarray, sigma_vr: float, chunk: int = 4096) -> np.ndarray:
    """Per particle, ``log sum_m w_{m,i}`` over the valid measurements of its run (method C, eqs 13-14).

    ``w_{m,i} = P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr_i, sigma_vr^2)``; a run without any
    valid measurement gives ``-inf`` for every particle.

    Shapes
    ------
    points : (B, N, 4)  particle ``[x, y, z, vr]``
    z : (B, M, 4)  measurement ``[x, y, z, vr]``
    valid : (B, M) bool
    log_pd, sigma_p : (B, M)
    returns : (B, N)
    """
    points = np.asarray(points, dtype=float)
    z = np.asarray(z, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    B, N, _ = points.shape
    out = np.full((B, N), -np.inf)
    for b in range(B):
        keep = valid[b]
        if not keep.any():
            continue
        zb, sp, lpd = z[b, keep], sigma_p[b, keep], log_pd[b, keep]
        for lo in range(0, N, chunk):
            p = points[b, lo:lo + chunk]
            # log w_{m,i} = log P_D + sum_axes log N(p_m,axis; p_i,axis, sigma_p,m) + log N(vr_m; vr_i, sigma_vr)
            log_w = (lpd[None, :]
                     + norm.logpdf(zb[None, :, 0], p[:, None, 0], sp[None, :])
                     + norm.logpdf(zb[None, :, 1], p[:, None, 1], sp[None, :])
                     + norm.logpdf(zb[None, :, 2], p[:, None, 2], sp[None, :])
                     + norm.logpdf(zb[None, :, 3], p[:, None, 3], sigma_vr))
            out[b, lo:lo + chunk] = logsumexp(log_w, axis=1)
    return out
