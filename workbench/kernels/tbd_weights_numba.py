"""The Numba backend of :func:`workbench.kernels.tbd_weights.tbd_log_weight_sums` (imported only when used).

Module-level functions, so that Numba's on-disk cache holds across processes (a kernel made in a
factory is a closure, whose cache key changes from process to process: every process compiled it
anew, about 2.7 s).  ``parallel`` and ``serial`` are the same loops compiled threaded and serial.
"""

import types as pytypes

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from .tbd_weights_numpy import EXP_COEFFS, EXP_FLOOR, INV_LN2, LN2_HI, LN2_LO, TILE


@intrinsic
def as_double(typingctx, bits):  # reinterpret int64 bits as float64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11 = EXP_COEFFS
inv_ln2, ln2_hi, ln2_lo, floor, tile = INV_LN2, LN2_HI, LN2_LO, EXP_FLOOR, TILE
# Fast-math without 'ninf'/'nnan': -inf never enters the kernel, but we do not let LLVM assume it.
flags = {"contract", "reassoc", "nsz", "arcp", "afn"}


@numba.njit(inline="always", fastmath=flags)
def fexp(x):
    x = max(x, floor)
    n = np.round(x * inv_ln2)
    r = x - n * ln2_hi - n * ln2_lo
    p = ((((((((((c0 * r + c1) * r + c2) * r + c3) * r + c4) * r + c5) * r + c6) * r + c7) * r + c8) * r + c9)
         * r + c10) * r + c11
    return p * as_double((np.int64(n) + 1023) << 52)


def kernel(pts, meas, counts, beta, out):
    B = pts.shape[0]
    N = pts.shape[2]
    tiles = (N + tile - 1) // tile
    for job in numba.prange(B * tiles):
        b = job // tiles
        lo = (job % tiles) * tile
        hi = min(lo + tile, N)
        n = hi - lo
        px = pts[b, 0, lo:hi]
        py = pts[b, 1, lo:hi]
        pz = pts[b, 2, lo:hi]
        pv = pts[b, 3, lo:hi]
        top = np.full(n, -1e300)  # running max of log w per particle
        s = np.zeros(n)  # running sum of exp(log w - top)
        for m in range(counts[b]):
            zx, zy, zz, zv = meas[b, 0, m], meas[b, 1, m], meas[b, 2, m], meas[b, 3, m]
            cm, am = meas[b, 4, m], meas[b, 5, m]
            for j in range(n):
                dx = zx - px[j]
                dy = zy - py[j]
                dz = zz - pz[j]
                dv = zv - pv[j]
                lw = cm - am * (dx * dx + dy * dy + dz * dz) - beta * dv * dv
                # online logsumexp: one exp per pair, rescaling the sum when the max moves up
                d = lw - top[j]
                e = fexp(-abs(d))
                s[j] = s[j] * e + 1.0 if d > 0.0 else s[j] + e
                top[j] = max(top[j], lw)
        if counts[b] > 0:
            for j in range(n):
                out[b, lo + j] = top[j] + np.log(s[j])


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
