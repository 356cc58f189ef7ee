"""Bootstrap (SIR) particle filter, batch-first and log-domain.

State: :class:`workbench.particle_core.ParticleState` with particles ``(B, N, n)`` and normalised
log-weights ``(B, N)``.

Predict: ``x_i <- F x_i + Q_sqrt e_i`` (the motion model is the proposal); for a motion model that overrides ``f``,
``x_i <- f(x_i) + Q_sqrt e_i`` with the same draws, through the model's compiled propagation where it declares one
and the backend runs Numba, else in NumPy (:func:`workbench.particle_core.predict`).
Update:  ``log w_i <- log w_i + log N(z; h(x_i), R)`` with the residual wrapped for angular
components (``R``: the detection's own covariance where the scan carries one); normalise with logsumexp;
resample systematically where ``N_eff < threshold * N`` (``threshold > 1``, e.g. ``inf``, resamples at
every update).  An item with every weight underflowed keeps its previous weights (counted in the
diagnostics).  The shared pieces (state, proposal, likelihood, reweighting, estimate) are
:mod:`workbench.particle_core`.

Step: :func:`step`, the filter's ``FilterSpec.step``, is predict, update and estimate in one call (the time loop
uses it), the three calls' numbers bit for bit; with the compiled backend, a linear motion model (or one that declares
the fused pass, as the coordinated turn with the rate in the state does) and the planar range-bearing measurement it
propagates and weighs the particles in one pass.

Backend: ``backend="auto"`` (the default) runs the compiled steps of :mod:`workbench.kernels.particle_numba` where
the kernel policy picks Numba (the CPU with Numba installed), else the NumPy code they are held to; ``"numba"`` or
``"numpy"`` ask for one.  The same seed gives the same particles on both (see :mod:`workbench.particle_core`).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import single_measurement
from workbench.kalman_core import measurement_covariance
from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param
from workbench.particle_core import (ParticleState, diagnostics, estimate, init, log_likelihood_cov, predict,
                                     predict_log_weights, reweight, reweight_estimate, weighted_log_likelihood)
from workbench.specs import FilterSpec
from workbench.types import InputError, Particles, Scan

#: Backends the bootstrap filter takes (no Taichi version: see :mod:`workbench.particle_core`).
SIR_BACKENDS = ("auto", "numba", "numpy")

PARAMETERS = (
    Param("particles", 500, "particles per run", "int", unit="dimensionless", minimum=1, footprint=40.0),
    Param("threshold", 0.5, "resample where N_eff < threshold N (above 1: at every update)", unit="dimensionless",
          minimum=0.0, maximum=1e3),
    Param("backend", "auto", "array steps: compiled (numba) or NumPy (auto: the kernel policy's choice)", "str",
          choices=SIR_BACKENDS),
)


def _measurement(scan: Scan) -> tuple[np.ndarray, np.ndarray]:
    """``(z (B, m), present (B,))`` of a scan with at most one valid row per item; a valid row holding a NaN or an
    inf is refused by name (it would make every weight of its item NaN, which the update would then replace by the
    previous weights, hiding it)."""
    z, present = single_measurement(scan, "sir")
    bad = present & ~np.all(np.isfinite(z), axis=1)
    if bad.any():
        item = int(np.argmax(bad))
        raise InputError(f"sir: the valid measurement of batch item {item} holds a non-finite value (NaN or inf): "
                         f"{z[item]}")
    return z, present


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator,
           threshold: float, backend: str = "numpy") -> ParticleState:
    z, present = _measurement(scan)
    if not present.any():
        return state
    cloud = state.cloud
    if scan.cov is None:
        log_w = weighted_log_likelihood(z, cloud.particles, model, cloud.log_weights, backend)
    else:
        R = measurement_covariance(scan, model, present)
        bad = present & ~np.all(np.isfinite(R), axis=(1, 2))
        if bad.any():
            raise InputError(f"sir: the own covariance (Scan.cov) of batch item {int(np.argmax(bad))}'s valid "
                             f"detection holds a non-finite value (NaN or inf)")
        log_w = log_likelihood_cov(z, cloud.particles, model, R)
        log_w += cloud.log_weights
    x, log_w, resampled, dead = reweight(cloud.particles, log_w, cloud.log_weights, present, threshold, rng, backend)
    return ParticleState(Particles.trusted(x, log_w), state.resamples + int(resampled.sum()),
                         state.underflows + int(dead.sum()))


def step(state: ParticleState, motion: MotionModel, scan: Scan, model: MeasurementModel, rng: np.random.Generator,
         threshold: float, backend: str = "numpy", predicted: bool = False):
    """Predict, update and estimate in one call (``FilterSpec.step``): ``(state, estimate, predicted_estimate)``, the
    last the estimate of the predicted state where ``predicted`` asks for it (else ``None``).  The numbers of
    :func:`~workbench.particle_core.predict`, :func:`update` and :func:`~workbench.particle_core.estimate` called one
    after the other, bit for bit, with the same draws in the same order.

    Where the compiled backend runs, the motion model is linear or declares the fused pass
    (:meth:`~workbench.models.MotionModel.fused_particle_propagator`: the coordinated turn with the rate in the
    state) and the measurement model is the planar range-bearing one without a per-detection covariance, the
    propagation, the likelihood and the rows' max are one pass
    (:func:`~workbench.particle_core.predict_log_weights`; for a linear model of the planar state it also takes the
    predicted estimate's sums, tile by tile, where ``predicted`` asks for it), and with resampling at every update (``threshold > 1``)
    the predicted particles, which never outlive the step, live in a reused work array; with a measurement for every
    item and the planar state, the estimate's sums are taken in the resampling's gather, tile by tile while the
    particles are in L1 (:func:`~workbench.particle_core.reweight_estimate`, the same tiles and sums as the
    estimate's); otherwise normalising, resampling and the estimate are the three-call path's own code.  Elsewhere
    it is the three calls."""
    z, present = _measurement(scan)
    fused = None
    if present.any() and scan.cov is None:
        # with threshold > 1 every item with a measurement is resampled (the others copied), so the predicted cloud
        # is never returned
        fused = predict_log_weights(state, motion, rng, z, present, model, backend, scratch=threshold > 1.0,
                                    predicted_estimate=predicted)
    if fused is None:
        moved = predict(state, motion, rng, backend)
        before = estimate(moved, backend) if predicted else None
        after = update(moved, scan, model, rng, threshold, backend)
        return after, estimate(after, backend), before
    x, log_w, top = fused[:3]
    previous = state.cloud.log_weights
    before = fused[3] if predicted else None
    if predicted and before is None:  # the pass did not take the predicted estimate's sums
        before = estimate(ParticleState(Particles.trusted(x, previous)), backend)
    # resampling every item with the estimate's sums in the gather's pass, where it applies (the same numbers)
    done = reweight_estimate(x, log_w, previous, present, threshold, rng, backend, top)
    if done is not None:
        x, log_w, resampled, dead, est = done
    else:
        x, log_w, resampled, dead = reweight(x, log_w, previous, present, threshold, rng, backend, top)
        est = None
    after = ParticleState(Particles.trusted(x, log_w), state.resamples + int(resampled.sum()),
                          state.underflows + int(dead.sum()))
    return after, estimate(after, backend) if est is None else est, before


def make_sir(particles: int = 500, threshold: float = 0.5, name: str | None = None,
             backend: str = "auto") -> FilterSpec:
    """A bootstrap particle filter with ``particles`` particles, resampling when ``N_eff < threshold N``; its array
    steps compiled or in NumPy as ``backend`` says."""
    if backend not in SIR_BACKENDS:
        raise InputError(f"sir: unknown backend {backend!r}; expected one of {', '.join(SIR_BACKENDS)}")
    return FilterSpec(
        name=name or "sir",
        summary=f"Bootstrap (SIR) particle filter, N={particles}, systematic resampling at N_eff < {threshold} N",
        init=partial(init, particles=particles),
        predict=partial(predict, backend=backend),
        update=partial(update, threshold=threshold, backend=backend),
        estimate=partial(estimate, backend=backend),
        step=partial(step, threshold=threshold, backend=backend),
        capabilities=frozenset({"stochastic", "detection_covariance"}),
        params={"particles": particles, "threshold": threshold, "backend": backend},
        diagnostics=diagnostics,
        parameters=PARAMETERS,
        build=make_sir,
    )


@hookimpl
def workbench_filters():
    return [make_sir()]
