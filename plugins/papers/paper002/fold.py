"""The two element-wise passes of the folded ECA + batches CAF, fused: a NumPy twin and a Numba version.

The folded chain (:func:`workbench_papers.paper002.signal.caf_folded`) works on three ``(B, F)`` complex64
arrays of per-batch spectra: ``S`` (surveillance segments), ``R`` (reference batches) and ``E`` (extended
reference segments).  Its element-wise work is two passes over them:

- :func:`normal_sums` -- the sums behind the ECA normal equations::

      bs[f] = sum_b S[b, f] conj(R[b, f])        ae[f] = sum_b E[b, f] conj(R[b, f])

  accumulated in complex128;
- :func:`clean_product` -- the cancelled, pilot-free correlation spectrum, written over ``S``::

      S[b, f] <- (S[b, f] - G[f] E[b, f]) * conj(R[b, f] - a[b] P[f])

  (``E`` and ``G`` absent without ECA; ``a`` and ``P`` absent without pilot removal).

In NumPy each is several whole-array passes with temporaries (about 8 ms each at ``(250, 10240)``); the Numba
version makes one serial pass over the data (see :mod:`.fold_numba` for why not threaded).  ``backend`` follows
:func:`workbench.kernels.backend.resolve`: ``"numba"`` on the CPU where
Numba is installed, otherwise the NumPy twin (this FFT-bound chain has no Taichi version; on another arch the
twin runs).  Tests hold the Numba version to the twin.
"""

from __future__ import annotations

import numpy as np

from workbench.kernels.backend import resolve

__all__ = ["normal_sums", "clean_product", "normal_sums_numpy", "clean_product_numpy"]

_BLOCK = 512  # frequency bins per block of the normal-equation sums (contiguous rows, vectorised)


def normal_sums_numpy(S: np.ndarray, R: np.ndarray, E: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """NumPy twin of :func:`normal_sums`.  Shapes: ``S, R, E (B, F)`` -> ``bs (F,)``, ``ae (F,)`` complex128."""
    conj_r = np.conj(R)
    # bs[f] = sum_b S[b, f] conj(R[b, f])
    bs = np.sum(S * conj_r, axis=0, dtype=np.complex128)
    # ae[f] = sum_b E[b, f] conj(R[b, f])
    ae = None if E is None else np.sum(E * conj_r, axis=0, dtype=np.complex128)
    return bs, ae


def clean_product_numpy(S: np.ndarray, R: np.ndarray, E: np.ndarray | None, G: np.ndarray | None,
                        a: np.ndarray | None, P: np.ndarray | None) -> np.ndarray:
    """NumPy twin of :func:`clean_product` (overwrites and returns ``S``).

    Shapes: ``S, R, E (B, F)``; ``G, P (F,)``; ``a (B,)``.
    """
    if E is not None:
        # S - G E: the ECA fit removed in the batch-spectrum domain
        S -= G[None, :] * E
    # R - a P: the pilot carrier removed from each reference batch
    ref = R if a is None else R - a[:, None] * P[None, :]
    S *= np.conj(ref)
    return S


def _use_numba(backend: str) -> bool:
    return resolve(backend) == "numba"


def normal_sums(S: np.ndarray, R: np.ndarray, E: np.ndarray | None, backend: str = "auto"
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """``bs[f] = sum_b S[b, f] conj(R[b, f])`` and ``ae[f] = sum_b E[b, f] conj(R[b, f])`` (complex128).

    Shapes: ``S, R, E (B, F)`` complex64 -> ``(F,)`` each; ``ae`` is None when ``E`` is None.
    """
    if not _use_numba(backend):
        return normal_sums_numpy(S, R, E)
    from . import fold_numba

    with_e = E is not None
    bs, ae = fold_numba.normal_sums(S, R, E if with_e else S, with_e, _BLOCK)
    return bs, (ae if with_e else None)


def clean_product(S: np.ndarray, R: np.ndarray, E: np.ndarray | None, G: np.ndarray | None,
                  a: np.ndarray | None, P: np.ndarray | None, backend: str = "auto") -> np.ndarray:
    """``S <- (S - G E) conj(R - a P)`` in place (see the module docstring); returns ``S``.

    Shapes: ``S, R, E (B, F)`` complex64; ``G, P (F,)`` complex64; ``a (B,)`` complex64.
    """
    if not _use_numba(backend):
        return clean_product_numpy(S, R, E, G, a, P)
    from . import fold_numba

    with_e, with_p = E is not None, a is not None
    dummy_f = np.zeros(1, dtype=S.dtype)
    return fold_numba.clean_product(S, R, E if with_e else S, G if with_e else dummy_f, a if with_p else np.zeros(1, dtype=S.dtype),
                 P if with_p else dummy_f, with_e, with_p)
