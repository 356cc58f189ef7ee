"""Numba loops for the batched UKF (:mod:`workbench_filters.sigma_point`), one item per parallel iteration.

The NumPy code of the filter is the reference these loops are held to (``tests/test_sigma_numba.py``):
the same formulas, item by item, where NumPy makes about a hundred passes over ``(B, ...)`` arrays
per step.  The motion's ``f`` and the sensor's ``h`` stay NumPy calls of the model (any model works).

- :func:`chol_sigma`: ``S = chol(P)`` and the points ``[x, x + c S_j, x - c S_j]``;
- :func:`predicted_moments`: ``x- = sum Wm X*``, ``P- = sum Wc (X* - x-)(.)^T + Q``;
- :func:`linear_predict`: the three steps of a predict in one call for a :attr:`~workbench.models.MotionModel.linear`
  motion (``X* = X F^T``, the model's declared ``f``), which needs no Python call between them;
- :func:`unscented_update`: the angle-aware ``y^``, ``Pxy``, ``Pyy = sum Wc dY dY^T + R``,
  ``K = Pxy Pyy^-1`` (Cholesky solves), ``x = x- + K wrap(z - y^)``, ``P = P- - (K L)(K L)^T``;
- :func:`central_linear_predict` and :func:`central_update`: the CDKF's full-covariance predict (linear motion)
  and update, the central differences ``a_i``, ``b_i`` of the points (wrapped for angles) in place of the
  unscented sums;
- :func:`sqrt_linear_predict` and :func:`sqrt_update`: the square-root forms (SR-UKF and SR-CDKF, van der Merwe
  2004) item by item: the QR of the weighted deviations (:func:`tria_into`, Householder, the factor's diagonal
  made non-negative as :func:`workbench.linalg.tria` does), the rank-1 :func:`cholupdate_into` sweep of
  :func:`workbench.linalg.cholupdate` (the same formulas in the same order), ``K`` by two triangular solves and the
  downdates ``S = cholupdate(S-, K S_y, -1)`` column by column.  A downdate or update that would lose positive
  definiteness makes the call return ``False``: the caller then takes the NumPy path, whose ``cholupdate`` falls
  back to a jittered refactorisation and counts it.

A matrix that is not numerically positive definite makes the call return ``False``; the caller then
takes the NumPy path, which adds and counts jitter.  So does a present measurement that is not finite: the NumPy
path refuses it by name (:func:`workbench.filtering.require_finite`).

Each loop is compiled twice, threaded and serial (``prange`` is ``range`` there), and called serial below
:data:`PARALLEL_MIN` items (for one track, waking the thread pool costs more than the work: milliseconds on a
loaded machine) and wherever Numba has one thread (:func:`workbench.kernels.backend.threaded`: a report worker never
compiles the threaded one).  Both give the same numbers (each item is computed alone).

Compile time (a fresh process compiles what it runs; Numba's on-disk cache serves later ones): the pieces the three
updates share (:func:`_measurement_mean`, :func:`_gain`, :func:`_updated_mean_into`, :func:`_downdated_cov_into`)
and the Cholesky are compiled once per process and called, not inlined into each loop; a failed item adds one to a count (a reduction the threaded loop supports) instead
of a flag array (``np.ones`` and ``.all()`` each compiled a generic implementation).  The predicts keep their short
loops inline: called helpers there cost run time at large batches (per-item call overhead).  The same formulas in
the same order, so the same bits.
"""

import math
import types as pytypes

import numba
import numpy as np

from workbench.kernels.backend import threaded as threaded_policy
from workbench.kernels.kalman_numba import gain_into

TWO_PI = 2.0 * math.pi
#: A helper the kernels call (compiled once per process, not inlined into each kernel).  With its Python wrapper:
#: without one it compiled about 1 s faster per process, but a call from Python crashed the interpreter.
inner = numba.njit(error_model="numpy", cache=True)
#: Batches of at least this many items run threaded.
PARALLEL_MIN = 64


def _compiled(fn, name: str, parallel: bool):
    """``fn`` compiled under its own name (Numba's cache tells functions apart by name, not by compile flags)."""
    renamed = pytypes.FunctionType(fn.__code__.replace(co_name=name, co_qualname=name), fn.__globals__, name)
    return numba.njit(parallel=parallel, error_model="numpy", cache=True)(renamed)


def _dispatch(fn, name: str):
    threaded, serial = _compiled(fn, name, True), _compiled(fn, f"{name}_serial", False)

    def call(*args):
        # threaded from PARALLEL_MIN items where Numba has more than one thread (a report worker has one: its
        # threaded compilation would never be called, nor compiled)
        return (threaded if threaded_policy(args[0].shape[0], PARALLEL_MIN) else serial)(*args)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = fn.__doc__
    call.threaded, call.serial = threaded, serial
    return call


@numba.njit(inline="always", error_model="numpy")
def wrap(a):
    # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
    return a - TWO_PI * math.ceil((a - math.pi) * (1.0 / TWO_PI))


@inner
def _measurement_mean(Y, b, wm, angular, count):
    """``y^ = sum Wm Y`` over item ``b``'s first ``count`` sigma points; an angular component as
    ``y_0 + sum Wm wrap(y_s - y_0)``, wrapped."""
    m = Y.shape[2]
    y_hat = np.empty(m)
    for k in range(m):
        acc = 0.0
        if angular[k]:
            ref = Y[b, 0, k]
            for s in range(count):
                acc += wm[s] * wrap(Y[b, s, k] - ref)
            y_hat[k] = wrap(ref + acc)
        else:
            for s in range(count):
                acc += wm[s] * Y[b, s, k]
            y_hat[k] = acc
    return y_hat


@inner
def _gain(Pxy, L):
    """``K = Pxy Pyy^-1`` with ``Pyy = L L^T`` (:func:`workbench.kernels.kalman_numba.gain_into`)."""
    K = np.empty(Pxy.shape)
    gain_into(Pxy, L, K)
    return K


@inner
def _updated_mean_into(x, b, K, z, y_hat, angular, mean):
    """``mean[b] = x[b] + K wrap(z[b] - y^)`` (angular components wrapped)."""
    n, m = K.shape
    for r in range(n):
        v = x[b, r]
        for k in range(m):
            d = z[b, k] - y_hat[k]
            v += K[r, k] * (wrap(d) if angular[k] else d)
        mean[b, r] = v


@inner
def _downdated_cov_into(P, b, K, L, cov):
    """``cov[b] = sym(P[b]) - (K L)(K L)^T``, written symmetric."""
    n, m = K.shape
    KL = np.zeros((n, m))
    for r in range(n):
        for k in range(m):
            v = 0.0
            for l in range(k, m):
                v += K[r, l] * L[l, k]
            KL[r, k] = v
    for r in range(n):
        for c in range(r + 1):
            v = 0.0
            for k in range(m):
                v += KL[r, k] * KL[c, k]
            w = 0.5 * (P[b, r, c] + P[b, c, r]) - v
            cov[b, r, c] = w
            cov[b, c, r] = w


@inner
def _cholesky_into(A, L):
    """Lower factor of the symmetric ``A (n, n)`` into ``L``; ``False`` if a pivot is not positive."""
    n = A.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


def _chol_sigma(mean, P, spread, X, S):
    """``S[b] = chol(P[b])``; ``X[b] = [x, x + c S_j, x - c S_j]``.  Returns whether every ``P[b]`` was PD."""
    B, n = mean.shape
    failed = 0
    for b in numba.prange(B):
        if not _cholesky_into(P[b], S[b]):
            failed += 1
            continue
        for r in range(n):
            X[b, 0, r] = mean[b, r]
        for j in range(n):
            for r in range(n):
                step = spread * S[b, r, j]  # column j of S
                X[b, 1 + j, r] = mean[b, r] + step
                X[b, 1 + n + j, r] = mean[b, r] - step
    return failed == 0


def _predicted_moments(Xf, wm, wc, Q, mean, cov):
    """``mean[b] = sum_s wm_s Xf[b, s]``, ``cov[b] = sym(sum_s wc_s d d^T + Q)``, ``d = Xf[b, s] - mean[b]``."""
    B, S, n = Xf.shape
    for b in numba.prange(B):
        for r in range(n):
            acc = 0.0
            for s in range(S):
                acc += wm[s] * Xf[b, s, r]
            mean[b, r] = acc
        for r in range(n):
            for c in range(r + 1):
                acc = 0.0
                for s in range(S):
                    acc += wc[s] * (Xf[b, s, r] - mean[b, r]) * (Xf[b, s, c] - mean[b, c])
                # symmetrise((P + Q)): both triangles from the mean of the two entries
                v = acc + 0.5 * (Q[r, c] + Q[c, r])
                cov[b, r, c] = v
                cov[b, c, r] = v


def _linear_predict(x, P, F, spread, wm, wc, Q, mean, cov):
    """:func:`_chol_sigma`, ``X* = X F^T`` and :func:`_predicted_moments` per item, without the ``(B, 2n + 1, n)``
    points between them.  Returns whether every ``P[b]`` was positive definite."""
    B, n = x.shape
    S = 2 * n + 1
    failed = 0
    for b in numba.prange(B):
        L = np.zeros((n, n))
        if not _cholesky_into(P[b], L):
            failed += 1
            continue
        X = np.empty((S, n))
        for r in range(n):
            X[0, r] = x[b, r]
        for j in range(n):
            for r in range(n):
                step = spread * L[r, j]  # column j of the factor
                X[1 + j, r] = x[b, r] + step
                X[1 + n + j, r] = x[b, r] - step
        Xf = np.empty((S, n))
        for s in range(S):  # X* = f(X) = X F^T
            for r in range(n):
                acc = 0.0
                for k in range(n):
                    acc += X[s, k] * F[r, k]
                Xf[s, r] = acc
        for r in range(n):
            acc = 0.0
            for s in range(S):
                acc += wm[s] * Xf[s, r]
            mean[b, r] = acc
        for r in range(n):
            for c in range(r + 1):
                acc = 0.0
                for s in range(S):
                    acc += wc[s] * (Xf[s, r] - mean[b, r]) * (Xf[s, c] - mean[b, c])
                v = acc + 0.5 * (Q[r, c] + Q[c, r])
                cov[b, r, c] = v
                cov[b, c, r] = v
    return failed == 0


def _unscented_update(x, P, X, Y, wm, wc, angular, R, z, present, mean, cov):
    """The UKF update of every present item (an absent one keeps ``x``, ``P``); ``False`` if some ``Pyy``
    was not positive definite (then nothing is to be used)."""
    B, S, n = X.shape
    m = Y.shape[2]
    failed = 0
    for b in numba.prange(B):
        if not present[b]:
            for r in range(n):
                mean[b, r] = x[b, r]
                for c in range(n):
                    cov[b, r, c] = P[b, r, c]
            continue
        finite = True
        for k in range(m):
            finite = finite and math.isfinite(z[b, k])
        if not finite:  # the NumPy path names it
            failed += 1
            continue
        y_hat = _measurement_mean(Y, b, wm, angular, S)
        dY = np.empty((S, m))
        for s in range(S):
            for k in range(m):
                d = Y[b, s, k] - y_hat[k]
                dY[s, k] = wrap(d) if angular[k] else d
        # Pxy = sum Wc (X - x-)(Y - y^)^T,  Pyy = sym(sum Wc dY dY^T + R)
        Pxy = np.zeros((n, m))
        Pyy = np.zeros((m, m))
        for s in range(S):
            for r in range(n):
                dx = wc[s] * (X[b, s, r] - x[b, r])
                for k in range(m):
                    Pxy[r, k] += dx * dY[s, k]
            for k in range(m):
                for l in range(m):
                    Pyy[k, l] += wc[s] * dY[s, k] * dY[s, l]
        for k in range(m):
            for l in range(k + 1):
                v = 0.5 * (Pyy[k, l] + Pyy[l, k] + R[k, l] + R[l, k])
                Pyy[k, l] = v
                Pyy[l, k] = v
        L = np.zeros((m, m))
        if not _cholesky_into(Pyy, L):
            failed += 1
            continue
        # K = Pxy Pyy^-1: L M = Pxy^T (forward), L^T K^T = M (back)
        K = _gain(Pxy, L)
        # x = x- + K wrap(z - y^)
        _updated_mean_into(x, b, K, z, y_hat, angular, mean)
        # P = sym(P- - (K L)(K L)^T)
        _downdated_cov_into(P, b, K, L, cov)
    return failed == 0


def _central_linear_predict(x, P, F, spread, wm, c1, c2, Q, mean, cov):
    """The CDKF predict of every item for a linear motion ``f(X) = X F^T``: ``S = chol(P)``, the points
    ``[x, x + h S_j, x - h S_j]``, ``x- = sum Wm X*`` and ``P- = sym(sum_i Wc1 a_i a_i^T + Wc2 b_i b_i^T + Q)`` with
    ``a_i = X*_i - X*_{L+i}``, ``b_i = X*_i + X*_{L+i} - 2 X*_0``.  Returns whether every ``P[b]`` was positive
    definite."""
    B, n = x.shape
    S = 2 * n + 1
    failed = 0
    for b in numba.prange(B):
        L = np.zeros((n, n))
        if not _cholesky_into(P[b], L):
            failed += 1
            continue
        X = np.empty((S, n))
        for r in range(n):
            X[0, r] = x[b, r]
        for j in range(n):
            for r in range(n):
                step = spread * L[r, j]
                X[1 + j, r] = x[b, r] + step
                X[1 + n + j, r] = x[b, r] - step
        Xf = np.empty((S, n))
        for s in range(S):  # X* = X F^T
            for r in range(n):
                acc = 0.0
                for k in range(n):
                    acc += X[s, k] * F[r, k]
                Xf[s, r] = acc
        for r in range(n):
            acc = 0.0
            for s in range(S):
                acc += wm[s] * Xf[s, r]
            mean[b, r] = acc
        A = np.empty((n, n))
        D = np.empty((n, n))
        for i in range(n):
            for r in range(n):
                A[i, r] = Xf[1 + i, r] - Xf[1 + n + i, r]
                D[i, r] = Xf[1 + i, r] + Xf[1 + n + i, r] - 2.0 * Xf[0, r]
        C = np.empty((n, n))
        for r in range(n):
            for c in range(n):
                aa = 0.0
                dd = 0.0
                for i in range(n):
                    aa += A[i, r] * A[i, c]
                    dd += D[i, r] * D[i, c]
                C[r, c] = c1 * aa + c2 * dd + Q[r, c]
        for r in range(n):  # sym(P + Q)
            for c in range(r + 1):
                v = 0.5 * (C[r, c] + C[c, r])
                cov[b, r, c] = v
                cov[b, c, r] = v
    return failed == 0


def _central_update(x, P, Y, spread, wm, c1, c2, angular, R, z, present, mean, cov):
    """The CDKF update of every present item (an absent one keeps ``x``, ``P``) from the measured points ``Y`` of
    the points ``[x, x + h S_j, x - h S_j]``, ``S = chol(P)``: the angle-aware ``y^``,
    ``Pyy = sym(sum_i Wc1 a_i a_i^T + Wc2 b_i b_i^T + R)`` with ``a_i = wrap(Y_i - Y_{L+i})``,
    ``b_i = wrap(Y_i - Y_0) + wrap(Y_{L+i} - Y_0)``, ``Pxy = sqrt(Wc1) S [a_1 .. a_L]``, ``K = Pxy Pyy^-1``
    (Cholesky solves), ``x = x- + K wrap(z - y^)``, ``P = sym(P- - (K L)(K L)^T)``.  ``False`` where some ``P`` or
    ``Pyy`` is not positive definite or a present ``z`` is not finite (nothing is then to be used)."""
    B, n = x.shape
    Sp = Y.shape[1]
    m = Y.shape[2]
    failed = 0
    for b in numba.prange(B):
        if not present[b]:
            for r in range(n):
                mean[b, r] = x[b, r]
                for c in range(n):
                    cov[b, r, c] = P[b, r, c]
            continue
        finite = True
        for k in range(m):
            finite = finite and math.isfinite(z[b, k])
        if not finite:
            failed += 1
            continue
        Sx = np.zeros((n, n))
        if not _cholesky_into(P[b], Sx):
            failed += 1
            continue
        y_hat = _measurement_mean(Y, b, wm, angular, Sp)
        A = np.empty((n, m))
        D = np.empty((n, m))
        for i in range(n):
            for k in range(m):
                d = Y[b, 1 + i, k] - Y[b, 1 + n + i, k]
                dp = Y[b, 1 + i, k] - Y[b, 0, k]
                dm = Y[b, 1 + n + i, k] - Y[b, 0, k]
                if angular[k]:
                    d, dp, dm = wrap(d), wrap(dp), wrap(dm)
                A[i, k] = d
                D[i, k] = dp + dm
        Pyy = np.empty((m, m))
        for k in range(m):
            for l in range(m):
                aa = 0.0
                dd = 0.0
                for i in range(n):
                    aa += A[i, k] * A[i, l]
                    dd += D[i, k] * D[i, l]
                Pyy[k, l] = c1 * aa + c2 * dd + R[k, l]
        for k in range(m):
            for l in range(k + 1):
                v = 0.5 * (Pyy[k, l] + Pyy[l, k])
                Pyy[k, l] = v
                Pyy[l, k] = v
        w1 = math.sqrt(c1)
        Pxy = np.empty((n, m))
        for r in range(n):
            for k in range(m):
                acc = 0.0
                for i in range(n):
                    acc += Sx[r, i] * A[i, k]
                Pxy[r, k] = w1 * acc
        L = np.zeros((m, m))
        if not _cholesky_into(Pyy, L):
            failed += 1
            continue
        K = _gain(Pxy, L)
        _updated_mean_into(x, b, K, z, y_hat, angular, mean)
        _downdated_cov_into(P, b, K, L, cov)
    return failed == 0


@numba.njit(error_model="numpy", cache=True)
def tria_into(M, S):
    """``S (n, n)`` = the lower factor of ``A A^T`` for ``M = A^T (k, n)``, ``k >= n``, by Householder QR of ``M``
    (overwritten): ``S = R^T`` with each column's sign made that of a non-negative diagonal
    (:func:`workbench.linalg.tria`)."""
    k, n = M.shape
    for j in range(n):
        tail = 0.0
        for i in range(j + 1, k):
            tail += M[i, j] * M[i, j]
        norm2 = M[j, j] * M[j, j] + tail
        if norm2 == 0.0:
            continue
        alpha = -math.copysign(math.sqrt(norm2), M[j, j])
        # v = M[j:, j] - alpha e_1, kept in column j below the diagonal and in v0
        v0 = M[j, j] - alpha
        vv = v0 * v0 + tail
        if vv > 0.0:
            for c in range(j + 1, n):
                dot = v0 * M[j, c]
                for i in range(j + 1, k):
                    dot += M[i, j] * M[i, c]
                f = 2.0 * dot / vv
                M[j, c] -= f * v0
                for i in range(j + 1, k):
                    M[i, c] -= f * M[i, j]
        M[j, j] = alpha
    for r in range(n):
        sign = -1.0 if M[r, r] < 0.0 else 1.0  # sign(0) = 1, as tria
        for c in range(n):
            S[c, r] = sign * M[r, c] if c >= r else 0.0


@numba.njit(error_model="numpy", cache=True)
def cholupdate_into(S, u, sign):
    """``S S^T + sign u u^T`` as a lower factor, in place: :func:`workbench.linalg.cholupdate`'s sweep, the same
    formulas in the same order; ``False`` (``S`` then garbage) where a pivot would not be positive."""
    n = S.shape[0]
    x = np.empty(n)
    scale = math.sqrt(abs(sign))
    for i in range(n):
        x[i] = u[i] * scale
    sgn = -1.0 if sign < 0.0 else 1.0
    for k in range(n):
        skk = S[k, k]
        r2 = skk * skk + sgn * x[k] * x[k]
        if r2 <= 0.0:
            return False
        r = math.sqrt(r2)
        safe = 1.0 if skk == 0.0 else skk
        c = r / safe
        sn = x[k] / safe
        S[k, k] = r
        for i in range(k + 1, n):
            col = (S[i, k] + sgn * sn * x[i]) / c
            x[i] = c * x[i] - sn * col
            S[i, k] = col
    return True


def _sqrt_linear_predict(x, S, F, spread, wm, wc, central, c1, c2, Qs, mean, S_new):
    """The square-root predict of every item for a linear motion ``f(X) = X F^T``: the points
    ``[x, x + c S_j, x - c S_j]``, ``x- = sum Wm X*`` and ``S- = tria([sqrt(Wc1) (X*_{1:2L} - x-), sqrt(Q)])``
    updated with ``X*_0 - x-`` (sign ``Wc0``; unscented), or ``S- = tria([sqrt(Wc1) (X*_i - X*_{L+i}),
    sqrt(Wc2) (X*_i + X*_{L+i} - 2 X*_0), sqrt(Q)])`` (central).  ``False`` where an update would fail."""
    B, n = x.shape
    P = 2 * n + 1
    q = Qs.shape[1]
    failed = 0
    for b in numba.prange(B):
        X = np.empty((P, n))
        for r in range(n):
            X[0, r] = x[b, r]
        for j in range(n):
            for r in range(n):
                step = spread * S[b, r, j]  # column j of the factor
                X[1 + j, r] = x[b, r] + step
                X[1 + n + j, r] = x[b, r] - step
        Xf = np.empty((P, n))
        for s in range(P):  # X* = X F^T
            for r in range(n):
                acc = 0.0
                for k in range(n):
                    acc += X[s, k] * F[r, k]
                Xf[s, r] = acc
        for r in range(n):
            acc = 0.0
            for s in range(P):
                acc += wm[s] * Xf[s, r]
            mean[b, r] = acc
        M = np.empty((2 * n + q, n))
        if central:
            w1, w2 = math.sqrt(c1), math.sqrt(c2)
            for i in range(n):
                for r in range(n):
                    M[i, r] = w1 * (Xf[1 + i, r] - Xf[1 + n + i, r])
                    M[n + i, r] = w2 * (Xf[1 + i, r] + Xf[1 + n + i, r] - 2.0 * Xf[0, r])
        else:
            w1 = math.sqrt(wc[1])
            for s in range(1, P):
                for r in range(n):
                    M[s - 1, r] = w1 * (Xf[s, r] - mean[b, r])
        for j in range(q):  # the columns of sqrt(Q) as rows of A^T
            for r in range(n):
                M[2 * n + j, r] = Qs[r, j]
        tria_into(M, S_new[b])
        if not central and wc[0] != 0.0:
            d0 = np.empty(n)
            for r in range(n):
                d0[r] = Xf[0, r] - mean[b, r]
            if not cholupdate_into(S_new[b], d0, wc[0]):
                failed += 1
    return failed == 0


def _sqrt_update(x, S, X, Y, wm, wc, central, c1, c2, angular, Rs, z, present, mean, S_new):
    """The square-root update of every present item (an absent one keeps ``x``, ``S``): the angle-aware ``y^``,
    ``S_y`` by :func:`tria_into` (and, unscented, the centre point's :func:`cholupdate_into`), ``Pxy``,
    ``K = Pxy S_y^-T S_y^-1``, ``x = x- + K wrap(z - y^)`` and ``S = cholupdate(S-, K S_y, -1)`` column by
    column.  ``False`` where a present ``z`` is not finite or an update or downdate would fail."""
    B, P, n = X.shape
    m = Y.shape[2]
    failed = 0
    for b in numba.prange(B):
        for r in range(n):
            mean[b, r] = x[b, r]
            for c in range(n):
                S_new[b, r, c] = S[b, r, c]
        if not present[b]:
            continue
        finite = True
        for k in range(m):
            finite = finite and math.isfinite(z[b, k])
        if not finite:  # the NumPy path names it
            failed += 1
            continue
        y_hat = _measurement_mean(Y, b, wm, angular, P)
        q = Rs.shape[1]
        M = np.empty((2 * n + q, m))
        Pxy = np.zeros((n, m))
        dY = np.empty((P, m))
        if central:
            w1, w2 = math.sqrt(c1), math.sqrt(c2)
            A = np.empty((n, m))
            for i in range(n):
                for k in range(m):
                    d = Y[b, 1 + i, k] - Y[b, 1 + n + i, k]
                    dp = Y[b, 1 + i, k] - Y[b, 0, k]
                    dm = Y[b, 1 + n + i, k] - Y[b, 0, k]
                    if angular[k]:
                        d, dp, dm = wrap(d), wrap(dp), wrap(dm)
                    A[i, k] = w1 * d
                    M[i, k] = A[i, k]
                    M[n + i, k] = w2 * (dp + dm)
            for r in range(n):  # Pxy = S- A
                for k in range(m):
                    acc = 0.0
                    for i in range(n):
                        acc += S[b, r, i] * A[i, k]
                    Pxy[r, k] = acc
        else:
            for s in range(P):
                for k in range(m):
                    d = Y[b, s, k] - y_hat[k]
                    dY[s, k] = wrap(d) if angular[k] else d
            w1 = math.sqrt(wc[1])
            for s in range(1, P):
                for k in range(m):
                    M[s - 1, k] = w1 * dY[s, k]
            for s in range(P):  # Pxy = sum Wc (X - x-)(Y - y^)^T
                for r in range(n):
                    dx = wc[s] * (X[b, s, r] - x[b, r])
                    for k in range(m):
                        Pxy[r, k] += dx * dY[s, k]
        for j in range(q):  # the columns of sqrt(R) as rows of A^T
            for k in range(m):
                M[2 * n + j, k] = Rs[k, j]
        Sy = np.empty((m, m))
        tria_into(M, Sy)
        if not central and wc[0] != 0.0:
            if not cholupdate_into(Sy, dY[0], wc[0]):
                failed += 1
                continue
        bad = False
        for k in range(m):
            bad = bad or not Sy[k, k] > 0.0
        if bad:
            failed += 1
            continue
        # K = Pxy (S_y S_y^T)^-1: S_y M = Pxy^T (forward), S_y^T K^T = M (back)
        K = _gain(Pxy, Sy)
        _updated_mean_into(x, b, K, z, y_hat, angular, mean)  # x = x- + K wrap(z - y^)
        u = np.empty(n)
        for j in range(m):  # S = cholupdate(S-, (K S_y)_j, -1), one column at a time
            for r in range(n):
                acc = 0.0
                for k in range(j, m):
                    acc += K[r, k] * Sy[k, j]
                u[r] = acc
            if not cholupdate_into(S_new[b], u, -1.0):
                failed += 1
                break
    return failed == 0


chol_sigma = _dispatch(_chol_sigma, "chol_sigma")
predicted_moments = _dispatch(_predicted_moments, "predicted_moments")
linear_predict = _dispatch(_linear_predict, "linear_predict")
unscented_update = _dispatch(_unscented_update, "unscented_update")
sqrt_linear_predict = _dispatch(_sqrt_linear_predict, "sqrt_linear_predict")
sqrt_update = _dispatch(_sqrt_update, "sqrt_update")
central_linear_predict = _dispatch(_central_linear_predict, "central_linear_predict")
central_update = _dispatch(_central_update, "central_update")
