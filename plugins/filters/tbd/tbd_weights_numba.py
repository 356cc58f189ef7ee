"""The Numba backend of :func:`workbench_filters.tbd.tbd_weights.tbd_log_weight_sums` (imported only when used).

Module-level functions, so that Numba's on-disk cache holds across processes (a kernel made in a
factory is a closure, whose cache key changes from process to process: every process compiled it
anew, about 2.7 s).  ``parallel`` and ``serial`` are the same loops compiled threaded and serial;
``parallel32`` and ``serial32`` the single-precision kernel.  The packed layouts are those of
:mod:`.tbd_weights_numpy`.  The loops vectorise with the CPU's full width (:mod:`workbench.kernels.vector_width`: eight doubles,
sixteen singles on AVX-512; 1.5x the throughput of LLVM's 256-bit default, bit for bit the same float64 weights).
"""

import types as pytypes

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from workbench.kernels.vector_width import wide_vectors

from .tbd_weights_numpy import EXP2_COEFFS, EXP2_COEFFS_F32, EXP2_FLOOR, EXP2_FLOOR_F32, LN2, TILE


@intrinsic
def as_double(typingctx, bits):  # reinterpret int64 bits as float64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@intrinsic
def as_single(typingctx, bits):  # reinterpret int32 bits as float32
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float32))

    return types.float32(types.int32), codegen


c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11 = EXP2_COEFFS
s0, s1, s2, s3, s4, s5, s6 = (np.float32(c) for c in EXP2_COEFFS_F32)
floor, floor32, tile, ln2 = EXP2_FLOOR, np.float32(EXP2_FLOOR_F32), TILE, LN2
one32, zero32, low32 = np.float32(1.0), np.float32(0.0), np.float32(-1e30)
i127, i23, half32 = np.int32(127), np.int32(23), np.float32(0.5)
# Fast-math without 'ninf'/'nnan': -inf never enters the kernel, but we do not let LLVM assume it.
flags = {"contract", "reassoc", "nsz", "arcp", "afn"}


@numba.njit(inline="always", fastmath=flags)
def fexp2(x):
    """``2^x`` for ``x <= 0`` (:func:`.tbd_weights_numpy.poly_exp2`)."""
    x = max(x, floor)
    # n = round(x) for x <= 0: truncating x - 1/2 toward zero (one conversion instruction each way)
    k = np.int64(x - 0.5)
    f = x - np.float64(k)
    p = ((((((((((c0 * f + c1) * f + c2) * f + c3) * f + c4) * f + c5) * f + c6) * f + c7) * f + c8) * f + c9)
         * f + c10) * f + c11
    return p * as_double((k + 1023) << 52)


@numba.njit(inline="always", fastmath=flags)
def fexp2_32(x):
    """``2^x`` for ``x <= 0`` in single precision (:func:`.tbd_weights_numpy.poly_exp2`, ``"float32"``)."""
    x = max(x, floor32)
    k = np.int32(x - half32)
    f = x - np.float32(k)
    p = (((((s0 * f + s1) * f + s2) * f + s3) * f + s4) * f + s5) * f + s6
    return p * as_single((k + i127) << i23)


def kernel(pts, meas, counts, out):
    B = pts.shape[0]
    N = pts.shape[2]
    tiles = (N + tile - 1) // tile
    for job in numba.prange(B * tiles):
        wide_vectors()  # eight doubles per vector where the CPU has AVX-512 (LLVM's tuning prefers four)
        b = job // tiles
        lo = (job % tiles) * tile
        hi = min(lo + tile, N)
        n = hi - lo
        qx = pts[b, 0, lo:hi]
        qy = pts[b, 1, lo:hi]
        qz = pts[b, 2, lo:hi]
        qv = pts[b, 3, lo:hi]
        qq = pts[b, 4, lo:hi]
        kv = pts[b, 5, lo:hi]
        top = np.full(n, -1e300)  # running max of log2 w per particle
        s = np.zeros(n)  # running sum of 2^(log2 w - top)
        for m in range(counts[b]):
            tx, ty, tz, tv, na, cm = meas[b, 0, m], meas[b, 1, m], meas[b, 2, m], meas[b, 3, m], meas[b, 4, m], \
                meas[b, 5, m]
            for j in range(n):
                # log2 w = C_m + T_m . q_i + u_m vr_i - A_m |q_i|^2 + K_i
                lw = cm + tx * qx[j] + ty * qy[j] + tz * qz[j] + tv * qv[j] + na * qq[j] + kv[j]
                # online logsumexp: one exp per pair, rescaling the sum when the max moves up
                d = lw - top[j]
                e = fexp2(-abs(d))
                s[j] = s[j] * e + 1.0 if d > 0.0 else s[j] + e
                top[j] = max(top[j], lw)
        if counts[b] > 0:
            for j in range(n):
                out[b, lo + j] = ln2 * (top[j] + np.log2(s[j]))


def kernel32(pts, meas, counts, beta2, out):
    B = pts.shape[0]
    N = pts.shape[2]
    tiles = (N + tile - 1) // tile
    for job in numba.prange(B * tiles):
        wide_vectors()
        b = job // tiles
        lo = (job % tiles) * tile
        hi = min(lo + tile, N)
        n = hi - lo
        px = pts[b, 0, lo:hi]
        py = pts[b, 1, lo:hi]
        pz = pts[b, 2, lo:hi]
        pv = pts[b, 3, lo:hi]
        top = np.full(n, low32)
        s = np.zeros(n, dtype=np.float32)
        for m in range(counts[b]):
            zx, zy, zz, zv, cm, am = meas[b, 0, m], meas[b, 1, m], meas[b, 2, m], meas[b, 3, m], meas[b, 4, m], \
                meas[b, 5, m]
            for j in range(n):
                dx = zx - px[j]
                dy = zy - py[j]
                dz = zz - pz[j]
                dv = zv - pv[j]
                # log2 w = c_m/ln2 - (a_m/ln2) |q_m - q_i|^2 - (beta/ln2) (vr_m - vr_i)^2
                lw = cm - am * (dx * dx + dy * dy + dz * dz) - beta2 * dv * dv
                d = lw - top[j]
                e = fexp2_32(-abs(d))
                s[j] = s[j] * e + one32 if d > zero32 else s[j] + e
                top[j] = max(top[j], lw)
        if counts[b] > 0:
            for j in range(n):
                out[b, lo + j] = ln2 * (np.float64(top[j]) + np.log2(np.float64(s[j])))


def _renamed(fn, name: str):
    """``fn``'s code under another name: Numba's cache tells functions apart by name and bytecode, not by
    compile flags, so the serial and the threaded compilations of one function would share an entry."""
    out = pytypes.FunctionType(fn.__code__.replace(co_name=name), fn.__globals__, name)
    out.__qualname__ = name
    return out


# The same loops compiled twice: threaded for real work, serial for small calls, where waking the
# thread pool costs more than the work (milliseconds on a loaded machine); prange is range there.
parallel = numba.njit(parallel=True, fastmath=flags, cache=True)(kernel)
serial = numba.njit(parallel=False, fastmath=flags, cache=True)(_renamed(kernel, "kernel_serial"))
parallel32 = numba.njit(parallel=True, fastmath=flags, cache=True)(kernel32)
serial32 = numba.njit(parallel=False, fastmath=flags, cache=True)(_renamed(kernel32, "kernel32_serial"))
