"""NumPy references that every compiled kernel of :mod:`workbench.kernels` is held to.

Written from the formulas with SciPy's own densities and ``logsumexp`` (not from the kernels'
algebra), and chunked over particles so that memory stays ``O(chunk * M)`` however large ``N`` is.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp
from scipy.stats import norm

__all__ = ["tbd_log_weight_sums_reference", "naive_log_weight_sums", "kernel_inputs"]


def tbd_log_weight_sums_reference(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                                  sigma_p: np.ndarray, sigma_vr: float, chunk: int = 4096) -> np.ndarray:
    """Per particle, ``log sum_m w_{m,i}`` over the valid measurements of its run (the track-before-detect weights).

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


def kernel_inputs(particles: int, measurements: int, batch: int = 1, seed: int = 0):
    """Random but realistic inputs of the weight kernel: a cloud around a target at ~35 km and detections around
    it (the test and benchmark inputs)."""
    rng = np.random.default_rng(seed)
    centre = np.array([35e3, 2e3, 2e3, -200.0])
    points = centre + rng.normal(size=(batch, particles, 4)) * [300.0, 300.0, 300.0, 20.0]
    z = centre + rng.normal(size=(batch, measurements, 4)) * [1000.0, 1000.0, 1000.0, 150.0]
    valid = np.ones((batch, measurements), dtype=bool)
    log_pd = np.log(rng.uniform(1e-3, 1.0, (batch, measurements)))
    sigma_p = rng.uniform(40.0, 700.0, (batch, measurements))
    return points, z, valid, log_pd, sigma_p, 15.0


def naive_log_weight_sums(points, z, valid, log_pd, sigma_p, sigma_vr):
    """The straightforward NumPy broadcast: the whole ``(B, N, M)`` array of log-weights, then logsumexp."""


    d2 = np.sum((z[:, None, :, :3] - points[:, :, None, :3]) ** 2, axis=-1)
    dv2 = (z[:, None, :, 3] - points[:, :, None, 3]) ** 2
    var = sigma_p[:, None, :] ** 2
    log_w = (log_pd[:, None, :] - 1.5 * np.log(2 * np.pi * var) - 0.5 * d2 / var
             - 0.5 * np.log(2 * np.pi * sigma_vr**2) - 0.5 * dv2 / sigma_vr**2)
    return logsumexp(np.where(valid[:, None, :], log_w, -np.inf), axis=2)
