"""Numba loops of the Kalman predict and update for small batches (one track: ``B = 1``).

At one item, the batched NumPy code of :mod:`workbench.kalman_core` spends its time in about forty tiny NumPy
calls; these loops do the same algebra item by item in one compiled call.  The NumPy code is the reference they
are held to (``tests/test_kalman_numba.py``)::

    predict   x- = F x,  P- = F P F^T + Q                       (symmetrised)
    update    S = H P- H^T + R,  S = L L^T
              K = P- H^T S^-1          (two triangular solves with L)
              x = x- + K nu            (nu: the model's wrapped residual, computed by the caller)
              P = (I - K H) P- (I - K H)^T + K R K^T   (Joseph form, symmetrised)

``R`` is ``(B, m, m)`` (the model's broadcast, or each item's own).  An item whose ``S`` is not numerically
positive definite makes the call return ``False`` and the caller takes the NumPy path (its solve falls back to
a general one).  Serial on purpose: these are for small batches, where a thread pool costs more than the work.
"""

import math

import numba
import numpy as np

jit = numba.njit(error_model="numpy", cache=True)


@jit
def predict_items(x, P, F, Q, x_out, P_out):
    B, n = x.shape
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


@jit
def update_items(x, P, nu, H, R, present, x_out, P_out):
    B, n = x.shape
    m = nu.shape[1]
    PHt = np.empty((n, m))
    S = np.empty((m, m))
    L = np.empty((m, m))
    K = np.empty((n, m))
    A = np.empty((n, n))
    AP = np.empty((n, n))
    KR = np.empty((n, m))
    for b in range(B):
        if not present[b]:
            x_out[b] = x[b]
            P_out[b] = P[b]
            continue
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
        for r in range(n):  # K^T = S^-1 (P H^T)^T: solve L y = PHt[r], then L^T k = y
            for i in range(m):
                s = PHt[r, i]
                for k in range(i):
                    s -= L[i, k] * K[r, k]
                K[r, i] = s / L[i, i]
            for i in range(m - 1, -1, -1):
                s = K[r, i]
                for k in range(i + 1, m):
                    s -= L[k, i] * K[r, k]
                K[r, i] = s / L[i, i]
        for i in range(n):  # x = x- + K nu
            s = x[b, i]
            for j in range(m):
                s += K[i, j] * nu[b, j]
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
    return True
