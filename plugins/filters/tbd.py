"""Method C of paper 000: a particle filter weighted directly by every gated detection (eqs 12-15).

For particle ``i`` (state ``s_i``) and gated detection ``m`` (position ``p_m``, radial velocity
``vr_m``, measured SNR ``snr_m``)::

    w_{m,i} = P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr(s_i), sigma_vr^2)      (13)
    w_i     = sum_m w_{m,i}                                                              (14)
    log w_k,i = log w_{k-1,i} + log(eps + w_i), normalised over i                        (15, SIS)

``p_i, vr(s_i)`` is the sensor's ``h(s_i)`` (a model in the ``position-doppler-3d`` frame), and ``P_D`` and
``sigma_p,m`` follow the detection's own SNR as the sensor declares them (``model.detection``, a
:class:`workbench.models.DetectionModel`).  The floor
``eps = floor_density * max_m P_D(snr_m) N(0; 0, sigma_vr^2)`` is the "target missed, every detection
is clutter" alternative: a spatial density (m^-3, default 5e-11 = 0.05 per km^3, a quarter of the
5 dB clutter density) in place of the position kernel.  Relative to the kernel's peak it is large
when the kernels are wide (low SNR, far away: a lone clutter point hardly drags the cloud) and tiny
when they are sharp (high SNR: a lagging cloud still feels the detection, e.g. in the sharp turn).
The brief's fixed ``1e-3 x peak`` lost almost every run at the turn or in the clutter of the low-SNR
segment (docs/paper000.md).  ``floor_density = 0`` is the literal paper (filter ``tbd-pf-eps0``).

Everything is in the log domain; the sum over ``m`` is the compiled kernel
:func:`workbench.kernels.tbd_weights.tbd_log_weight_sums` (streaming, no (B, N, M) array).  Items
without a gated detection keep their weights (predict only); an item whose weights all underflow
keeps its previous weights (counted).  Systematic resampling when
``N_eff < threshold * N`` (eq 16), followed by post-regularisation (:func:`regularise`, Musso, Oudjane
and Le Gland's regularised particle filter): each resampled particle is jittered by
``h D e``, ``D D^T`` the cloud's weighted covariance before resampling, ``h = 0.5 h_opt``
(:func:`regularisation_bandwidth`), so that the copies of the few particles that keep up with a sharp
manoeuvre become distinct particles (``regularisation = 0`` turns it off).  The state, prediction and
estimate are those of the bootstrap filter (:mod:`workbench.particle_core`).

The update takes the whole gated scan: ``scan.z = [x, y, z, vr]`` (B, M, 4), ``scan.snr`` (dB).

Manoeuvres (the same two-level process noise for methods A, B and C; docs/paper000.md).  The particle
filters predict with a jump-Markov (two-mode) CV model, :func:`predict_jump_markov`: each particle
carries a mode, quiet (the motion model's ``W``) or manoeuvre (``MANOEUVRE_SCALE^2 W``), switching
quiet -> manoeuvre with probability ``SWITCH_ON`` and back with ``SWITCH_OFF`` per scan; the mode
rides along through resampling.  Filters registered here:

- ``tbd-pf`` (method C) and ``tbd-pf-eps0`` (no floor), both with the two-mode prediction;
- ``sir-jm`` (method B): the bootstrap filter of :mod:`workbench.particle_core` (its likelihood),
  with the same two-mode prediction;
- ``ekf-nis`` (method A): the EKF (:func:`workbench.kalman_core.ekf_update`) whose process noise
  switches to ``MANOEUVRE_SCALE^2 W`` for the next prediction when the normalised innovation squared
  of the pseudo-measurement exceeds the chi-square 99 % point (4 dof), the Gaussian filter's
  counterpart of the two modes (noise-level switching by manoeuvre detection).

Clutter (methods A and B): where the scan declares the clutter density at the measurement
(``Scan.clutter_density = b`` per unit measurement volume; the paper-000 pipeline computes it from the
clutter model and the measurement's amplitude), the measurement may be clutter: B's likelihood is the mixture
``b + N(z; h(x_i), R)``; A's update is the PDAF's for one validated measurement,
``beta_0 = b / (b + N(nu; 0, S))``.  ``R`` is the measurement's own covariance where the scan carries one
(``Scan.cov``, e.g. the pseudo-measurement's ``R_bar``), else the model's.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.stats import chi2

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.kalman_core import ekf_update, measurement_covariance
from workbench.kernels.backend import BACKENDS
from workbench.kernels.tbd_weights import tbd_log_weight_sums
from workbench.linalg import psd_solve, safe_cholesky, symmetrise
from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param
from workbench.particle_core import (ParticleState, combine_columns, component_major, diagnostics, estimate, init,
                                     log_likelihood_cov, predict)
from workbench.particle_core import log_likelihood as sir_log_likelihood
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Particles, Scan

#: two-mode process noise [U, chosen by a sweep, docs/paper000.md]: P(quiet -> manoeuvre), P(manoeuvre -> quiet)
#: per scan and the manoeuvre mode's factor on sigma_a
SWITCH_ON, SWITCH_OFF, MANOEUVRE_SCALE = 0.05, 0.2, 4.0
#: post-regularisation of method C (tbd-pf) after resampling, as a fraction of the optimal kernel bandwidth
REGULARISATION = 0.5


def _detection(model: MeasurementModel):
    if model.detection is None or model.frame != "position-doppler-3d":
        raise InputError(f"tbd-pf needs a measurement model in the position-doppler-3d frame that declares how its "
                         f"detections' quality follows their SNR (model.detection); {model.name!r} is in frame "
                         f"{model.frame or 'undeclared'!r} with detection {model.detection!r:.40}")
    return model.detection


def log_likelihood(particles: np.ndarray, scan: Scan, model: MeasurementModel, sigma_vr: float,
                   floor_density: float, backend: str = "auto") -> np.ndarray:
    """``log(eps + sum_m w_{m,i})`` for particles ``(B, N, 6)`` and a gated scan -> ``(B, N)``.

    ``-inf`` for items without a valid detection.
    """
    if scan.snr is None:
        raise InputError("tbd-pf needs the measured SNR of every detection (scan.snr, dB)")
    if not (np.all(np.isfinite(scan.z[scan.valid])) and np.all(np.isfinite(scan.snr[scan.valid]))):
        raise InputError("tbd-pf: a valid detection holds a non-finite value (NaN or inf) in z or snr")
    detection = _detection(model)
    z = scan.z
    points = model.h(particles)  # [p_i, vr(s_i)]
    snr_db = np.where(scan.valid, scan.snr, 0.0)
    log_pd = detection.log_pd(snr_db)
    sigma_p = detection.position_sigma(snr_db, np.linalg.norm(z[..., :3], axis=-1))
    # log sum_m P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr_i, sigma_vr^2)     (13), (14)
    log_sum = tbd_log_weight_sums(points, z, scan.valid, log_pd, sigma_p, sigma_vr, backend=backend)
    if floor_density <= 0.0:
        return log_sum
    # eps = floor_density * max_m P_D(snr_m) N(0; 0, sigma_vr^2)
    top = np.max(np.where(scan.valid, log_pd, -np.inf), axis=1, keepdims=True)
    log_eps = np.log(floor_density) + top - 0.5 * np.log(2.0 * np.pi * sigma_vr**2)
    # log(eps + sum_m w_{m,i})
    return np.where(np.isfinite(log_eps), np.logaddexp(log_eps, log_sum), -np.inf)


@dataclass(frozen=True)
class ModeState(ParticleState):
    """A particle cloud with a manoeuvre mode per particle (0 quiet, 1 manoeuvre): ``mode (B, N)``."""

    mode: np.ndarray | None = None


def _modes(state: ParticleState) -> np.ndarray:
    mode = getattr(state, "mode", None)
    return np.zeros(state.cloud.log_weights.shape) if mode is None else mode


def predict_jump_markov(state: ParticleState, motion: MotionModel, rng: np.random.Generator, *, switch_on: float,
                        switch_off: float, scale: float) -> ModeState:
    """Jump-Markov (two-mode) prediction: each particle carries a mode, quiet (noise ``W``) or manoeuvre
    (noise ``scale^2 W``), that switches with ``P(quiet -> manoeuvre) = switch_on`` and
    ``P(manoeuvre -> quiet) = switch_off`` before the particle moves::

        m_i <- Markov(m_i),   x_i <- F x_i + (scale if m_i else 1) W^(1/2) e_i

    A particle that the detections select during a manoeuvre keeps a large noise for its
    descendants (mean sojourn ``1 / switch_off`` scans), so the cloud can follow a sustained turn.

    Shapes
    ------
    particles (B, N, n), mode (B, N)
    """
    x = state.cloud.particles
    B, N, n = x.shape
    mode = _modes(state)
    u = rng.random((B, N))
    # m <- 1 - m with probability switch_off (m = 1) or switch_on (m = 0)
    mode = np.where(u < np.where(mode > 0, switch_off, switch_on), 1.0 - mode, mode)
    g = motion.Q_sqrt[:, np.flatnonzero(np.any(motion.Q_sqrt != 0.0, axis=0))]  # non-zero columns of W^(1/2)
    e = rng.standard_normal((B, N, g.shape[1]))
    e *= np.where(mode > 0, scale, 1.0)[..., None]
    # x_i <- F x_i + s_i W^(1/2) e_i  (small products written out per component, no threaded BLAS call)
    moved = combine_columns(component_major(B, N, n), np.hstack([motion.F, g]), x, e)
    return ModeState(Particles(moved, state.cloud.log_weights), state.resamples, state.underflows, mode)


def regularisation_bandwidth(particles: int, dim: int) -> float:
    """Optimal bandwidth of a Gaussian kernel for a ``dim``-dimensional density from ``particles`` samples
    (Musso, Oudjane and Le Gland 2001, the regularised particle filter)::

        h_opt = (4 / (N (n + 2)))^(1 / (n + 4))
    """
    # h_opt = A N^(-1/(n+4)),  A = (4 / (n + 2))^(1/(n+4))
    return float((4.0 / (particles * (dim + 2.0))) ** (1.0 / (dim + 4.0)))


def regularise(x: np.ndarray, cov: np.ndarray, rows: np.ndarray, scale: float, rng: np.random.Generator) -> np.ndarray:
    """Post-regularisation of the rows just resampled: ``x_i <- x_i + h D e_i``, ``e_i ~ N(0, I)``.

    ``D D^T = cov`` is the weighted covariance of the cloud before resampling and ``h = scale * h_opt``
    (:func:`regularisation_bandwidth`): the resampled cloud becomes a draw from the kernel-smoothed
    posterior instead of copies of a few particles (sample impoverishment).

    Shapes
    ------
    x : (B, N, n) resampled particles; cov : (B, n, n); rows : (B,) bool; returns (B, N, n)
    """
    if scale <= 0.0 or not rows.any():
        return x
    B, N, n = x.shape
    h = scale * regularisation_bandwidth(N, n)
    D, _ = safe_cholesky(cov[rows])
    e = rng.standard_normal((int(rows.sum()), N, n))
    out = x.copy(order="K")
    # x_i <- x_i + h D e_i
    out[rows] += h * np.einsum("bij,bnj->bni", D, e)
    return out


def _finish(state: ParticleState, log_w: np.ndarray, present: np.ndarray, threshold: float, dead: np.ndarray,
            rng: np.random.Generator, regularisation: float = 0.0) -> ParticleState:
    """Resample where ``N_eff < threshold N`` (eq 16), carrying the particles' modes along; with
    ``regularisation > 0`` the resampled rows are jittered by :func:`regularise`."""
    cloud = state.cloud
    n = log_w.shape[1]
    resample = present & (effective_sample_size(log_w) < threshold * n)
    cov = Particles(cloud.particles, log_w).to_gaussian().cov if regularisation > 0.0 and resample.any() else None
    mode = getattr(state, "mode", None)
    if mode is None:
        x, log_w = resample_where(resample, cloud.particles, log_w, rng)
        if cov is not None:
            x = regularise(x, cov, resample, regularisation, rng)
        return ParticleState(Particles(x, log_w), state.resamples + int(resample.sum()),
                             state.underflows + int(dead.sum()))
    joint, log_w = resample_where(resample, np.concatenate([cloud.particles, mode[..., None]], axis=-1), log_w, rng)
    x = np.ascontiguousarray(joint[..., :-1])
    if cov is not None:
        x = regularise(x, cov, resample, regularisation, rng)
    return ModeState(Particles(x, log_w), state.resamples + int(resample.sum()),
                     state.underflows + int(dead.sum()), np.ascontiguousarray(joint[..., -1]))


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator, *,
           threshold: float, floor_density: float, sigma_vr: float, backend: str,
           regularisation: float = 0.0) -> ParticleState:
    present = scan.valid.any(axis=1)
    if not present.any():
        return state
    cloud = state.cloud
    log_lik = log_likelihood(cloud.particles, scan, model, sigma_vr, floor_density, backend)
    log_w = cloud.log_weights + log_lik
    dead = present & ~np.isfinite(np.max(log_w, axis=1))
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights)
    log_w = keep_where(present, log_w, cloud.log_weights)
    return _finish(state, log_w, present, threshold, dead, rng, regularisation)


def _predict(switch_on: float, switch_off: float, scale: float):
    if switch_on <= 0.0 or scale == 1.0:
        return predict
    return partial(predict_jump_markov, switch_on=switch_on, switch_off=switch_off, scale=scale)


def _check_modes(who: str, switch_on: float, switch_off: float, scale: float) -> None:
    if not (0.0 <= switch_on <= 1.0 and 0.0 < switch_off <= 1.0 and scale >= 1.0):
        raise InputError(f"{who}: need 0 <= switch_on <= 1, 0 < switch_off <= 1, manoeuvre_scale >= 1; got "
                         f"{switch_on}, {switch_off}, {scale}")


TBD_PARAMETERS = (
    Param("particles", 600, "particles per run", "int", minimum=1),
    Param("threshold", 0.5, "resample where N_eff < threshold N", minimum=0.0, maximum=1.0),
    Param("floor_density", 5e-11, "spatial density (m^-3) of the 'every detection is clutter' floor eps; 0: the "
          "literal paper", minimum=0.0),
    Param("sigma_vr", 15.0, "width of the Doppler kernel", unit="speed", above=0.0),
    Param("backend", "auto", "kernel backend of the weights (auto: the policy's choice)", "str", choices=BACKENDS),
    Param("switch_on", SWITCH_ON, "P(quiet -> manoeuvre) per scan of the two-mode prediction (0: plain CV)",
          minimum=0.0, maximum=1.0),
    Param("switch_off", SWITCH_OFF, "P(manoeuvre -> quiet) per scan", above=0.0, maximum=1.0),
    Param("manoeuvre_scale", MANOEUVRE_SCALE, "factor on the process-noise sigma in the manoeuvre mode", minimum=1.0),
    Param("regularisation", REGULARISATION, "post-regularisation bandwidth after resampling, x h_opt (0: off)",
          minimum=0.0),
)


def make_tbd_pf(particles: int = 600, threshold: float = 0.5, floor_density: float = 5e-11, sigma_vr: float = 15.0,
                backend: str = "auto", name: str | None = None, switch_on: float = SWITCH_ON,
                switch_off: float = SWITCH_OFF, manoeuvre_scale: float = MANOEUVRE_SCALE,
                regularisation: float = REGULARISATION) -> FilterSpec:
    """Method C with ``particles`` particles, floor density ``floor_density`` (m^-3) and Doppler sigma
    ``sigma_vr`` (m/s); resampling when ``N_eff < threshold N``; weights by the kernel ``backend``; the
    two-mode (jump-Markov) prediction of :func:`predict_jump_markov` (``switch_on = 0``: plain CV);
    ``regularisation`` x the optimal kernel bandwidth jitters the resampled particles (:func:`regularise`)."""
    if regularisation < 0.0:
        raise InputError(f"tbd-pf: need regularisation >= 0, got {regularisation}")
    if backend not in BACKENDS:
        raise InputError(f"tbd-pf: unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if floor_density < 0 or particles < 1 or not 0 <= threshold <= 1 or sigma_vr <= 0:
        raise InputError(f"tbd-pf: need particles >= 1, 0 <= threshold <= 1, floor_density >= 0, sigma_vr > 0; "
                         f"got {particles}, {threshold}, {floor_density}, {sigma_vr}")
    _check_modes("tbd-pf", switch_on, switch_off, manoeuvre_scale)
    return FilterSpec(
        name=name or "tbd-pf",
        summary=(f"TBD particle filter (paper 000, method C): weights from every gated detection, N={particles}, "
                 f"floor {floor_density:g} m^-3, two-mode CV (x{manoeuvre_scale:g} noise, on {switch_on:g}, "
                 f"off {switch_off:g}), regularised resampling ({regularisation:g} h_opt)"),
        init=partial(init, particles=particles),
        predict=_predict(switch_on, switch_off, manoeuvre_scale),
        update=partial(update, threshold=threshold, floor_density=floor_density, sigma_vr=sigma_vr,
                       backend=backend, regularisation=regularisation),
        estimate=estimate,
        capabilities=frozenset({"stochastic", "multi_measurement", "position_doppler_3d", "manoeuvre_modes"}),
        params={"particles": particles, "threshold": threshold, "floor_density": floor_density, "sigma_vr": sigma_vr,
                "backend": backend, "switch_on": switch_on, "switch_off": switch_off,
                "manoeuvre_scale": manoeuvre_scale, "regularisation": regularisation},
        diagnostics=diagnostics,
        parameters=TBD_PARAMETERS,
        build=make_tbd_pf,
    )


def log_clutter_density(scan: Scan, present: np.ndarray) -> np.ndarray | None:
    """``log b`` of each item's measurement from the scan's declared clutter density (``None`` when the scan
    declares none): ``(B,)``, ``-inf`` where the density is 0 (a measurement that is surely the target's)."""
    if scan.clutter_density is None:
        return None
    row = np.argmax(scan.valid, axis=1) if scan.z.shape[1] else np.zeros(scan.batch, dtype=int)
    density = scan.clutter_density[np.arange(scan.batch), row] if scan.z.shape[1] else np.zeros(scan.batch)
    density = np.where(present, density, 0.0)
    if np.any(~np.isfinite(density) | (density < 0)):
        raise InputError("a scan's clutter_density must be finite and >= 0 at every valid measurement")
    with np.errstate(divide="ignore"):
        return np.log(density)


def sir_update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator, *,
               threshold: float, regularisation: float = 0.0) -> ParticleState:
    """The bootstrap update (``log w_i += log N(z; h(x_i), R)``, :mod:`workbench.particle_core`), with
    the particles' modes carried through resampling.

    Where the scan declares the clutter density ``b`` at the measurement (per unit measurement volume) the
    likelihood is the mixture of a target-originated and a clutter-originated measurement, ``b + N(z; h(x_i), R)``:
    a measurement that no particle explains (clutter) pulls the cloud no more than ``b`` allows."""
    z, present = single_measurement(scan, "sir-jm")
    if not present.any():
        return state
    cloud = state.cloud
    m = z.shape[-1]
    if scan.cov is not None:
        # log N(z; h(x_i), R_b) with the measurement's own covariance
        log_lik = log_likelihood_cov(z, cloud.particles, model, measurement_covariance(scan, model, present))
    else:
        # log N(z; h(x_i), R) = -|L^-1 (z - h)|^2 / 2 - (m log 2 pi + log |R|) / 2
        log_det = np.linalg.slogdet(np.asarray(model.R, dtype=float))[1]
        log_lik = sir_log_likelihood(z, cloud.particles, model) - 0.5 * (m * np.log(2.0 * np.pi) + log_det)
    log_b = log_clutter_density(scan, present)
    if log_b is not None:
        # log(b + N(z; h(x_i), R))
        log_lik = np.logaddexp(log_b[:, None], log_lik)
    log_w = log_lik + cloud.log_weights
    dead = present & ~np.isfinite(np.max(log_w, axis=1))
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights)
    log_w = keep_where(present, log_w, cloud.log_weights)
    return _finish(state, log_w, present, threshold, dead, rng, regularisation)


SIR_JM_PARAMETERS = (
    Param("particles", 600, "particles per run", "int", minimum=1),
    Param("threshold", 0.5, "resample where N_eff < threshold N", minimum=0.0, maximum=1.0),
    Param("switch_on", SWITCH_ON, "P(quiet -> manoeuvre) per scan of the two-mode prediction (0: plain CV)",
          minimum=0.0, maximum=1.0),
    Param("switch_off", SWITCH_OFF, "P(manoeuvre -> quiet) per scan", above=0.0, maximum=1.0),
    Param("manoeuvre_scale", MANOEUVRE_SCALE, "factor on the process-noise sigma in the manoeuvre mode", minimum=1.0),
    Param("regularisation", 0.0, "post-regularisation bandwidth after resampling, x h_opt (0: off)", minimum=0.0),
)


def make_sir_jm(particles: int = 600, threshold: float = 0.5, switch_on: float = SWITCH_ON,
                switch_off: float = SWITCH_OFF, manoeuvre_scale: float = MANOEUVRE_SCALE,
                name: str | None = None, regularisation: float = 0.0) -> FilterSpec:
    """Method B: the bootstrap filter with the same two-mode prediction as method C; where the scan declares a
    clutter density the likelihood is the clutter mixture (:func:`sir_update`), ``regularisation > 0`` jitters
    the resampled particles (:func:`regularise`; off by default: it widened B's cloud in the low-SNR segment)."""
    if particles < 1 or not 0 <= threshold <= 1 or regularisation < 0:
        raise InputError(f"sir-jm: need particles >= 1, 0 <= threshold <= 1 and regularisation >= 0, got "
                         f"{particles}, {threshold}, {regularisation}")
    _check_modes("sir-jm", switch_on, switch_off, manoeuvre_scale)
    return FilterSpec(
        name=name or "sir-jm",
        summary=(f"Bootstrap PF with a two-mode CV prediction (x{manoeuvre_scale:g} noise, on {switch_on:g}, off "
                 f"{switch_off:g}), N={particles}"),
        init=partial(init, particles=particles),
        predict=_predict(switch_on, switch_off, manoeuvre_scale),
        update=partial(sir_update, threshold=threshold, regularisation=regularisation),
        estimate=estimate,
        capabilities=frozenset({"stochastic", "detection_covariance", "clutter_density", "manoeuvre_modes"}),
        params={"particles": particles, "threshold": threshold, "switch_on": switch_on, "switch_off": switch_off,
                "manoeuvre_scale": manoeuvre_scale, "regularisation": regularisation},
        diagnostics=diagnostics,
        parameters=SIR_JM_PARAMETERS,
        build=make_sir_jm,
    )


@dataclass(frozen=True)
class AdaptiveGaussian:
    """An EKF state with a manoeuvre flag per item: ``gaussian`` (B, n), ``manoeuvre (B,)`` bool."""

    gaussian: Gaussian
    manoeuvre: np.ndarray


def nis_init(prior: Gaussian, rng=None) -> AdaptiveGaussian:
    return AdaptiveGaussian(prior, np.zeros(prior.batch, dtype=bool))


def nis_predict(state: AdaptiveGaussian, motion: MotionModel, rng=None, *, scale: float) -> AdaptiveGaussian:
    """``x- = F x``, ``P- = F P F^T + q_b W`` with ``q_b = scale^2`` for an item in manoeuvre, else 1."""
    g = state.gaussian
    q = np.where(state.manoeuvre, scale**2, 1.0)
    mean = g.mean @ motion.F.T
    # P- = F P F^T + q_b W
    cov = symmetrise(motion.F @ g.cov @ motion.F.T + q[:, None, None] * motion.Q)
    return AdaptiveGaussian(Gaussian(mean, cov), state.manoeuvre)


def nis_update(state: AdaptiveGaussian, scan: Scan, model: MeasurementModel, rng=None, *,
               nis_threshold: float) -> AdaptiveGaussian:
    """The EKF update; an item whose normalised innovation ``nu^T S^-1 nu`` exceeds ``nis_threshold``
    switches to the manoeuvre noise for the next prediction, and back when it falls below (an item
    without a measurement keeps its flag).

    Where the scan declares the clutter density ``b`` at the measurement (per unit measurement volume) the
    update is the probabilistic data association filter's for one validated measurement (Bar-Shalom and Tse):
    the measurement is clutter with probability ``beta_0 = b / (b + N(nu; 0, S))``, and::

        x = x- + (1 - beta_0) K nu,   P = beta_0 P- + (1 - beta_0) P+ + beta_0 (1 - beta_0) K nu nu^T K^T

    Only a measurement taken as the target's (``beta_0 < 1/2``) can switch on the manoeuvre noise."""
    z, present = single_measurement(scan, "ekf-nis")
    if not present.any():
        return state
    g = state.gaussian
    H = model.jacobian(g.mean)
    R = measurement_covariance(scan, model, present)
    # S = H P- H^T + R;  NIS = nu^T S^-1 nu
    S = symmetrise(H @ g.cov @ np.swapaxes(H, -1, -2) + R)
    nu = model.residual(z, model.h(g.mean))
    nis = np.einsum("bi,bi->b", nu, psd_solve(S, nu[..., None])[..., 0])
    updated = ekf_update(g, scan, model)
    log_b = log_clutter_density(scan, present)
    if log_b is None:
        flag = np.where(present, nis > nis_threshold, state.manoeuvre)
        return AdaptiveGaussian(updated, flag)
    m = nu.shape[-1]
    # log N(nu; 0, S)
    log_n = -0.5 * (nis + m * np.log(2.0 * np.pi) + np.linalg.slogdet(S)[1])
    # beta_0 = b / (b + N(nu; 0, S))
    beta0 = np.exp(log_b - np.logaddexp(log_b, log_n))
    beta0 = np.where(present, beta0, 1.0)
    shift = updated.mean - g.mean  # K nu (zero where no measurement)
    # x = x- + (1 - beta_0) K nu
    mean = g.mean + (1.0 - beta0)[:, None] * shift
    # P = beta_0 P- + (1 - beta_0) P+ + beta_0 (1 - beta_0) K nu nu^T K^T
    b = beta0[:, None, None]
    cov = symmetrise(b * g.cov + (1.0 - b) * updated.cov + b * (1.0 - b) * shift[:, :, None] * shift[:, None, :])
    flag = np.where(present, (nis > nis_threshold) & (beta0 < 0.5), state.manoeuvre)
    return AdaptiveGaussian(Gaussian(mean, cov), flag)


def nis_estimate(state: AdaptiveGaussian) -> Gaussian:
    return state.gaussian


EKF_NIS_PARAMETERS = (
    Param("manoeuvre_scale", MANOEUVRE_SCALE, "factor on the process-noise sigma after a manoeuvre is detected",
          minimum=1.0),
    Param("nis_threshold", float(chi2.ppf(0.99, 4)), "NIS above which the next prediction uses the manoeuvre noise "
          "(default: the chi-square 99 % point, 4 dof)", above=0.0),
)


def make_ekf_nis(manoeuvre_scale: float = MANOEUVRE_SCALE, nis_threshold: float = float(chi2.ppf(0.99, 4)),
                 name: str | None = None) -> FilterSpec:
    """Method A: the EKF with the two-level noise switched by the NIS of the pseudo-measurement (the
    Gaussian filter's counterpart of the two-mode particle prediction: quiet ``W``, manoeuvre
    ``scale^2 W``; Bar-Shalom, Li and Kirubarajan's noise-level switching by manoeuvre detection); where the
    scan declares a clutter density the update is the PDAF's for one validated measurement (:func:`nis_update`)."""
    if manoeuvre_scale < 1.0 or nis_threshold <= 0.0:
        raise InputError(f"ekf-nis: need manoeuvre_scale >= 1 and nis_threshold > 0, got "
                         f"{manoeuvre_scale}, {nis_threshold}")
    return FilterSpec(
        name=name or "ekf-nis",
        summary=f"EKF with NIS-switched process noise (x{manoeuvre_scale:g} above NIS {nis_threshold:.2f})",
        init=nis_init,
        predict=partial(nis_predict, scale=manoeuvre_scale),
        update=partial(nis_update, nis_threshold=nis_threshold),
        estimate=nis_estimate,
        capabilities=frozenset({"gaussian", "needs_jacobian", "detection_covariance", "clutter_density",
                                "manoeuvre_modes"}),
        params={"manoeuvre_scale": manoeuvre_scale, "nis_threshold": nis_threshold},
        parameters=EKF_NIS_PARAMETERS,
        build=make_ekf_nis,
    )


@hookimpl
def workbench_filters():
    return [make_tbd_pf(), make_tbd_pf(floor_density=0.0, name="tbd-pf-eps0"), make_sir_jm(), make_ekf_nis()]
