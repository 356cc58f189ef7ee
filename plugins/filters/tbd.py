"""Method C of paper 000: a particle filter weighted directly by every gated detection (eqs 12-15).

For particle ``i`` (state ``s_i``) and gated detection ``m`` (position ``p_m``, radial velocity
``vr_m``, measured SNR ``snr_m``)::

    w_{m,i} = P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr(s_i), sigma_vr^2)      (13)
    w_i     = sum_m w_{m,i}                                                              (14)
    log w_k,i = log w_{k-1,i} + log(eps + w_i), normalised over i                        (15, SIS)

``sigma_p,m`` follows the detection's own SNR (:func:`workbench.radar.position_sigma`).  The floor
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
``N_eff < threshold * N`` (eq 16).  The state, prediction and estimate are those of the bootstrap
filter (:mod:`workbench_filters.particle`).

The update takes the whole gated scan: ``scan.z = [x, y, z, vr]`` (B, M, 4), ``scan.snr`` (dB).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where
from workbench.kernels.tbd_weights import BACKENDS, tbd_log_weight_sums
from workbench.models import MeasurementModel
from workbench.radar import RadarParameters, log_detection_probability, from_db, position_sigma, radial_velocity
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where
from workbench.specs import FilterSpec
from workbench.types import InputError, Particles, Scan
from workbench_filters.particle import ParticleState, diagnostics, estimate, init, predict


def _radar(model: MeasurementModel) -> RadarParameters:
    known = RadarParameters().as_dict()
    return RadarParameters(**{k: model.params[k] for k in known if k in model.params})


def log_likelihood(particles: np.ndarray, scan: Scan, model: MeasurementModel, sigma_vr: float,
                   floor_density: float, backend: str = "auto", arch: str = "cpu") -> np.ndarray:
    """``log(eps + sum_m w_{m,i})`` for particles ``(B, N, 6)`` and a gated scan -> ``(B, N)``.

    ``-inf`` for items without a valid detection.
    """
    if scan.snr is None:
        raise InputError("tbd-pf needs the measured SNR of every detection (scan.snr, dB)")
    if not (np.all(np.isfinite(scan.z[scan.valid])) and np.all(np.isfinite(scan.snr[scan.valid]))):
        raise InputError("tbd-pf: a valid detection holds a non-finite value (NaN or inf) in z or snr")
    radar = _radar(model)
    z = scan.z
    points = np.concatenate([particles[..., :3], radial_velocity(particles)[..., None]], axis=-1)
    snr_db = np.where(scan.valid, scan.snr, 0.0)
    log_pd = log_detection_probability(from_db(snr_db), radar.pfa)
    sigma_p = position_sigma(snr_db, np.linalg.norm(z[..., :3], axis=-1), radar)
    # log sum_m P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr_i, sigma_vr^2)     (13), (14)
    log_sum = tbd_log_weight_sums(points, z, scan.valid, log_pd, sigma_p, sigma_vr, backend=backend, arch=arch)
    if floor_density <= 0.0:
        return log_sum
    # eps = floor_density * max_m P_D(snr_m) N(0; 0, sigma_vr^2)
    top = np.max(np.where(scan.valid, log_pd, -np.inf), axis=1, keepdims=True)
    log_eps = np.log(floor_density) + top - 0.5 * np.log(2.0 * np.pi * sigma_vr**2)
    # log(eps + sum_m w_{m,i})
    return np.where(np.isfinite(log_eps), np.logaddexp(log_eps, log_sum), -np.inf)


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator, *,
           threshold: float, floor_density: float, sigma_vr: float, backend: str, arch: str = "cpu") -> ParticleState:
    present = scan.valid.any(axis=1)
    if not present.any():
        return state
    cloud = state.cloud
    log_lik = log_likelihood(cloud.particles, scan, model, sigma_vr, floor_density, backend, arch)
    log_w = cloud.log_weights + log_lik
    dead = present & ~np.isfinite(np.max(log_w, axis=1))
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights)
    log_w = keep_where(present, log_w, cloud.log_weights)
    n = log_w.shape[1]
    resample = present & (effective_sample_size(log_w) < threshold * n)
    x, log_w = resample_where(resample, cloud.particles, log_w, rng)
    return ParticleState(Particles(x, log_w), state.resamples + int(resample.sum()),
                         state.underflows + int(dead.sum()))


def make_tbd_pf(particles: int = 600, threshold: float = 0.5, floor_density: float = 5e-11, sigma_vr: float = 15.0,
                backend: str = "auto", arch: str = "cpu", name: str | None = None) -> FilterSpec:
    """Method C with ``particles`` particles, floor density ``floor_density`` (m^-3) and Doppler sigma
    ``sigma_vr`` (m/s); resampling when ``N_eff < threshold N``; weights by the kernel ``backend``."""
    if backend not in BACKENDS:
        raise InputError(f"tbd-pf: unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if floor_density < 0 or particles < 1 or not 0 <= threshold <= 1 or sigma_vr <= 0:
        raise InputError(f"tbd-pf: need particles >= 1, 0 <= threshold <= 1, floor_density >= 0, sigma_vr > 0; "
                         f"got {particles}, {threshold}, {floor_density}, {sigma_vr}")
    return FilterSpec(
        name=name or "tbd-pf",
        summary=(f"TBD particle filter (paper 000, method C): weights from every gated detection, N={particles}, "
                 f"floor {floor_density:g} m^-3"),
        init=partial(init, particles=particles),
        predict=predict,
        update=partial(update, threshold=threshold, floor_density=floor_density, sigma_vr=sigma_vr,
                       backend=backend, arch=arch),
        estimate=estimate,
        capabilities=frozenset({"stochastic", "multi_measurement", "position_doppler_3d"}),
        params={"particles": particles, "threshold": threshold, "floor_density": floor_density, "sigma_vr": sigma_vr,
                "backend": backend},
        diagnostics=diagnostics,
    )


@hookimpl
def workbench_filters():
    return [make_tbd_pf(), make_tbd_pf(floor_density=0.0, name="tbd-pf-eps0")]
