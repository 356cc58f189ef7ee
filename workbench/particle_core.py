"""Bootstrap particle-filter pieces shared by filter plugins, batch-first and log-domain.

Plugins may not import each other, so what more than one particle filter needs lives here: the particle
state, the motion-model proposal (:func:`predict`), the Gaussian log-likelihood of a measurement for every
particle (:func:`log_likelihood`, or with a per-item covariance :func:`log_likelihood_cov`), the weighted
estimate and the counters.

State: :class:`ParticleState` with particles ``(B, N, n)`` and normalised log-weights ``(B, N)``.

Predict: ``x_i <- F x_i + Q_sqrt e_i`` (the motion model is the proposal).
Likelihood: ``log N(z; h(x_i), R)`` up to a constant, with the residual wrapped for angular components.

Speed: the particle arrays made here are stored component-major (``(n, B, N)`` in memory, seen as
``(B, N, n)``), so that every per-component operation runs over ``B N`` contiguous numbers; the small
matrix products (``F x``, ``Q_sqrt e``, the whitening by ``chol(R)^-1``) are written out one component at a
time, skipping zero entries, instead of calling BLAS on ``(N, 4) x (4, 4)`` shapes.  Any layout of the input
particles is accepted.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .linalg import safe_cholesky
from .models import MeasurementModel, MotionModel
from .types import Gaussian, Particles

__all__ = ["ParticleState", "component_major", "combine_columns", "init", "predict", "log_likelihood",
           "log_likelihood_cov", "estimate", "diagnostics"]


@dataclass(frozen=True)
class ParticleState:
    cloud: Particles
    resamples: int = 0  # total resampling events over the batch
    underflows: int = 0  # updates in which every weight of an item underflowed


def component_major(batch: int, particles: int, dim: int) -> np.ndarray:
    """An empty ``(B, N, n)`` array stored as ``(n, B, N)``: each ``x[..., j]`` is one contiguous block."""
    return np.empty((dim, batch, particles)).transpose(1, 2, 0)


@lru_cache(maxsize=64)
def _plan(matrix_bytes: bytes, rows: int, cols: int) -> tuple:
    """Per output row of a ``(rows, cols)`` matrix: its ``(column, coefficient)`` pairs other than one, and
    the columns whose coefficient is one (zeros are skipped)."""
    matrix = np.frombuffer(matrix_bytes, dtype=float).reshape(rows, cols)
    return tuple((tuple((int(j), float(matrix[i, j])) for j in np.flatnonzero((matrix[i] != 0.0) & (matrix[i] != 1.0))),
                  tuple(int(j) for j in np.flatnonzero(matrix[i] == 1.0)))
                 for i in range(rows))


def combine_columns(out: np.ndarray, matrix: np.ndarray, *sources: np.ndarray) -> np.ndarray:
    """``out[..., i] = sum_j matrix[i, j] s[..., j]`` over the columns of ``sources`` side by side.

    The small product ``s @ matrix.T`` written out one output component at a time, skipping zero
    entries and multiplications by one (``x_0 + x_2`` is one pass); ``out`` must not share memory
    with a source.

    Shapes
    ------
    out : (..., r)
    matrix : (r, c) with ``c`` the total trailing size of ``sources``
    sources : (..., c_k) each
    """
    matrix = np.ascontiguousarray(matrix, dtype=float)
    columns = [s[..., j] for s in sources for j in range(s.shape[-1])]
    scratch = None
    for i, (scaled, unit) in enumerate(_plan(matrix.tobytes(), *matrix.shape)):
        col = out[..., i]
        unit = [columns[j] for j in unit]
        if scaled:
            np.multiply(columns[scaled[0][0]], scaled[0][1], out=col)
            for j, coef in scaled[1:]:
                if scratch is None:
                    scratch = np.empty(col.shape)
                np.multiply(columns[j], coef, out=scratch)
                col += scratch
        elif len(unit) >= 2:
            np.add(unit[0], unit[1], out=col)
            unit = unit[2:]
        elif unit:
            np.copyto(col, unit.pop())
        else:
            col[...] = 0.0
        for src in unit:
            col += src
    return out


def init(prior: Gaussian, rng: np.random.Generator, particles: int) -> ParticleState:
    chol, _ = safe_cholesky(prior.cov)
    e = rng.standard_normal((prior.batch, particles, prior.dim))
    x = component_major(prior.batch, particles, prior.dim)
    # x_i = mean + chol e_i
    x[...] = prior.mean[:, None, :] + np.einsum("bij,bnj->bni", chol, e)
    return ParticleState(Particles.trusted(x, np.full((prior.batch, particles), -np.log(particles))))


def _noise_columns(motion: MotionModel) -> np.ndarray:
    """The non-zero columns of ``Q_sqrt`` (``Q`` may be singular): ``(n, k)``."""
    return motion.Q_sqrt[:, np.flatnonzero(np.any(motion.Q_sqrt != 0.0, axis=0))]


def predict(state: ParticleState, motion: MotionModel, rng: np.random.Generator) -> ParticleState:
    x = state.cloud.particles
    B, N, n = x.shape
    g = _noise_columns(motion)
    # x_i <- F x_i + Q_sqrt e_i, drawing e only for the non-zero columns of Q_sqrt
    sources = [x]
    if g.shape[1]:
        sources.append(rng.standard_normal((B, N, g.shape[1])))
    moved = combine_columns(component_major(B, N, n), np.hstack([motion.F, g]), *sources)
    return ParticleState(Particles.trusted(moved, state.cloud.log_weights), state.resamples, state.underflows)


def _inverse_cholesky(R: np.ndarray) -> np.ndarray:
    """``L^-1`` for ``R = L L^T`` (``m x m``, computed once per distinct ``R``)."""
    R = np.ascontiguousarray(R, dtype=float)
    return _inverse_cholesky_cached(R.tobytes(), R.shape[0])


@lru_cache(maxsize=64)
def _inverse_cholesky_cached(r_bytes: bytes, m: int) -> np.ndarray:
    out = np.linalg.inv(np.linalg.cholesky(np.frombuffer(r_bytes, dtype=float).reshape(m, m)))
    out.flags.writeable = False
    return out


def log_likelihood(z: np.ndarray, x: np.ndarray, model: MeasurementModel) -> np.ndarray:
    """``log N(z_b; h(x_bi), R)`` up to a constant, for ``z (B, m)`` and particles ``x (B, N, n)`` -> ``(B, N)``."""
    nu = model.residual(z[:, None, :], model.h(x))
    B, N, m = nu.shape
    # white = L^-1 nu with R = L L^T
    white = combine_columns(np.empty((m, B, N)).transpose(1, 2, 0), _inverse_cholesky(model.R), nu)
    # -1/2 nu^T R^-1 nu = -1/2 |white|^2
    np.square(white, out=white)
    out = white[..., 0].copy() if m == 1 else np.add(white[..., 0], white[..., 1])
    for j in range(2, m):
        out += white[..., j]
    out *= -0.5
    return out


def log_likelihood_cov(z: np.ndarray, x: np.ndarray, model: MeasurementModel, R: np.ndarray) -> np.ndarray:
    """``log N(z_b; h(x_bi), R_b)`` for a per-item covariance ``R (B, m, m)``, including the normalising
    ``-(m log 2 pi + log |R_b|) / 2``; ``z (B, m)``, ``x (B, N, n)`` -> ``(B, N)``."""
    nu = model.residual(z[:, None, :], model.h(x))
    L = np.linalg.cholesky(R)
    # white = L_b^-1 nu (one triangular solve per item for all its particles)
    white = np.linalg.solve(L, np.swapaxes(nu, 1, 2))
    m = nu.shape[-1]
    log_det = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
    return -0.5 * np.einsum("bmn,bmn->bn", white, white) - 0.5 * (m * np.log(2.0 * np.pi) + log_det)[:, None]


def estimate(state: ParticleState) -> Gaussian:
    return state.cloud.to_gaussian()


def diagnostics(state: ParticleState) -> dict:
    return {"resamples": state.resamples, "weight_underflows": state.underflows}


