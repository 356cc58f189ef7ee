"""The Numba twin of :mod:`workbench.kernels.counter_normals` (imported only when it is used).

``row_normals(key, b, out)`` fills ``out (count,)`` with row ``b``'s normals of stream ``key`` (a
``np.uint64``), the numbers of ``counter_normals(key, rows, count)[b]``; it is inlined where it is
called and vectorises.  Module-level functions, so that Numba's on-disk cache holds across processes.

How the loop over pairs is kept vectorisable (the assembly of a small wrapper was read to check it; the numbers
are the NumPy twin's bit for bit, held by the tests):

- :func:`quotient`, a bare IEEE ``fdiv``: Numba's ``/`` on floats tests the divisor for zero and branches
  (even with ``error_model="numpy"``), and with that branch in ``log``'s ``(m - 1) / (m + 1)`` the loop stayed
  scalar in some callers (1.3-1.8x slower per normal on one AVX2 core); for a non-zero divisor the two give the
  same bits.
- no int64-to-float conversion (AVX2 has none for 64-bit lanes): ``(2 (bits >> 12) + 1) 2^-53`` is
  ``(1 + m 2^-52) - (1 - 2^-53)`` with ``m = bits >> 12`` put in the mantissa of 1.0, and the exponent ``e`` is
  ``(2^52 + e_bits) - (2^52 + 1023)`` the same way; both subtractions are exact.
- the last pair of an odd ``count`` (one normal stored, not two) is done after the loop, so the loop body has no
  conditional store.
"""

import functools
import math

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from .counter_normals_numpy import COS_SERIES, GAMMA, LN2_HI, LN2_LO, LOG_SERIES, MIX1, MIX2, SIN_SERIES, SQRT2


@intrinsic
def bits_of(typingctx, x):  # reinterpret float64 as int64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@intrinsic
def double_of(typingctx, bits):  # reinterpret int64 as float64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


gamma, mix1, mix2 = np.uint64(GAMMA), np.uint64(MIX1), np.uint64(MIX2)
u2, u12, u27, u30, u31, u62 = (np.uint64(k) for k in (2, 12, 27, 30, 31, 62))
l0, l1, l2, l3, l4, l5, l6, l7, l8, l9, l10 = LOG_SERIES
s0, s1, s2, s3, s4, s5, s6, s7, s8 = SIN_SERIES
c0, c1, c2, c3, c4, c5, c6, c7, c8, c9 = COS_SERIES
ln2_hi, ln2_lo, sqrt2, half_pi = LN2_HI, LN2_LO, SQRT2, 0.5 * math.pi
one_bits, big_bits, umant, u52 = (np.uint64(k) for k in (0x3FF0000000000000, 0x4330000000000000,
                                                          0x000FFFFFFFFFFFFF, 52))
below_one = 1.0 - 2.0 ** -53  # exact
exp_offset = 2.0 ** 52 + 1023.0  # exact
jit = functools.partial(numba.njit, error_model="numpy", inline="always")


@intrinsic
def quotient(typingctx, a, b):
    """``a / b`` as one IEEE division, without Numba's zero-divisor branch (which stops vectorisation)."""

    def codegen(context, builder, signature, args):
        return builder.fdiv(args[0], args[1])

    return types.float64(types.float64, types.float64), codegen


@jit
def splitmix(key, counter):
    s = key + np.uint64(counter) * gamma
    s = (s ^ (s >> u30)) * mix1
    s = (s ^ (s >> u27)) * mix2
    return s ^ (s >> u31)


@jit
def unit(bits):
    """``(2 (bits >> 12) + 1) 2^-53`` for uint64 ``bits``, exactly: ``(1 + m 2^-52) - (1 - 2^-53)``, ``m = bits >> 12``."""
    return double_of(np.int64((bits >> u12) | one_bits)) - below_one


@jit
def log_pos(x):  # log_poly
    bits = np.uint64(bits_of(x))
    m = double_of(np.int64((bits & umant) | one_bits))
    big = m > sqrt2
    m = 0.5 * m if big else m
    # e = exponent bits - 1023 (+ 1 where m was halved), as a float without an int64 conversion
    e = (double_of(np.int64((bits >> u52) | big_bits)) - exp_offset) + (1.0 if big else 0.0)
    s = quotient(m - 1.0, m + 1.0)
    z = s * s
    poly = ((((((((((l10 * z + l9) * z + l8) * z + l7) * z + l6) * z + l5) * z + l4) * z + l3) * z + l2) * z
             + l1) * z + l0)
    return e * ln2_hi + (e * ln2_lo + s * poly)


@jit
def pair(key, g):
    """The two normals of pair ``g`` (a uint64) of stream ``key``: ``(rad cos th, rad sin th)``."""
    a = splitmix(key, 2 * g + 1)
    c = splitmix(key, 2 * g + 2)
    # rad = sqrt(-2 log p)
    rad = math.sqrt(-2.0 * log_pos(unit(a)))
    quadrant = c >> u62
    w = unit(c << u2)
    flip = w > 0.5
    t = (1.0 - w if flip else w) * half_pi
    z = t * t
    st = t * ((((((((s8 * z + s7) * z + s6) * z + s5) * z + s4) * z + s3) * z + s2) * z + s1) * z + s0)
    ct = (((((((((c9 * z + c8) * z + c7) * z + c6) * z + c5) * z + c4) * z + c3) * z + c2) * z + c1) * z
          + c0)
    s_psi = ct if flip else st
    c_psi = st if flip else ct
    odd = (quadrant & np.uint64(1)) != np.uint64(0)
    cos = -s_psi if odd else c_psi
    sin = c_psi if odd else s_psi
    sign = -rad if quadrant >= u2 else rad
    return sign * cos, sign * sin


@jit
def row_normals(key, b, out):
    count = out.shape[0]
    full = count // 2
    base = np.uint64(b * ((count + 1) // 2))  # the row's first pair
    for j in range(full):
        n0, n1 = pair(key, base + np.uint64(j))
        out[2 * j] = n0
        out[2 * j + 1] = n1
    if count & 1:  # the last pair's sine is dropped
        n0, n1 = pair(key, base + np.uint64(full))
        out[count - 1] = n0


@numba.njit(parallel=True, error_model="numpy", cache=True)
def fill_rows(key, out):
    """``out (rows, count)`` = the normals of rows ``0 .. rows - 1`` of stream ``key``, one row per iteration."""
    for b in numba.prange(out.shape[0]):
        row_normals(key, b, out[b])
