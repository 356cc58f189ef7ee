"""Numba loops for the batched UKF (:mod:`workbench_filters.sigma_point`), one item per parallel iteration.

The NumPy code of the filter is the reference these loops are held to (``tests/test_sigma_numba.py``):
the same formulas, item by item, where NumPy makes about a hundred passes over ``(B, ...)`` arrays
per step.  The motion's ``f`` and the sensor's ``h`` stay NumPy calls of the model (any model works).

- :func:`chol_sigma`: ``S = chol(P)`` and the points ``[x, x + c S_j, x - c S_j]``;
- :func:`predicted_moments`: ``x- = sum Wm X*``, ``P- = sum Wc (X* - x-)(.)^T + Q``;
- :func:`linear_predict`: the three steps of a predict in one call for a :attr:`~workbench.models.MotionModel.linear`
  motion (``X* = X F^T``, the model's declared ``f``), which needs no Python call between them;
- :func:`unscented_update`: the angle-aware ``y^``, ``Pxy``, ``Pyy = sum Wc dY dY^T + R``,
  ``K = Pxy Pyy^-1`` (Cholesky solves), ``x = x- + K wrap(z - y^)``, ``P = P- - (K L)(K L)^T``.

A matrix that is not numerically positive definite makes the call return ``False``; the caller then
takes the NumPy path, which adds and counts jitter.  So does a present measurement that is not finite: the NumPy
path refuses it by name (:func:`workbench.filtering.require_finite`).

Each loop is compiled twice, threaded and serial (``prange`` is ``range`` there), and called serial below
:data:`PARALLEL_MIN` items: for one track, waking the thread pool costs more than the work (milliseconds on a
loaded machine).  Both give the same numbers (each item is computed alone).
"""

import math
import types as pytypes

import numba
import numpy as np

TWO_PI = 2.0 * math.pi
#: Batches of at least this many items run threaded.
PARALLEL_MIN = 64


def _compiled(fn, name: str, parallel: bool):
    """``fn`` compiled under its own name (Numba's cache tells functions apart by name, not by compile flags)."""
    renamed = pytypes.FunctionType(fn.__code__.replace(co_name=name, co_qualname=name), fn.__globals__, name)
    return numba.njit(parallel=parallel, error_model="numpy", cache=True)(renamed)


def _dispatch(fn, name: str):
    threaded, serial = _compiled(fn, name, True), _compiled(fn, f"{name}_serial", False)

    def call(*args):
        return (threaded if args[0].shape[0] >= PARALLEL_MIN else serial)(*args)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = fn.__doc__
    call.threaded, call.serial = threaded, serial
    return call


@numba.njit(inline="always", error_model="numpy")
def wrap(a):
    # wrap to (-pi, pi]: a - 2 pi ceil((a - pi) / 2 pi)
    return a - TWO_PI * math.ceil((a - math.pi) * (1.0 / TWO_PI))


@numba.njit(error_model="numpy")
def cholesky_into(A, L):
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
    ok = np.ones(B, dtype=np.bool_)
    for b in numba.prange(B):
        if not cholesky_into(P[b], S[b]):
            ok[b] = False
            continue
        for r in range(n):
            X[b, 0, r] = mean[b, r]
        for j in range(n):
            for r in range(n):
                step = spread * S[b, r, j]  # column j of S
                X[b, 1 + j, r] = mean[b, r] + step
                X[b, 1 + n + j, r] = mean[b, r] - step
    return ok.all()


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
    ok = np.ones(B, dtype=np.bool_)
    for b in numba.prange(B):
        L = np.zeros((n, n))
        if not cholesky_into(P[b], L):
            ok[b] = False
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
    return ok.all()


def _unscented_update(x, P, X, Y, wm, wc, angular, R, z, present, mean, cov):
    """The UKF update of every present item (an absent one keeps ``x``, ``P``); ``False`` if some ``Pyy``
    was not positive definite (then nothing is to be used)."""
    B, S, n = X.shape
    m = Y.shape[2]
    ok = np.ones(B, dtype=np.bool_)
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
            ok[b] = False
            continue
        # y^ = sum Wm Y; angular components as y_0 + sum Wm wrap(y_s - y_0), wrapped
        y_hat = np.empty(m)
        for k in range(m):
            acc = 0.0
            if angular[k]:
                ref = Y[b, 0, k]
                for s in range(S):
                    acc += wm[s] * wrap(Y[b, s, k] - ref)
                y_hat[k] = wrap(ref + acc)
            else:
                for s in range(S):
                    acc += wm[s] * Y[b, s, k]
                y_hat[k] = acc
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
        if not cholesky_into(Pyy, L):
            ok[b] = False
            continue
        # K = Pxy Pyy^-1: L M = Pxy^T (forward), L^T K^T = M (back)
        K = np.empty((n, m))
        for r in range(n):
            for k in range(m):
                v = Pxy[r, k]
                for l in range(k):
                    v -= L[k, l] * K[r, l]
                K[r, k] = v / L[k, k]
            for k in range(m - 1, -1, -1):
                v = K[r, k]
                for l in range(k + 1, m):
                    v -= L[l, k] * K[r, l]
                K[r, k] = v / L[k, k]
        # x = x- + K wrap(z - y^)
        nu = np.empty(m)
        for k in range(m):
            d = z[b, k] - y_hat[k]
            nu[k] = wrap(d) if angular[k] else d
        for r in range(n):
            v = x[b, r]
            for k in range(m):
                v += K[r, k] * nu[k]
            mean[b, r] = v
        # P = sym(P- - (K L)(K L)^T)
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
    return ok.all()


chol_sigma = _dispatch(_chol_sigma, "chol_sigma")
predicted_moments = _dispatch(_predicted_moments, "predicted_moments")
linear_predict = _dispatch(_linear_predict, "linear_predict")
unscented_update = _dispatch(_unscented_update, "unscented_update")
