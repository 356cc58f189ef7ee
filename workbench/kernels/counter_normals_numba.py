"""The Numba twin of :mod:`workbench.kernels.counter_normals` (imported only when it is used).

``row_normals(key, b, out, words)`` fills ``out (count,)`` with row ``b``'s normals of stream ``key`` (a
``np.uint64``), the numbers of ``counter_normals(key, rows, count)[b]``, with ``words`` a ``uint64`` scratch of at
least ``count`` words; it is inlined where it is called and vectorises.  Module-level functions, so that Numba's
on-disk cache holds across processes.

The two hashes of a pair and its Box-Muller are two loops (:data:`SPLIT_HASH`, on a CPU without a 64-bit vector
multiply): a scalar loop writes the row's hash words (:func:`row_words`), then the vectorised loop turns them into
normals (:func:`box_muller`).  AVX2 has no 64-bit lane multiply: LLVM emulates each of the hash's multiplies with
three 32x32 ``vpmuludq`` and shifts and adds, on the same pipes as the float work, where the hashes cost 2.2-2.7 ns
a normal; scalar ``imul`` runs on the integer pipes, and the scalar loop costs 1.9 ns a normal (Box-Muller alone
5.7-6.9).  On one core of a 2-core AMD EPYC Zen 1 (AVX2 on 128-bit units; rows of 2,000, best of 30-300 interleaved
calls on a shared machine) :func:`fill_rows` on one thread went from 9.1-9.7 to 8.2-8.4 ns a normal, and the CRPF
step (B = 250, N = 500, n = 4, one thread) from 100-101 to 95-96 ns a particle, the same numbers bit for bit; the
first call of that kernel in a fresh cache compiles for about 1 s more (14.6 instead of 13.6 s of CPU).  Tried
and slower there: the hash words by a vectorised loop (the fused loop's cost), blocks of 4-128 pairs alternating a
scalar and a vectorised loop (11-12 ns: the vector loads wait for the scalar stores just before them), the log
and the sine and cosine in loops of their own (11-13 ns), 128-bit vectors (10.5 ns), and 4 pairs written out by
hand for LLVM's SLP vectoriser (left scalar, 24 ns).  Where AVX-512 DQ has the 64-bit lane multiply
(``vpmullq``) the fused loop is kept: the split was not measured there.  The counters are exact ``uint64``
arithmetic (a running sum of ``2 GAMMA`` from the row's first pair: ``key + (2 g + 1) GAMMA`` modulo 2^64).

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
from llvmlite import ir
from numba import types
from numba.core import config
from numba.core.codegen import get_host_cpu_features
from numba.extending import intrinsic

from .vector_width import wide_vectors
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


def _has_vector_u64_multiply():
    """Whether Numba compiles for a CPU with AVX-512 DQ (``vpmullq``, a 64-bit multiply per vector lane)."""
    features = config.CPU_FEATURES if config.CPU_FEATURES is not None else get_host_cpu_features()
    return "+avx512dq" in str(features).split(",")


#: The hashes in a scalar loop of their own (:func:`row_words`), the floats in a vectorised one; else one fused
#: vectorised loop.  Read when a function is compiled (Numba's cache is keyed on the CPU and its features).
SPLIT_HASH = not _has_vector_u64_multiply()


@intrinsic
def scalar_word(typingctx, x):
    """``x`` (a uint64) unchanged, through an empty inline-assembly statement in a general register: a loop that
    holds one is not vectorised, so its 64-bit multiplies stay scalar ``imul`` (see the module docstring)."""

    def codegen(context, builder, signature, args):
        ty = context.get_value_type(types.uint64)
        return builder.asm(ir.FunctionType(ty, [ty]), "", "=r,0", [args[0]], side_effect=False)

    return types.uint64(types.uint64), codegen


@jit
def mix(s):
    """SplitMix64's output function of the state ``s`` (a uint64)."""
    s = (s ^ (s >> u30)) * mix1
    s = (s ^ (s >> u27)) * mix2
    return s ^ (s >> u31)


@jit
def splitmix(key, counter):
    """``mix(key + counter GAMMA)`` for a uint64 ``counter``."""
    return mix(key + counter * gamma)


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
def box_muller(a, c):
    """The two normals of the pair with hash words ``a`` and ``c``: ``(rad cos th, rad sin th)``."""
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
def pair(key, g):
    """The two normals of pair ``g`` (a uint64) of stream ``key``."""
    a = splitmix(key, u2 * g + np.uint64(1))
    return box_muller(a, splitmix(key, u2 * g + u2))


@jit
def row_words(key, first, words, full):
    """``words[j]``, ``words[full + j]`` = the hash words ``a``, ``c`` of pair ``first + j``, ``j < full``, in a
    scalar loop (:func:`scalar_word`); the counter ``2 (first + j) + 1`` as a running sum of ``2 GAMMA``."""
    state = key + (u2 * first + np.uint64(1)) * gamma
    step = gamma + gamma
    for j in range(full):
        s = scalar_word(state + np.uint64(j) * step)
        words[j] = mix(s)
        words[full + j] = mix(s + gamma)


@jit
def split_loops(key, first, out, words, full):
    """Pairs ``first .. first + full - 1`` into ``out[:2 full]``: the scalar loop of hash words, then Box-Muller."""
    row_words(key, first, words, full)
    for j in range(full):
        n0, n1 = box_muller(words[j], words[full + j])
        out[2 * j] = n0
        out[2 * j + 1] = n1


@jit
def fused_loop(key, first, out, full):
    """Pairs ``first .. first + full - 1`` into ``out[:2 full]``: hashes and Box-Muller in one vectorised loop."""
    for j in range(full):
        n0, n1 = pair(key, first + np.uint64(j))
        out[2 * j] = n0
        out[2 * j + 1] = n1


@jit
def odd_tail(key, first, out, full):
    """The last normal of an odd ``count``: the cosine of pair ``first + full`` (its sine is dropped)."""
    if out.shape[0] & 1:
        n0, n1 = pair(key, first + np.uint64(full))
        out[out.shape[0] - 1] = n0


@jit
def row_normals_as(key, b, out, words, split):
    """:func:`row_normals` by the split loops (``split``) or by the fused one, both compiled (for the tests)."""
    full = out.shape[0] // 2
    first = np.uint64(b) * np.uint64((out.shape[0] + 1) // 2)  # the row's first pair
    if split:
        split_loops(key, first, out, words, full)
    else:
        fused_loop(key, first, out, full)
    odd_tail(key, first, out, full)


# row_normals holds only the loops this CPU uses (the other would add to every caller's compile time)
if SPLIT_HASH:
    @jit
    def row_normals(key, b, out, words):
        """``out (count,)`` = row ``b``'s normals of stream ``key``; ``words``: uint64 scratch, ``count`` or more
        (``count + 1`` in :func:`fill_rows`: with a scratch of exactly ``count`` words allocated beside the loop
        that wrapper ran at 9.2 instead of 7.1 ns a normal, the same machine code; not understood)."""
        # the caller's full vector width: at LLVM's default width for Zen 1 the split loop of Box-Muller stayed
        # scalar in some callers (11 instead of 8 ns a normal); an element-wise loop, so no bit changes
        wide_vectors()
        full = out.shape[0] // 2
        first = np.uint64(b) * np.uint64((out.shape[0] + 1) // 2)  # the row's first pair
        split_loops(key, first, out, words, full)
        odd_tail(key, first, out, full)
else:
    @jit
    def row_normals(key, b, out, words):
        """``out (count,)`` = row ``b``'s normals of stream ``key`` (``words`` unused on this CPU)."""
        full = out.shape[0] // 2
        first = np.uint64(b) * np.uint64((out.shape[0] + 1) // 2)  # the row's first pair
        fused_loop(key, first, out, full)
        odd_tail(key, first, out, full)


@numba.njit(parallel=True, error_model="numpy", cache=True)
def fill_rows(key, out):
    """``out (rows, count)`` = the normals of rows ``0 .. rows - 1`` of stream ``key``, one row per iteration."""
    for b in numba.prange(out.shape[0]):
        row_normals(key, b, out[b], np.empty(out.shape[1] + 1, dtype=np.uint64))  # count + 1: see row_normals
