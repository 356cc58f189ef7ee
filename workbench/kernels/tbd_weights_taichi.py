"""The Taichi version of the track-before-detect weight kernel (any Taichi arch), held to the NumPy reference.
(No ``from __future__ import annotations``: Taichi reads the kernel annotations as objects.)"""

import functools

from .tbd_weights_numpy import EXP_COEFFS, EXP_FLOOR, INV_LN2, LN2_HI, LN2_LO

# -- the kernel ---------------------------------------------------------------------------------------


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
