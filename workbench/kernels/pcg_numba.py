"""NumPy's standard normals on PCG64 with the generator's state in registers (imported only when used).

Shared by the compiled particle propagations (:mod:`.motion_numba`'s coordinated turn, :mod:`.particle_numba`'s
linear and range-bearing passes and its floor draw :func:`~.particle_numba.fill_normals`): NumPy's own
``Generator.standard_normal`` (the ziggurat on the bit generator's 64-bit words), the same numbers in the same order
and the generator left where NumPy leaves it.  For PCG64 (every ``wb.generator``) the state is read once per call
(:func:`pcg64_stream`) and stepped in registers (:func:`_pcg_normal`: one 128-bit multiply-add per word, the first
box of the ziggurat without branches); any other bit generator is drawn through Numba's ``Generator``, which calls
it through a pointer with its state in memory (about three times the time per normal on the machine of
``docs/benchmarks.md``).  Tested against NumPy in ``tests/test_motion_kernels.py`` and ``tests/test_pcg_draws.py``.
"""

import threading
from contextlib import contextmanager

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic
from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r

__all__ = ["pcg64_stream", "PCG_MIN_DRAWS", "draw_tile"]


#: PCG64's 128-bit LCG multiplier (NumPy's ``pcg64.h``: ``PCG_DEFAULT_MULTIPLIER_HIGH``, ``_LOW``).
PCG_MULTIPLIER = (2549297995355413924 << 64) | 4865540595714422341
_U64 = (1 << 64) - 1
#: The kernels' ``pcg`` where the generator is not PCG64 (empty; writable, so that both cases are one signature).
_NO_STREAM = np.zeros(0, dtype=np.uint64)


@intrinsic
def _pcg_step(typingctx, hi, lo, inc_hi, inc_lo):
    """PCG64's state step ``s <- s PCG_MULTIPLIER + inc (mod 2^128)`` on the halves ``(hi, lo)`` of ``s`` and
    ``(inc_hi, inc_lo)`` of ``inc``: one 128-bit multiply-add in LLVM, returned as ``(hi, lo)``."""
    sig = types.UniTuple(types.uint64, 2)(types.uint64, types.uint64, types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        wide, half = ir.IntType(128), ir.IntType(64)

        def join(h, l):
            return builder.or_(builder.shl(builder.zext(h, wide), ir.Constant(wide, 64)), builder.zext(l, wide))

        s = builder.add(builder.mul(join(args[0], args[1]), ir.Constant(wide, PCG_MULTIPLIER)),
                        join(args[2], args[3]))
        hi = builder.trunc(builder.lshr(s, ir.Constant(wide, 64)), half)
        return context.make_tuple(builder, signature.return_type, (hi, builder.trunc(s, half)))

    return sig, codegen


@numba.njit(inline="always", error_model="numpy")
def _pcg_next64(hi, lo, inc_hi, inc_lo):
    """PCG64's ``next_uint64``: step, then the XSL-RR output of the new state; returns ``(value, hi, lo)``."""
    hi, lo = _pcg_step(hi, lo, inc_hi, inc_lo)
    v = hi ^ lo
    rot = hi >> numba.uint64(58)
    return (v >> rot) | (v << ((numba.uint64(64) - rot) & numba.uint64(63))), hi, lo


@numba.njit(inline="always", error_model="numpy")
def _pcg_next_double(hi, lo, inc_hi, inc_lo):
    """NumPy's ``next_double`` on PCG64: the top 53 bits of ``next_uint64`` over ``2^53``; ``(value, hi, lo)``."""
    v, hi, lo = _pcg_next64(hi, lo, inc_hi, inc_lo)
    return np.int64(v >> numba.uint64(11)) * (1.0 / 9007199254740992.0), hi, lo


#: ``+1`` and ``-1``: the ziggurat's sign bit as a factor (a product with ``-1`` is the exact negation, and a
#: branch on a random bit would be mispredicted half the time).
_SIGNS = np.array([1.0, -1.0])


@numba.njit(inline="always", error_model="numpy")
def _first_box(r):
    """The ziggurat's reading of one 64-bit word ``r``: ``(idx, rabs, x)``, its box, its 52-bit magnitude and the
    candidate value with its sign (NumPy's ``random_standard_normal``), the draw accepted where ``rabs <
    ki_double[idx]``."""
    idx = np.intp(r & numba.uint64(0xFF))
    r >>= numba.uint64(8)
    rabs = (r >> numba.uint64(1)) & numba.uint64(0x000FFFFFFFFFFFFF)
    return idx, rabs, (np.int64(rabs) * wi_double[idx]) * _SIGNS[np.intp(r & numba.uint64(1))]


@numba.njit(inline="always", error_model="numpy")
def _pcg_normal(hi, lo, inc_hi, inc_lo):
    """NumPy's ``random_standard_normal`` (its ziggurat, with the tables Numba copies from it) on PCG64 whose state
    ``(hi, lo)`` the caller keeps in locals: ``(value, hi, lo)``, the number ``Generator.standard_normal`` gives
    and the state it leaves.  Numba's ``Generator`` runs the same algorithm, calling the bit generator through a
    pointer and keeping its state in memory; here the 99.3 % of draws that take the first box are straight-line
    code (no branch on the sign) and the rest go to :func:`_pcg_normal_rest`, out of line."""
    r, hi, lo = _pcg_next64(hi, lo, inc_hi, inc_lo)
    idx, rabs, x = _first_box(r)
    if rabs < ki_double[idx]:
        return x, hi, lo
    return _pcg_normal_rest(idx, rabs, x, hi, lo, inc_hi, inc_lo)


@numba.njit(cache=True, error_model="numpy")
def _pcg_normal_rest(idx, rabs, x, hi, lo, inc_hi, inc_lo):
    """The rest of :func:`_pcg_normal` for a draw outside the first box (``idx``, ``rabs``, ``x`` its numbers):
    NumPy's tail (``idx = 0``) or wedge test, then, if rejected, fresh draws until one is accepted."""
    while True:
        if idx == 0:
            while True:
                u, hi, lo = _pcg_next_double(hi, lo, inc_hi, inc_lo)
                xx = -ziggurat_nor_inv_r * np.log1p(-u)
                u, hi, lo = _pcg_next_double(hi, lo, inc_hi, inc_lo)
                yy = -np.log1p(-u)
                if yy + yy > xx * xx:
                    if (rabs >> numba.uint64(8)) & numba.uint64(1):
                        return -(ziggurat_nor_r + xx), hi, lo
                    return ziggurat_nor_r + xx, hi, lo
        else:
            u, hi, lo = _pcg_next_double(hi, lo, inc_hi, inc_lo)
            if (fi_double[idx - 1] - fi_double[idx]) * u + fi_double[idx] < np.exp(-0.5 * x * x):
                return x, hi, lo
        r, hi, lo = _pcg_next64(hi, lo, inc_hi, inc_lo)
        idx, rabs, x = _first_box(r)
        if rabs < ki_double[idx]:
            return x, hi, lo


@numba.njit(inline="always", error_model="numpy")
def pcg_tile(pcg, e, m, k):
    """``e[:k, :m]``: the next ``m k`` normals of the PCG64 state ``pcg`` ``[state_hi, state_lo, inc_hi, inc_lo]``
    (advanced in place), ``e[j, t]`` the ``j``-th of particle ``t``: the numbers of ``standard_normal((m, k))``,
    transposed (stored by noise column, so that each is contiguous)."""
    hi, lo, inc_hi, inc_lo = pcg[0], pcg[1], pcg[2], pcg[3]
    for t in range(m):
        for j in range(k):
            e[j, t], hi, lo = _pcg_normal(hi, lo, inc_hi, inc_lo)
    pcg[0], pcg[1] = hi, lo


@numba.njit(inline="always", error_model="numpy")
def draw_tile(rng, pcg, e, m, k):
    """``e[:k, :m]``: the next ``m k`` normals of the stream, ``e[j, t]`` the ``j``-th of particle ``t`` (the
    numbers of ``rng.standard_normal((m, k))``, transposed: stored by noise column, so that each is contiguous),
    from the PCG64 state ``pcg`` ``[state_hi, state_lo, inc_hi, inc_lo]`` (advanced in place) where it holds four
    words (:func:`pcg_tile`), else from Numba's ``Generator`` ``rng``."""
    if pcg.shape[0] == 4:
        pcg_tile(pcg, e, m, k)
    else:
        for t in range(m):
            for j in range(k):
                e[j, t] = rng.standard_normal()


_PCG_LOCK = threading.Lock()
#: Normals per call from which :func:`pcg64_stream` hands out the PCG64 state: reading and writing it back costs
#: some ten microseconds (Python's view of the state), which the cheaper draws repay from a few thousand normals
#: on.  Either way the numbers are the same.
PCG_MIN_DRAWS = 8192


@contextmanager
def pcg64_stream(rng, draws: int, min_draws: int | None = None):
    """The PCG64 state of the ``numpy.random.Generator`` ``rng`` as the kernels' ``pcg`` words ``[state_hi,
    state_lo, inc_hi, inc_lo]`` (uint64), written back to ``rng`` on leaving (the generator then stands where
    ``rng.standard_normal`` would leave it after the same draws), its lock held meanwhile; an empty array (the
    kernels draw through Numba's ``Generator``) for any other bit generator and for fewer than
    :data:`PCG_MIN_DRAWS` ``draws``.  ``has_uint32`` / ``uinteger``, which ``next_uint64`` never touches, are
    kept.  ``min_draws``: the threshold in place of :data:`PCG_MIN_DRAWS` (a caller's own setting)."""
    bits = getattr(rng, "bit_generator", None)
    if type(bits) is not np.random.PCG64 or draws < (PCG_MIN_DRAWS if min_draws is None else min_draws):
        yield _NO_STREAM
        return
    with getattr(bits, "lock", _PCG_LOCK):
        state = bits.state
        s, inc = int(state["state"]["state"]), int(state["state"]["inc"])
        words = np.array([s >> 64, s & _U64, inc >> 64, inc & _U64], dtype=np.uint64)
        yield words
        state["state"]["state"] = (int(words[0]) << 64) | int(words[1])
        bits.state = state
