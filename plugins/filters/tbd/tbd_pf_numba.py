"""The Numba twins of ``tbd-pf``'s (and ``sir-jm``'s) array steps (imported only when used).

Each function here is held, number for number, to the NumPy code it replaces in :mod:`workbench_filters.tbd`
(tests/test_tbd.py):

- :func:`jump_markov` is :func:`workbench_filters.tbd.predict_jump_markov_numpy`: the mode switches, the noise
  draws and the ``[F | G]`` product in one pass over the particles, with no ``(B, N, k)`` noise array.  The random
  numbers are drawn here from the caller's ``numpy.random.Generator``, in the order of NumPy's
  ``rng.random((B, N))`` then ``rng.standard_normal((B, N, k))`` (Numba's ``Generator`` runs NumPy's algorithms on
  the same bit generator and state: the same numbers, and the generator left where NumPy leaves it); on PCG64 (every
  ``wb.generator``) the state is stepped in registers (:func:`workbench.kernels.pcg_numba.pcg64_stream`).  The
  product follows :func:`workbench.particle_core.combine_columns`' plan (the scaled terms first, then the unit
  ones, zeros skipped), so the particles are the same bit for bit.
- :func:`normals` is ``rng.standard_normal(shape)`` (the draws of :func:`workbench_filters.tbd.regularise`), by
  :func:`workbench.kernels.particle_numba.fill_normals`.
- :func:`add_jitter` is the last line of :func:`workbench_filters.tbd.regularise` (``out[rows] += h (e D^T)``)
  without the boolean gather and scatter of a component-major array.
- :func:`log_add_floor` is ``where(present, logaddexp(log_eps, log_sum), -inf)`` of
  :func:`workbench_filters.tbd.log_likelihood`, with NumPy's ``logaddexp`` written out (the same ``exp`` and
  ``log1p`` of the C library, the same branches), skipping the library calls where the smaller term cannot
  change the larger one's last bit (:data:`GAP`).
- :func:`systematic_parents` and :func:`gather_rows` are :func:`workbench.resampling.resample_where` after the
  weights' ``exp`` (which stays NumPy's): the cumulative sum, the edges and the ``repeat`` of
  :func:`workbench.resampling.systematic_counts`, then the gather of every resampled item's particles and modes
  (:func:`workbench_filters.tbd.resample_rows`).

No fast-math anywhere (no fused multiply-adds, no reassociation): every result is its twin's bit for bit.
``error_model="numpy"``; module-level functions with ``cache=True`` so that Numba's on-disk cache holds across
processes.
"""

import functools
import math

import numba
import numpy as np

from workbench.kernels.particle_numba import _combine_tile_cols, fill_normals
from workbench.kernels.pcg_numba import _pcg_next_double, draw_tile, pcg64_stream

jit = functools.partial(numba.njit, error_model="numpy", cache=True)

#: particles per tile of :func:`jump_markov` (its noise buffer stays in L1)
TILE = 512
LOGE2 = math.log(2.0)


def normals(rng, shape) -> np.ndarray:
    """``rng.standard_normal(shape)``: the same numbers, and ``rng`` left where NumPy leaves it (C order)."""
    out = np.empty(shape)
    fill_normals(rng, out.reshape(-1, shape[-1]))
    return out


def jump_markov(out, x, mode, new_mode, rng, switch_on, switch_off, scale, k, src, coef, ptr):
    """Two-mode prediction of particles ``x`` into ``out``, modes ``mode`` into ``new_mode``.

    ``new_mode = 1 - mode`` where ``u < (switch_off if mode > 0 else switch_on)``, ``u = rng.random()`` per particle
    (all ``L`` of them first); then per particle ``e_j = rng.standard_normal() * (scale if new_mode > 0 else 1)``,
    ``j < k``, and ``out[i] = sum_t coef[t] s_{src[t]}`` over row ``i``'s terms ``ptr[i]:ptr[i+1]`` in order
    (``s_j = x[j]`` for ``j < n``, ``e_{j - n}`` beyond; a row without terms is zero).

    Shapes: ``out (r, L)``, ``x (n, L)``, ``mode, new_mode (L,)``; ``src, coef (T,)``, ``ptr (r + 1,)``.
    """
    with pcg64_stream(rng, mode.shape[0] * (k + 1)) as pcg:
        _jump_markov(out, x, mode, new_mode, rng, pcg, k, switch_on, switch_off, scale, src, coef, ptr)
    return out


@jit
def _jump_markov(out, x, mode, new_mode, rng, pcg, k, switch_on, switch_off, scale, src, coef, ptr):
    """:func:`jump_markov` with the stream's words ``pcg`` (:func:`workbench.kernels.pcg_numba.pcg64_stream`: the
    PCG64 state, or empty for Numba's ``Generator``)."""
    L = mode.shape[0]
    if pcg.shape[0] == 4:
        hi, lo, inc_hi, inc_lo = pcg[0], pcg[1], pcg[2], pcg[3]
        for t in range(L):
            m = mode[t]
            u, hi, lo = _pcg_next_double(hi, lo, inc_hi, inc_lo)
            new_mode[t] = 1.0 - m if u < (switch_off if m > 0 else switch_on) else m
        pcg[0], pcg[1] = hi, lo
    else:
        for t in range(L):
            m = mode[t]
            u = rng.random()
            new_mode[t] = 1.0 - m if u < (switch_off if m > 0 else switch_on) else m
    e = np.empty((max(k, 1), TILE))
    for lo in range(0, L, TILE):
        hi = min(lo + TILE, L)
        draw_tile(rng, pcg, e, hi - lo, k)
        for t in range(hi - lo):
            s = scale if new_mode[lo + t] > 0 else 1.0
            for j in range(k):
                e[j, t] *= s
        _combine_tile_cols(out, x, e, lo, hi, src, coef, ptr)  # the bootstrap PF's combination, the same sums
    return out


@jit
def add_jitter(out, x, y, rows, h):
    """``out = x`` with ``out[:, rows[r]] = x[:, rows[r]] + h y[r]`` (``h y`` rounded first, as NumPy's
    ``out[rows] += h * y`` does).

    Shapes: ``out, x (n, B, N)`` (component rows of ``(B, N, n)`` particles, any strides), ``y (R, N, n)``,
    ``rows (R,)`` item indices.
    """
    n, B, N = x.shape
    for j in range(n):
        for b in range(B):
            for i in range(N):
                out[j, b, i] = x[j, b, i]
    for r in range(rows.shape[0]):
        b = rows[r]
        for j in range(n):
            for i in range(N):
                out[j, b, i] = x[j, b, i] + h * y[r, i, j]
    return out


#: ``|d| > GAP`` and ``|a| >= BIG``: ``log1p(exp(-|d|)) < 2e-22`` is below half an ulp of ``a`` (``2^-63`` at
#: ``|a| = 2^-10``), so ``a + log1p(exp(-|d|))`` rounds to ``a``: the sum is ``a`` without the two library calls.
GAP, BIG = 50.0, 2.0**-10


@jit(inline="always")
def _logaddexp(a, b):
    # NumPy's npy_logaddexp, with the exact shortcut of a term too small to change the larger one
    if a == b:
        return a + LOGE2
    d = a - b
    if d > GAP and abs(a) >= BIG:
        return a
    if d < -GAP and abs(b) >= BIG:
        return b
    if d > 0:
        return a + math.log1p(math.exp(-d))
    if d <= 0:
        return b + math.log1p(math.exp(d))
    return d  # NaN


@jit
def log_add_floor(log_eps, log_sum, present, out):
    """``out[b, i] = logaddexp(log_eps[b, i or 0], log_sum[b, i])`` where ``present[b]``, else ``-inf``.

    Shapes: ``log_eps (B, 1)`` or ``(B, N)``, ``log_sum, out (B, N)``, ``present (B,)``.
    """
    B, N = log_sum.shape
    wide = log_eps.shape[1] != 1
    for b in range(B):
        if not present[b]:
            for i in range(N):
                out[b, i] = -np.inf
            continue
        for i in range(N):
            out[b, i] = _logaddexp(log_eps[b, i if wide else 0], log_sum[b, i])
    return out


@jit
def systematic_parents(w, u0, parents):
    """The draws of systematic resampling as parent indices, from weights already exponentiated:
    ``parents[r, j] = i`` for ``edge_{i-1} <= j < edge_i``, ``edge_i = clip(ceil((c_i / c_{N-1}) N - u0_r), 0, N)``,
    ``c`` the cumulative sum of ``w[r]`` in index order: the steps of
    :func:`workbench.resampling.systematic_counts` after its ``exp`` (``np.cumsum``, then ``/=``, ``*=``, ``-=``,
    ``ceil``, ``clip``, each rounded as there) and of its ``np.repeat``.  Returns False, leaving ``parents``
    partly written, where an edge is not a number (a NaN weight): NumPy's ``repeat`` refuses that row.

    Shapes: ``w (R, N)``, ``u0 (R,)``, ``parents (R, N)`` int64.
    """
    R, N = w.shape
    cdf = np.empty(N)
    count = float(N)
    for r in range(R):
        acc = 0.0
        for i in range(N):
            acc += w[r, i]
            cdf[i] = acc
        last = cdf[N - 1]
        start = 0
        for i in range(N):
            edge = np.ceil((cdf[i] / last) * count - u0[r])
            if edge != edge:
                return False
            stop = int(min(max(edge, 0.0), count))
            for j in range(start, stop):
                parents[r, j] = i
            start = max(start, stop)
    return True


@jit
def gather_rows(x, out, rows, parents):
    """``out[c, rows[r], j] = x[c, rows[r], parents[r, j]]`` for every component ``c`` (the resampled items; the
    others of ``out`` untouched).  Shapes: ``x, out (k, B, N)`` (component rows, any strides), ``rows (R,)``,
    ``parents (R, N)``."""
    k = x.shape[0]
    for r in range(rows.shape[0]):
        b = rows[r]
        for c in range(k):
            for j in range(parents.shape[1]):
                out[c, b, j] = x[c, b, parents[r, j]]
    return out
