"""Compiled ``f`` and Jacobian of the coordinated turn with the rate in the state (imported only when used).

The model is :class:`workbench.models.CoordinatedTurnRate`, state ``[x, y, vx, vy, omega]``; its NumPy form
(``CoordinatedTurnRate.f_numpy`` / ``jacobian_numpy``) is the twin these loops are held to
(``tests/test_motion_kernels.py``, to 1e-12 on both sides of ``omega = 0``).  The model asks the backend policy
(:func:`workbench.kernels.backend.resolve`) which to run: these loops where it resolves to Numba, the NumPy twin
elsewhere (no Numba, or a GPU arch: there is no Taichi version).

The formulas are the twin's, one state per iteration: with ``u = omega T``, ``sin u / u``, ``(1 - cos u) / u``
and their ``u``-derivatives from their closed forms, or, where ``|u| < small``, from the Taylor coefficients the
twin evaluates (passed in, so that both use one table).  The twin evaluates both forms for every state (four
series of 25 coefficients, blended by ``np.where``: about a hundred passes over the batch); these loops make one
pass and take one form per state.  In the series band they sum only the terms that can reach 1e-20 there, by
Horner's rule in ``u^2`` (each series has powers of one parity), and take ``sin u = u (sin u / u)`` and
``cos u = 1 - u ((1 - cos u) / u)`` from the same series (no libm call there).  The two differ by round-off, far
less than 1e-12.

:func:`ct_rate_propagate` is the particle filter's propagation through the model, ``f`` plus the process noise
drawn inside the loop, in one pass (the model declares it: :meth:`CoordinatedTurnRate.particle_propagator`); its
twin is the NumPy path of :func:`workbench.particle_core.predict` (the model's ``f``, NumPy's draws, the noise added
by :func:`~workbench.particle_core.combine_columns`), which it equals bit for bit where that ``f`` is
:func:`ct_rate_f` (the same formula, one inline function) and to ``f``'s round-off against ``f_numpy``.

Serial loops (no ``prange``): a UKF step calls ``f`` on ``B (2n + 1)`` sigma points, a particle filter on ``B N``
particles, each a few microseconds to a millisecond of work here, and the callers' own compiled loops already
use the cores.  Module-level functions compiled with ``cache=True`` (Numba's on-disk cache holds across
processes).  The input may be any 2-D float64 view (a particle cloud stored component-major arrives strided).
"""

import math

import numba
import numpy as np

__all__ = ["ct_rate_f", "ct_rate_jacobian", "ct_rate_propagate"]


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


@numba.njit(inline="always", error_model="numpy")
def _turn(px, py, vx, vy, w, T, small, sinc, cosc, n_s, p_s, n_c, p_c):
    """``f`` of one state ``[px, py, vx, vy, w]`` over ``T``: the five components (the one formula of
    :func:`ct_rate_f` and :func:`ct_rate_propagate`, so both give the same numbers)."""
    u = w * T
    if abs(u) < small:
        u2 = u * u
        sa, ca = _series(sinc, n_s, p_s, u, u2), _series(cosc, n_c, p_c, u, u2)
        s, c = u * sa, 1.0 - u * ca  # sin u and cos u from the same series (within an ulp or two of libm's)
    else:
        s, c = math.sin(u), math.cos(u)
        sa, ca = s / u, (1.0 - c) / u
    a, b = T * sa, T * ca
    return px + a * vx - b * vy, py + b * vx + a * vy, c * vx - s * vy, s * vx + c * vy, w


@numba.njit(cache=True, error_model="numpy")
def ct_rate_f(x, T, small, sinc, cosc, out):
    """``out[i] = f(x[i])`` for states ``x (K, 5)`` over the step ``T`` (s); ``sinc``, ``cosc``: the Taylor
    coefficients of ``sin u / u`` and ``(1 - cos u) / u`` used where ``|u| < small``."""
    n_s, p_s = _plan(sinc, small)
    n_c, p_c = _plan(cosc, small)
    for i in range(x.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4] = _turn(x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4],
                                                                      T, small, sinc, cosc, n_s, p_s, n_c, p_c)


#: Particles per tile of :func:`ct_rate_propagate` (the tile's moved states and normals stay in L1).
TILE = 512


@numba.njit(cache=True, error_model="numpy")
def ct_rate_propagate(out, x, rng, k, src, coef, ptr, T, small, sinc, cosc):
    """``out_i = f(x_i) + G e_i`` for the particles ``x (5, L)`` stored component-major, in one pass: the particle
    filter's propagation through the coordinated turn (:func:`workbench.particle_core.predict`), ``e`` drawn here
    from the ``numpy.random.Generator`` ``rng`` in the order of ``rng.standard_normal((L, k))`` (the same numbers,
    the generator left where NumPy leaves it), one tile at a time.

    ``src, coef, ptr``: the plan of ``[I | G]`` (:func:`workbench.particle_core._plan_arrays`): row ``i`` of ``out``
    is ``sum_t coef[t] s_{src[t]}`` over its terms ``t`` in order, ``s_j`` being component ``j`` of ``f(x)`` for
    ``j < 5`` and noise column ``j - 5`` beyond.  That is the order of the NumPy twin
    (:func:`workbench.particle_core.combine_columns` of ``[I | G]`` on ``f(x)`` (:func:`ct_rate_f`) and the
    draws), products and sums rounded one by one (no fused multiply-adds), so the result is the twin's bit for
    bit.  ``out`` must not share memory with ``x``.

    Shapes: ``out, x (5, L)``; ``k`` noise columns; ``src, coef (T,)``, ``ptr (6,)``.
    """
    n_s, p_s = _plan(sinc, small)
    n_c, p_c = _plan(cosc, small)
    L = out.shape[1]
    e = np.empty((TILE, max(k, 1)))
    fx = np.empty((5, TILE))
    for lo in range(0, L, TILE):
        m = min(lo + TILE, L) - lo
        for t in range(m):
            for j in range(k):
                e[t, j] = rng.standard_normal()
        for t in range(m):
            i = lo + t
            fx[0, t], fx[1, t], fx[2, t], fx[3, t], fx[4, t] = _turn(x[0, i], x[1, i], x[2, i], x[3, i], x[4, i], T,
                                                                     small, sinc, cosc, n_s, p_s, n_c, p_c)
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
                    s = e[:m, j - 5]
                    if q == ptr[r]:
                        for t in range(m):
                            o[t] = c * s[t]
                    else:
                        for t in range(m):
                            o[t] += c * s[t]
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

