"""The Numba version of :mod:`workbench_papers.paper002.fold` (imported only when used).

Module-level functions, so that Numba's on-disk cache holds across processes.  Serial: each pass is bound by
memory bandwidth, and a thread pool of its own would contend on two cores with the FFT threads that run before
and after it (measured: the OpenMP pool's wake-up and spinning cost more than the second thread saved).
"""

import numba
import numpy as np


@numba.njit(cache=True, fastmath=True)
def normal_sums(S, R, E, with_e, block):
    """``bs[f] = sum_b S[b, f] conj(R[b, f])``, ``ae[f] = sum_b E[b, f] conj(R[b, f])``, over blocks of bins."""
    B, F = S.shape
    bs = np.zeros(F, dtype=np.complex128)
    ae = np.zeros(F, dtype=np.complex128)
    nblocks = (F + block - 1) // block
    for k in range(nblocks):
        lo = k * block
        hi = min(lo + block, F)
        acc_b = np.zeros(hi - lo, dtype=np.complex128)
        acc_e = np.zeros(hi - lo, dtype=np.complex128)
        for b in range(B):
            for f in range(lo, hi):
                cr = np.conj(R[b, f])
                acc_b[f - lo] += S[b, f] * cr
                if with_e:
                    acc_e[f - lo] += E[b, f] * cr
        for f in range(lo, hi):  # element by element: a slice assignment compiles Numba's shape-mismatch message
            bs[f] = acc_b[f - lo]
            ae[f] = acc_e[f - lo]
    return bs, ae


@numba.njit(cache=True, fastmath=True)
def clean_product(S, R, E, G, a, P, with_e, with_p):
    """``S[b, f] <- (S[b, f] - G[f] E[b, f]) conj(R[b, f] - a[b] P[f])`` in place, batch by batch."""
    B, F = S.shape
    for b in range(B):
        ab = a[b] if with_p else a[0] * 0
        for f in range(F):
            x = S[b, f]
            if with_e:
                x = x - G[f] * E[b, f]
            r = R[b, f]
            if with_p:
                r = r - ab * P[f]
            S[b, f] = x * np.conj(r)
    return S
