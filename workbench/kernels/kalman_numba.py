"""Numba loops of the Kalman predict and update for small batches (one track: ``B = 1``).

At one item, the batched NumPy code of :mod:`workbench.kalman_core` spends its time in about forty tiny NumPy
calls; these loops do the same algebra item by item in one compiled call.  The NumPy code is the reference they
are held to (``tests/test_kalman_numba.py``, ``tests/test_one_track.py``)::

    predict   x- = F x,  P- = F P F^T + Q                       (symmetrised)
    update    nu = z - h(x-), angular components wrapped to (-pi, pi]   (the model's residual)
              S = H P- H^T + R,  S = L L^T
              K = P- H^T S^-1          (two triangular solves with L)
              x = x- + K nu
              P = (I - K H) P- (I - K H)^T + K R K^T   (Joseph form, symmetrised)

``R`` is ``(B, m, m)`` (the model's broadcast, or each item's own).  Both loops check every number they write
finite and return ``False`` where one is not (an overflow, a NaN from the model's ``h`` or Jacobian), as the
update does for an item whose ``S`` is not numerically positive definite: the caller then takes the NumPy path,
which names the problem or (for ``S``) falls back to a general solve.  So the caller may wrap what they return
without reading it again (:meth:`workbench.types.Gaussian.kernel_output`).  Serial on purpose: these are for
small batches, where a thread pool costs more than the work.
"""

import math

import numba
import numpy as np

jit = numba.njit(error_model="numpy", cache=True)
TWO_PI = 2.0 * math.pi


@numba.njit(inline="always", error_model="numpy")
def _wrap(a):
    # wrap to (-pi, pi], the formula of workbench.linalg.wrap_angle: a - 2 pi ceil((a - pi) / 2 pi)
    return a - TWO_PI * math.ceil((a - math.pi) * (1.0 / TWO_PI))


@numba.njit(inline="always", error_model="numpy")
def _finite(x_out, P_out, b):
    """Whether item ``b`` of the outputs is finite (NaN and inf make the sum NaN or inf)."""
    s = 0.0
    for i in range(x_out.shape[1]):
        s += x_out[b, i] * 0.0
        for j in range(x_out.shape[1]):
            s += P_out[b, i, j] * 0.0
    return s == 0.0


@numba.njit(inline="always", error_model="numpy")
def gain_into(Pxy, L, K):
    """``K = Pxy S^-1`` with ``S = L L^T`` (``L`` lower triangular), row by row: ``L y = Pxy[r]`` (forward), then
    ``L^T k = y`` (back); ``K (n, m)`` written in place.  The Kalman update's gain and the sigma-point filters'."""
    n, m = Pxy.shape
    for r in range(n):
        for i in range(m):
            s = Pxy[r, i]
            for k in range(i):
                s -= L[i, k] * K[r, k]
            K[r, i] = s / L[i, i]
        for i in range(m - 1, -1, -1):
            s = K[r, i]
            for k in range(i + 1, m):
                s -= L[k, i] * K[r, k]
            K[r, i] = s / L[i, i]


@jit
def predict_items(x, P, F, Q, x_out, P_out):
    """``x_out, P_out`` = the prediction of every item; ``False`` if some number written is not finite."""
    B, n = x.shape
    ok = True
    FP = np.empty((n, n))
    for b in range(B):
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += F[i, j] * x[b, j]
            x_out[b, i] = s
        for i in range(n):  # FP = F P
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += F[i, k] * P[b, k, j]
                FP[i, j] = s
        for i in range(n):  # P- = FP F^T + Q
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += FP[i, k] * F[j, k]
                P_out[b, i, j] = s + Q[i, j]
        for i in range(n):
            for j in range(i + 1, n):
                m = 0.5 * (P_out[b, i, j] + P_out[b, j, i])
                P_out[b, i, j] = m
                P_out[b, j, i] = m
        ok = ok and _finite(x_out, P_out, b)
    return ok


@jit
def update_items(x, P, z, hx, angular, H, R, present, x_out, P_out):
    """``x_out, P_out`` = the update of every present item with ``nu = z - hx`` (wrapped where ``angular``);
    absent items are copied.  ``False`` if some ``S`` is not positive definite or some number written is not
    finite (then nothing is to be used)."""
    B, n = x.shape
    m = z.shape[1]
    nu = np.empty(m)
    PHt = np.empty((n, m))
    S = np.empty((m, m))
    L = np.empty((m, m))
    K = np.empty((n, m))
    A = np.empty((n, n))
    AP = np.empty((n, n))
    KR = np.empty((n, m))
    for b in range(B):
        if not present[b]:
            for i in range(n):  # copied element by element: an array assignment compiles Numba's shape-mismatch
                x_out[b, i] = x[b, i]  # message (its string formatting: seconds of compile time per process)
                for j in range(n):
                    P_out[b, i, j] = P[b, i, j]
            if not _finite(x_out, P_out, b):
                return False
            continue
        for i in range(m):  # nu = z - h(x-), angles wrapped
            d = z[b, i] - hx[b, i]
            nu[i] = _wrap(d) if angular[i] else d
        for i in range(n):  # P H^T
            for j in range(m):
                s = 0.0
                for k in range(n):
                    s += P[b, i, k] * H[b, j, k]
                PHt[i, j] = s
        for i in range(m):  # S = H P H^T + R, symmetrised
            for j in range(m):
                s = 0.0
                for k in range(n):
                    s += H[b, i, k] * PHt[k, j]
                S[i, j] = s + R[b, i, j]
        for i in range(m):
            for j in range(i + 1, m):
                v = 0.5 * (S[i, j] + S[j, i])
                S[i, j] = v
                S[j, i] = v
        for j in range(m):  # S = L L^T
            d = S[j, j]
            for k in range(j):
                d -= L[j, k] * L[j, k]
            if not d > 0.0:
                return False
            L[j, j] = math.sqrt(d)
            for i in range(j + 1, m):
                s = S[i, j]
                for k in range(j):
                    s -= L[i, k] * L[j, k]
                L[i, j] = s / L[j, j]
        gain_into(PHt, L, K)  # K = P H^T S^-1
        for i in range(n):  # x = x- + K nu
            s = x[b, i]
            for j in range(m):
                s += K[i, j] * nu[j]
            x_out[b, i] = s
        for i in range(n):  # A = I - K H
            for j in range(n):
                s = 1.0 if i == j else 0.0
                for k in range(m):
                    s -= K[i, k] * H[b, k, j]
                A[i, j] = s
        for i in range(n):  # A P
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += A[i, k] * P[b, k, j]
                AP[i, j] = s
        for i in range(n):  # K R
            for j in range(m):
                s = 0.0
                for k in range(m):
                    s += K[i, k] * R[b, k, j]
                KR[i, j] = s
        for i in range(n):  # P = A P A^T + K R K^T, symmetrised
            for j in range(i, n):
                s = 0.0
                for k in range(n):
                    s += AP[i, k] * A[j, k]
                for k in range(m):
                    s += KR[i, k] * K[j, k]
                P_out[b, i, j] = s
                P_out[b, j, i] = s
        if not _finite(x_out, P_out, b):
            return False
    return True
