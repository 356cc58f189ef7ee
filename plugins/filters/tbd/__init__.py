"""A track-before-detect particle filter weighted directly by every gated detection, and its pseudo-measurement
companions (the methods of the L-band TBD study; docs/paper000.md).

For particle ``i`` (state ``s_i``) and gated detection ``m`` (position ``p_m``, radial velocity
``vr_m``, measured SNR ``snr_m``)::

    w_{m,i} = P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr(s_i), sigma_vr^2)      (13)
    w_i     = sum_m w_{m,i}                                                              (14)
    log w_k,i = log w_{k-1,i} + log(eps_i + w_i), normalised over i                      (15, SIS)

``p_i, vr(s_i)`` is the sensor's ``h(s_i)`` (a model in the ``position-doppler-3d`` frame), and ``P_D`` and
``sigma_p,m`` follow the detection's own SNR as the sensor declares them (``model.detection``, a
:class:`workbench.models.DetectionModel`).

The floor ``eps_i`` is the "target missed, every gated detection is clutter" alternative (parameter ``floor``):

- ``"amplitude"`` (default): the clutter intensity the scan declares at its detections (``Scan.clutter_density``,
  per unit ``(x, y, z, vr)`` volume), scaled like the detections' own terms and by how target-like the strongest
  detection is::

      eps = kappa lambda max_m P_D(snr_m) (1 - P_D^T(p_hat)) / max(1, l)
      l   = f_T(snr_* | SNR(p_hat)) / f_C(snr_*)

  ``snr_*`` is the strongest gated detection, ``p_hat`` the cloud's predicted (weighted mean) position,
  ``SNR(p_hat)`` the nominal SNR of the sensor's design target there (``detection.nominal_snr_db``), ``f_T`` the
  declared law of a target detection's measured SNR (``detection.log_snr_density``) and ``f_C`` that of a clutter
  detection (``detection.clutter_log_snr_density``): a strong detection that clutter almost never makes lowers the
  floor, so a cloud that lags a sharp high-SNR detection still follows it.  ``P_D^T`` is the sensor's detection
  probability of its design target (``detection.log_detection``): the "all clutter" alternative needs the target
  to have been missed.  ``kappa = floor_scale``.  Each declaration the model or the scan lacks drops its factor (no
  clutter density: no floor).  With ``missed_detection = "particle"`` (an ablation) the factor is taken at every
  particle, ``1 - P_D^T(s_i)``, and also weights the particles of a scan with an empty gate; the filter does not
  know the gate, so a target detection that fell outside it counts as a miss and this factor drives the cloud
  towards lower SNR (docs/paper000.md).
- ``"flat"`` (the previous floor, an ablation): ``eps = floor_density max_m P_D(snr_m) N(0; 0, sigma_vr^2)``, a
  spatial density (m^-3) in place of the position kernel; an empty gate leaves the weights as they are.
- ``"none"``: ``eps = 0`` (the literal eqs 13-15).

Everything is in the log domain; the sum over ``m`` is the compiled kernel
:func:`workbench_filters.tbd.tbd_weights.tbd_log_weight_sums` (streaming, no (B, N, M) array) and every floor term is
``O(B N + M)``.  An item whose weights all underflow keeps its previous weights (counted).  Systematic resampling
when ``N_eff < threshold * N`` (eq 16), followed by post-regularisation (:func:`regularise`, Musso, Oudjane and
Le Gland's regularised particle filter): each resampled particle is jittered by ``h D e``, ``D D^T`` the cloud's
weighted covariance before resampling, ``h = regularisation x h_opt`` (:func:`regularisation_bandwidth`), so that
the copies of the few particles that keep up with a sharp manoeuvre become distinct particles.  The state,
prediction and estimate are those of the bootstrap filter (:mod:`workbench.particle_core`).  Where the backend runs
Numba, the two-mode prediction, the floor's ``logaddexp``, the systematic resampling's draws and gathers
(:func:`resample_rows`) and the regularisation's jitter run compiled (:mod:`.tbd_pf_numba`), each held bit for bit
to the NumPy lines it replaces, random draws included.

``sigma_vr`` (default 15 m/s) is the width of the Doppler kernel.  The sensor's radial-velocity noise is 2 m/s;
the wider kernel is a tempering device (``N(vr; 15^2) ∝ N(vr; 2^2)^(4/225)``) that keeps a cloud of a few hundred
particles from collapsing onto the few that match the Doppler (docs/paper000.md shows the collapse).

The update takes the whole gated scan: ``scan.z = [x, y, z, vr]`` (B, M, 4), ``scan.snr`` (dB).

Manoeuvres (the same two-level process noise for every method; docs/paper000.md).  The particle filters predict
with a jump-Markov (two-mode) CV model, :func:`predict_jump_markov`: each particle carries a mode, quiet (the
motion model's ``W``) or manoeuvre (``manoeuvre_scale^2 W``), switching quiet -> manoeuvre with probability
``switch_on`` and back with ``switch_off`` per scan; the mode rides along through resampling.  Filters registered
here:

- ``tbd-pf``: the direct-weight filter above, with the two-mode prediction;
- ``sir-jm``: the bootstrap filter of :mod:`workbench.particle_core` (its likelihood), with the same two-mode
  prediction;
- ``ekf-nis``: the EKF (:func:`workbench.kalman_core.ekf_update`) whose process noise switches to
  ``manoeuvre_scale^2 W`` for the next prediction when the normalised innovation squared of the measurement
  exceeds the chi-square 99 % point (4 dof), the Gaussian filter's counterpart of the two modes (noise-level
  switching by manoeuvre detection).

Clutter (``sir-jm``, ``ekf-nis``): where the scan declares the clutter density at the measurement
(``Scan.clutter_density = b`` per unit measurement volume), the measurement may be clutter: the particle filter's
likelihood is the mixture ``b + N(z; h(x_i), R)``; the EKF's update is the PDAF's for one validated measurement,
``beta_0 = b / (b + N(nu; 0, S))``.  ``R`` is the measurement's own covariance where the scan carries one
(``Scan.cov``), else the model's.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.stats import chi2

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.kalman_core import ekf_update, linearised, measurement_covariance
from workbench.kernels.backend import BACKENDS
from workbench.linalg import psd_solve, safe_cholesky, symmetrise
from workbench.models import MeasurementModel, MotionModel
from workbench.params import Param
from workbench.particle_core import (ParticleState, combine_columns, compiled, component_major, diagnostics, estimate,
                                     init, log_likelihood_cov, need_rng, noise_columns, predict, propagate_f,
                                     propagation_plan)
from workbench.particle_core import log_likelihood as sir_log_likelihood
from workbench.resampling import effective_sample_size, normalise_log_weights, resample_where, systematic_weights
from workbench.specs import BenchmarkSpec, FilterSpec, join_batch, take_batch
from workbench.types import Gaussian, InputError, Particles, Scan

from .tbd_weights import PRECISIONS, tbd_log_weight_sums

#: two-mode process noise [U, chosen on tuning seeds, docs/paper000.md]: P(quiet -> manoeuvre), P(manoeuvre ->
#: quiet) per scan and the manoeuvre mode's factor on sigma_a
SWITCH_ON, SWITCH_OFF, MANOEUVRE_SCALE = 0.05, 0.2, 4.0
#: post-regularisation of tbd-pf after resampling, as a fraction of the optimal kernel bandwidth
REGULARISATION = 0.5
#: the floors of tbd-pf
FLOORS = ("amplitude", "flat", "none")
#: kappa of the amplitude-aware floor: its level relative to the declared clutter intensity [chosen on tuning seeds]
FLOOR_SCALE = 16.0


def _detection(model: MeasurementModel):
    if model.detection is None or model.frame != "position-doppler-3d":
        raise InputError(f"tbd-pf needs a measurement model in the position-doppler-3d frame that declares how its "
                         f"detections' quality follows their SNR (model.detection); {model.name!r} is in frame "
                         f"{model.frame or 'undeclared'!r} with detection {model.detection!r:.40}")
    return model.detection


def _centre(particles: np.ndarray, log_weights: np.ndarray) -> np.ndarray:
    """The cloud's weighted mean position, ``(B, 3)``."""
    return np.einsum("bn,bnk->bk", np.exp(log_weights), particles[..., :3])


def log_missed(model: MeasurementModel, particles: np.ndarray, log_weights: np.ndarray | None = None, *,
               centre: np.ndarray | None = None, nominal: np.ndarray | None = None) -> np.ndarray | None:
    """``log(1 - P_D^T)``: the log probability that the sensor misses its design target, at the cloud's predicted
    position ``(B, 1)`` (``log_weights`` given) or at every particle ``(B, N)``; ``None`` when the model declares no
    design target (``detection.nominal_snr_db``, ``detection.log_detection``).  ``centre``: the cloud's weighted
    mean position :func:`_centre` of ``particles`` and ``log_weights`` where the caller has it already, and
    ``nominal (B,)`` the nominal SNR there (``detection.nominal_snr_db(centre)``)."""
    detection = _detection(model)
    if detection.nominal_snr_db is None or detection.log_detection is None:
        return None
    if log_weights is None:
        snr = detection.nominal_snr_db(particles[..., :3])
    elif nominal is not None:
        snr = nominal[:, None]
    else:
        snr = detection.nominal_snr_db((_centre(particles, log_weights) if centre is None else centre)[:, None, :])
    log_pd = np.minimum(detection.log_detection(snr), 0.0)
    # log(1 - P_D) = log(-expm1(log P_D))
    with np.errstate(divide="ignore"):
        return np.log(-np.expm1(log_pd))


def log_amplitude_ratio(model: MeasurementModel, snr_db: np.ndarray, position: np.ndarray, *,
                        nominal: np.ndarray | None = None) -> np.ndarray:
    """``log l = log f_T(snr | SNR(position)) - log f_C(snr)``: how much more likely a detection of measured SNR
    ``snr_db`` is the design target's (nominal SNR at ``position``) than clutter's, from the model's declared laws;
    0 where the model lacks one of them.  ``nominal``: ``detection.nominal_snr_db(position)`` where the caller has
    it.  Shapes: ``snr_db (B,)``, ``position (B, 3)`` -> ``(B,)``."""
    detection = _detection(model)
    snr_db = np.asarray(snr_db, dtype=float)
    if (detection.nominal_snr_db is None or detection.log_snr_density is None
            or detection.clutter_log_snr_density is None):
        return np.zeros(snr_db.shape)
    if nominal is None:
        nominal = detection.nominal_snr_db(position)
    with np.errstate(invalid="ignore"):
        out = detection.log_snr_density(snr_db, nominal) - detection.clutter_log_snr_density(snr_db)
    out = np.asarray(out, dtype=float)
    return np.where(np.isnan(out), 0.0, out)  # NaN (two undeclared laws' -inf - -inf) -> 0, infinities kept


def log_floor(particles: np.ndarray, log_weights: np.ndarray, scan: Scan, model: MeasurementModel,
              log_pd: np.ndarray, *, floor: str, floor_density: float = 0.0, floor_scale: float = 1.0,
              sigma_vr: float = 15.0, missed: np.ndarray | None = None,
              centre: np.ndarray | None = None, nominal: np.ndarray | None = None) -> np.ndarray:
    """``log eps`` of the floor ``floor`` (see the module docstring), ``(B, 1)`` or ``(B, N)``; ``-inf`` for an
    item without a valid detection.  ``centre``: :func:`_centre` of ``particles`` and ``log_weights`` where the
    caller has it already, ``nominal (B,)`` the design target's nominal SNR there (``detection.nominal_snr_db``).

    Shapes
    ------
    particles (B, N, n); log_weights (B, N) (the predicted cloud's); log_pd (B, M) = log P_D(snr_m) of every
    detection; missed (B, N) = :func:`log_missed` or None
    """
    B = scan.batch
    top = np.max(np.where(scan.valid, log_pd, -np.inf), axis=1, initial=-np.inf)[:, None]  # log max_m P_D(snr_m)
    if floor == "none":
        return np.full((B, 1), -np.inf)
    if floor == "flat":
        # eps = floor_density max_m P_D(snr_m) N(0; 0, sigma_vr^2)
        with np.errstate(divide="ignore"):
            return np.log(floor_density) + top - 0.5 * np.log(2.0 * np.pi * sigma_vr**2)
    if floor != "amplitude":
        raise InputError(f"tbd-pf: unknown floor {floor!r}; expected one of {', '.join(FLOORS)}")
    if scan.clutter_density is None or scan.z.shape[1] == 0:
        return np.full((B, 1), -np.inf)  # no clutter declared: nothing but the target
    snr = np.where(scan.valid, scan.snr, -np.inf)
    star = np.argmax(snr, axis=1)  # the strongest gated detection
    rows = np.arange(B)
    density = np.where(scan.valid[rows, star], scan.clutter_density[rows, star], 0.0)
    if np.any(~np.isfinite(density) | (density < 0)):
        raise InputError("a scan's clutter_density must be finite and >= 0 at every valid detection")
    # the cloud's predicted position: the weighted mean of the predicted particles
    if centre is None:
        centre = _centre(particles, log_weights)
    log_l = log_amplitude_ratio(model, np.where(scan.valid[rows, star], snr[rows, star], 0.0), centre,
                                nominal=nominal)
    with np.errstate(divide="ignore"):
        # log eps = log kappa + log lambda + log max_m P_D(snr_m) - log max(1, l) [+ log(1 - P_D^T(s_i))]
        out = np.log(floor_scale) + np.log(density)[:, None] + top - np.maximum(log_l, 0.0)[:, None]
    return out if missed is None else out + missed


def log_likelihood(particles: np.ndarray, scan: Scan, model: MeasurementModel, sigma_vr: float,
                   floor_density: float = 0.0, backend: str = "auto", *, floor: str = "flat",
                   floor_scale: float = 1.0, log_weights: np.ndarray | None = None,
                   missed: np.ndarray | None = None, precision: str = "float64",
                   centre: np.ndarray | None = None, present: np.ndarray | None = None,
                   nominal: np.ndarray | None = None) -> np.ndarray:
    """``log(eps_i + sum_m w_{m,i})`` for particles ``(B, N, 6)`` and a gated scan -> ``(B, N)``.

    ``-inf`` for items without a valid detection.  ``log_weights (B, N)`` are the predicted cloud's (uniform when
    not given), ``missed`` is :func:`log_missed` (the amplitude floor's ``1 - P_D^T`` factor), ``centre`` the
    cloud's weighted mean position (:func:`_centre`) where the caller has it, ``present (B,)`` is
    ``scan.valid.any(axis=1)`` and ``nominal (B,)`` the design target's nominal SNR at ``centre``
    (``detection.nominal_snr_db(centre)``) where the caller has them.  Where ``backend`` runs Numba the
    last step (``logaddexp`` of the floor and the sum) is compiled (:func:`.tbd_pf_numba.log_add_floor`, the same
    numbers as the NumPy lines it replaces).
    """
    if scan.snr is None:
        raise InputError("tbd-pf needs the measured SNR of every detection (scan.snr, dB)")
    valid = scan.valid
    snr_db = np.where(valid, scan.snr, 0.0)
    if not (np.isfinite(scan.z[valid]).all() and np.isfinite(snr_db).all()):
        raise InputError("tbd-pf: a valid detection holds a non-finite value (NaN or inf) in z or snr")
    detection = _detection(model)
    z = scan.z
    points = model.h(particles)  # [p_i, vr(s_i)]
    log_pd = np.full(snr_db.shape, -np.inf)
    log_pd[valid] = detection.log_pd(snr_db[valid])
    sigma_p = detection.position_sigma(snr_db, np.linalg.norm(z[..., :3], axis=-1))
    # log sum_m P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I_3) N(vr_m; vr_i, sigma_vr^2)     (13), (14)
    log_sum = tbd_log_weight_sums(points, z, valid, np.where(valid, log_pd, 0.0), sigma_p, sigma_vr,
                                  backend=backend, precision=precision)
    if floor == "none":
        return log_sum
    if log_weights is None:
        log_weights = np.full(particles.shape[:2], -np.log(particles.shape[1]))
    log_eps = log_floor(particles, log_weights, scan, model, log_pd, floor=floor, floor_density=floor_density,
                        floor_scale=floor_scale, sigma_vr=sigma_vr, missed=missed, centre=centre, nominal=nominal)
    if present is None:
        present = valid.any(axis=1)
    if compiled(backend):
        from . import tbd_pf_numba

        # the lines below in one compiled pass
        return tbd_pf_numba.log_add_floor(np.asarray(log_eps, dtype=float), log_sum, present,
                                          np.empty(log_sum.shape))
    present = present[:, None]
    # log(eps + sum_m w_{m,i})  (a NaN particle, e.g. from a NaN prior, stays NaN: it reaches the estimate)
    with np.errstate(invalid="ignore"):
        return np.where(present, np.logaddexp(log_eps, log_sum), -np.inf)


@dataclass(frozen=True)
class ModeState(ParticleState):
    """A particle cloud with a manoeuvre mode per particle (0 quiet, 1 manoeuvre): ``mode (B, N)``."""

    mode: np.ndarray | None = None

    #: The batch-first fields; ``mode`` is ``None`` until the first jump-Markov predict (all quiet).
    batch_fields = ("cloud", "mode")


def _modes(state: ParticleState) -> np.ndarray:
    mode = getattr(state, "mode", None)
    return np.zeros(state.cloud.log_weights.shape) if mode is None else mode


def join_modes(states) -> ParticleState:
    """The filter-state contract's join for the two-mode filters, whose states are a :class:`ParticleState` (after
    ``init``: every particle quiet) or a :class:`ModeState`: all of one class are joined field by field
    (:func:`workbench.specs.join_batch`); a mix is joined as :class:`ModeState`, a state without modes giving its
    particles the quiet mode (0), exactly what :func:`_modes` reads for it."""
    states = list(states)
    if len({type(s) for s in states}) > 1 or any(isinstance(s, ModeState) and s.mode is None for s in states):
        states = [ModeState(s.cloud, s.resamples, s.underflows, _modes(s)) for s in states]
    return join_batch(states)


def predict_jump_markov(state: ParticleState, motion: MotionModel, rng: np.random.Generator, *, switch_on: float,
                        switch_off: float, scale: float, backend: str = "auto") -> ModeState:
    """Jump-Markov (two-mode) prediction: each particle carries a mode, quiet (noise ``W``) or manoeuvre
    (noise ``scale^2 W``), that switches with ``P(quiet -> manoeuvre) = switch_on`` and
    ``P(manoeuvre -> quiet) = switch_off`` before the particle moves::

        m_i <- Markov(m_i),   x_i <- F x_i + (scale if m_i else 1) W^(1/2) e_i

    (``f(x_i)`` in place of ``F x_i`` for a motion model that overrides ``f``, the same draws.)
    A particle that the detections select during a manoeuvre keeps a large noise for its
    descendants (mean sojourn ``1 / switch_off`` scans), so the cloud can follow a sustained turn.

    The draws are ``u = rng.random((B, N))``, then ``e = rng.standard_normal((B, N, k))`` (``k`` noise columns).
    Where ``backend`` runs Numba (:func:`workbench.particle_core.compiled`) and ``rng`` is a
    ``numpy.random.Generator``, the switches, the draws and the product run in one compiled pass
    (:func:`.tbd_pf_numba.jump_markov`) that gives the particles, modes and generator state of the NumPy lines
    (:func:`predict_jump_markov_numpy`) bit for bit.

    Shapes
    ------
    particles (B, N, n), mode (B, N)
    """
    need_rng(rng, "the two-mode particle prediction")
    if not (compiled(backend) and type(rng) is np.random.Generator):
        return predict_jump_markov_numpy(state, motion, rng, switch_on=switch_on, switch_off=switch_off, scale=scale)
    from . import tbd_pf_numba

    x = state.cloud.particles
    B, N, n = x.shape
    mode = np.ascontiguousarray(_modes(state), dtype=float).reshape(B * N)
    base, A = (x, motion.F) if motion.linear else (propagate_f(x, motion, "the two-mode particle prediction"),
                                                   np.eye(n))
    A = np.ascontiguousarray(A, dtype=float)
    G = np.ascontiguousarray(motion.Q_sqrt, dtype=float)
    rows = base.transpose(2, 0, 1)  # (n, B, N): no copy for a component-major array
    rows = np.ascontiguousarray(rows, dtype=float).reshape(n, B * N)
    out = np.empty((n, B, N))
    new_mode = np.empty((B, N))
    tbd_pf_numba.jump_markov(out.reshape(n, B * N), rows, mode, new_mode.reshape(B * N), rng,
                             float(switch_on), float(switch_off), float(scale),
                             *propagation_plan(A, G))
    return ModeState(Particles.trusted(out.transpose(1, 2, 0), state.cloud.log_weights), state.resamples,
                     state.underflows, new_mode)


def predict_jump_markov_numpy(state: ParticleState, motion: MotionModel, rng: np.random.Generator, *,
                              switch_on: float, switch_off: float, scale: float) -> ModeState:
    """:func:`predict_jump_markov` in NumPy: the reference the compiled pass is held to."""
    x = state.cloud.particles
    B, N, n = x.shape
    mode = _modes(state)
    u = rng.random((B, N))
    # m <- 1 - m with probability switch_off (m = 1) or switch_on (m = 0)
    mode = np.where(u < np.where(mode > 0, switch_off, switch_on), 1.0 - mode, mode)
    g = noise_columns(motion)  # non-zero columns of W^(1/2)
    e = rng.standard_normal((B, N, g.shape[1]))
    e *= np.where(mode > 0, scale, 1.0)[..., None]
    # x_i <- F x_i + s_i W^(1/2) e_i, or f(x_i) + s_i W^(1/2) e_i for a model that overrides f  (small products
    # written out per component, no threaded BLAS call)
    base, A = (x, motion.F) if motion.linear else (propagate_f(x, motion, "the two-mode particle prediction"),
                                                   np.eye(n))
    moved = combine_columns(component_major(B, N, n), np.hstack([A, g]), base, e)
    return ModeState(Particles.trusted(moved, state.cloud.log_weights), state.resamples, state.underflows, mode)


def regularisation_bandwidth(particles: int, dim: int) -> float:
    """Optimal bandwidth of a Gaussian kernel for a ``dim``-dimensional density from ``particles`` samples
    (Musso, Oudjane and Le Gland 2001, the regularised particle filter)::

        h_opt = (4 / (N (n + 2)))^(1 / (n + 4))
    """
    # h_opt = A N^(-1/(n+4)),  A = (4 / (n + 2))^(1/(n+4))
    return float((4.0 / (particles * (dim + 2.0))) ** (1.0 / (dim + 4.0)))


def regularise(x: np.ndarray, cov: np.ndarray, rows: np.ndarray, scale: float, rng: np.random.Generator,
               backend: str = "auto") -> np.ndarray:
    """Post-regularisation of the rows just resampled: ``x_i <- x_i + h D e_i``, ``e_i ~ N(0, I)``.

    ``D D^T = cov`` is the weighted covariance of the cloud before resampling and ``h = scale * h_opt``
    (:func:`regularisation_bandwidth`): the resampled cloud becomes a draw from the kernel-smoothed
    posterior instead of copies of a few particles (sample impoverishment).  ``D`` is one batched Cholesky
    factorisation of the rows' covariances; where ``backend`` runs Numba the jitter is added in one compiled pass
    (:func:`.tbd_pf_numba.add_jitter`, the numbers of the NumPy line) instead of a gather and scatter of the rows, and
    the normals are drawn compiled (:func:`.tbd_pf_numba.normals`, NumPy's numbers) where ``rng`` is a
    ``numpy.random.Generator``.

    Shapes
    ------
    x : (B, N, n) resampled particles; cov : (B, n, n); rows : (B,) bool; returns (B, N, n)
    """
    if scale <= 0.0 or not rows.any():
        return x
    B, N, n = x.shape
    h = scale * regularisation_bandwidth(N, n)
    D, _ = safe_cholesky(cov[rows])
    fast = compiled(backend) and type(rng) is np.random.Generator
    if fast:
        from . import tbd_pf_numba

        e = tbd_pf_numba.normals(rng, (int(rows.sum()), N, n))  # the numbers of the line below
    else:
        e = rng.standard_normal((int(rows.sum()), N, n))
    # D e_i for every resampled particle (one batched product)
    y = e @ np.swapaxes(D, 1, 2)
    if fast:
        out = np.empty_like(x, dtype=float)  # x's memory layout, as x.copy(order="K")
        # x_i <- x_i + h D e_i
        tbd_pf_numba.add_jitter(out.transpose(2, 0, 1), np.asarray(x, dtype=float).transpose(2, 0, 1), y,
                                np.flatnonzero(rows), float(h))
        return out
    out = x.copy(order="K")
    # x_i <- x_i + h D e_i
    out[rows] += h * y
    return out


def weighted_covariance(x: np.ndarray, log_w: np.ndarray) -> np.ndarray:
    """``sum_i w_i (x_i - x_bar)(x_i - x_bar)^T`` of normalised log-weights: ``x (R, N, n)``, ``log_w (R, N)`` ->
    ``(R, n, n)``."""
    w = np.exp(log_w)[..., None]
    mean = np.sum(w * x, axis=1, keepdims=True)
    d = x - mean
    # sum_i w_i d_i d_i^T as one batched product (d^T (w d))
    return symmetrise(np.swapaxes(d, 1, 2) @ (w * d))


def resample_rows(mask: np.ndarray, particles: np.ndarray, log_w: np.ndarray, rng: np.random.Generator,
                  *extra: np.ndarray, backend: str = "auto") -> tuple[np.ndarray, ...]:
    """:func:`workbench.resampling.resample_where` (the same draw, particles, weights and carried arrays, bit for
    bit, in the same memory layout); where ``backend`` runs Numba the steps after the weights' ``exp`` (cumulative
    sum, edges, draws) and the gathers run compiled (:func:`.tbd_pf_numba.systematic_parents`,
    :func:`.tbd_pf_numba.gather_rows`) instead of a dozen small NumPy calls and a gather per component.

    Shapes: ``mask (B,)``; ``particles (B, N, n)``; ``log_w (B, N)``; ``extra`` arrays ``(B, N)``.
    """
    if not compiled(backend) or any(np.ndim(a) != 2 for a in extra) or not mask.any():
        return resample_where(mask, particles, log_w, rng, *extra)
    from . import tbd_pf_numba

    B, N = log_w.shape
    every = bool(mask.all())
    rows = np.arange(B) if every else np.flatnonzero(mask)
    u0 = rng.random((rows.size, 1))  # the draw of resample_where
    w = systematic_weights(log_w if every else log_w[rows])  # the weights systematic_counts draws from
    parents = np.empty((rows.size, N), dtype=np.int64)
    if not tbd_pf_numba.systematic_parents(w, u0[:, 0], parents):
        raise InputError("tbd-pf: a particle weight is not a number (NaN) where the cloud is resampled")
    out = []
    for arr in (particles, *extra):
        new = np.empty_like(arr) if every else arr.copy(order="K")  # resample_where's layouts
        if arr.ndim == 2:
            tbd_pf_numba.gather_rows(arr[None], new[None], rows, parents)
        else:
            tbd_pf_numba.gather_rows(arr.transpose(2, 0, 1), new.transpose(2, 0, 1), rows, parents)
        out.append(new)
    if every:
        log_w = np.full((B, N), -np.log(N))
    else:
        log_w = log_w.copy()
        log_w[rows] = -np.log(N)
    return (out[0], log_w, *out[1:])


def _finish(state: ParticleState, log_w: np.ndarray, present: np.ndarray, threshold: float, dead: np.ndarray,
            rng: np.random.Generator, regularisation: float = 0.0, backend: str = "auto") -> ParticleState:
    """Resample where ``N_eff < threshold N`` (eq 16), carrying the particles' modes along; with
    ``regularisation > 0`` the resampled rows are jittered by :func:`regularise`."""
    cloud = state.cloud
    n = log_w.shape[1]
    resample = present & (effective_sample_size(log_w) < threshold * n)
    cov = None
    if regularisation > 0.0 and resample.any():
        cov = np.zeros(cloud.particles.shape[:1] + cloud.particles.shape[2:] * 2)
        cov[resample] = weighted_covariance(cloud.particles[resample], log_w[resample])
    mode = getattr(state, "mode", None)
    extra = () if mode is None else (mode,)
    x, log_w, *moved = resample_rows(resample, cloud.particles, log_w, rng, *extra, backend=backend)
    if cov is not None:
        x = regularise(x, cov, resample, regularisation, rng, backend)
    cloud = Particles.trusted(x, log_w)
    if mode is None:
        return ParticleState(cloud, state.resamples + int(resample.sum()), state.underflows + int(dead.sum()))
    return ModeState(cloud, state.resamples + int(resample.sum()), state.underflows + int(dead.sum()), moved[0])


def update(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator, *,
           threshold: float, sigma_vr: float, backend: str, floor: str = "amplitude", floor_density: float = 0.0,
           floor_scale: float = FLOOR_SCALE, missed_detection: str = "cloud", regularisation: float = 0.0,
           tempering: int = 1, precision: str = "float64") -> ParticleState:
    """The direct-weight update (eqs 13-15) with the floor ``floor``.

    With the amplitude floor the "every detection is clutter" term carries the missed-detection factor
    ``1 - P_D^T``, at the cloud's predicted position (``missed_detection = "cloud"``: a constant over the cloud, so
    an empty gate leaves the weights as they are) or at every particle (``"particle"``: an empty gate weights the
    particles by ``1 - P_D^T(s_i)``; an ablation: the filter does not know the gate, so a target detection that fell
    outside it counts as a miss and the factor pushes the cloud towards lower SNR, docs/paper000.md).

    ``tempering = K > 1`` is progressive correction (Oudjane and Musso): the likelihood is applied as ``K`` equal
    powers ``L^(1/K)``, each followed by the resampling test and the regularisation, so that a sharp likelihood
    meets a cloud already moved towards it instead of collapsing it at once."""
    for _ in range(int(tempering)):
        state = _update_once(state, scan, model, rng, threshold=threshold, sigma_vr=sigma_vr, backend=backend,
                             floor=floor, floor_density=floor_density, floor_scale=floor_scale,
                             missed_detection=missed_detection, regularisation=regularisation,
                             power=1.0 / int(tempering), precision=precision)
    return state


def _update_once(state: ParticleState, scan: Scan, model: MeasurementModel, rng: np.random.Generator, *,
                 threshold: float, sigma_vr: float, backend: str, floor: str, floor_density: float,
                 floor_scale: float, missed_detection: str, regularisation: float, power: float,
                 precision: str = "float64") -> ParticleState:
    """One (power ``power`` of the) likelihood step of :func:`update`, then resampling and regularisation."""
    present = scan.valid.any(axis=1)
    cloud = state.cloud
    missed = centre = nominal = None
    if floor == "amplitude":
        per_cloud = missed_detection == "cloud"
        # the cloud's predicted position and the design target's nominal SNR there, read by the missed-detection
        # factor and by the floor: computed once
        if per_cloud or scan.clutter_density is not None:
            centre = _centre(cloud.particles, cloud.log_weights)
            detection = _detection(model)
            if detection.nominal_snr_db is not None:
                nominal = detection.nominal_snr_db(centre)
        missed = log_missed(model, cloud.particles, cloud.log_weights if per_cloud else None, centre=centre,
                            nominal=nominal)
    every = bool(present.all())
    touched = present if missed is None or missed.shape[1] == 1 else np.ones_like(present)
    if not touched.any():
        return state
    log_w = cloud.log_weights
    if present.any():
        # log w_i <- log w_i + power log(eps_i + sum_m w_{m,i})
        log_lik = log_likelihood(cloud.particles, scan, model, sigma_vr, floor_density, backend, floor=floor,
                                 floor_scale=floor_scale, log_weights=cloud.log_weights, missed=missed,
                                 precision=precision, centre=centre, present=present, nominal=nominal)
        log_w = log_w + (log_lik if power == 1.0 else power * log_lik)
    if not every:
        # an empty gate: log w_i <- log w_i + power log(1 - P_D^T(s_i)) (per particle), or unchanged
        empty = touched & ~present
        if empty.any():
            log_w = np.where(empty[:, None], cloud.log_weights + power * missed, log_w)
    top = np.max(log_w, axis=1)  # read by the underflow count and by the normalisation
    dead = touched & ~np.isfinite(top)
    log_w = normalise_log_weights(log_w, fallback=cloud.log_weights, top=top)
    if not (every or touched.all()):
        log_w = keep_where(touched, log_w, cloud.log_weights)
    return _finish(state, log_w, touched, threshold, dead, rng, regularisation, backend)


def _predict(switch_on: float, switch_off: float, scale: float, backend: str = "auto"):
    if switch_on <= 0.0 or scale == 1.0:
        return predict
    return partial(predict_jump_markov, switch_on=switch_on, switch_off=switch_off, scale=scale, backend=backend)


def _check_modes(who: str, switch_on: float, switch_off: float, scale: float) -> None:
    if not (0.0 <= switch_on <= 1.0 and 0.0 < switch_off <= 1.0 and scale >= 1.0):
        raise InputError(f"{who}: need 0 <= switch_on <= 1, 0 < switch_off <= 1, manoeuvre_scale >= 1; got "
                         f"{switch_on}, {switch_off}, {scale}")


#: The two-mode prediction and the regularisation, declared alike by the particle filters of this plugin.
MODE_PARAMETERS = (
    Param("switch_on", SWITCH_ON, "P(quiet -> manoeuvre) per scan of the two-mode prediction (0: plain CV)",
          unit="dimensionless", minimum=0.0, maximum=1.0),
    Param("switch_off", SWITCH_OFF, "P(manoeuvre -> quiet) per scan", unit="dimensionless", above=0.0, maximum=1.0),
    Param("manoeuvre_scale", MANOEUVRE_SCALE, "factor on the process-noise sigma in the manoeuvre mode",
          unit="dimensionless", minimum=1.0, maximum=1e3),
    Param("regularisation", REGULARISATION, "post-regularisation bandwidth after resampling, x h_opt (0: off)",
          unit="dimensionless", minimum=0.0, maximum=100.0),
)


TBD_PARAMETERS = (
    Param("particles", 600, "particles per run", "int", unit="dimensionless", minimum=1, footprint=48.0),
    Param("threshold", 0.5, "resample where N_eff < threshold N", unit="dimensionless", minimum=0.0, maximum=1.0),
    Param("floor", "amplitude", "the 'target missed, every detection is clutter' floor: amplitude (the scan's clutter "
          "density, lowered by the strongest detection's amplitude likelihood ratio, times 1 - P_D of the design "
          "target; empty gates weighted by 1 - P_D), flat (floor_density, the previous floor) or none (eqs 13-15 "
          "as printed)", "str", choices=FLOORS),
    Param("floor_scale", FLOOR_SCALE, "the amplitude floor's level relative to the scan's clutter density",
          unit="dimensionless", above=0.0, maximum=1e12),
    Param("missed_detection", "cloud", "where the amplitude floor's 1 - P_D of the design target is taken: at the "
          "cloud's predicted position (cloud) or at every particle (particle, an ablation)", "str",
          choices=("cloud", "particle")),
    Param("floor_density", 5e-11, "spatial density (m^-3) of the flat floor", unit="inverse_volume", minimum=0.0),
    Param("sigma_vr", 15.0, "width of the Doppler kernel (the sensor's 2 m/s, widened as a tempering device)",
          unit="speed", above=0.0),
    Param("backend", "auto", "kernel backend of the weights and of the compiled prediction, likelihood and "
          "regularisation steps (auto: the policy's choice; numpy: the NumPy reference throughout)", "str",
          choices=BACKENDS),
    *MODE_PARAMETERS,
    Param("tempering", 1, "progressive correction: the likelihood applied as this many equal powers, each followed by "
          "resampling and regularisation (1: off)", "int", unit="dimensionless", minimum=1, maximum=1000),
    Param("precision", "float64", "arithmetic of the weight kernel (float32: faster, normalised weights within 1e-4 "
          "of float64)", "str", choices=PRECISIONS),
)


def make_tbd_pf(particles: int = 600, threshold: float = 0.5, floor: str = "amplitude",
                floor_scale: float = FLOOR_SCALE, missed_detection: str = "cloud", floor_density: float = 5e-11,
                sigma_vr: float = 15.0,
                backend: str = "auto", name: str | None = None, switch_on: float = SWITCH_ON,
                switch_off: float = SWITCH_OFF, manoeuvre_scale: float = MANOEUVRE_SCALE,
                regularisation: float = REGULARISATION, tempering: int = 1, precision: str = "float64") -> FilterSpec:
    """The direct-weight TBD particle filter with ``particles`` particles, the floor ``floor`` (see the module
    docstring) and Doppler kernel ``sigma_vr`` (m/s); resampling when ``N_eff < threshold N``; weights by the kernel
    ``backend``; the two-mode (jump-Markov) prediction of :func:`predict_jump_markov` (``switch_on = 0``: plain CV);
    ``regularisation`` x the optimal kernel bandwidth jitters the resampled particles (:func:`regularise`)."""
    if regularisation < 0.0:
        raise InputError(f"tbd-pf: need regularisation >= 0, got {regularisation}")
    if backend not in BACKENDS:
        raise InputError(f"tbd-pf: unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if int(tempering) < 1:
        raise InputError(f"tbd-pf: need tempering >= 1, got {tempering}")
    if missed_detection not in ("cloud", "particle"):
        raise InputError(f"tbd-pf: missed_detection must be 'cloud' or 'particle', got {missed_detection!r}")
    if floor not in FLOORS:
        raise InputError(f"tbd-pf: unknown floor {floor!r}; expected one of {', '.join(FLOORS)}")
    if floor_density < 0 or not floor_scale > 0 or particles < 1 or not 0 <= threshold <= 1 or sigma_vr <= 0:
        raise InputError(f"tbd-pf: need particles >= 1, 0 <= threshold <= 1, floor_density >= 0, floor_scale > 0, "
                         f"sigma_vr > 0; got {particles}, {threshold}, {floor_density}, {floor_scale}, {sigma_vr}")
    _check_modes("tbd-pf", switch_on, switch_off, manoeuvre_scale)
    level = {"amplitude": f"amplitude-aware floor ({floor_scale:g} x clutter density)",
             "flat": f"flat floor {floor_density:g} m^-3", "none": "no floor"}[floor]
    return FilterSpec(
        name=name or "tbd-pf",
        summary=(f"TBD particle filter: weights from every gated detection, N={particles}, {level}, Doppler kernel "
                 f"{sigma_vr:g} m/s, two-mode CV (x{manoeuvre_scale:g} noise, on {switch_on:g}, off {switch_off:g}), "
                 f"regularised resampling ({regularisation:g} h_opt)"),
        init=partial(init, particles=particles),
        predict=_predict(switch_on, switch_off, manoeuvre_scale, backend),
        update=partial(update, threshold=threshold, floor=floor, floor_scale=floor_scale,
                       missed_detection=missed_detection, floor_density=floor_density,
                       sigma_vr=sigma_vr, backend=backend, regularisation=regularisation, tempering=int(tempering),
                       precision=precision),
        estimate=estimate,
        capabilities=frozenset({"stochastic", "multi_measurement", "position_doppler_3d", "manoeuvre_modes"}),
        params={"particles": particles, "threshold": threshold, "floor": floor, "floor_scale": floor_scale,
                "missed_detection": missed_detection,
                "floor_density": floor_density, "sigma_vr": sigma_vr, "backend": backend, "switch_on": switch_on,
                "switch_off": switch_off, "manoeuvre_scale": manoeuvre_scale, "regularisation": regularisation,
                "tempering": int(tempering), "precision": precision},
        diagnostics=diagnostics,
        parameters=TBD_PARAMETERS,
        build=make_tbd_pf,
        take=take_batch,
        join=join_modes,
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
    # a NaN or inf would make every weight of its item NaN, which the fallback would then hide: refuse it
    bad = present & ~np.all(np.isfinite(z), axis=1)
    if bad.any():
        item = int(np.argmax(bad))
        raise InputError(f"sir-jm: the valid measurement of batch item {item} holds a non-finite value (NaN or inf): "
                         f"{z[item]}")
    if scan.cov is not None:
        R = measurement_covariance(scan, model, present)
        bad = present & ~np.all(np.isfinite(R), axis=(1, 2))
        if bad.any():
            raise InputError(f"sir-jm: the own covariance (Scan.cov) of batch item {int(np.argmax(bad))}'s valid "
                             "detection holds a non-finite value (NaN or inf)")
        # log N(z; h(x_i), R_b) with the measurement's own covariance
        log_lik = log_likelihood_cov(z, cloud.particles, model, R)
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
    Param("particles", 600, "particles per run", "int", unit="dimensionless", minimum=1, footprint=48.0),
    Param("threshold", 0.5, "resample where N_eff < threshold N", unit="dimensionless", minimum=0.0, maximum=1.0),
    *MODE_PARAMETERS,
)


def make_sir_jm(particles: int = 600, threshold: float = 0.5, switch_on: float = SWITCH_ON,
                switch_off: float = SWITCH_OFF, manoeuvre_scale: float = MANOEUVRE_SCALE,
                name: str | None = None, regularisation: float = REGULARISATION) -> FilterSpec:
    """Method B: the bootstrap filter with the same two-mode prediction as method C; where the scan declares a
    clutter density the likelihood is the clutter mixture (:func:`sir_update`), ``regularisation > 0`` jitters
    the resampled particles (:func:`regularise`; 0 turns it off)."""
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
        take=take_batch,
        join=join_modes,
    )


@dataclass(frozen=True)
class AdaptiveGaussian:
    """An EKF state with a manoeuvre flag per item: ``gaussian`` (B, n), ``manoeuvre (B,)`` bool."""

    gaussian: Gaussian
    manoeuvre: np.ndarray

    #: The batch-first fields.
    batch_fields = ("gaussian", "manoeuvre")


def nis_init(prior: Gaussian, rng=None) -> AdaptiveGaussian:
    return AdaptiveGaussian(prior, np.zeros(prior.batch, dtype=bool))


def nis_predict(state: AdaptiveGaussian, motion: MotionModel, rng=None, *, scale: float,
                who: str = "ekf-nis") -> AdaptiveGaussian:
    """``x- = F x``, ``P- = F P F^T + q_b W`` with ``q_b = scale^2`` for an item in manoeuvre, else 1.

    A motion model that overrides ``f``: ``x- = f(x)``, ``P- = J P J^T + q_b W`` with the model's ``jacobian``
    ``J`` at ``x`` (refused by name without one)."""
    g = state.gaussian
    q = np.where(state.manoeuvre, scale**2, 1.0)
    if motion.linear:
        mean = g.mean @ motion.F.T
        # P- = F P F^T + q_b W
        cov = symmetrise(motion.F @ g.cov @ motion.F.T + q[:, None, None] * motion.Q)
        return AdaptiveGaussian(Gaussian(mean, cov), state.manoeuvre)
    mean, J = linearised(g.mean, motion, who)  # x- = f(x), J = df/dx at x
    # P- = J P J^T + q_b W
    cov = symmetrise(J @ g.cov @ np.swapaxes(J, -1, -2) + q[:, None, None] * motion.Q)
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
          unit="dimensionless", minimum=1.0, maximum=1e3),
    Param("nis_threshold", float(chi2.ppf(0.99, 4)), "NIS above which the next prediction uses the manoeuvre noise "
          "(default: the chi-square 99 % point, 4 dof)", unit="gate", above=0.0),
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
    label = name or "ekf-nis"
    return FilterSpec(
        name=label,
        summary=f"EKF with NIS-switched process noise (x{manoeuvre_scale:g} above NIS {nis_threshold:.2f})",
        init=nis_init,
        predict=partial(nis_predict, scale=manoeuvre_scale, who=label),
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
    return [make_tbd_pf(), make_sir_jm(), make_ekf_nis()]


def _bench(quick: bool) -> dict:
    from .bench import bench

    return bench(quick)


@hookimpl
def workbench_benchmarks():
    return [BenchmarkSpec("tbd-weights", "tbd-pf's weight kernel (paper 000's method C): throughput per backend and "
                                         "precision against NumPy and against its FMA-peak limit", _bench)]
