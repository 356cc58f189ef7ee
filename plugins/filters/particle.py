"""Bootstrap (SIR) particle filter, batch-first and log-domain.

State: :class:`ParticleState` with particles ``(B, N, n)`` and normalised log-weights ``(B, N)``.

Predict: ``x_i <- F x_i + Q_sqrt e_i`` (the motion model is the proposal).
Update:  ``log w_i <- log w_i + log N(z; h(x_i), R)`` with the residual wrapped for angular
components; normalise with logsumexp; resample systematically where ``N_eff < threshold * N``.
An item with every weight underflowed keeps its previous weights (counted in the diagnostics).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.linalg import safe_cholesky
from workbench.models import MeasurementModel, MotionModel
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where
from workbench.specs import FilterSpec
from workbench.types import Gaussian, Particles, Scan


@dataclass(frozen=True)
class ParticleState:
    cloud: Particles
    resamples: int = 0  # total resampling events over the batch
    underflows: int = 0  # updates in which every weight of an item underflowed


def init(prior: Gaussian, rng: np.random.Generator, particles: int) -> ParticleState:
    chol, _ = safe_cholesky(prior.cov)
    e = rng.standard_normal((prior.batch, particles, prior.dim))
    x = prior.mean[:, None, :] + np.einsum("bij,bnj->bni", chol, e)
    return ParticleState(Particles(x, np.full((prior.batch, particles), -np.log(particles))))


def predict(state: ParticleState, motion: MotionModel, rng: np.random.Generator) -> ParticleState:
    x = state.cloud.particles
    # x_i <- F x_i + Q_sqrt e_i, drawing e only for the non-zero columns of Q_sqrt (Q may be singular).
    cols = np.flatnonzero(np.any(motion.Q_sqrt != 0.0, axis=0))
    moved = x @ motion.F.T
    if cols.size:
        moved += rng.standard_normal((*x.shape[:2], cols.size)) @ motion.Q_sqrt[:, cols].T
    return ParticleState(Particles(moved, state.cloud.log_weights), state.resamples, state.underflows)


def log_likelihood(z: np.ndarray, x: np.ndarray, model: MeasurementModel) -> np.ndarray:
    """``log N(z_b; h(x_bi), R)`` up to a constant, for ``z (B, m)`` and particles ``x (B, N, n)`` -> ``(B, N)``."""
    nu = model.residual(z[:, None, :], model.h(x))
    # -1/2 nu^T R^-1 nu = -1/2 |L^-1 nu|^2 with R = L L^T
    white = nu @ np.linalg.inv(np.linalg.cholesky(model.R)).T
    return -0.5 * np.einsum("bnm,bnm->bn", white, white)


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator,
           threshold: float) -> ParticleState:
    z, present = single_measurement(scan, "sir")
    if not present.any():
        return state
    cloud = state.cloud
    log_w = cloud.log_weights + log_likelihood(z, cloud.particles, model)
    dead = ~np.isfinite(log_w).any(axis=1) | ~np.isfinite(np.max(log_w, axis=1))
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights)
    log_w = keep_where(present, log_w, cloud.log_weights)
    n = log_w.shape[1]
    resample = present & (effective_sample_size(log_w) < threshold * n)
    x, log_w = resample_where(resample, cloud.particles, log_w, rng)
    return ParticleState(Particles(x, log_w), state.resamples + int(resample.sum()),
                         state.underflows + int((dead & present).sum()))


def estimate(state: ParticleState) -> Gaussian:
    return state.cloud.to_gaussian()


def diagnostics(state: ParticleState) -> dict:
    return {"resamples": state.resamples, "weight_underflows": state.underflows}


def make_sir(particles: int = 500, threshold: float = 0.5, name: str | None = None) -> FilterSpec:
    """A bootstrap particle filter with ``particles`` particles, resampling when ``N_eff < threshold N``."""
    return FilterSpec(
        name=name or "sir",
        summary=f"Bootstrap (SIR) particle filter, N={particles}, systematic resampling at N_eff < {threshold} N",
        init=partial(init, particles=particles),
        predict=predict,
        update=partial(update, threshold=threshold),
        estimate=estimate,
        capabilities=frozenset({"stochastic"}),
        params={"particles": particles, "threshold": threshold},
        diagnostics=diagnostics,
    )


@hookimpl
def workbench_filters():
    return [make_sir()]
