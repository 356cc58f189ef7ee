"""Constants and array packing shared by every backend of the track-before-detect weight kernel, and the NumPy
form of its polynomial ``exp`` (no backend imports).  The dispatcher is :mod:`.tbd_weights`; the reference every
backend is held to is :func:`.reference.tbd_log_weight_sums_reference`."""

from __future__ import annotations

import numpy as np

__all__ = ["TILE", "SERIAL_PAIRS", "INV_LN2", "LN2_HI", "LN2_LO", "EXP_COEFFS", "EXP_FLOOR", "poly_exp", "pack_points",
           "pack_measurements"]

#: Particles per tile of the Numba kernel (its per-tile accumulators stay in L1).
TILE = 128

#: Below this many particle-measurement pairs the Numba kernel runs on one thread.
SERIAL_PAIRS = 2_000_000

# exp(x) = 2^n exp(r), n = round(x / ln 2), r = x - n ln2 with ln2 split in a high and a low part
# (Cody-Waite), so that n * LN2_HI is exact for |n| < 2^20.
INV_LN2 = 1.4426950408889634
LN2_HI = 0.6931471803691238
LN2_LO = 1.9082149292705877e-10
#: Taylor coefficients 1/k!, k = 11 ... 0 (Horner order).
EXP_COEFFS = tuple(1.0 / float(np.prod(np.arange(1, k + 1))) for k in range(11, -1, -1))
#: Arguments below this are clamped: exp(-708) is the smallest normal double's order of magnitude.
EXP_FLOOR = -708.0


def poly_exp(x: np.ndarray) -> np.ndarray:
    """The kernels' ``exp`` for ``x <= 0`` in NumPy (same steps), for tests and documentation.

    Shapes: any -> same.
    """
    x = np.maximum(np.asarray(x, dtype=float), EXP_FLOOR)
    n = np.round(x * INV_LN2)
    r = x - n * LN2_HI - n * LN2_LO
    p = np.full_like(r, EXP_COEFFS[0])
    for c in EXP_COEFFS[1:]:
        p = p * r + c
    # 2^n: the biased exponent n + 1023 in bits 52..62 of an IEEE double
    return p * ((n.astype(np.int64) + 1023) << 52).view(np.float64)


def pack_points(points: np.ndarray) -> np.ndarray:
    """Particles ``[x, y, z, vr]`` as contiguous structure-of-arrays rows.

    Shapes: ``points (B, N, 4)`` -> ``(B, 4, N)``.
    """
    return np.ascontiguousarray(np.swapaxes(np.asarray(points, dtype=np.float64), 1, 2))


def pack_measurements(z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray, sigma_p: np.ndarray,
                      sigma_vr: float) -> tuple[np.ndarray, np.ndarray]:
    """Valid measurements moved to the front, as rows ``[x, y, z, vr, c_m, a_m]``, plus their counts.

    Shapes
    ------
    z : (B, M, 4); valid, log_pd, sigma_p : (B, M)
    returns : ``meas (B, 6, M')`` with ``M' = max count`` and ``counts (B,)`` int32
    """
    valid = np.asarray(valid, dtype=bool)
    B, M = valid.shape
    counts = valid.sum(axis=1).astype(np.int32)
    width = int(counts.max()) if B and M else 0
    order = np.argsort(~valid, axis=1, kind="stable")[:, :width]  # valid rows first, in their order
    take = lambda a: np.take_along_axis(np.asarray(a, dtype=np.float64), order, axis=1)  # noqa: E731
    zz = np.take_along_axis(np.asarray(z, dtype=np.float64), order[..., None], axis=1)
    var_p = take(sigma_p) ** 2
    meas = np.empty((B, 6, width))
    meas[:, :4] = np.swapaxes(zz, 1, 2)
    # c_m = log P_D - 3/2 log(2 pi sigma_p^2) - 1/2 log(2 pi sigma_vr^2)
    meas[:, 4] = take(log_pd) - 1.5 * np.log(2.0 * np.pi * var_p) - 0.5 * np.log(2.0 * np.pi * sigma_vr**2)
    # a_m = 1 / (2 sigma_p^2)
    meas[:, 5] = 0.5 / var_p
    live = np.arange(width)[None, :] < counts[:, None]
    meas[:, 4] = np.where(live, meas[:, 4], 0.0)  # padding: harmless finite values, never read
    meas[:, 5] = np.where(live, meas[:, 5], 0.0)
    return np.ascontiguousarray(meas), counts
