"""Bootstrap (SIR) particle filter, batch-first and log-domain.

State: :class:`workbench.particle_core.ParticleState` with particles ``(B, N, n)`` and normalised
log-weights ``(B, N)``.

Predict: ``x_i <- F x_i + Q_sqrt e_i`` (the motion model is the proposal).
Update:  ``log w_i <- log w_i + log N(z; h(x_i), R)`` with the residual wrapped for angular
components (``R``: the detection's own covariance where the scan carries one); normalise with logsumexp;
resample systematically where ``N_eff < threshold * N`` (``threshold > 1``, e.g. ``inf``, resamples at
every update).  An item with every weight underflowed keeps its previous weights (counted in the
diagnostics).  The shared pieces (state, proposal, likelihood) are :mod:`workbench.particle_core`.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.kalman_core import measurement_covariance
from workbench.params import Param
from workbench.particle_core import (ParticleState, diagnostics, estimate, init, log_likelihood, log_likelihood_cov,
                                     predict)
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where
from workbench.specs import FilterSpec
from workbench.types import Particles, Scan
from workbench.models import MeasurementModel

PARAMETERS = (
    Param("particles", 500, "particles per run", "int", minimum=1),
    Param("threshold", 0.5, "resample where N_eff < threshold N (above 1: at every update)", minimum=0.0),
)


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator,
           threshold: float) -> ParticleState:
    z, present = single_measurement(scan, "sir")
    if not present.any():
        return state
    cloud = state.cloud
    if scan.cov is None:
        log_w = log_likelihood(z, cloud.particles, model)
    else:
        log_w = log_likelihood_cov(z, cloud.particles, model, measurement_covariance(scan, model, present))
    log_w += cloud.log_weights
    # every weight of an item underflowed (or a NaN/inf crept in): its max is not finite
    dead = ~np.isfinite(np.max(log_w, axis=1))
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights)
    if not present.all():
        log_w = keep_where(present, log_w, cloud.log_weights)
    n = log_w.shape[1]
    # N_eff <= N, so a threshold above one resamples every item with a measurement
    resample = present if threshold > 1.0 else present & (effective_sample_size(log_w) < threshold * n)
    x, log_w = resample_where(resample, cloud.particles, log_w, rng)
    return ParticleState(Particles.trusted(x, log_w), state.resamples + int(resample.sum()),
                         state.underflows + int((dead & present).sum()))


def make_sir(particles: int = 500, threshold: float = 0.5, name: str | None = None) -> FilterSpec:
    """A bootstrap particle filter with ``particles`` particles, resampling when ``N_eff < threshold N``."""
    return FilterSpec(
        name=name or "sir",
        summary=f"Bootstrap (SIR) particle filter, N={particles}, systematic resampling at N_eff < {threshold} N",
        init=partial(init, particles=particles),
        predict=predict,
        update=partial(update, threshold=threshold),
        estimate=estimate,
        capabilities=frozenset({"stochastic", "detection_covariance"}),
        params={"particles": particles, "threshold": threshold},
        diagnostics=diagnostics,
        parameters=PARAMETERS,
        build=make_sir,
    )


@hookimpl
def workbench_filters():
    return [make_sir()]
