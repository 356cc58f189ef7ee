"""The Numba twin of :mod:`workbench.kernels.counter_normals` (imported only when it is used).

``row_normals(key, b, out, words)`` fills ``out (count,)`` with row ``b``'s normals of stream ``key`` (a
``np.uint64``), the numbers of ``counter_normals(key, rows, count)[b]``, with ``words`` a ``uint64`` scratch of at
least ``count // 2`` words (one hash word per pair); its loop over pairs vectorises.  Module-level functions, so
that Numba's on-disk cache holds across processes.  The generator is the float32 one specified in
:mod:`.counter_normals_numpy`'s docstring; this twin does the same float32 operations in the same order and
gives the same bits (held by the tests, which also check that the compiled Box-Muller has no float64
arithmetic: every constant here is an ``np.float32`` or ``np.uint32`` global, since a Python float would
promote the work to float64; no fastmath, so LLVM contracts nothing into an FMA).

The hash of a pair and its Box-Muller are two loops: a scalar loop writes the row's hash words (:func:`row_words`,
one SplitMix64 word per pair), then the vectorised loop turns them into normals (:func:`box_muller`; LLVM takes 4
float32 lanes there on Zen 1).  AVX2 has no 64-bit lane multiply: LLVM would emulate each of the hash's multiplies
with three 32x32 ``vpmuludq`` and shifts and adds, on the same pipes as the float work; scalar ``imul`` runs on the
integer pipes.  On one core of a 2-core AMD EPYC Zen 1 (AVX2 on 128-bit units; rows of 2,000, one thread, best of
50-100 interleaved calls) :func:`fill_rows` takes 3.6 ns a normal (the scalar loop of words 0.7, the float32
Box-Muller 2.9), against 7.0 ns for the float64 generator it replaced (two hash words per pair, an 11-term log series
and 9/10-term sine and cosine series in float64) measured beside it; the CRPF step (B = 250, N = 500, n = 4, one
thread) went from 80.4-80.7 to 66.1-67.1 ns a particle-step.  Tried and no faster there: the words split into two
``uint32`` arrays so that the float loop has only 32-bit lanes (3.58 against 3.62 ns).  Tried and slower with the
float64 generator: the hash words by a vectorised loop, blocks of pairs alternating a scalar and a vectorised loop,
the log and the sine and cosine in loops of their own, 128-bit vectors, 4 pairs written out by hand for LLVM's SLP
vectoriser.  The split loops are used on every CPU, AVX-512 DQ included: there the 64-bit lane multiply (``vpmullq``)
would let one fused loop vectorise, but LLVM keeps the fused loop scalar (with or without
:func:`~.vector_width.wide_vectors`), and on one core of a 2-core AMD EPYC Zen 4 (AVX-512; rows of 2,000, best of 7
runs of 2,000 rows) the fused loop took 7.4 ns a normal against 1.5 for the split ones; the CRPF step (B = 250, N =
500, n = 4, one thread) 55 against 31 ns a particle-step.  The fused loop stays for the tests
(:func:`row_normals_as`), which hold the two to the same bits.  The counters are exact ``uint64`` arithmetic (a
running sum of ``GAMMA`` from the row's first pair: ``key + (g + 1) GAMMA`` modulo 2^64).

The helpers are ordinary Numba functions, inlined by LLVM, not by Numba (``inline="always"`` copies Numba's IR
into every caller: a wrapper of :func:`row_normals` compiled in 2.2 s of CPU that way, 1.5 s this way, with the
same loops, vectorised, and the same speed).

How the loop over pairs is kept vectorisable (the LLVM IR and assembly of a small wrapper were read to check
it: ``<4 x float>`` ``fmul``, one ``vdivps`` and one ``vsqrtps`` in the loop):

- :func:`quotient`, a bare IEEE ``fdiv``: Numba's ``/`` on floats tests the divisor for zero and branches
  (even with ``error_model="numpy"``), and with that branch in ``log``'s ``f / (2 + f)`` the loop stayed
  scalar in some callers; for a non-zero divisor the two give the same bits.
- no integer-to-float conversion: ``p = (2 k + 1) 2^-24`` is ``(1 + k 2^-23) - (1 - 2^-24)`` with ``k`` put in
  the mantissa of 1.0 (:func:`unit24`), and the log's exponent ``e`` is ``(2^23 + e_bits) - (2^23 + 127)`` the
  same way; the subtractions are exact.
- the last pair of an odd ``count`` (one normal stored, not two) is done after the loop, so the loop body has no
  conditional store.
"""

import functools
import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from .vector_width import wide_vectors
from .counter_normals_numpy import (BELOW_ONE, COS_SERIES, EXP_OFFSET, GAMMA, HALF, LN2_HI, LN2_LO, LOG_SERIES,
                                    MINUS_TWO, MIX1, MIX2, ONE, ONE_BITS, SIN_SERIES, SQRT2, TWO)


@intrinsic
def f32_of(typingctx, bits):
    """The float32 whose bits are the low 32 bits of the integer ``bits`` (a bit cast, after a truncation)."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        v = args[0]
        if bits.bitwidth > 32:
            v = builder.trunc(v, ir.IntType(32))
        elif bits.bitwidth < 32:
            v = builder.zext(v, ir.IntType(32))
        return builder.bitcast(v, ir.FloatType())

    return types.float32(bits), codegen


@intrinsic
def bits_of_f32(typingctx, x):
    """The bits of the float32 ``x`` as a uint32 (a bit cast)."""
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))

    return types.uint32(types.float32), codegen


gamma, mix1, mix2 = np.uint64(GAMMA), np.uint64(MIX1), np.uint64(MIX2)
u1, u2, u3, u16, u27, u30, u31, u39, u41 = (np.uint64(k) for k in (1, 2, 3, 16, 27, 30, 31, 39, 41))
mask23 = np.uint64(0x7FFFFF)
# the float32 work's integers are uint32 and its constants float32 (a Python float would make it float64)
one_bits, exp_bits, mant_bits = np.uint32(ONE_BITS), np.uint32(0x4B000000), np.uint32(0x007FFFFF)
w23 = np.uint32(23)
l0, l1, l2, l3 = LOG_SERIES
s0, s1, s2, s3, s4 = SIN_SERIES
c0, c1, c2, c3, c4, c5 = COS_SERIES
ln2_hi, ln2_lo, sqrt2 = LN2_HI, LN2_LO, SQRT2
half, one, two, minus_two, zero = HALF, ONE, TWO, MINUS_TWO, np.float32(0.0)
below_one, exp_offset = BELOW_ONE, EXP_OFFSET
jit = functools.partial(numba.njit, error_model="numpy")  # inlined by LLVM (see the module docstring)


@intrinsic
def quotient(typingctx, a, b):
    """``a / b`` (float32) as one IEEE division, without Numba's zero-divisor branch (which stops vectorisation)."""
    if a != types.float32 or b != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.fdiv(args[0], args[1])

    return types.float32(types.float32, types.float32), codegen


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
def unit24(bits23):
    """``(2 i + 1) 2^-24`` (float32) for the 23-bit integer ``bits23``, exactly: ``(1 + i 2^-23) - (1 - 2^-24)``."""
    return f32_of(np.uint32(bits23) | one_bits) - below_one


@jit
def log_pos(x):  # log_poly, float32
    bits = bits_of_f32(x)
    e = f32_of((bits >> w23) | exp_bits) - exp_offset  # the exponent, as a float32 without an integer conversion
    m = f32_of((bits & mant_bits) | one_bits)
    big = m > sqrt2
    m = half * m if big else m
    e = e + (one if big else zero)
    f = m - one
    s = quotient(f, two + f)
    z = s * s
    r = z * (((l3 * z + l2) * z + l1) * z + l0)
    h = half * f * f
    # log(1 + f) = f - h + s (h + R), summed small terms first
    return e * ln2_hi - ((h - (s * (h + r) + e * ln2_lo)) - f)


@jit
def box_muller(w):
    """The two normals (float32) of the pair with hash word ``w``: ``(rad cos th, rad sin th)``."""
    # rad = sqrt(-2 log p)
    rad = math.sqrt(minus_two * log_pos(unit24(w >> u41)))
    quadrant = (w >> u39) & u3
    u = unit24((w >> u16) & mask23)
    flip = u > half
    t = one - u if flip else u
    z = t * t
    st = t * ((((s4 * z + s3) * z + s2) * z + s1) * z + s0)
    ct = ((((c5 * z + c4) * z + c3) * z + c2) * z + c1) * z + c0
    s_psi = ct if flip else st
    c_psi = st if flip else ct
    odd = (quadrant & u1) != np.uint64(0)
    cos = -s_psi if odd else c_psi
    sin = c_psi if odd else s_psi
    neg = quadrant >= u2
    cos = -cos if neg else cos
    sin = -sin if neg else sin
    return rad * cos, rad * sin


@jit
def pair(key, g):
    """The two normals (float32) of pair ``g`` (a uint64) of stream ``key``."""
    return box_muller(mix(key + (g + u1) * gamma))


@jit
def row_words(key, first, words, full):
    """``words[j]`` = the hash word of pair ``first + j``, ``j < full``, in a scalar loop (:func:`scalar_word`);
    the counter ``key + (first + j + 1) GAMMA`` as a running sum of ``GAMMA``."""
    state = key + (first + u1) * gamma
    for j in range(full):
        words[j] = mix(scalar_word(state + np.uint64(j) * gamma))


@jit
def split_loops(key, first, out, words, full):
    """Pairs ``first .. first + full - 1`` into ``out[:2 full]``: the scalar loop of hash words, then Box-Muller."""
    row_words(key, first, words, full)
    for j in range(full):
        n0, n1 = box_muller(words[j])
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


@jit
def row_normals(key, b, out, words):
    """``out (count,)`` = row ``b``'s normals of stream ``key``; ``words``: uint64 scratch of ``count // 2`` words or
    more (the split loops on every CPU: see the module docstring)."""
    # the caller's full vector width: at LLVM's default width for Zen 1 the split loop of Box-Muller stayed scalar in
    # some callers; an element-wise loop, so no bit changes
    wide_vectors()
    full = out.shape[0] // 2
    first = np.uint64(b) * np.uint64((out.shape[0] + 1) // 2)  # the row's first pair
    split_loops(key, first, out, words, full)
    odd_tail(key, first, out, full)


@numba.njit(parallel=True, error_model="numpy", cache=True)
def fill_rows(key, out):
    """``out (rows, count)`` = the normals of rows ``0 .. rows - 1`` of stream ``key``, one row per iteration."""
    for b in numba.prange(out.shape[0]):
        row_normals(key, b, out[b], np.empty(out.shape[1] // 2 + 1, dtype=np.uint64))
