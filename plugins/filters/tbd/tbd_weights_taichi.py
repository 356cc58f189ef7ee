"""The Taichi version of the track-before-detect weight kernel (any Taichi arch), in float64 and float32, held to
the NumPy reference.  The packed layouts and the base-2 arithmetic are those of :mod:`.tbd_weights_numpy`.
(No ``from __future__ import annotations``: Taichi reads the kernel annotations as objects.)"""

import functools

from .tbd_weights_numpy import EXP2_COEFFS, EXP2_COEFFS_F32, EXP2_FLOOR, EXP2_FLOOR_F32, LN2

# -- the kernels --------------------------------------------------------------------------------------


@functools.cache
def _taichi_kernel(precision: str = "float64"):
    import taichi as ti

    if precision == "float32":
        return _float32(ti)
    return _float64(ti)


def _float64(ti):
    # Every constant goes through ti.f64(...) in Taichi scope: a bare literal would take default_fp (f32).
    @ti.func
    def fexp2(x):
        x = ti.max(x, ti.f64(EXP2_FLOOR))
        n = ti.round(x)
        f = x - n
        p = ti.f64(EXP2_COEFFS[0])
        for k in ti.static(range(1, len(EXP2_COEFFS))):
            p = p * f + ti.f64(EXP2_COEFFS[k])
        return p * ti.bit_cast((ti.cast(n, ti.i64) + 1023) << 52, ti.f64)

    @ti.func
    def log2_w(pts: ti.template(), meas: ti.template(), b, i, m):
        # log2 w = C_m + T_m . q_i + u_m vr_i - A_m |q_i|^2 + K_i
        return (meas[b, 5, m] + meas[b, 0, m] * pts[b, 0, i] + meas[b, 1, m] * pts[b, 1, i]
                + meas[b, 2, m] * pts[b, 2, i] + meas[b, 3, m] * pts[b, 3, i] + meas[b, 4, m] * pts[b, 4, i]
                + pts[b, 5, i])

    @ti.kernel
    def kernel(pts: ti.types.ndarray(dtype=ti.f64, ndim=3), meas: ti.types.ndarray(dtype=ti.f64, ndim=3),
               counts: ti.types.ndarray(dtype=ti.i32, ndim=1), beta2: ti.f64,
               out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for b, i in ti.ndrange(pts.shape[0], pts.shape[2]):
            M = counts[b]
            # pass 1: an upper bound within 2 of max_m log2 w, as an integer max (vectorises, unlike an
            # f64 max reduction under Taichi's fast-math flags)
            top = ti.i64(-(1 << 62))
            for m in range(M):
                top = ti.max(top, ti.cast(ti.max(log2_w(pts, meas, b, i, m), ti.f64(-1e18)), ti.i64))
            shift = ti.cast(top, ti.f64) + ti.f64(1.0)
            # pass 2: sum_m 2^(log2 w - shift), every term <= 1 and the largest >= 2^-2
            s = ti.f64(0.0)
            for m in range(M):
                s += fexp2(log2_w(pts, meas, b, i, m) - shift)
            if M > 0:
                out[b, i] = ti.f64(LN2) * (shift + ti.log(s) * ti.f64(1.0 / LN2))

    return kernel


def _float32(ti):
    @ti.func
    def fexp2(x):
        x = ti.max(x, ti.f32(EXP2_FLOOR_F32))
        n = ti.round(x)
        f = x - n
        p = ti.f32(EXP2_COEFFS_F32[0])
        for k in ti.static(range(1, len(EXP2_COEFFS_F32))):
            p = p * f + ti.f32(EXP2_COEFFS_F32[k])
        return p * ti.bit_cast((ti.cast(n, ti.i32) + 127) << 23, ti.f32)

    @ti.func
    def log2_w(pts: ti.template(), meas: ti.template(), b, i, m, beta2):
        dx = meas[b, 0, m] - pts[b, 0, i]
        dy = meas[b, 1, m] - pts[b, 1, i]
        dz = meas[b, 2, m] - pts[b, 2, i]
        dv = meas[b, 3, m] - pts[b, 3, i]
        # log2 w = c_m/ln2 - (a_m/ln2) |q_m - q_i|^2 - (beta/ln2) (vr_m - vr_i)^2
        return meas[b, 4, m] - meas[b, 5, m] * (dx * dx + dy * dy + dz * dz) - beta2 * dv * dv

    @ti.kernel
    def kernel(pts: ti.types.ndarray(dtype=ti.f32, ndim=3), meas: ti.types.ndarray(dtype=ti.f32, ndim=3),
               counts: ti.types.ndarray(dtype=ti.i32, ndim=1), beta2: ti.f64,
               out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for b, i in ti.ndrange(pts.shape[0], pts.shape[2]):
            M = counts[b]
            b32 = ti.cast(beta2, ti.f32)
            top = ti.i32(-(1 << 30))
            for m in range(M):
                top = ti.max(top, ti.cast(ti.max(log2_w(pts, meas, b, i, m, b32), ti.f32(-1e9)), ti.i32))
            shift = ti.cast(top, ti.f32) + ti.f32(1.0)
            s = ti.f32(0.0)
            for m in range(M):
                s += fexp2(log2_w(pts, meas, b, i, m, b32) - shift)
            if M > 0:
                out[b, i] = ti.f64(LN2) * (ti.cast(shift, ti.f64) + ti.log(ti.cast(s, ti.f64)) * ti.f64(1.0 / LN2))

    return kernel
