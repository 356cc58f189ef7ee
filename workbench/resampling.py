"""Resampling and log-domain weight helpers for particle filters, vectorised over ``(B, N)``.

Everything here is ``O(B N)``: log-sum-exp by a max shift, systematic resampling by counting how
many of the ``N`` evenly spaced points fall in each particle's slice of the weight CDF (no search),
and the resampled rows gathered one trailing component at a time, which keeps whatever memory
layout the particle array has (a component-major array stays component-major).
"""

from __future__ import annotations

import numpy as np

__all__ = ["normalise_log_weights", "effective_sample_size", "systematic_counts", "systematic_resample",
           "resample_where", "systematic_weights"]


def _log_sum_exp_rows(log_w: np.ndarray, scale: float = 1.0, top: np.ndarray | None = None) -> np.ndarray:
    """``log sum_i exp(scale log_w[b, i])`` for ``(B, N)`` -> ``(B,)`` (``scale > 0``): ``-inf`` for an all
    ``-inf`` row, NaN/inf kept.  One temporary.  ``top``: ``np.max(log_w, axis=1)`` where the caller has it."""
    top = scale * (np.max(log_w, axis=1) if top is None else top)
    shift = np.where(np.isfinite(top), top, 0.0)
    # log sum_i exp(s l_i) = m + log sum_i exp(s l_i - m),  m = max_i s l_i  (log 0 = -inf, without a warning)
    tmp = np.multiply(log_w, scale) if scale != 1.0 else np.array(log_w, dtype=float)
    tmp -= shift[:, None]
    total = np.sum(np.exp(tmp, out=tmp), axis=1)
    return shift + np.log(total, out=np.full_like(total, -np.inf), where=total != 0.0)


def normalise_log_weights(log_w: np.ndarray, fallback: np.ndarray | None = None,
                          top: np.ndarray | None = None) -> np.ndarray:
    """Normalise ``log_w (B, N)`` so each row's weights sum to one, in the log domain.

    A row whose weights are all ``-inf`` (every likelihood underflowed, or an empty gate) keeps
    ``fallback`` (by default uniform weights) instead of becoming NaN.  ``top (B,)``: ``np.max(log_w, axis=1)``
    where the caller has it (not recomputed).
    """
    log_w = np.asarray(log_w, dtype=float)
    total = _log_sum_exp_rows(log_w, top=top)
    dead = ~np.isfinite(total)
    # log w_i <- log w_i - log sum_j w_j
    out = log_w - np.where(dead, 0.0, total)[:, None]
    if dead.any():
        n = log_w.shape[1]
        keep = np.full((int(dead.sum()), n), -np.log(n)) if fallback is None else fallback[dead]
        out[dead] = keep
    return out


def effective_sample_size(log_w: np.ndarray) -> np.ndarray:
    """``N_eff = 1 / sum_i w_i^2`` for normalised log-weights ``(B, N)`` -> ``(B,)``."""
    # 1 / sum_i w_i^2 = exp(-log sum_i exp(2 log w_i))
    return np.exp(-_log_sum_exp_rows(np.asarray(log_w, dtype=float), 2.0))


def systematic_counts(log_w: np.ndarray, u0: np.ndarray, count: int | None = None) -> np.ndarray:
    """How often systematic resampling draws each particle, for given offsets ``u0 (B,)`` in ``[0, 1)``.

    The points are ``u_j = (u0 + j) / M``, ``j = 0..M-1`` (``M = count``, default ``N``).  Particle ``i``
    owns the CDF slice ``[c_{i-1}, c_i)`` and is drawn once for every point inside it::

        k_i = #{j : u_j < c_i} - #{j : u_j < c_{i-1}},   #{j : u_j < c} = ceil(M c - u0)

    so ``k_i`` is ``floor(M w_i)`` or ``ceil(M w_i)`` and ``sum_i k_i = M``.  ``log_w`` need not be
    normalised; a row whose largest log-weight is not finite (all ``-inf``, or a NaN) counts as uniform.

    Shapes
    ------
    log_w : (B, N)
    u0 : (B,) or (B, 1)
    returns : (B, N) int64
    """
    log_w = np.asarray(log_w, dtype=float)
    B, N = log_w.shape
    count = N if count is None else int(count)
    w = systematic_weights(log_w)
    cdf = np.cumsum(w, axis=1)
    # c_i = sum_{k <= i} w_k / sum_k w_k  (the last entry is exactly 1)
    cdf /= cdf[:, -1:]
    # #{j : (u0 + j) / M < c_i} = ceil(M c_i - u0), clipped to [0, M]; monotone in c_i, so k_i >= 0
    cdf *= count
    cdf -= np.reshape(u0, (B, 1))
    np.ceil(cdf, out=cdf)
    np.clip(cdf, 0, count, out=cdf)
    # k_i = edge_i - edge_{i-1} (whole numbers, exact in float64), written over the spent weights
    w[:, 0] = cdf[:, 0]
    np.subtract(cdf[:, 1:], cdf[:, :-1], out=w[:, 1:])
    return w.astype(np.int64)


def systematic_weights(log_w: np.ndarray) -> np.ndarray:
    """The unnormalised weights :func:`systematic_counts` draws from: ``w = exp(log_w - max)`` per row, and 1 for
    every entry of a row whose largest log-weight is not finite (all ``-inf``, or a NaN).  ``(B, N)`` -> a new
    ``(B, N)`` float array."""
    log_w = np.asarray(log_w, dtype=float)
    top = np.max(log_w, axis=1, keepdims=True)
    finite = np.isfinite(top[:, 0])
    w = log_w - np.where(finite[:, None], top, 0.0)
    np.exp(w, out=w)
    w[~finite] = 1.0
    return w


def systematic_resample(log_w: np.ndarray, rng: np.random.Generator, count: int | None = None) -> np.ndarray:
    """Systematic resampling: ``u_j = (u_0 + j) / N``, ``u_0 ~ U[0, 1)`` per row; indices ``(B, count)``.

    Each particle ``i`` is drawn ``floor(N w_i)`` or ``ceil(N w_i)`` times, so its expected count is
    exactly ``N w_i``.  The indices of a row come out sorted (``O(N)``: counts, then a repeat).
    """
    B, N = np.shape(log_w)
    return _systematic_flat(log_w, rng, count) - (np.arange(B) * N)[:, None]


def _systematic_flat(log_w: np.ndarray, rng: np.random.Generator, count: int | None = None) -> np.ndarray:
    """:func:`systematic_resample` as indices into the flattened ``(B N,)`` rows: ``(B, count)``."""
    B, N = np.shape(log_w)
    count = N if count is None else int(count)
    counts = systematic_counts(log_w, rng.random((B, 1)), count)
    # particle i of row b (flat index b N + i) repeated k_bi times; every row holds exactly `count`
    return np.repeat(np.arange(B * N), counts.ravel()).reshape(B, count)


def _gather(arr: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """``out[b, j] = arr.reshape(B N, ...)[flat[b, j]]``, one trailing component at a time, keeping ``arr``'s layout."""
    out = np.empty_like(arr)
    B, N = arr.shape[:2]
    for tail in np.ndindex(arr.shape[2:]):
        src = arr[(slice(None), slice(None)) + tail].reshape(B * N)
        # mode="wrap": the indices are valid, and any mode but "raise" writes into `out` unbuffered
        np.take(src, flat, out=out[(slice(None), slice(None)) + tail], mode="wrap")
    return out


def resample_where(mask: np.ndarray, particles: np.ndarray, log_w: np.ndarray, rng: np.random.Generator,
                   *extra: np.ndarray) -> tuple[np.ndarray, ...]:
    """Systematically resample the rows where ``mask (B,)`` is true and reset their weights to ``1/N``.

    Returns ``(particles, log_w, *extra)`` with ``extra`` arrays ``(B, N, ...)`` carried along.
    Rows where ``mask`` is false are returned unchanged.  New arrays are returned (inputs are never
    written); they keep the memory layout of the inputs.
    """
    if not mask.any():
        return (particles, log_w, *extra)
    B, N = log_w.shape
    if mask.all():
        flat = _systematic_flat(log_w, rng)
        return (_gather(particles, flat), np.full((B, N), -np.log(N)), *(_gather(arr, flat) for arr in extra))
    rows = np.flatnonzero(mask)
    flat = _systematic_flat(log_w[rows], rng)
    log_w = log_w.copy()
    log_w[rows] = -np.log(N)
    # only some rows: gather within those rows, copy the others as they are
    out = []
    for arr in (particles, *extra):
        new = arr.copy(order="K")
        new[rows] = _gather(arr[rows], flat)
        out.append(new)
    return (out[0], log_w, *out[1:])
