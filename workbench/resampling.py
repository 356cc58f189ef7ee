"""Resampling and log-domain weight helpers for particle filters, vectorised over ``(B, N)``."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

__all__ = ["normalise_log_weights", "effective_sample_size", "systematic_resample", "resample_where"]


def normalise_log_weights(log_w: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """Normalise ``log_w (B, N)`` so each row's weights sum to one, in the log domain.

    A row whose weights are all ``-inf`` (every likelihood underflowed, or an empty gate) keeps
    ``fallback`` (by default uniform weights) instead of becoming NaN.
    """
    log_w = np.asarray(log_w, dtype=float)
    total = logsumexp(log_w, axis=1, keepdims=True)
    dead = ~np.isfinite(total[:, 0])
    out = log_w - np.where(np.isfinite(total), total, 0.0)
    if dead.any():
        n = log_w.shape[1]
        keep = np.full((int(dead.sum()), n), -np.log(n)) if fallback is None else fallback[dead]
        out[dead] = keep
    return out


def effective_sample_size(log_w: np.ndarray) -> np.ndarray:
    """``N_eff = 1 / sum_i w_i^2`` for normalised log-weights ``(B, N)`` -> ``(B,)``."""
    return np.exp(-logsumexp(2.0 * log_w, axis=1))


def systematic_resample(log_w: np.ndarray, rng: np.random.Generator, count: int | None = None) -> np.ndarray:
    """Systematic resampling: ``u_j = (u_0 + j) / N``, ``u_0 ~ U[0, 1)`` per row; indices ``(B, count)``.

    Each particle ``i`` is drawn ``floor(N w_i)`` or ``ceil(N w_i)`` times, so its expected count is
    exactly ``N w_i``.
    """
    B, N = log_w.shape
    count = N if count is None else count
    cdf = np.cumsum(np.exp(log_w - logsumexp(log_w, axis=1, keepdims=True)), axis=1)
    cdf[:, -1] = 1.0  # guard against round-off below 1
    u = (rng.random((B, 1)) + np.arange(count)[None, :]) / count
    # Row-wise searchsorted, vectorised by offsetting each row into its own interval [b, b + 1).
    offsets = np.arange(B)[:, None]
    idx = np.searchsorted((cdf + offsets).ravel(), (u + offsets).ravel(), side="right")
    return (idx.reshape(B, count) - offsets * N).clip(0, N - 1)


def resample_where(mask: np.ndarray, particles: np.ndarray, log_w: np.ndarray, rng: np.random.Generator,
                   *extra: np.ndarray) -> tuple[np.ndarray, ...]:
    """Systematically resample the rows where ``mask (B,)`` is true and reset their weights to ``1/N``.

    Returns ``(particles, log_w, *extra)`` with ``extra`` arrays ``(B, N, ...)`` carried along.
    Rows where ``mask`` is false are returned unchanged.
    """
    if not mask.any():
        return (particles, log_w, *extra)
    rows = np.flatnonzero(mask)
    idx = systematic_resample(log_w[rows], rng)
    particles = particles.copy()
    log_w = log_w.copy()
    particles[rows] = np.take_along_axis(particles[rows], idx[..., None], axis=1)
    log_w[rows] = -np.log(log_w.shape[1])
    out = []
    for arr in extra:
        arr = arr.copy()
        sub = arr[rows]
        arr[rows] = np.take_along_axis(sub, idx.reshape(idx.shape + (1,) * (sub.ndim - 2)), axis=1)
        out.append(arr)
    return (particles, log_w, *out)
