"""Error and consistency metrics, batch-first."""

from __future__ import annotations

import numpy as np

from ..linalg import psd_solve

__all__ = ["nees", "nis", "chi2_band", "position_sq_error", "rmse"]


def nees(truth: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^{-1} e`` with ``e = truth - mean``.

    Shapes: ``truth, mean (..., n)``, ``cov (..., n, n)`` -> ``(...)``.
    """
    e = np.asarray(truth, dtype=float) - np.asarray(mean, dtype=float)
    return np.einsum("...i,...i->...", e, psd_solve(cov, e[..., None])[..., 0])


def nis(innovation: np.ndarray, innovation_cov: np.ndarray) -> np.ndarray:
    """Normalised innovation squared ``nu^T S^{-1} nu``; shapes as :func:`nees`."""
    return nees(innovation, np.zeros_like(innovation), innovation_cov)


def chi2_band(dof: int, runs: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided band for the mean over ``runs`` of a chi-square(``dof``) statistic.

    ``runs * mean`` is chi-square with ``runs * dof`` degrees of freedom, so the band is
    ``chi2.ppf([a/2, 1 - a/2], runs * dof) / runs``.
    """
    alpha = 1.0 - confidence
    from scipy import stats  # imported on use: scipy.stats takes a second to import

    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], runs * dof)
    return float(lo / runs), float(hi / runs)


def position_sq_error(truth: np.ndarray, mean: np.ndarray, dims: int = 2) -> np.ndarray:
    """Squared position error over the first ``dims`` components, ``(...)``."""
    d = np.asarray(truth, dtype=float)[..., :dims] - np.asarray(mean, dtype=float)[..., :dims]
    return np.einsum("...i,...i->...", d, d)


def rmse(sq_error: np.ndarray, axis=0) -> np.ndarray:
    """Root of the mean of squared errors over ``axis`` (by default the batch axis)."""
    return np.sqrt(np.mean(sq_error, axis=axis))
