"""Track-before-detect particle weights: every particle against every gated detection, weighted by each detection's
own SNR.

For run ``b``, particle ``i`` and valid measurement ``m``::

    log w_{m,i} = c_m - a_m |p_m - p_i|^2 - beta (vr_m - vr_i)^2
    c_m  = log P_D(snr_m) - 3/2 log(2 pi sigma_p,m^2) - 1/2 log(2 pi sigma_vr^2)
    a_m  = 1 / (2 sigma_p,m^2),   beta = 1 / (2 sigma_vr^2)

and the kernels return ``log sum_m w_{m,i}`` (``-inf`` for a run with no valid measurement), computed
as a streaming max/sum over ``m`` so that memory stays ``O(B N + M)``: no ``(B, N, M)`` array is formed.

Backends (all held to :func:`workbench.kernels.reference.tbd_log_weight_sums_reference`):

- ``"taichi"``: one particle per parallel iteration, two streaming passes over ``m`` (an integer max,
  which LLVM vectorises, then the sum of exponentials); runs on any Taichi arch.
- ``"numba"`` (the CPU default): particles in tiles of :data:`TILE`, a one-pass online logsumexp
  vectorised across the particles of a tile; CPU only.
- ``"numpy"``: the chunked NumPy reference.
- ``"auto"``: Numba when the arch is the CPU and Numba is installed, else Taichi.

Both compiled kernels use the same inlined polynomial ``exp`` (:func:`poly_exp`): range reduction
``x = n ln2 + r`` with ``|r| <= ln2 / 2``, a degree-11 Taylor polynomial in Horner form (relative error
below 1e-14) and ``2^n`` built by writing ``n + 1023`` into the exponent bits.  A call to ``libm``
would stop the loop from vectorising.  Kernels take plain arrays; Taichi and Numba are imported and
started on first use only.  (No ``from __future__ import annotations`` here: Taichi reads the kernel
annotations as objects.)
"""

import functools

import numpy as np

from .backend import BACKENDS, current_arch, numba_available, resolve
from .reference import tbd_log_weight_sums_reference
from .runtime import ensure_taichi

__all__ = [
    "BACKENDS",
    "TILE",
    "numba_available",
    "resolve_backend",
    "pack_points",
    "pack_measurements",
    "poly_exp",
    "tbd_log_weight_sums",
]

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


def resolve_backend(backend: str = "auto", arch: str | None = None) -> str:
    """The backend ``"auto"`` stands for (:func:`workbench.kernels.backend.resolve`)."""
    return resolve(backend, arch)


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


def tbd_log_weight_sums(points: np.ndarray, z: np.ndarray, valid: np.ndarray, log_pd: np.ndarray,
                        sigma_p: np.ndarray, sigma_vr: float, backend: str = "auto", arch: str | None = None) -> np.ndarray:
    """``log sum_m w_{m,i}`` for every particle of every run (eqs 13-14), ``-inf`` where a run has no
    valid measurement.

    Parameters
    ----------
    points : particle ``[x, y, z, vr]`` (radial velocity positive when receding)
    z : measurement ``[x, y, z, vr]``, padded; ``valid`` marks the real rows
    log_pd : ``log P_D(snr_m)``; sigma_p : isotropic position sigma of each measurement (m)
    sigma_vr : radial-velocity sigma (m/s)
    backend, arch : see the module docstring

    Shapes
    ------
    points : (B, N, 4); z : (B, M, 4); valid, log_pd, sigma_p : (B, M); returns (B, N)
    """
    which = resolve_backend(backend, arch)
    if which == "numpy":
        return tbd_log_weight_sums_reference(points, z, valid, log_pd, sigma_p, sigma_vr)
    pts = pack_points(points)
    meas, counts = pack_measurements(z, valid, log_pd, sigma_p, sigma_vr)
    B, _, N = pts.shape
    out = np.zeros((B, N))
    beta = 0.5 / float(sigma_vr) ** 2
    if B and N and meas.shape[2]:
        if which == "numba":
            parallel, serial = _numba_kernel()
            (parallel if B * N * int(counts.max()) >= SERIAL_PAIRS else serial)(pts, meas, counts, beta, out)
        else:
            ensure_taichi(current_arch() if arch is None else arch)
            _taichi_kernel()(pts, meas, counts, beta, out)
    out[counts == 0] = -np.inf
    return out


# -- Taichi ---------------------------------------------------------------------------------------


@functools.cache
def _taichi_kernel():
    import taichi as ti

    # Every constant goes through ti.f64(...) in Taichi scope: a bare literal would take default_fp (f32).
    @ti.func
    def fexp(x):
        x = ti.max(x, ti.f64(EXP_FLOOR))
        n = ti.round(x * ti.f64(INV_LN2))
        r = x - n * ti.f64(LN2_HI) - n * ti.f64(LN2_LO)
        p = ti.f64(EXP_COEFFS[0])
        for k in ti.static(range(1, len(EXP_COEFFS))):
            p = p * r + ti.f64(EXP_COEFFS[k])
        return p * ti.bit_cast((ti.cast(n, ti.i64) + 1023) << 52, ti.f64)

    @ti.func
    def log_w(meas: ti.template(), b, m, px, py, pz, pv, beta):
        dx = meas[b, 0, m] - px
        dy = meas[b, 1, m] - py
        dz = meas[b, 2, m] - pz
        dv = meas[b, 3, m] - pv
        # log w = c_m - a_m |p_m - p_i|^2 - beta (vr_m - vr_i)^2
        return meas[b, 4, m] - meas[b, 5, m] * (dx * dx + dy * dy + dz * dz) - beta * dv * dv

    @ti.kernel
    def kernel(pts: ti.types.ndarray(dtype=ti.f64, ndim=3), meas: ti.types.ndarray(dtype=ti.f64, ndim=3),
               counts: ti.types.ndarray(dtype=ti.i32, ndim=1), beta: ti.f64,
               out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for b, i in ti.ndrange(pts.shape[0], pts.shape[2]):
            px, py, pz, pv = pts[b, 0, i], pts[b, 1, i], pts[b, 2, i], pts[b, 3, i]
            M = counts[b]
            # pass 1: an upper bound within 2 of max_m log w, as an integer max (vectorises, unlike an
            # f64 max reduction under Taichi's fast-math flags)
            top = ti.i64(-(1 << 62))
            for m in range(M):
                top = ti.max(top, ti.cast(ti.max(log_w(meas, b, m, px, py, pz, pv, beta), ti.f64(-1e18)), ti.i64))
            shift = ti.cast(top, ti.f64) + ti.f64(1.0)
            # pass 2: sum_m exp(log w - shift), every term <= 1 and the largest >= e^-2
            s = ti.f64(0.0)
            for m in range(M):
                s += fexp(log_w(meas, b, m, px, py, pz, pv, beta) - shift)
            if M > 0:
                out[b, i] = shift + ti.log(s)

    return kernel


# -- Numba (the CPU default) ---------------------------------------------------------------------


def _numba_kernel():
    from .tbd_weights_numba import parallel, serial

    return parallel, serial
