"""Compiled ``f`` and Jacobian of the coordinated turn with the rate in the state (imported only when used).

The model is :class:`workbench.models.CoordinatedTurnRate`, state ``[x, y, vx, vy, omega]``; its NumPy form
(``CoordinatedTurnRate.f_numpy`` / ``jacobian_numpy``) is the twin these loops are held to
(``tests/test_motion_kernels.py``, to 1e-12 on both sides of ``omega = 0``).  The model asks the backend policy
(:func:`workbench.kernels.backend.resolve`) which to run: these loops where it resolves to Numba, the NumPy twin
elsewhere (no Numba, or a GPU arch: there is no Taichi version).

The formulas are the twin's, one state per iteration: with ``u = omega T``, ``sin u / u``, ``(1 - cos u) / u``
and their ``u``-derivatives from their closed forms, or, near ``u = 0``, from the Taylor coefficients the twin
evaluates (passed in, so that both use one table).  The twin evaluates both forms for every state (four series of
25 coefficients, blended by ``np.where`` at ``|u| = 0.1``: about a hundred passes over the batch); these loops
make one pass and take one form per state.  The Jacobian takes the series where ``|u| < small`` (the twin's band),
summing only the terms that can reach 1e-20 there, by Horner's rule in ``u^2`` (each series has powers of one
parity).  ``f`` takes them wherever ``|u| <`` :data:`SERIES_BOUND` (``pi / 4``: ten terms each, written out, so
that the particle filter's tile loop has no branch and vectorises; libm's ``sin`` and ``cos`` beyond, for the
few particles there), with ``sin u = u (sin u / u)`` and ``cos u = 1 - u ((1 - cos u) / u)`` from the same
series.  The two forms differ by round-off, far less than 1e-12.

:func:`ct_rate_propagate` is the particle filter's propagation through the model, ``f`` plus the process noise
drawn inside the loop, in one pass (the model declares it: :meth:`CoordinatedTurnRate.particle_propagator`); its
twin is the NumPy path of :func:`workbench.particle_core.predict` (the model's ``f``, NumPy's draws, the noise added
by :func:`~workbench.particle_core.combine_columns`), which it equals bit for bit where that ``f`` is
:func:`ct_rate_f` (the same formula, one inline function) and to ``f``'s round-off against ``f_numpy``.
:func:`ct_rate_propagate_range_bearing` adds the planar range-bearing log-weights and their rows' max, tile by
tile while the moved particles are in L1 (:meth:`CoordinatedTurnRate.fused_particle_propagator`, used by
:func:`workbench.particle_core.predict_log_weights` and the bootstrap filter's fused step), the two calls' numbers
bit for bit.

Normals: NumPy's own (``Generator.standard_normal``: the ziggurat on the bit generator's 64-bit words), the same
numbers in the same order and the generator left where NumPy leaves it, drawn by :mod:`.pcg_numba` (shared with the
linear models' passes of :mod:`.particle_numba`).  For PCG64 (every ``wb.generator``) the
state is read once per call (:func:`pcg64_stream`) and stepped in registers (:func:`_pcg_normal`: one 128-bit
multiply-add per word, the first box of the ziggurat without branches); any other bit generator is drawn through
Numba's ``Generator``, which calls it through a pointer with its state in memory (about three times the time per
normal on the machine of ``docs/benchmarks.md``).

Serial loops (no ``prange``): a UKF step calls ``f`` on ``B (2n + 1)`` sigma points, a particle filter on ``B N``
particles, each a few microseconds to a millisecond of work here, and the callers' own compiled loops already
use the cores.  Module-level functions compiled with ``cache=True`` (Numba's on-disk cache holds across
processes).  The input may be any 2-D float64 view (a particle cloud stored component-major arrives strided).
"""

import math

import numba
import numpy as np

from .particle_numba import _weigh_tile
from .pcg_numba import PCG_MIN_DRAWS, PCG_MULTIPLIER, _pcg_normal, pcg64_stream  # noqa: F401 - this module's names too
from .pcg_numba import draw_tile as _draw_tile

__all__ = ["ct_rate_f", "ct_rate_jacobian", "ct_rate_propagate", "ct_rate_propagate_range_bearing", "pcg64_stream"]


@numba.njit(inline="always", error_model="numpy")
def _plan(coef, small):
    """``(terms, parity)`` of a series used where ``|u| < small``: the leading coefficients up to the last whose
    term can reach 1e-20 (the series' values are of order 1 there, so the rest lie far below one ulp; the twin sums
    all 25), and the parity of its powers where every non-zero one is even (0) or odd (1), else -1."""
    terms = 1
    scale = 1.0
    for i in range(coef.shape[0]):
        if abs(coef[i]) * scale >= 1e-20:
            terms = i + 1
        scale *= small
    parity = -1
    for i in range(terms):
        if coef[i] != 0.0:
            if parity == -1:
                parity = i % 2
            elif i % 2 != parity:
                return terms, -1
    return terms, parity


@numba.njit(inline="always", error_model="numpy")
def _series(coef, terms, parity, u, u2):
    """``sum_{i < terms} coef[i] u^i`` by Horner's rule, in ``u^2`` where the powers are of one parity (half the
    multiply-adds; the twin's order differs by round-off only)."""
    out = 0.0
    if parity < 0:
        for i in range(terms - 1, -1, -1):
            out = out * u + coef[i]
        return out
    top = terms - 1 if (terms - 1) % 2 == parity else terms - 2
    for i in range(top, parity - 1, -2):
        out = out * u2 + coef[i]
    return out * u if parity == 1 else out


#: ``|u|`` below which :func:`ct_rate_f` and the propagation take ``sin u / u`` and ``(1 - cos u) / u`` from
#: their series (:data:`SERIES_TERMS` terms each; the first term left out is below 1e-19 there), a polynomial
#: without branches that the propagation's tile loop vectorises; libm's ``sin`` and ``cos`` beyond (turns of more
#: than 45 degrees in one step).
SERIES_BOUND = math.pi / 4
#: Terms of each series summed below :data:`SERIES_BOUND` (the model's tables hold twelve).
SERIES_TERMS = 10


@numba.njit(inline="always", error_model="numpy")
def _coefficients(sinc, cosc):
    """The non-zero coefficients of the two series as tuples of :data:`SERIES_TERMS`: ``sinc``'s even powers
    ``u^0 .. u^18`` and ``cosc``'s odd powers ``u^1 .. u^19``."""
    return ((sinc[0], sinc[2], sinc[4], sinc[6], sinc[8], sinc[10], sinc[12], sinc[14], sinc[16], sinc[18]),
            (cosc[1], cosc[3], cosc[5], cosc[7], cosc[9], cosc[11], cosc[13], cosc[15], cosc[17], cosc[19]))


@numba.njit(inline="always", error_model="numpy")
def _series_terms(u, sp, cp):
    """``(sin u / u, (1 - cos u) / u)`` from the series ``sp``, ``cp`` (:func:`_coefficients`) by Horner's rule in
    ``u^2``, written out (straight-line code, which vectorises)."""
    u2 = u * u
    sa = ((((((((sp[9] * u2 + sp[8]) * u2 + sp[7]) * u2 + sp[6]) * u2 + sp[5]) * u2 + sp[4]) * u2 + sp[3]) * u2
           + sp[2]) * u2 + sp[1]) * u2 + sp[0]
    ca = ((((((((cp[9] * u2 + cp[8]) * u2 + cp[7]) * u2 + cp[6]) * u2 + cp[5]) * u2 + cp[4]) * u2 + cp[3]) * u2
           + cp[2]) * u2 + cp[1]) * u2 + cp[0]
    return sa, ca * u


@numba.njit(inline="always", error_model="numpy")
def _move(px, py, vx, vy, w, T, sa, ca, s, c):
    """``f`` of one state from ``sa = sin u / u``, ``ca = (1 - cos u) / u``, ``s = sin u``, ``c = cos u``."""
    a, b = T * sa, T * ca
    return px + a * vx - b * vy, py + b * vx + a * vy, c * vx - s * vy, s * vx + c * vy, w


@numba.njit(inline="always", error_model="numpy")
def _series_move(px, py, vx, vy, w, T, sp, cp):
    """``f`` of one state by the series (for ``|omega T| <`` :data:`SERIES_BOUND`)."""
    u = w * T
    sa, ca = _series_terms(u, sp, cp)
    return _move(px, py, vx, vy, w, T, sa, ca, u * sa, 1.0 - u * ca)  # sin u, cos u within an ulp or two of libm's


@numba.njit(inline="always", error_model="numpy")
def _closed_move(px, py, vx, vy, w, T):
    """``f`` of one state by libm's ``sin`` and ``cos`` (for ``|omega T| >=`` :data:`SERIES_BOUND`)."""
    u = w * T
    s, c = math.sin(u), math.cos(u)
    return _move(px, py, vx, vy, w, T, s / u, (1.0 - c) / u, s, c)


@numba.njit(inline="always", error_model="numpy")
def _turn(px, py, vx, vy, w, T, sp, cp):
    """``f`` of one state ``[px, py, vx, vy, w]`` over ``T``: the five components (the formula of
    :func:`ct_rate_f` and :func:`ct_rate_propagate`, so both give the same numbers)."""
    if abs(w * T) < SERIES_BOUND:
        return _series_move(px, py, vx, vy, w, T, sp, cp)
    return _closed_move(px, py, vx, vy, w, T)


@numba.njit(cache=True, error_model="numpy")
def ct_rate_f(x, T, sinc, cosc, out):
    """``out[i] = f(x[i])`` for states ``x (K, 5)`` over the step ``T`` (s); ``sinc``, ``cosc``: the Taylor
    coefficients of ``sin u / u`` and ``(1 - cos u) / u`` (the model's tables, at least 20 powers), used where
    ``|u| <`` :data:`SERIES_BOUND`."""
    sp, cp = _coefficients(sinc, cosc)
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4] = _turn(x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4],
                                                                      T, sp, cp)


#: Particles per tile of :func:`ct_rate_propagate` (the tile's moved states and normals stay in L1).
TILE = 512


@numba.njit(inline="always", error_model="numpy")
def _propagate_tile(out, x, rng, pcg, k, src, coef, ptr, lo, m, e, fx, T, sp, cp):
    """The particles ``lo : lo + m`` of :func:`ct_rate_propagate`: their ``k`` normals each drawn into ``e``
    (:func:`_draw_tile`), their ``f`` into ``fx`` (tile-sized work arrays), then ``out[:, lo : lo + m]`` from the
    plan, row by row.  ``f`` is :func:`_turn`'s: the series for every particle in one loop without branches (it
    vectorises), then libm's form for the particles at or beyond :data:`SERIES_BOUND`, if any."""
    _draw_tile(rng, pcg, e, m, k)
    beyond = 0
    for t in range(m):
        i = lo + t
        px, py, vx, vy, w = x[0, i], x[1, i], x[2, i], x[3, i], x[4, i]
        fx[0, t], fx[1, t], fx[2, t], fx[3, t], fx[4, t] = _series_move(px, py, vx, vy, w, T, sp, cp)
        beyond += abs(w * T) >= SERIES_BOUND
    if beyond:
        for t in range(m):
            i = lo + t
            px, py, vx, vy, w = x[0, i], x[1, i], x[2, i], x[3, i], x[4, i]
            if abs(w * T) >= SERIES_BOUND:
                fx[0, t], fx[1, t], fx[2, t], fx[3, t], fx[4, t] = _closed_move(px, py, vx, vy, w, T)
    for r in range(5):
        o = out[r, lo:lo + m]
        if ptr[r] == ptr[r + 1]:
            o[:] = 0.0
            continue
        for q in range(ptr[r], ptr[r + 1]):
            j = src[q]
            c = coef[q]
            if j < 5:
                s = fx[j, :m]
                if q == ptr[r]:
                    for t in range(m):
                        o[t] = c * s[t]
                else:
                    for t in range(m):
                        o[t] += c * s[t]
            else:
                s = e[j - 5, :m]
                if q == ptr[r]:
                    for t in range(m):
                        o[t] = c * s[t]
                else:
                    for t in range(m):
                        o[t] += c * s[t]


def ct_rate_propagate(out, x, rng, k, src, coef, ptr, T, sinc, cosc):
    """``out_i = f(x_i) + G e_i`` for the particles ``x (5, L)`` stored component-major, in one pass: the particle
    filter's propagation through the coordinated turn (:func:`workbench.particle_core.predict`), ``e`` drawn here
    from the ``numpy.random.Generator`` ``rng`` in the order of ``rng.standard_normal((L, k))`` (the same numbers,
    the generator left where NumPy leaves it; on PCG64 by :func:`_pcg_normal` through :func:`pcg64_stream`), one
    tile at a time.

    ``src, coef, ptr``: the plan of ``[I | G]`` (:func:`workbench.particle_core._plan_arrays`): row ``i`` of ``out``
    is ``sum_t coef[t] s_{src[t]}`` over its terms ``t`` in order, ``s_j`` being component ``j`` of ``f(x)`` for
    ``j < 5`` and noise column ``j - 5`` beyond.  That is the order of the NumPy twin
    (:func:`workbench.particle_core.combine_columns` of ``[I | G]`` on ``f(x)`` (:func:`ct_rate_f`) and the
    draws), products and sums rounded one by one (no fused multiply-adds), so the result is the twin's bit for
    bit.  ``out`` must not share memory with ``x``.

    Shapes: ``out, x (5, L)``; ``k`` noise columns; ``src, coef (T,)``, ``ptr (6,)``.
    """
    with pcg64_stream(rng, k * out.shape[1], PCG_MIN_DRAWS) as pcg:  # this module's setting (tests lower it)
        _ct_rate_propagate(out, x, rng, pcg, k, src, coef, ptr, T, sinc, cosc)
    return out


@numba.njit(cache=True, error_model="numpy")
def _ct_rate_propagate(out, x, rng, pcg, k, src, coef, ptr, T, sinc, cosc):
    """:func:`ct_rate_propagate` with the stream's words ``pcg`` (:func:`pcg64_stream`)."""
    sp, cp = _coefficients(sinc, cosc)
    L = out.shape[1]
    e = np.empty((max(k, 1), TILE))
    fx = np.empty((5, TILE))
    for lo in range(0, L, TILE):
        _propagate_tile(out, x, rng, pcg, k, src, coef, ptr, lo, min(lo + TILE, L) - lo, e, fx, T, sp, cp)
    return out


def ct_rate_propagate_range_bearing(out, x, rng, k, src, coef, ptr, T, sinc, cosc, present, z, sensor, linv, prev,
                                    log_w, top):
    """:func:`ct_rate_propagate` and, for the items with ``present``, the planar range-bearing log-weights and
    their rows' max in one pass, one tile of particles at a time: a tile's particles are moved through the turn
    (its normals drawn from ``rng`` in the order of ``rng.standard_normal((B, N, k))``), then weighed while they
    are in L1 by :func:`workbench.kernels.particle_numba._weigh_tile`, the code of
    :func:`~workbench.kernels.particle_numba.range_bearing_log_weights`.  So the particles are
    :func:`ct_rate_propagate`'s and the log-weights that function's on them, bit for bit: the linear models' fused
    pass (:func:`~workbench.kernels.particle_numba.propagate_range_bearing`) with the turn in place of ``F``.
    ``top[b]`` is ``np.max(log_w[b])`` (NaN where a log-weight is NaN).  Items without ``present``: moved,
    ``log_w = prev``, ``top`` not written.

    Shapes: ``out, x (5, L)`` component rows with ``L = B N`` (``out`` not sharing memory with ``x``); ``k`` noise
    columns; the plan ``src, coef, ptr`` of :func:`ct_rate_propagate`; ``present (B,)``; ``z (B, 2)``;
    ``sensor (2,)``; ``linv (2, 2)``; ``prev, log_w (B, N)``; ``top (B,)``.
    """
    with pcg64_stream(rng, k * out.shape[1], PCG_MIN_DRAWS) as pcg:  # this module's setting (tests lower it)
        _ct_rate_propagate_range_bearing(out, x, rng, pcg, k, src, coef, ptr, T, sinc, cosc, present, z, sensor,
                                         linv, prev, log_w, top)
    return out


@numba.njit(cache=True, error_model="numpy")
def _ct_rate_propagate_range_bearing(out, x, rng, pcg, k, src, coef, ptr, T, sinc, cosc, present, z, sensor, linv,
                                     prev, log_w, top):
    """:func:`ct_rate_propagate_range_bearing` with the stream's words ``pcg`` (:func:`pcg64_stream`)."""
    sp, cp = _coefficients(sinc, cosc)
    B, N = log_w.shape
    e = np.empty((max(k, 1), TILE))
    fx = np.empty((5, TILE))
    for b in range(B):
        weigh = present[b]
        zr, zb = z[b, 0], z[b, 1]
        m = -np.inf
        nan = False
        wb, ob = prev[b], log_w[b]
        for lo in range(b * N, (b + 1) * N, TILE):
            hi = min(lo + TILE, (b + 1) * N)
            _propagate_tile(out, x, rng, pcg, k, src, coef, ptr, lo, hi - lo, e, fx, T, sp, cp)
            a, c = lo - b * N, hi - b * N
            if weigh:
                v = _weigh_tile(out[0, lo:hi], out[1, lo:hi], zr, zb, sensor, linv, wb[a:c], ob[a:c])
                nan |= v != v
                m = v if v > m else m
            else:
                for t in range(c - a):
                    ob[a + t] = wb[a + t]
        if weigh:
            top[b] = np.nan if nan else m
    return out


@numba.njit(cache=True, error_model="numpy")
def ct_rate_jacobian(x, T, small, sinc, cosc, dsinc, dcosc, out):
    """``out[i] = df/dx`` at the states ``x (K, 5)`` over the step ``T`` (s): ``out (K, 5, 5)``, every entry
    written; ``dsinc``, ``dcosc``: the Taylor coefficients of ``(u cos u - sin u) / u^2`` and
    ``(u sin u - (1 - cos u)) / u^2`` used where ``|u| < small``."""
    n_s, p_s = _plan(sinc, small)
    n_c, p_c = _plan(cosc, small)
    n_ds, p_ds = _plan(dsinc, small)
    n_dc, p_dc = _plan(dcosc, small)
    for i in range(x.shape[0]):
        vx, vy, w = x[i, 2], x[i, 3], x[i, 4]
        u = w * T
        if abs(u) < small:
            u2 = u * u
            sa, ca = _series(sinc, n_s, p_s, u, u2), _series(cosc, n_c, p_c, u, u2)
            dsa, dca = _series(dsinc, n_ds, p_ds, u, u2), _series(dcosc, n_dc, p_dc, u, u2)
            s, c = u * sa, 1.0 - u * ca
        else:
            s, c = math.sin(u), math.cos(u)
            sa, ca = s / u, (1.0 - c) / u
            dsa, dca = (u * c - s) / (u * u), (u * s - (1.0 - c)) / (u * u)
        a, b = T * sa, T * ca  # sin(wT)/w, (1 - cos(wT))/w
        da, db = T * T * dsa, T * T * dca  # their derivatives in w
        J = out[i]
        for r in range(5):
            for k in range(5):
                J[r, k] = 0.0
        J[0, 0] = J[1, 1] = J[4, 4] = 1.0
        J[0, 2], J[0, 3], J[0, 4] = a, -b, da * vx - db * vy
        J[1, 2], J[1, 3], J[1, 4] = b, a, db * vx + da * vy
        J[2, 2], J[2, 3], J[2, 4] = c, -s, -T * s * vx - T * c * vy
        J[3, 2], J[3, 3], J[3, 4] = s, c, T * c * vx - T * s * vy

