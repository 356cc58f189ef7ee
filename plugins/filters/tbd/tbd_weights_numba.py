"""The Numba backend of :func:`workbench_filters.tbd.tbd_weights.tbd_log_weight_sums` (imported only when used).

Module-level functions, so that Numba's on-disk cache holds across processes (a kernel made in a
factory is a closure, whose cache key changes from process to process: every process compiled it
anew, about 2.7 s).  ``parallel`` and ``serial`` are the same loops compiled threaded and serial;
``parallel32`` and ``serial32`` the single-precision kernel.  The packed layouts are those of
:mod:`.tbd_weights_numpy`.  The loops vectorise with the CPU's full width (:mod:`workbench.kernels.vector_width`: eight doubles,
sixteen singles on AVX-512; 1.5x the throughput of LLVM's 256-bit default, bit for bit the same float64 weights).

What bounds the loop over particles on an AVX2 CPU (issue 26, measured on a Zen 2): the latency of one pair's
chain (the log-weight's multiply-adds, ``2^x``, the sum's update: about a hundred cycles), not the multiply-add
pipes.  So each iteration takes two particles (``j`` and ``j + n/2``: two independent chains, every load before
any store, so the loop still vectorises), ``2^x``'s polynomial is Estrin's (four multiply-adds deep instead of
eleven), ``2^x`` converts no double to an integer (AVX2 has no vector instruction for int64), the running max is
stored every time (a conditional store became a slow masked store) and the coefficients are run-time values.
On that CPU the float64 kernel went from 1.15e8 to about 2.1e8 pairs per second on one thread, float32 from
3.3e8 to about 4.6e8 (``docs/benchmarks.md``).
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
def as_int64(typingctx, value):  # reinterpret float64 bits as int64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


#: ``1.5 * 2^52``: for a whole double ``k`` with ``|k| < 2^51``, ``k + ROUND_SHIFT`` is exact and its low 12 bits
#: are those of the integer ``k`` (two's complement), so ``(bits(k + ROUND_SHIFT) + 1023) << 52`` is ``2^k``'s.
ROUND_SHIFT = 6755399441055744.0


@intrinsic
def as_single(typingctx, bits):  # reinterpret int32 bits as float32
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float32))

    return types.float32(types.int32), codegen


#: The polynomials' coefficients as arrays the kernels take as an argument (``coef``): values the compiled loop reads
#: at run time rather than constants of its code, so that LLVM keeps them in vector registers or, out of registers,
#: folds their broadcast copies on the stack into the multiply-adds as memory operands.  As constants, every
#: coefficient cost two more instructions per vector of pairs (an absolute address into a register, a broadcast
#: load): a quarter of the float64 loop's instructions on AVX2, whose 16 vector registers cannot hold them all (no
#: measurable change of speed on the Zen 2 of ``docs/benchmarks.md``, whose loop the chain's latency bounds).
COEFFS = np.array(EXP2_COEFFS, dtype=np.float64)
COEFFS_F32 = np.array(EXP2_COEFFS_F32, dtype=np.float32)
for _a in (COEFFS, COEFFS_F32):
    _a.flags.writeable = False
floor, floor32, tile, ln2 = EXP2_FLOOR, np.float32(EXP2_FLOOR_F32), TILE, LN2
one32, zero32, low32 = np.float32(1.0), np.float32(0.0), np.float32(-1e30)
i127, i23, half32 = np.int32(127), np.int32(23), np.float32(0.5)
# Fast-math without 'ninf'/'nnan': -inf never enters the kernel, but we do not let LLVM assume it.
flags = {"contract", "reassoc", "nsz", "arcp", "afn"}


@numba.njit(inline="always", fastmath=flags)
def fexp2(x, c):
    """``2^x`` for ``x <= 0`` (:func:`.tbd_weights_numpy.poly_exp2`, the same steps); ``c``: the 12 coefficients
    (:data:`COEFFS`), the polynomial by Estrin's scheme (:func:`.tbd_weights_numpy.estrin`)."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11 = c
    x = max(x, floor)
    # n = round(x) for x <= 0: x - 1/2 truncated toward zero, kept a double (np.trunc, one rounding
    # instruction): x86 has no vector conversion between double and int64 before AVX-512DQ, so the former
    # np.int64(x - 0.5) and its way back ran lane by lane on AVX2; the same whole number either way
    k = np.trunc(x - 0.5)
    f = x - k
    f2 = f * f
    f4 = f2 * f2
    p = ((((c0 * f + c1) * f2 + (c2 * f + c3)) * f4 + ((c4 * f + c5) * f2 + (c6 * f + c7))) * f4
         + ((c8 * f + c9) * f2 + (c10 * f + c11)))
    return p * as_double((as_int64(k + ROUND_SHIFT) + 1023) << 52)


@numba.njit(inline="always", fastmath=flags)
def fexp2_32(x, c):
    """``2^x`` for ``x <= 0`` in single precision (:func:`.tbd_weights_numpy.poly_exp2`, ``"float32"``); ``c``: the 7
    coefficients (:data:`COEFFS_F32`), by Estrin's scheme."""
    s0, s1, s2, s3, s4, s5, s6 = c
    x = max(x, floor32)
    k = np.int32(x - half32)
    f = x - np.float32(k)
    f2 = f * f
    f4 = f2 * f2
    p = (s0 * f2 + (s1 * f + s2)) * f4 + ((s3 * f + s4) * f2 + (s5 * f + s6))
    return p * as_single((k + i127) << i23)


@numba.njit(inline="always", fastmath=flags)
def log2_weight(q, kv, j, tx, ty, tz, tv, na, cm):
    """One pair's ``log2 w = C_m + T_m . q_j + u_m vr_j - A_m |q_j|^2 + K_j`` (float64 packing: ``q`` the rows ``x, y,
    z, vr, |q|^2`` of the tile, ``kv`` its ``K``)."""
    return cm + tx * q[0][j] + ty * q[1][j] + tz * q[2][j] + tv * q[3][j] + na * q[4][j] + kv[j]


@numba.njit(inline="always", fastmath=flags)
def log2_weight32(p, j, zx, zy, zz, zv, cm, am, beta2):
    """One pair's ``log2 w = c_m/ln2 - (a_m/ln2) |q_m - q_j|^2 - (beta/ln2) (vr_m - vr_j)^2`` in float32 (the
    differences formed directly: the expansion would cancel in single precision)."""
    dx = zx - p[0][j]
    dy = zy - p[1][j]
    dz = zz - p[2][j]
    dv = zv - p[3][j]
    return cm - am * (dx * dx + dy * dy + dz * dz) - beta2 * dv * dv


@numba.njit(inline="always", fastmath=flags)
def lse_step(s, t, lw, e):
    """The online logsumexp's update of one particle's ``(s, top)`` by a log-weight ``lw`` with ``e = 2^-|lw - top|``:
    the sum rescaled when the max moves up.  Both values written every time (a ``max`` stored only where it grows
    became a masked store, which AVX2 CPUs run slowly)."""
    up = lw > t
    return (s * e + 1.0 if up else s + e), (lw if up else t)


def kernel(pts, meas, counts, coef, out):
    B = pts.shape[0]
    c = (coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6], coef[7], coef[8], coef[9], coef[10], coef[11])
    N = pts.shape[2]
    tiles = (N + tile - 1) // tile
    for job in numba.prange(B * tiles):
        wide_vectors()  # eight doubles per vector where the CPU has AVX-512 (LLVM's tuning prefers four)
        b = job // tiles
        lo = (job % tiles) * tile
        hi = min(lo + tile, N)
        n = hi - lo
        q = (pts[b, 0, lo:hi], pts[b, 1, lo:hi], pts[b, 2, lo:hi], pts[b, 3, lo:hi], pts[b, 4, lo:hi])
        kv = pts[b, 5, lo:hi]
        top = np.full(n, -1e300)  # running max of log2 w per particle
        s = np.zeros(n)  # running sum of 2^(log2 w - top)
        h = n // 2
        for m in range(counts[b]):
            tx, ty, tz, tv, na, cm = meas[b, 0, m], meas[b, 1, m], meas[b, 2, m], meas[b, 3, m], meas[b, 4, m], \
                meas[b, 5, m]
            # two particles per iteration, j and i = j + n/2, every load before any store: two independent
            # chains in flight (one chain's latency, about a hundred cycles, is what bounded the loop), and both
            # accesses contiguous, so the loop still vectorises
            for j in range(h):
                i = j + h
                lw = log2_weight(q, kv, j, tx, ty, tz, tv, na, cm)
                lw2 = log2_weight(q, kv, i, tx, ty, tz, tv, na, cm)
                t, t2 = top[j], top[i]
                s1, s2 = s[j], s[i]
                # online logsumexp: one exp per pair, rescaling the sum when the max moves up
                e = fexp2(-abs(lw - t), c)
                e2 = fexp2(-abs(lw2 - t2), c)
                s[j], top[j] = lse_step(s1, t, lw, e)
                s[i], top[i] = lse_step(s2, t2, lw2, e2)
            if n % 2:
                lw = log2_weight(q, kv, n - 1, tx, ty, tz, tv, na, cm)
                t = top[n - 1]
                s[n - 1], top[n - 1] = lse_step(s[n - 1], t, lw, fexp2(-abs(lw - t), c))
        if counts[b] > 0:
            for j in range(n):
                out[b, lo + j] = ln2 * (top[j] + np.log2(s[j]))


def kernel32(pts, meas, counts, beta2, coef, out):
    B = pts.shape[0]
    c = (coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6])
    N = pts.shape[2]
    tiles = (N + tile - 1) // tile
    for job in numba.prange(B * tiles):
        wide_vectors()
        b = job // tiles
        lo = (job % tiles) * tile
        hi = min(lo + tile, N)
        n = hi - lo
        p = (pts[b, 0, lo:hi], pts[b, 1, lo:hi], pts[b, 2, lo:hi], pts[b, 3, lo:hi])
        top = np.full(n, low32)
        s = np.zeros(n, dtype=np.float32)
        h = n // 2
        for m in range(counts[b]):
            zx, zy, zz, zv, cm, am = meas[b, 0, m], meas[b, 1, m], meas[b, 2, m], meas[b, 3, m], meas[b, 4, m], \
                meas[b, 5, m]
            for j in range(h):  # two particles per iteration, as in kernel
                i = j + h
                lw = log2_weight32(p, j, zx, zy, zz, zv, cm, am, beta2)
                lw2 = log2_weight32(p, i, zx, zy, zz, zv, cm, am, beta2)
                t, t2 = top[j], top[i]
                s1, s2 = s[j], s[i]
                e = fexp2_32(-abs(lw - t), c)
                e2 = fexp2_32(-abs(lw2 - t2), c)
                s[j], top[j] = lse_step32(s1, t, lw, e)
                s[i], top[i] = lse_step32(s2, t2, lw2, e2)
            if n % 2:
                lw = log2_weight32(p, n - 1, zx, zy, zz, zv, cm, am, beta2)
                t = top[n - 1]
                s[n - 1], top[n - 1] = lse_step32(s[n - 1], t, lw, fexp2_32(-abs(lw - t), c))
        if counts[b] > 0:
            for j in range(n):
                out[b, lo + j] = ln2 * (np.float64(top[j]) + np.log2(np.float64(s[j])))


@numba.njit(inline="always", fastmath=flags)
def lse_step32(s, t, lw, e):
    """:func:`lse_step` in float32."""
    up = lw > t
    return (s * e + one32 if up else s + e), (lw if up else t)


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


# -- the particles' packing (:func:`.tbd_weights_numpy.pack_points`), compiled --------------------------------
# IEEE arithmetic (no fast-math flags): the packed rows are those of the NumPy function bit for bit, given its origin.


def mean_position(points, origin):
    """``origin[b] = points[b, :, :3].mean(axis=0)`` summed in particle order, the order NumPy sums it in for a
    C-ordered ``points (B, N, 4)`` (N >= 1): the reduced axis is not its innermost, so NumPy adds whole rows
    element by element, particle after particle (another layout may make it sum pairwise: not for this)."""
    B, N = points.shape[0], points.shape[1]
    for b in range(B):
        s0 = points[b, 0, 0]
        s1 = points[b, 0, 1]
        s2 = points[b, 0, 2]
        for n in range(1, N):
            s0 += points[b, n, 0]
            s1 += points[b, n, 1]
            s2 += points[b, n, 2]
        origin[b, 0] = s0 / N
        origin[b, 1] = s1 / N
        origin[b, 2] = s2 / N


def pack64(points, scale, out, origin):
    """float64 rows ``[q_x, q_y, q_z, vr, |q|^2, K]`` of ``points (B, N, 4)`` into ``out (B, 6, N)``, centred on
    ``origin (B, 3)``; ``K = scale vr^2``."""
    B, N = points.shape[0], points.shape[1]
    for b in range(B):
        ox, oy, oz = origin[b, 0], origin[b, 1], origin[b, 2]
        for n in numba.prange(N):
            x = points[b, n, 0] - ox
            y = points[b, n, 1] - oy
            z = points[b, n, 2] - oz
            v = points[b, n, 3]
            out[b, 0, n] = x
            out[b, 1, n] = y
            out[b, 2, n] = z
            out[b, 3, n] = v
            xx = x * x
            yy = y * y
            zz = z * z
            out[b, 4, n] = (xx + yy) + zz
            out[b, 5, n] = scale * (v * v)


def pack32(points, out, origin):
    """float32 rows ``[q_x, q_y, q_z, vr]`` (differences in float64, then rounded) into ``out (B, 4, N)``."""
    B, N = points.shape[0], points.shape[1]
    for b in range(B):
        ox, oy, oz = origin[b, 0], origin[b, 1], origin[b, 2]
        for n in numba.prange(N):
            out[b, 0, n] = np.float32(points[b, n, 0] - ox)
            out[b, 1, n] = np.float32(points[b, n, 1] - oy)
            out[b, 2, n] = np.float32(points[b, n, 2] - oz)
            out[b, 3, n] = np.float32(points[b, n, 3])


mean_position_compiled = numba.njit(cache=True)(mean_position)
pack64_parallel = numba.njit(parallel=True, cache=True)(pack64)
pack64_serial = numba.njit(parallel=False, cache=True)(_renamed(pack64, "pack64_serial"))
pack32_parallel = numba.njit(parallel=True, cache=True)(pack32)
pack32_serial = numba.njit(parallel=False, cache=True)(_renamed(pack32, "pack32_serial"))
