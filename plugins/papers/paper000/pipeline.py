"""Paper 000's per-scan chain on the core time loop: gate, the weighted-mean pseudo-measurement of methods A and B
(eqs 9-11) with its PDA-like noise ``R_bar``, the error metrics of eqs 19-21 and the gated run.

The loop and the radius gate are the core's (:func:`workbench.tracking.run` with
:class:`workbench.tracking.Gated`); what is paper 000's own is here.  Detection quality (``P_D`` and the
position sigma at a detection's SNR) comes from the sensor's declared :class:`~workbench.models.DetectionModel`.

Shapes
------
Positions ``(..., 3)``, states ``[x, y, z, vx, vy, vz]`` ``(..., 6)``, measurements ``[x, y, z, vr]`` ``(..., 4)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from workbench.models import MeasurementModel, MotionModel
from workbench.models.measurement import linear_measurement
from workbench.sensing.radar import radial_velocity
from workbench.specs import FilterSpec
from workbench.tracking import Gated, run
from workbench.types import Gaussian, InputError, Scan, Scans

__all__ = ["weighted_mean_measurement", "weighted_mean_position", "position_model", "pseudo_measurement_covariance", "whitened_model", "measurement_error",
           "estimation_error", "lost_track", "moment_matched_scale", "GatedRun", "run_gated"]


def _log_weights(scan: Scan, predicted: np.ndarray, sigma_g: float, sigma_vr: float, model: MeasurementModel):
    """``log w_m = log P_D(snr_m) - r_m^2 / (2 sigma_g^2) - (vr_m - vr_hat)^2 / (2 sigma_d^2)`` (eq 10), -inf on
    invalid rows."""
    r2 = np.sum((scan.z[..., :3] - predicted[:, None, :3]) ** 2, axis=-1)
    dv = scan.z[..., 3] - radial_velocity(predicted)[:, None]
    log_w = model.detection.log_pd(np.nan_to_num(scan.snr)) - 0.5 * r2 / sigma_g**2 - 0.5 * dv**2 / sigma_vr**2
    return np.where(scan.valid, log_w, -np.inf)


def _normalised_weights(scan: Scan, predicted: np.ndarray, sigma_g: float, sigma_vr: float,
                        model: MeasurementModel) -> np.ndarray:
    """``w~_m = w_m / sum_m w_m`` of eq 10 per item ``(B, M)``, computed in the log domain (the largest log weight
    taken out first); 0 on invalid rows and on every row of an item without a valid detection."""
    log_w = _log_weights(scan, predicted, sigma_g, sigma_vr, model)
    top = np.max(log_w, axis=1, keepdims=True)
    w = np.exp(log_w - np.where(np.isfinite(top), top, 0.0))
    total = w.sum(axis=1, keepdims=True)
    return w / np.where(total > 0, total, 1.0)


def _detection(model: MeasurementModel):
    if model.detection is None:
        raise InputError(f"the weighted-mean pseudo-measurement needs a sensor that declares its detection quality "
                         f"(model.detection); {model.name!r} does not")
    return model.detection


def weighted_mean_measurement(scan: Scan, predicted: np.ndarray, model: MeasurementModel, sigma_g: float = 500.0,
                              sigma_vr: float = 15.0) -> Scan:
    """The weighted-mean pseudo-measurement of methods A and B (eqs 9-11), one row per batch item.

    ``w_m = P_D(snr_m) exp(-r_m^2 / (2 sigma_g^2)) exp(-(vr_m - vr_hat)^2 / (2 sigma_vr^2))`` with
    ``r_m`` the distance of detection ``m`` from the predicted position and ``vr_hat`` the predicted
    radial velocity; ``z_bar = sum_m w~_m z_m`` with ``w~ = w / sum w`` (computed in the log domain).
    An item without detections comes back with no valid row (the filter then predicts only).

    Shapes
    ------
    scan.z : (B, M, 4), scan.snr : (B, M) in dB; predicted : (B, 6); returns a Scan (B, 1, 4)
    """
    if scan.snr is None:
        raise InputError("weighted_mean_measurement needs scan.snr (dB) for P_D(snr_m)")
    _detection(model)
    predicted = np.asarray(predicted, dtype=float)
    present = scan.valid.any(axis=1)
    if scan.z.shape[1] == 0:
        return Scan.single(np.zeros((scan.batch, 4)), present, time=scan.time)
    w = _normalised_weights(scan, predicted, sigma_g, sigma_vr, model)  # w~_m = w_m / sum_m w_m
    # z_bar = sum_m w~_m [p_m; vr_m]     (11)
    z_bar = np.einsum("bm,bmk->bk", w, scan.z)
    return Scan.single(z_bar, present, time=scan.time)


def weighted_mean_position(scan: Scan, predicted: np.ndarray, model: MeasurementModel, sigma_g: float = 500.0,
                           sigma_vr: float = 15.0) -> Scan:
    """The paper's weighted-mean *coordinate* of methods A and B (eqs 9-11 as the paper writes them).

    The weights are eq 10's: ``w_m = P_D(snr_m) exp(-r_m^2 / (2 sigma_g^2)) exp(-(vr_m - vr_hat)^2 /
    (2 sigma_vr^2))``, so the Doppler enters only the weights; the pseudo-measurement (eq 11) is the weighted mean
    of the gated detections' *positions*, ``z_bar = sum_m w~_m p_m``, a 3-D coordinate (no Doppler row; the
    4-vector ``[p; v_r]`` of :func:`weighted_mean_measurement` is the brief's earlier reading).  An item without
    detections comes back with no valid row (the filter then predicts only).

    Shapes
    ------
    scan.z : (B, M, 4), scan.snr : (B, M) in dB; predicted : (B, 6); returns a Scan (B, 1, 3)
    """
    full = weighted_mean_measurement(scan, predicted, model, sigma_g, sigma_vr)
    return Scan.single(full.z[:, 0, :3], full.valid[:, 0], time=full.time)


def position_model(model: MeasurementModel) -> MeasurementModel:
    """The measurement model of the weighted-mean coordinate: ``h(s) = [x, y, z]`` (linear) with the fixed noise
    ``R_bar = diag(s_x^2, s_y^2, s_z^2)`` from the position components of the sensor's stated pseudo-measurement
    accuracy (``model.std[:3]``: the lband-radar's declared ``pseudo_sigma_pos``, the brief's 300 m [U])."""
    if model.dim < 3 or any(model.angular[:3]):
        raise InputError(f"position_model: {model.name!r} has no Cartesian position in its first three components")
    std = tuple(float(v) for v in model.stated_std[:3])
    n = 6
    H = np.zeros((3, n))
    H[:, :3] = np.eye(3)
    return linear_measurement(H, np.diag(np.square(std)), name=f"{model.name}-position", frame="cartesian-3d",
                              std=std)


def pseudo_measurement_covariance(scan: Scan, predicted: np.ndarray, model: MeasurementModel,
                                  sigma_g: float = 500.0, sigma_vr: float = 15.0,
                                  doppler_mismatch: bool = False) -> tuple[Scan, np.ndarray]:
    """The pseudo-measurement of eqs 9-11 with the PDA-like noise ``R_bar`` of the brief's alternative.

    ``R_bar = sum_m w~_m R_m + sum_m w~_m (z_m - z_bar)(z_m - z_bar)^T`` with
    ``R_m = diag(sigma_p,m^2, sigma_p,m^2, sigma_p,m^2, sigma_vr_meas^2)``, ``sigma_p,m`` from the detection's
    own SNR and range and ``sigma_vr_meas`` the sensor's radial-velocity sigma (its declared detection model, the
    same accuracy as method C's kernel).  An item without detections gets the identity (the filter ignores it).

    Shapes
    ------
    scan.z : (B, M, 4), scan.snr : (B, M) dB; predicted : (B, 6); returns (Scan (B, 1, 4), R_bar (B, 4, 4))
    """
    detection = _detection(model)
    if scan.snr is None:
        raise InputError("pseudo_measurement_covariance needs scan.snr (dB) for P_D(snr_m)")
    B = scan.batch
    R_bar = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
    if scan.z.shape[1] == 0:
        return Scan.single(np.zeros((B, 4)), np.zeros(B, dtype=bool), time=scan.time), R_bar
    snr_db = np.nan_to_num(scan.snr)
    predicted = np.asarray(predicted, dtype=float)
    w = _normalised_weights(scan, predicted, sigma_g, sigma_vr, model)
    # z_bar = sum_m w~_m [p_m; vr_m]     (11)
    z_bar = Scan.single(np.einsum("bm,bmk->bk", w, scan.z), scan.valid.any(axis=1), time=scan.time)
    # sum_m w~_m R_m: isotropic position variance at each detection's SNR, radial-velocity noise
    var_p = detection.position_sigma(np.where(scan.valid, snr_db, 10.0), np.linalg.norm(scan.z[..., :3], axis=-1)) ** 2
    meas = np.zeros((B, 4, 4))
    meas[:, [0, 1, 2], [0, 1, 2]] = np.einsum("bm,bm->b", w, var_p)[:, None]
    meas[:, 3, 3] = detection.doppler_sigma**2
    # + sum_m w~_m (z_m - z_bar)(z_m - z_bar)^T  (spread of the gated detections)
    d = scan.z - z_bar.z[:, :1, :]
    spread = np.einsum("bm,bmi,bmj->bij", w, d, d)
    if doppler_mismatch:
        spread[:, 3, 3] += (z_bar.z[:, 0, 3] - radial_velocity(predicted)) ** 2
    present = z_bar.valid[:, 0]
    R_bar[present] = (meas + spread)[present]
    return z_bar, R_bar


def whitened_model(model: MeasurementModel, z_bar: Scan, R_bar: np.ndarray) -> tuple[Scan, MeasurementModel]:
    """A measurement with its own noise ``R_bar (B, m, m)`` per item, for a filter that takes only the model's ``R``.

    With ``R_bar = L L^T``: ``z' = L^-1 z``, ``h'(x) = L^-1 h(x)``, ``H' = L^-1 H`` and ``R' = I``: the same
    likelihood up to the constant ``|R_bar|^(-1/2)`` and the same (E)KF update.  ``model`` must have no angular
    components.  Shapes: z_bar (B, 1, m); R_bar (B, m, m).
    """
    if any(model.angular):
        raise InputError("whitened_model: angular measurement components are not supported")
    L_inv = np.linalg.inv(np.linalg.cholesky(R_bar))

    def h(x):
        y = model.h(x)
        return np.einsum("bij,bj->bi", L_inv, y) if y.ndim == 2 else np.einsum("bij,bnj->bni", L_inv, y)

    jac = None if model.jacobian is None else (lambda x: L_inv @ model.jacobian(x))
    white = MeasurementModel(name=f"{model.name}-whitened", h=h, R=np.eye(model.dim), jacobian=jac)
    z = np.einsum("bij,bj->bi", L_inv, z_bar.z[:, 0])
    return Scan.single(z, z_bar.valid[:, 0], time=z_bar.time), white


# -- metrics (eqs 19-21) ------------------------------------------------------------------------------


def measurement_error(z: np.ndarray, valid: np.ndarray, true_position: np.ndarray) -> np.ndarray:
    """``M_error = (1/n) sum_j ||M_pos,j - R_pos||`` over the valid (gated) detections (eq 19).

    NaN for an item without detections.  Shapes: z (B, M, 4), valid (B, M), true_position (B, 3) -> (B,).
    """
    d = np.linalg.norm(z[..., :3] - np.asarray(true_position, dtype=float)[:, None, :], axis=-1)
    n = valid.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sum(np.where(valid, d, 0.0), axis=1) / n, np.nan)


def estimation_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``E_error = ||E_pos - R_pos||`` (eq 20).  Shapes: ``(..., >=3)`` twice -> ``(...)``."""
    return np.linalg.norm(np.asarray(estimate)[..., :3] - np.asarray(truth)[..., :3], axis=-1)


def lost_track(error: np.ndarray, limit: float = 3000.0, scans: int = 5) -> np.ndarray:
    """Whether each run's track was lost: ``E_error > limit`` for ``scans`` consecutive scans.

    Shapes: ``error (B, T) -> (B,)`` bool.  The trackers are never re-initialised; this only flags.
    """
    over = np.asarray(error) > limit
    run_length = np.zeros(over.shape[0], dtype=int)
    lost = np.zeros(over.shape[0], dtype=bool)
    for k in range(over.shape[1]):
        run_length = np.where(over[:, k], run_length + 1, 0)
        lost |= run_length >= scans
    return lost


def moment_matched_scale(switch_on: float, switch_off: float, manoeuvre_scale: float) -> float:
    """Factor on sigma_a of the one Gaussian process noise with the covariance of the two-mode noise.

    Two modes, quiet (``W``) and manoeuvre (``scale^2 W``), switching with ``P(quiet -> manoeuvre) = on`` and
    ``P(manoeuvre -> quiet) = off``: stationary manoeuvre share ``pi = on / (on + off)`` and covariance
    ``((1 - pi) + pi scale^2) W``, so a filter with a single Gaussian noise (the EKF) uses
    ``sigma_a sqrt((1 - pi) + pi scale^2)``.
    """
    share = switch_on / (switch_on + switch_off)
    return float(np.sqrt((1.0 - share) + share * manoeuvre_scale**2))


# -- the gated run ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GatedRun:
    """What :func:`run_gated` records.

    Shapes
    ------
    mean, predicted : (B, T, 6); gated_count : (B, T); measurement_error : (B, T) (NaN for an empty gate)
    gated_points : (K, 6) rows ``[k, x, y, z, vr, origin]``: every gated detection of the recorded item
    seconds, cpu_seconds : the tracking loop's wall time and this process's CPU time in it (all threads), the
    scoring after it excluded
    """

    mean: np.ndarray
    predicted: np.ndarray
    gated_count: np.ndarray
    measurement_error: np.ndarray
    seconds: float
    diagnostics: dict
    gated_points: np.ndarray
    cpu_seconds: float = float("nan")


def run_gated(spec: FilterSpec, prior: Gaussian, motion: MotionModel, model: MeasurementModel, scans: Scans,
              radius: float, rng: np.random.Generator, *, truth: np.ndarray | None = None,
              pseudo: Callable[..., Scan] | None = None, record_item: int = 0) -> GatedRun:
    """Track through ``scans`` with a gate of ``radius`` around each predicted position (the core loop with the
    :class:`~workbench.tracking.Gated` role), then score the gated detections against the truth.

    A filter with the ``multi_measurement`` capability (method C) is updated with the whole gated scan, any other
    with ``pseudo(gated, predicted_state, rng)`` (methods A and B).  ``truth (B, T, >=3)`` only feeds the
    measurement-error metric (eq 19); the filter never sees it, nor the detections' origin, which the gated points
    of batch item ``record_item`` carry for plotting.
    """
    cpu = time.process_time()
    track = run(spec, scans, motion, model, association=Gated(radius, pseudo, dims=3), prior=prior, rng=rng)
    cpu = time.process_time() - cpu
    M = scans.z.shape[2]
    gated = track.records["gated"][:, :, :M]
    B, T = scans.batch, scans.steps
    m_err = np.full((B, T), np.nan)
    if truth is not None:
        # eq 19 at every scan, over the gated detections only (a few per scan among the scan's padded rows)
        b_idx, k_idx, m_idx = np.nonzero(gated)
        d = np.linalg.norm(scans.z[b_idx, k_idx, m_idx, :3] - np.asarray(truth, dtype=float)[b_idx, k_idx, :3], axis=-1)
        cell = b_idx * T + k_idx
        n = np.bincount(cell, minlength=B * T).reshape(B, T)
        total = np.bincount(cell, weights=d, minlength=B * T).reshape(B, T)
        with np.errstate(invalid="ignore", divide="ignore"):
            m_err = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    # every gated detection of the recorded item, scan by scan: [k, x, y, z, vr, origin]
    k_idx, m_idx = np.nonzero(gated[record_item])
    origin = scans.origin[record_item][k_idx, m_idx] if scans.origin is not None else np.full(k_idx.size, -1)
    points = np.column_stack([k_idx, scans.z[record_item][k_idx, m_idx], origin]) if k_idx.size else \
        np.zeros((0, 2 + scans.z.shape[3]))
    return GatedRun(track.mean, track.predicted_mean, track.records["gated_count"], m_err, track.seconds,
                    dict(track.diagnostics), points, cpu)
