"""The Numba twin of the bootstrap particle filter's array steps (imported only when it is used).

The NumPy twins, which the tests hold every function here to, are the array code of
:mod:`workbench.particle_core` (:func:`~workbench.particle_core.combine_columns` after
``rng.standard_normal``, :func:`~workbench.particle_core.log_likelihood`, ``Particles.to_gaussian``) and of
:mod:`workbench.resampling` (:func:`~workbench.resampling.normalise_log_weights`,
:func:`~workbench.resampling.effective_sample_size`, :func:`~workbench.resampling.systematic_counts` with the
gather of :func:`~workbench.resampling.resample_where`).  :mod:`workbench.particle_core` chooses between them
through the backend policy (:func:`workbench.kernels.backend.resolve`).

Arrays arrive component-major: particles as rows ``(n, L)`` or ``(n, B, N)`` (row ``j`` holds component ``j`` of
every particle of every item, ``L = B N``), log-weights as ``(B, N)``.  Module-level functions compiled with
``cache=True``, so that Numba's on-disk cache holds across processes.

Random numbers.  :func:`propagate`, :func:`propagate_range_bearing` and :func:`fill_normals` draw their normals
from the caller's ``numpy.random.Generator`` in the order ``rng.standard_normal((B, N, k))`` would: on PCG64
(every ``wb.generator``) inside the loop by :mod:`.pcg_numba`, the generator's state read once per call and
stepped in registers; for any other bit generator, and for fewer than :data:`.pcg_numba.PCG_MIN_DRAWS` normals,
by NumPy itself before the kernel (``rng.standard_normal((L, k))``, which the kernel copies tile by tile), so that
no kernel compiles Numba's ``Generator`` code.  Either way the same numbers, and the generator is left where NumPy
would leave it (tested).  A tile's normals are stored by noise column (``e (k, TILE)``), so that
each column the plan reads is contiguous.

Floating point.  No fast-math where a result is held to its twin number for number: :func:`combine` and
:func:`propagate` make the products and sums in the twin's order without fused multiply-adds, so the propagated
particles are the same bit for bit.  The reductions (sums of exponentials, moments) are compiled with
``reassoc`` only (vector partial sums), which changes their last bits; ``nnan``/``ninf`` are never given, so
the NaN and infinity checks hold.  ``exp`` is a polynomial (:func:`exp`, within 1 ulp of the library's) because
the library call does not vectorise.  The likelihood, exponential and moment loops vectorise with the CPU's full
width (:mod:`.vector_width`).  ``error_model="numpy"``: a division by zero gives ``inf``, no exception
branch.  Loops run over 1-D views from index 0, so that Numba emits no negative-index fix-ups and LLVM vectorises.
"""

import functools
import math

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from .atan_poly import TAN_PI_8, atan_reduced
from .particle_numpy import EXP_COEFFS, EXP_UNDERFLOW, INV_LN2, LN2_HI, LN2_LO
from .pcg_numba import _pcg_normal, pcg64_stream, pcg_tile
from .vector_width import wide_vectors

jit = functools.partial(numba.njit, error_model="numpy", cache=True)
#: Reductions and exponentials: reassociation lets LLVM keep vector partial sums, contraction fuses the
#: polynomial's multiply-adds (half the instructions of :func:`exp`).
reduce_jit = functools.partial(numba.njit, error_model="numpy", cache=True, fastmath={"reassoc", "contract"})

tan_pi_8, pi, two_pi, inv_two_pi = TAN_PI_8, math.pi, 2.0 * math.pi, 1.0 / (2.0 * math.pi)
e0, e1, e2, e3, e4, e5, e6, e7, e8, e9, e10, e11, e12, e13 = EXP_COEFFS
inv_ln2, ln2_hi, ln2_lo, underflow = INV_LN2, LN2_HI, LN2_LO, EXP_UNDERFLOW
#: Particles per tile of the multi-pass loops (every row of a tile stays in L1).
TILE = 1024


@intrinsic
def _as_double(typingctx, bits):  # reinterpret int64 bits as float64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@intrinsic
def _as_int64(typingctx, value):  # reinterpret float64 bits as int64
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


#: ``1.5 * 2^52``: for a whole ``n`` with ``|n| < 2^51``, ``n + ROUND_SHIFT`` is exact and its bits are
#: ``bits(ROUND_SHIFT) + n``, whose low 12 bits are those of ``n``.
ROUND_SHIFT = 6755399441055744.0


@jit(inline="always")
def exp(x):
    """``exp(x)`` for ``x <= 0``, the steps of :func:`.particle_numpy.poly_exp`: ``0`` below ``EXP_UNDERFLOW``
    (and for ``-inf``), NaN for NaN.

    No conversion between double and integer (on a CPU without AVX-512DQ, x86 has no vector instruction for
    it, and the loop would run lane by lane): ``n`` is rounded to the nearest whole double, ties to even, as
    Python's ``round`` and ``np.round`` do (``np.rint``), and ``2^n`` is built from the bits of ``n +``
    :data:`ROUND_SHIFT` (the same ``(n + 1023) << 52`` in the exponent field, all other bits shifted out)."""
    y = max(x, underflow)
    n = np.rint(y * inv_ln2)
    r = (y - n * ln2_hi) - n * ln2_lo
    p = ((((((((((((e0 * r + e1) * r + e2) * r + e3) * r + e4) * r + e5) * r + e6) * r + e7) * r + e8) * r + e9)
             * r + e10) * r + e11) * r + e12) * r + e13
    v = p * _as_double((_as_int64(n + ROUND_SHIFT) + 1023) << 52)
    return v if x >= underflow else (0.0 if x < underflow else x)


@jit(inline="always")
def _term(o, c, s, first):
    """``o = c s`` (``first``) or ``o += c s`` over 1-D views."""
    if first:
        for t in range(o.shape[0]):
            o[t] = c * s[t]
    else:
        for t in range(o.shape[0]):
            o[t] += c * s[t]


@jit
def _combine_tile_cols(out, x, e, lo, hi, src, coef, ptr):
    """:func:`combine` on the particles ``lo:hi``, the tile's noise stored by column: ``e[j, t]`` noise ``j`` of
    particle ``lo + t`` (:func:`.pcg_numba.pcg_tile`'s layout; each column contiguous).  A tile of noise stored by
    row (``e[t, j]``) is passed transposed (a view): the same products and sums in the same order."""
    n = x.shape[0]
    m = hi - lo
    for i in range(out.shape[0]):
        o = out[i, lo:hi]
        if ptr[i] == ptr[i + 1]:
            o[:] = 0.0
            continue
        for q in range(ptr[i], ptr[i + 1]):
            j = src[q]
            if j < n:
                _term(o, coef[q], x[j, lo:hi], q == ptr[i])
            else:
                _term(o, coef[q], e[j - n, :m], q == ptr[i])


@jit
def combine(out, x, e, src, coef, ptr):
    """``out[i] = sum_t coef[t] s_{src[t]}`` over the terms ``t`` of row ``i`` (``ptr[i]:ptr[i+1]``), in order.

    ``s_j`` is ``x[j]`` for ``j < n`` and ``e[:, j - n]`` beyond: the product ``[F | G] [x; e]`` with only the
    non-zero coefficients of each row, in the order of :func:`workbench.particle_core.combine_columns` (a
    coefficient one multiplies exactly, so the result is that function's bit for bit).  A row without terms is
    zero.

    Shapes: ``out (r, L)``, ``x (n, L)``, ``e (L, k)``, ``src, coef (T,)``, ``ptr (r + 1,)``.
    """
    L = out.shape[1]
    for lo in range(0, L, TILE):
        hi = min(lo + TILE, L)
        _combine_tile_cols(out, x, e[lo:hi].T, lo, hi, src, coef, ptr)  # the rows' tile, transposed: a view
    return out


def propagate(out, x, rng, k, src, coef, ptr):
    """:func:`combine` with ``e`` drawn here: ``e = rng.standard_normal((L, k))``, the same numbers in the same
    order; on PCG64 one tile at a time with the state stepped in registers (:func:`.pcg_numba.pcg64_stream`; no
    ``(L, k)`` array), else drawn by NumPy first (:func:`_numpy_normals`).

    Shapes: ``out (r, L)``, ``x (n, L)``; ``k`` noise columns.
    """
    with pcg64_stream(rng, k * out.shape[1]) as pcg:
        _propagate(out, x, pcg, _numpy_normals(rng, pcg, out.shape[1], k), k, src, coef, ptr)
    return out


#: The kernels' ``pre`` where the normals are drawn in the kernel (PCG64) or there are none.
_NO_NORMALS = np.zeros((0, 0))


def _numpy_normals(rng, pcg, L, k):
    """The normals of ``L`` particles with ``k`` noise columns as NumPy draws them, ``rng.standard_normal((L, k))``
    (C order: particle by particle), where the kernel does not draw them itself (``pcg`` empty: not PCG64, or too
    few draws); else (and for ``k = 0``) an empty array."""
    if pcg.shape[0] == 4 or k == 0:
        return _NO_NORMALS
    return np.ascontiguousarray(rng.standard_normal((L, k)), dtype=np.float64)


@jit
def _draw_tile(pcg, pre, e, lo, m, k):
    """``e[:k, :m]``: the normals of the particles ``lo:lo + m`` stored by noise column (``e[j, t]`` the ``j``-th
    of particle ``lo + t``): drawn from the PCG64 words ``pcg`` (advanced in place, :func:`.pcg_numba.pcg_tile`) where it holds four, else copied from NumPy's draws ``pre (L, k)``.  Compiled once for :func:`_propagate`
    and :func:`propagate_range_bearing` (a call per tile, instead of a copy of the loop compiled into each)."""
    if pcg.shape[0] == 4:
        pcg_tile(pcg, e, m, k)
    else:
        for t in range(m):
            for j in range(k):
                e[j, t] = pre[lo + t, j]


@jit
def _propagate(out, x, pcg, pre, k, src, coef, ptr):
    """:func:`propagate` with the stream's words ``pcg`` (:func:`.pcg_numba.pcg64_stream`) or NumPy's normals
    ``pre``."""
    L = out.shape[1]
    e = np.empty((max(k, 1), TILE))
    for lo in range(0, L, TILE):
        hi = min(lo + TILE, L)
        _draw_tile(pcg, pre, e, lo, hi - lo, k)
        _combine_tile_cols(out, x, e, lo, hi, src, coef, ptr)
    return out


def fill_normals(rng, out):
    """``out[...] = rng.standard_normal(out.shape)``: the draw loop of :func:`propagate` alone (the numbers NumPy
    would draw, in C order, by the same code: on PCG64 the state stepped in registers, else NumPy's own call), for
    the benchmark's floor.  Shapes: ``out (L, k)``, C-contiguous."""
    with pcg64_stream(rng, out.size) as pcg:
        if pcg.shape[0] == 4:
            _fill_normals(pcg, out)
        else:
            out[...] = rng.standard_normal(out.shape)
    return out


@jit
def _fill_normals(pcg, out):
    """:func:`fill_normals` with the PCG64 stream's words ``pcg`` (:func:`.pcg_numba.pcg64_stream`, four)."""
    hi, lo, inc_hi, inc_lo = pcg[0], pcg[1], pcg[2], pcg[3]
    for t in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[t, j], hi, lo = _pcg_normal(hi, lo, inc_hi, inc_lo)
    pcg[0], pcg[1] = hi, lo
    return out


_atan_reduced = jit(inline="always")(atan_reduced)  # the twin's own expression, compiled


@jit(inline="always")
def atan2(y, x):
    """``atan2(y, x)`` by range reduction (one division) and :func:`.atan_poly.atan_reduced` (a degree-10 polynomial
    by Estrin's scheme; within 2 ulp), with selects only (a library ``atan2`` per particle does not vectorise; this
    does): the NumPy twin :func:`.atan_poly.atan2_poly`, the same operations in the same order."""
    ax = abs(x)
    ay = abs(y)
    swap = ay > ax
    mx = ay if swap else ax
    mn = ax if swap else ay
    big = mn > tan_pi_8 * mx
    num = mn - mx if big else mn
    den = mn + mx if big else mx
    t = num / (den if den > 0.0 else 1.0)
    r = _atan_reduced(t) + (0.25 * pi if big else 0.0)
    r = 0.5 * pi - r if swap else r
    r = pi - r if math.copysign(1.0, x) < 0.0 else r  # the sign bit: atan2(+-0, -0) = +-pi
    return math.copysign(r, y)


@jit
def range_bearing_log_weights(px, py, z, sensor, linv, prev, out):
    """``out = -1/2 |L^-1 nu|^2 + prev`` with ``nu = [z_r - |p - s|, wrap(z_b - atan2(p - s))]`` per particle.

    The log-likelihood of :func:`workbench.particle_core.log_likelihood` for a range-bearing model, plus the
    previous log-weights, in one pass: ``R = L L^T`` with ``linv = L^-1`` lower triangular (a zero entry is
    skipped, as the twin skips it, so that an infinite residual makes no NaN); the bearing residual wrapped to
    ``(-pi, pi]`` as :func:`workbench.linalg.wrap_angle` does.

    Shapes: ``px, py (B, N)`` positions, ``z (B, 2)`` ``[range, bearing]``, ``sensor (2,)``, ``linv (2, 2)``,
    ``prev, out (B, N)``.
    """
    wide_vectors()
    B = out.shape[0]
    sx, sy = sensor[0], sensor[1]
    l00, l10, l11 = linv[0, 0], linv[1, 0], linv[1, 1]
    cross = l10 != 0.0
    for b in range(B):
        zr, zb = z[b, 0], z[b, 1]
        xb, yb, wb, ob = px[b], py[b], prev[b], out[b]
        for i in range(ob.shape[0]):
            ob[i] = _range_bearing_term(xb[i] - sx, yb[i] - sy, zr, zb, l00, l10, l11, cross) + wb[i]
    return out


@jit(inline="always")
def _range_bearing_term(dx, dy, zr, zb, l00, l10, l11, cross):
    """``-1/2 |L^-1 nu|^2`` for one particle at ``(dx, dy)`` from the sensor (:func:`range_bearing_log_weights`)."""
    nr = zr - math.sqrt(dx * dx + dy * dy)
    a = zb - atan2(dy, dx)
    # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
    nb = a - two_pi * np.ceil((a - pi) * inv_two_pi)
    # white = L^-1 nu;  -1/2 nu^T R^-1 nu = -1/2 |white|^2
    w0 = l00 * nr
    w1 = l10 * nr + l11 * nb if cross else l11 * nb
    return -0.5 * (w0 * w0 + w1 * w1)


@jit
def _weigh_tile(px, py, zr, zb, sensor, linv, prev, out):
    """:func:`range_bearing_log_weights` of one item's tile (1-D views); returns the tile's max (NaN where one
    log-weight is NaN).  Its own function, so that its loop vectorises with the full width
    (:func:`.vector_width.wide_vectors`) while the draws of :func:`propagate_range_bearing` keep LLVM's choice."""
    wide_vectors()
    sx, sy = sensor[0], sensor[1]
    l00, l10, l11 = linv[0, 0], linv[1, 0], linv[1, 1]
    cross = l10 != 0.0
    for i in range(out.shape[0]):
        out[i] = _range_bearing_term(px[i] - sx, py[i] - sy, zr, zb, l00, l10, l11, cross) + prev[i]
    m = -np.inf
    nan = False
    for i in range(out.shape[0]):
        v = out[i]
        m = v if v > m else m
        nan |= v != v
    return np.nan if nan else m


#: Empty estimate outputs: :func:`propagate_range_bearing` without the predicted estimate (one signature either way).
_NO_MEAN = np.zeros((0, 4))
_NO_COV = np.zeros((0, 4, 4))


def propagate_range_bearing(out, x, rng, k, src, coef, ptr, present, z, sensor, linv, prev, log_w, top, mean=None,
                            cov=None):
    """:func:`propagate` and, for the items with ``present``, :func:`range_bearing_log_weights` and the rows' max
    in one pass, one tile of particles at a time: a tile's particles are moved (the normals drawn from ``rng`` in
    the order of ``rng.standard_normal((B, N, k))``, on PCG64 with the state in registers, else by NumPy first
    as :func:`propagate` does), then weighed while they
    are in L1, instead of read back from memory by a second pass.  The arithmetic per particle is those two
    functions' (the same inline code), so the particles and log-weights are theirs bit for bit; ``top[b]`` is
    ``np.max(log_w[b])`` (NaN where a log-weight is NaN).  Items without ``present``: moved, ``log_w = prev``,
    ``top`` not written.

    ``mean (B, 4)``, ``cov (B, 4, 4)`` (the planar state only; ``None``: not computed): :func:`moments` of the moved
    particles with the weights ``prev`` (the estimate of the predicted state), its numbers bit for bit: where an
    item's ``prev`` are all equal, each tile's sums are taken while it is in L1, the tiles, sums and pivot of
    :func:`moments`; otherwise :func:`moments`' weighted pass over the item right after its last tile.

    Shapes: ``out, x (n, L)`` component rows with ``L = B N`` (``out`` not sharing memory with ``x``); ``k`` noise
    columns; the plan ``src, coef, ptr`` of :func:`combine`; ``present (B,)``; ``z (B, 2)``; ``sensor (2,)``;
    ``linv (2, 2)``; ``prev, log_w (B, N)``; ``top (B,)``.
    """
    if mean is None:
        mean, cov = _NO_MEAN, _NO_COV
    elif out.shape[0] != 4 or mean.shape != (log_w.shape[0], 4) or cov.shape != (log_w.shape[0], 4, 4):
        raise ValueError(f"propagate_range_bearing: the predicted estimate needs the planar state (n = 4) and "
                         f"mean (B, 4), cov (B, 4, 4); got n = {out.shape[0]}, {mean.shape}, {cov.shape}")
    with pcg64_stream(rng, k * out.shape[1]) as pcg:
        _propagate_range_bearing(out, x, pcg, _numpy_normals(rng, pcg, out.shape[1], k), k, src, coef, ptr, present,
                                 z, sensor, linv, prev, log_w, top, mean, cov)
    return out


@jit
def _propagate_range_bearing(out, x, pcg, pre, k, src, coef, ptr, present, z, sensor, linv, prev, log_w, top, mean,
                             cov):
    """:func:`propagate_range_bearing` with the stream's words ``pcg`` (:func:`.pcg_numba.pcg64_stream`) or NumPy's
    normals ``pre``; the estimate where ``mean`` has ``B`` rows."""
    B, N = log_w.shape
    e = np.empty((max(k, 1), TILE))
    est = mean.shape[0] == B and N > 0
    s = np.empty(4)
    acc = np.zeros(14)
    for b in range(B):
        weigh = present[b]
        zr, zb = z[b, 0], z[b, 1]
        m = -np.inf
        nan = False
        wb, ob = prev[b], log_w[b]
        pivot, uniform = _pivot(wb) if est else (0, False)
        acc[:] = 0.0
        for lo in range(b * N, (b + 1) * N, TILE):
            hi = min(lo + TILE, (b + 1) * N)
            _draw_tile(pcg, pre, e, lo, hi - lo, k)
            _combine_tile_cols(out, x, e, lo, hi, src, coef, ptr)
            a, c = lo - b * N, hi - b * N
            x0, x1, wt, ot = out[0, lo:hi], out[1, lo:hi], wb[a:c], ob[a:c]  # each view made once
            if weigh:
                v = _weigh_tile(x0, x1, zr, zb, sensor, linv, wt, ot)
                nan |= v != v
                m = v if v > m else m
            else:
                _copy(ot, wt)
            if est and uniform:  # moments' equal-weight sums of this tile (pivot: the item's first particle)
                if a == 0:
                    s[0], s[1], s[2], s[3] = out[0, lo], out[1, lo], out[2, lo], out[3, lo]
                _equal_weight_tile_sums(x0, x1, out[2, lo:hi], out[3, lo:hi], s, acc)
        if weigh:
            top[b] = np.nan if nan else m
        if est:
            if uniform:
                _finish_equal(float(N), wb[0], acc, s, mean[b], cov[b])
            else:
                q = b * N
                for r in range(4):
                    s[r] = out[r, q + pivot]
                # uniform (False here), not a literal False: a literal is another signature, a second compile
                _moments_planar(out[0, q:q + N], out[1, q:q + N], out[2, q:q + N], out[3, q:q + N], wb, s, uniform,
                                mean[b], cov[b])
    return out


@jit
def _pivot(row):
    """``(pivot, uniform)`` of one item's log-weights for :func:`moments`: the first heaviest particle (the first
    one where ``row[0]`` is NaN; NaNs are never picked) and whether every entry equals ``row[0]``: one function, so
    that :func:`moments` and :func:`propagate_range_bearing` pick the same pivot."""
    first = row[0]
    pivot = 0
    uniform = True
    for i in range(row.shape[0]):
        if row[i] > row[pivot]:
            pivot = i
        uniform &= row[i] == first
    return pivot, uniform


@reduce_jit
def _sum_exp(row, shift, scale):
    """``sum_i exp(scale row_i - shift)``."""
    wide_vectors()
    s = 0.0
    for i in range(row.shape[0]):
        s += exp(scale * row[i] - shift)
    return s


@jit(inline="always")
def _copy(out, row):
    for i in range(out.shape[0]):
        out[i] = row[i]


@reduce_jit
def normalise(log_w, top, present, fallback, out, dead):
    """Rows ``b`` with ``present[b]``: ``out = log_w - log sum_i exp(log_w_i)``; a present row whose largest entry
    ``top[b]`` is not finite (all ``-inf``, a NaN or ``+inf``) gets ``fallback`` and ``dead[b] = True``.  Rows
    without ``present``: ``fallback``.

    Shapes: ``log_w, fallback, out (B, N)``; ``top (B,)`` (``np.max(log_w, axis=1)``); ``present, dead (B,)``.
    """
    B = log_w.shape[0]
    for b in range(B):
        dead[b] = False
        row = log_w[b]
        dst = out[b]
        if present[b]:
            m = top[b]
            if math.isfinite(m):
                # log sum_i exp(l_i) = m + log sum_i exp(l_i - m)
                total = m + math.log(_sum_exp(row, m, 1.0))
                for i in range(dst.shape[0]):
                    dst[i] = row[i] - total
                continue
            dead[b] = True
        _copy(dst, fallback[b])
    return out


@reduce_jit
def effective_sample_size(log_w, top, out):
    """``N_eff = 1 / sum_i w_i^2 = exp(-log sum_i exp(2 log w_i))`` per row of normalised log-weights.

    Shapes: ``log_w (B, N)``, ``top (B,)`` (``np.max(log_w, axis=1)``) -> ``out (B,)``.
    """
    B = log_w.shape[0]
    for b in range(B):
        m = 2.0 * top[b]
        shift = m if math.isfinite(m) else 0.0
        s = _sum_exp(log_w[b], shift, 2.0)
        out[b] = math.exp(-(shift + math.log(s))) if s > 0.0 else np.inf
    return out


@reduce_jit
def _exp_shifted(row, top, out):
    wide_vectors()
    for i in range(out.shape[0]):
        out[i] = exp(row[i] - top)


@jit(inline="always")  # one caller: no dispatcher of its own to compile
def _take_first_parents(dst, src, parent):
    """``dst[c, j] = src[c, p_j]`` for every row ``c`` with ``p_j = max(parent[:j + 1])`` (the running max fills the
    slots :func:`systematic_gather` left unwritten), in one pass over the parents for the planar state."""
    n = dst.shape[0]
    p = 0
    if n == 4:  # the common planar state, unrolled: the running max and the four gathers in one pass
        d0, d1, d2, d3 = dst[0], dst[1], dst[2], dst[3]
        s0, s1, s2, s3 = src[0], src[1], src[2], src[3]
        for j in range(parent.shape[0]):
            p = max(p, parent[j])
            d0[j] = s0[p]
            d1[j] = s1[p]
            d2[j] = s2[p]
            d3[j] = s3[p]
        return
    for j in range(parent.shape[0]):
        p = max(p, parent[j])
        parent[j] = p
    for c in range(n):
        d = dst[c]
        s = src[c]
        for j in range(parent.shape[0]):
            d[j] = s[parent[j]]


@jit
def _parents(row, m, u, cdf, parent):
    """The systematic draws of one item as parent slots: ``c_i = sum_{k<=i} w_k / sum_k w_k`` with ``w = exp(row -
    m)`` (uniform where ``m``, the row's max, is not finite), ``edge_i = ceil(N c_i - u)`` clipped to ``[0, N]``,
    and ``parent[edge_{i-1}] = i`` for every ``i`` in order (other slots 0), so that the running max of ``parent``
    is the particle of each draw.  ``cdf (N,)`` and ``parent (N + 1,)`` are work arrays."""
    N = row.shape[0]
    if math.isfinite(m):
        _exp_shifted(row, m, cdf)
    else:
        cdf[:] = 1.0
    # c_i = sum_{k <= i} w_k in index order, then / c_{N-1}
    acc = 0.0
    for i in range(N):
        acc += cdf[i]
        cdf[i] = acc
    last = cdf[N - 1]
    # #{j : (u0 + j) / N < c_i} = ceil(N c_i - u0), clipped to [0, N]
    for i in range(N):
        cdf[i] = min(max(np.ceil((cdf[i] / last) * N - u), 0.0), float(N))
    # parent[edge_{i-1}] = i for every i in order: the last writer of a slot is the particle whose draws
    # start there (those with no draw share the slot with it and come before); then a running max, taken
    # as the particles are gathered, fills the slots of repeated draws.  No branch on the counts.
    parent[:] = 0
    start = 0
    for i in range(N):
        parent[start] = i
        start = int(cdf[i])


@jit
def systematic_gather(log_w, top, rows, u0, x, out, cdf, parent):
    """Systematic resampling of the items ``rows``, gathered into ``out``; other items copied unchanged.

    For item ``b = rows[r]``: ``c_i = sum_{k<=i} w_k / sum_k w_k`` with ``w = exp(log_w - top_b)`` (uniform where
    ``top_b``, the row's max, is not finite), ``edge_i = ceil(N c_i - u0_r)`` clipped to ``[0, N]``, and draw ``j``
    is particle ``i`` for ``edge_{i-1} <= j < edge_i``: the steps of :func:`workbench.resampling.systematic_counts`
    and its ``repeat``, in the same order (the cumulative sum in index order, as ``np.cumsum``).

    Shapes: ``log_w (B, N)``; ``top (B,)``; ``rows (R,)`` int, ascending; ``u0 (R,)``; ``x, out (n, B, N)``;
    ``cdf (N,)`` and ``parent (N + 1,)`` int64 scratch.
    """
    n, B, N = x.shape
    r = 0
    for b in range(B):
        if r < rows.shape[0] and rows[r] == b:
            _parents(log_w[b], top[b], u0[r], cdf, parent)
            _take_first_parents(out[:, b], x[:, b], parent[:N])
            r += 1
        else:
            for c in range(n):
                _copy(out[c, b], x[c, b])
    return out


@jit
def systematic_gather_moments(log_w, top, u0, x, out, cdf, parent, lw_equal, mean, cov):
    """:func:`systematic_gather` of every item of the planar state (``n = 4``) and :func:`moments` of the result
    with the equal weights ``exp(lw_equal)`` (``-log N``, what the resampled items' log-weights are), in the
    gather's pass: each tile of :data:`MOMENT_TILE` gathered particles is summed (:func:`_equal_weight_tile_sums`)
    while it is in L1, instead of being read back from memory by the estimate.  The same tiles, sums and pivot (the
    first particle: every weight is the largest) as :func:`moments`, so ``mean`` and ``cov`` are its numbers bit for
    bit, and ``out`` is :func:`systematic_gather`'s.

    Shapes: ``log_w (B, N)``; ``top (B,)``; ``u0 (B,)``; ``x, out (4, B, N)``; ``cdf (N,)``, ``parent (N + 1,)``
    int64 scratch; ``mean (B, 4)``, ``cov (B, 4, 4)``.
    """
    n, B, N = x.shape
    s = np.empty(4)
    acc = np.zeros(14)
    for b in range(B):
        _parents(log_w[b], top[b], u0[b], cdf, parent)
        d0, d1, d2, d3 = out[0, b], out[1, b], out[2, b], out[3, b]
        s0, s1, s2, s3 = x[0, b], x[1, b], x[2, b], x[3, b]
        acc[:] = 0.0
        p = 0
        for lo in range(0, N, MOMENT_TILE):
            hi = min(lo + MOMENT_TILE, N)
            for j in range(lo, hi):  # _take_first_parents' planar loop, one tile
                p = max(p, parent[j])
                d0[j] = s0[p]
                d1[j] = s1[p]
                d2[j] = s2[p]
                d3[j] = s3[p]
            if lo == 0:
                s[0], s[1], s[2], s[3] = d0[0], d1[0], d2[0], d3[0]
            _equal_weight_tile_sums(d0[lo:hi], d1[lo:hi], d2[lo:hi], d3[lo:hi], s, acc)
        _finish_equal(float(N), lw_equal, acc, s, mean[b], cov[b])
    return out


@reduce_jit(inline="always")
def _dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@reduce_jit(inline="always")
def _dot3(w, a, b):
    s = 0.0
    for i in range(w.shape[0]):
        s += w[i] * a[i] * b[i]
    return s


#: Particles per tile of the planar moments' equal-weight sums: :func:`moments` sums each tile by
#: :func:`_equal_weight_tile_sums` and adds the tiles' sums in order, and :func:`systematic_gather_moments` and
#: :func:`propagate_range_bearing` (whose tiles are :data:`TILE`) do the same on each tile they have just written
#: (while it is in L1), so that all give the same bits.
MOMENT_TILE = TILE


@reduce_jit
def _equal_weight_tile_sums(x0, x1, x2, x3, s, acc):
    """``acc += [sum d_0 .. sum d_3, sum d_j d_k (j <= k, row by row)]`` over one tile of the planar state, with
    ``d = x - s`` (``acc (14,)``): the unweighted sums of :func:`_moments_planar` for equal weights.  Its own
    function, compiled once, so that both callers sum a tile in the same order."""
    wide_vectors()
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    a0 = a1 = a2 = a3 = 0.0
    c00 = c01 = c02 = c03 = c11 = c12 = c13 = c22 = c23 = c33 = 0.0
    for i in range(x0.shape[0]):
        d0 = x0[i] - s0
        d1 = x1[i] - s1
        d2 = x2[i] - s2
        d3 = x3[i] - s3
        a0 += d0
        a1 += d1
        a2 += d2
        a3 += d3
        c00 += d0 * d0
        c01 += d0 * d1
        c02 += d0 * d2
        c03 += d0 * d3
        c11 += d1 * d1
        c12 += d1 * d2
        c13 += d1 * d3
        c22 += d2 * d2
        c23 += d2 * d3
        c33 += d3 * d3
    acc[0] += a0
    acc[1] += a1
    acc[2] += a2
    acc[3] += a3
    acc[4] += c00
    acc[5] += c01
    acc[6] += c02
    acc[7] += c03
    acc[8] += c11
    acc[9] += c12
    acc[10] += c13
    acc[11] += c22
    acc[12] += c23
    acc[13] += c33


@reduce_jit
def _finish_planar(sw, acc, s, mean, cov):
    """``mean = s sum w + sum w d`` and ``cov = sum w d d^T - e a^T - a e^T + e e^T sum w`` from the weighted sums
    ``acc`` (``a = acc[:4]``, then ``sum w d d^T`` as in :func:`_equal_weight_tile_sums`) about the pivot ``s``,
    ``e = mean - s`` (the twin's ``sum w (x - mean)(x - mean)^T`` expanded)."""
    a0, a1, a2, a3 = acc[0], acc[1], acc[2], acc[3]
    a = (a0, a1, a2, a3)
    # e = mean - s
    e = (a0 + s[0] * (sw - 1.0), a1 + s[1] * (sw - 1.0), a2 + s[2] * (sw - 1.0), a3 + s[3] * (sw - 1.0))
    for j in range(4):
        mean[j] = s[j] * sw + a[j]
    t = 4
    for j in range(4):
        for k in range(j, 4):
            v = acc[t] - e[j] * a[k] - a[j] * e[k] + e[j] * e[k] * sw
            cov[j, k] = v
            cov[k, j] = v
            t += 1


@reduce_jit
def _finish_equal(count, lw, acc, s, mean, cov):
    """:func:`_finish_planar` for ``count`` equal weights ``w = exp(lw)``: the unweighted sums ``acc`` scaled by
    ``w`` once (summing the equal weights themselves would add up correlated round-off, N ulps), ``sum w = count
    w``.  The ``exp`` is taken here, so that every caller gets the same bits (a caller compiled without
    contraction would round the polynomial otherwise)."""
    w = exp(lw)
    for t in range(14):
        acc[t] *= w
    _finish_planar(count * w, acc, s, mean, cov)


@reduce_jit
def _moments_planar(x0, x1, x2, x3, row, s, uniform, mean, cov):
    """:func:`moments` of one item of the planar state ``(x0..x3)``: the weighted sums of ``d = x - s`` and
    ``d d^T`` about a pivot particle ``s``, then :func:`_finish_planar`.  The cancellation in ``cov`` grows
    with ``k^2``, the pivot's squared distance from the mean in standard deviations; a pivot of weight ``w_s`` adds
    ``w_s k^2`` to the normalised variance, so ``k^2 <= 1 / w_s``, at most ``N`` for the heaviest particle, which
    :func:`moments` pivots on (round-off of order ``N`` ulps of the variance at worst, tested).  Equal weights
    (every step after resampling): unweighted sums, tile by tile (:func:`_equal_weight_tile_sums`), scaled once
    (:func:`_finish_equal`)."""
    wide_vectors()
    acc = np.zeros(14)
    if uniform:
        N = x0.shape[0]
        for lo in range(0, N, MOMENT_TILE):
            hi = min(lo + MOMENT_TILE, N)
            _equal_weight_tile_sums(x0[lo:hi], x1[lo:hi], x2[lo:hi], x3[lo:hi], s, acc)
        _finish_equal(float(N), row[0], acc, s, mean, cov)
        return
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    sw = a0 = a1 = a2 = a3 = 0.0
    c00 = c01 = c02 = c03 = c11 = c12 = c13 = c22 = c23 = c33 = 0.0
    for i in range(row.shape[0]):
        w = exp(row[i])
        d0 = x0[i] - s0
        d1 = x1[i] - s1
        d2 = x2[i] - s2
        d3 = x3[i] - s3
        w0 = w * d0
        w1 = w * d1
        w2 = w * d2
        w3 = w * d3
        sw += w
        a0 += w0
        a1 += w1
        a2 += w2
        a3 += w3
        c00 += w0 * d0
        c01 += w0 * d1
        c02 += w0 * d2
        c03 += w0 * d3
        c11 += w1 * d1
        c12 += w1 * d2
        c13 += w1 * d3
        c22 += w2 * d2
        c23 += w2 * d3
        c33 += w3 * d3
    acc[0], acc[1], acc[2], acc[3] = a0, a1, a2, a3
    acc[4], acc[5], acc[6], acc[7], acc[8] = c00, c01, c02, c03, c11
    acc[9], acc[10], acc[11], acc[12], acc[13] = c12, c13, c22, c23, c33
    _finish_planar(sw, acc, s, mean, cov)


def moments(x, log_w, mean, cov, w):
    """Weighted mean and covariance of each item's particles: ``mean = sum_i w_i x_i``,
    ``cov = sum_i w_i (x_i - mean)(x_i - mean)^T`` with ``w = exp(log_w)`` (``Particles.to_gaussian``).

    The planar state (``n = 4``) in one pass over the particles about the heaviest particle
    (:func:`_moments_planar`; a row with a NaN pivots on its first particle, equal weights take one ``exp``);
    other dimensions in two (the mean, then the covariance about it).

    Shapes: ``x (n, B, N)``, ``log_w (B, N)``, ``mean (B, n)``, ``cov (B, n, n)``, ``w (N,)`` scratch.
    """
    if x.shape[0] == 4:
        _moments4(x, log_w, mean, cov)
    else:
        _moments_n(x, log_w, mean, cov, w)
    return mean


@reduce_jit
def _moments4(x, log_w, mean, cov):
    """:func:`moments` of the planar state: one pass per item (:func:`_moments_planar`)."""
    B = x.shape[1]
    s = np.empty(4)
    for b in range(B):
        row = log_w[b]
        pivot, uniform = _pivot(row)
        for c in range(4):
            s[c] = x[c, b, pivot]
        _moments_planar(x[0, b], x[1, b], x[2, b], x[3, b], row, s, uniform, mean[b], cov[b])


@reduce_jit
def _moments_n(x, log_w, mean, cov, w):
    """:func:`moments` of any other dimension: the mean, then the covariance about it, tile by tile (its own
    kernel, chosen in Python, so that the planar state's compiles none of it)."""
    n, B, N = x.shape
    d = np.empty((n, TILE))
    for b in range(B):
        row = log_w[b]
        for i in range(N):
            w[i] = exp(row[i])
        for c in range(n):
            # mean_c = sum_i w_i x_ic
            mean[b, c] = _dot(w, x[c, b])
        cov[b] = 0.0
        for lo in range(0, N, TILE):
            hi = min(lo + TILE, N)
            wt = w[lo:hi]
            for c in range(n):
                m = mean[b, c]
                dc = d[c, : hi - lo]
                xc = x[c, b, lo:hi]
                for i in range(dc.shape[0]):
                    dc[i] = xc[i] - m
            for c in range(n):
                for k in range(c, n):
                    # cov_ck = sum_i w_i d_ic d_ik
                    cov[b, c, k] += _dot3(wt, d[c, : hi - lo], d[k, : hi - lo])
        for c in range(n):
            for k in range(c + 1, n):
                cov[b, k, c] = cov[b, c, k]
