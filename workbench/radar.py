"""Radar maths and the track-before-detect measurement chain of paper 000 (L-band, low SNR).

Radar equation, Swerling-0 detection probability (Marcum Q), SNR-dependent accuracies, spherical and
Cartesian coordinates, radial velocity (positive when receding), and the per-scan processing that
feeds the trackers: gating by a radius around the predicted position and the weighted-mean
pseudo-measurement of methods A and B (eqs 9-11), plus the error metrics of eqs 19-21.

Shapes
------
Positions ``(..., 3)``, states ``[x, y, z, vx, vy, vz]`` ``(..., 6)``, measurements
``[x, y, z, vr]`` ``(..., 4)``; scans are batch-first :class:`~workbench.types.Scan` records.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
from scipy.special import erfc, logsumexp
from scipy.stats import ncx2

from .models import MeasurementModel, MotionModel
from .specs import FilterSpec
from .types import Gaussian, InputError, Scan, Scans

__all__ = [
    "SPEED_OF_LIGHT",
    "BOLTZMANN",
    "T0",
    "RadarParameters",
    "db",
    "from_db",
    "radar_snr",
    "marcum_q",
    "detection_probability",
    "log_detection_probability",
    "north_detection_probability",
    "range_accuracy",
    "angle_accuracy",
    "position_sigma",
    "cartesian_to_spherical",
    "spherical_to_cartesian",
    "radial_velocity",
    "position_radial_velocity",
    "position_radial_velocity_jacobian",
    "aspect_rcs_db",
    "clutter_pass_fraction",
    "gate",
    "weighted_mean_measurement",
    "pseudo_measurement_covariance",
    "whitened_model",
    "measurement_error",
    "estimation_error",
    "lost_track",
    "moment_matched_scale",
    "GatedRun",
    "run_gated",
]

SPEED_OF_LIGHT = 299_792_458.0  # m/s
BOLTZMANN = 1.380649e-23  # J/K
T0 = 290.0  # K, reference noise temperature


def db(x):
    """``10 log10(x)``."""
    return 10.0 * np.log10(x)


def from_db(x_db):
    """``10^(x/10)``."""
    return 10.0 ** (np.asarray(x_db, dtype=float) / 10.0)


@dataclass(frozen=True)
class RadarParameters:
    """Table 2 of the paper plus the brief's chosen values where the paper withholds them.

    Stated: N = 100 pulses, Gt = Gr = 35 dBi, F = 10 dB, L-band.  Chosen [U]: f = 1.3 GHz, Pt = 10 kW,
    tau = 1 us (B = 1/tau), L = 6 dB, Pfa = 1e-6.
    """

    frequency: float = 1.3e9  # Hz
    peak_power: float = 10e3  # W
    pulse_width: float = 1e-6  # s
    pulses: int = 100
    gain_tx_db: float = 35.0
    gain_rx_db: float = 35.0
    noise_figure_db: float = 10.0
    loss_db: float = 6.0
    pfa: float = 1e-6

    @property
    def wavelength(self) -> float:
        return SPEED_OF_LIGHT / self.frequency

    @property
    def bandwidth(self) -> float:
        return 1.0 / self.pulse_width

    @property
    def beamwidth(self) -> float:
        """3 dB beamwidth (rad) of the receive antenna: ``theta = sqrt(4 pi 0.65 / G)``."""
        return float(np.sqrt(4.0 * np.pi * 0.65 / from_db(self.gain_rx_db)))

    def as_dict(self) -> dict:
        return asdict(self)


def radar_snr(range_m, rcs_m2, radar: RadarParameters = RadarParameters()) -> np.ndarray:
    """Signal-to-noise ratio (linear) after ideal coherent integration of ``radar.pulses`` pulses.

    ``SNR = Pt Gt Gr lambda^2 sigma N_p / ((4 pi)^3 R^4 k T0 B F L)``.  Shapes: broadcast of the inputs.
    """
    r = np.asarray(range_m, dtype=float)
    num = (radar.peak_power * from_db(radar.gain_tx_db) * from_db(radar.gain_rx_db) * radar.wavelength**2
           * np.asarray(rcs_m2, dtype=float) * radar.pulses)
    den = ((4.0 * np.pi) ** 3 * r**4 * BOLTZMANN * T0 * radar.bandwidth * from_db(radar.noise_figure_db)
           * from_db(radar.loss_db))
    return num / den


def marcum_q(a, b) -> np.ndarray:
    """First-order Marcum Q function ``Q1(a, b)`` = survival function of a noncentral chi-square.

    ``Q1(a, b) = P(X > b^2)`` for ``X ~ ncx2(df=2, nc=a^2)``.  Shapes: broadcast of ``a`` and ``b``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return ncx2.sf(b**2, 2, a**2)


def detection_probability(snr, pfa: float = 1e-6) -> np.ndarray:
    """Swerling-0 single-look detection probability ``P_D = Q1(sqrt(2 SNR), sqrt(-2 ln Pfa))`` (eq 9).

    ``snr`` is linear.  Shapes: as ``snr``.
    """
    snr = np.asarray(snr, dtype=float)
    return marcum_q(np.sqrt(2.0 * snr), np.sqrt(-2.0 * np.log(pfa)))


def log_detection_probability(snr, pfa: float = 1e-6) -> np.ndarray:
    """``log P_D`` computed by ``ncx2.logsf`` (no underflow at low SNR, where ``P_D -> Pfa``)."""
    snr = np.maximum(np.asarray(snr, dtype=float), 0.0)
    return ncx2.logsf(-2.0 * np.log(pfa), 2, 2.0 * snr)


def north_detection_probability(snr, pfa: float = 1e-6) -> np.ndarray:
    """North's approximation ``P_D = 0.5 erfc(sqrt(-ln Pfa) - sqrt(SNR + 0.5))`` (a check on eq 9)."""
    snr = np.asarray(snr, dtype=float)
    return 0.5 * erfc(np.sqrt(-np.log(pfa)) - np.sqrt(snr + 0.5))


def range_accuracy(snr, pulse_width: float) -> np.ndarray:
    """Range standard deviation (m): ``sigma_R = c tau / (2 sqrt(2 SNR))``; ``snr`` linear."""
    return SPEED_OF_LIGHT * pulse_width / (2.0 * np.sqrt(2.0 * np.asarray(snr, dtype=float)))


def angle_accuracy(snr, beamwidth: float) -> np.ndarray:
    """Angle standard deviation (rad): ``sigma_ang = theta_3dB / (1.6 sqrt(2 SNR))``; ``snr`` linear."""
    return beamwidth / (1.6 * np.sqrt(2.0 * np.asarray(snr, dtype=float)))


def position_sigma(snr_db, range_m, radar: RadarParameters = RadarParameters()) -> np.ndarray:
    """Isotropic position sigma (m) of a detection for method C's kernel (eq 13).

    ``sigma_p = sqrt(sigma_R^2 + (R sigma_ang)^2)``: the cross-range term dominates at these ranges; the
    sum covers both, so the sphere is never narrower than the true error ellipsoid.  Shapes: broadcast.
    """
    snr = from_db(snr_db)
    cross = np.asarray(range_m, dtype=float) * angle_accuracy(snr, radar.beamwidth)
    return np.hypot(range_accuracy(snr, radar.pulse_width), cross)


def cartesian_to_spherical(p) -> np.ndarray:
    """``[x, y, z] -> [range, azimuth, elevation]`` (azimuth from +x towards +y, elevation above x-y).

    Shapes: ``(..., 3) -> (..., 3)``.
    """
    p = np.asarray(p, dtype=float)
    horiz = np.hypot(p[..., 0], p[..., 1])
    return np.stack([np.sqrt(horiz**2 + p[..., 2] ** 2), np.arctan2(p[..., 1], p[..., 0]),
                     np.arctan2(p[..., 2], horiz)], axis=-1)


def spherical_to_cartesian(s) -> np.ndarray:
    """``[range, azimuth, elevation] -> [x, y, z]``.  Shapes: ``(..., 3) -> (..., 3)``."""
    s = np.asarray(s, dtype=float)
    r, az, el = s[..., 0], s[..., 1], s[..., 2]
    return np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], axis=-1)


def radial_velocity(x) -> np.ndarray:
    """``vr = (p . v) / |p|`` for states ``[p, v]``: positive when the target recedes from the radar.

    Shapes: ``(..., 6) -> (...)``.
    """
    x = np.asarray(x, dtype=float)
    p, v = x[..., :3], x[..., 3:6]
    return np.einsum("...i,...i->...", p, v) / np.maximum(np.linalg.norm(p, axis=-1), 1e-9)


def position_radial_velocity(x) -> np.ndarray:
    """``h(s) = [x, y, z, (p . v) / |p|]``.  Shapes: ``(..., 6) -> (..., 4)``."""
    x = np.asarray(x, dtype=float)
    return np.concatenate([x[..., :3], radial_velocity(x)[..., None]], axis=-1)


def position_radial_velocity_jacobian(x) -> np.ndarray:
    """Jacobian of :func:`position_radial_velocity`.

    Rows x, y, z select the position; the vr row is ``d vr/d p = v/|p| - (p . v) p / |p|^3`` and
    ``d vr/d v = p / |p|``.  Shapes: ``(B, 6) -> (B, 4, 6)``.
    """
    x = np.asarray(x, dtype=float)
    p, v = x[:, :3], x[:, 3:6]
    r = np.maximum(np.linalg.norm(p, axis=1), 1e-9)[:, None]
    pv = np.einsum("bi,bi->b", p, v)[:, None]
    jac = np.zeros((x.shape[0], 4, 6))
    jac[:, 0, 0] = jac[:, 1, 1] = jac[:, 2, 2] = 1.0
    jac[:, 3, :3] = v / r - pv * p / r**3
    jac[:, 3, 3:] = p / r
    return jac


def aspect_rcs_db(times: np.ndarray, rcs_ref_dbsm: float, rcs_offsets_db, aspect_change_times) -> np.ndarray:
    """Nominal RCS (dBsm) at each time: Ref + the offset of the aspect phase (front, top, side).

    Shapes: ``times (T,) -> (T,)``.
    """
    offsets = np.asarray(rcs_offsets_db, dtype=float)
    edges = np.asarray(aspect_change_times, dtype=float)
    if offsets.shape[0] != edges.shape[0] + 1:
        raise InputError(f"aspect_rcs_db: {offsets.shape[0]} RCS offsets need {offsets.shape[0] - 1} change times, "
                         f"got {edges.shape[0]}")
    phase = np.searchsorted(edges, np.asarray(times, dtype=float), side="left")  # t <= edge stays in phase
    return rcs_ref_dbsm + offsets[phase]


def clutter_pass_fraction(threshold_db, mean_power: float = 2.0) -> np.ndarray:
    """Fraction of clutter returns whose SNR passes ``threshold_db``.

    Rayleigh amplitude = exponential power with mean ``mean_power`` (linear):
    ``P(power >= t) = exp(-t / mean_power)``.
    """
    return np.exp(-from_db(threshold_db) / mean_power)


# -- the per-scan chain: gate, pseudo-measurement ----------------------------------------------------


def gate(scan: Scan, centre: np.ndarray, radius: float) -> Scan:
    """Keep the detections within ``radius`` (m) of ``centre``; the kept rows are moved to the front
    and the scan narrowed to the largest kept count, so later steps loop over few rows.

    Shapes
    ------
    scan.z : (B, M, 4) ``[x, y, z, vr]``; centre : (B, 3); returns a Scan (B, M', 4), M' <= M
    """
    centre = np.asarray(centre, dtype=float)
    if centre.shape != (scan.batch, 3):
        raise InputError(f"gate centre must have shape {(scan.batch, 3)}, got {centre.shape}")
    if not radius > 0:
        raise InputError(f"gate radius must be > 0 m, got {radius}")
    d2 = np.sum((scan.z[..., :3] - centre[:, None, :]) ** 2, axis=-1)
    keep = scan.valid & (d2 <= radius * radius)
    width = int(keep.sum(axis=1).max()) if keep.size else 0
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    pick = lambda a: None if a is None else np.take_along_axis(a, order, axis=1)  # noqa: E731
    return Scan(np.take_along_axis(scan.z, order[..., None], axis=1), np.take_along_axis(keep, order, axis=1),
                pick(scan.snr), pick(scan.doppler), pick(scan.origin), time=scan.time)


def weighted_mean_measurement(scan: Scan, predicted: np.ndarray, sigma_g: float = 500.0, sigma_vr: float = 15.0,
                              pfa: float = 1e-6) -> Scan:
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
    predicted = np.asarray(predicted, dtype=float)
    present = scan.valid.any(axis=1)
    if scan.z.shape[1] == 0:
        return Scan.single(np.zeros((scan.batch, 4)), present, time=scan.time)
    r2 = np.sum((scan.z[..., :3] - predicted[:, None, :3]) ** 2, axis=-1)
    dv = scan.z[..., 3] - radial_velocity(predicted)[:, None]
    # log w_m = log P_D(snr_m) - r_m^2 / (2 sigma_g^2) - (vr_m - vr_hat)^2 / (2 sigma_d^2)     (10)
    log_w = log_detection_probability(from_db(np.nan_to_num(scan.snr)), pfa) - 0.5 * r2 / sigma_g**2 \
        - 0.5 * dv**2 / sigma_vr**2
    log_w = np.where(scan.valid, log_w, -np.inf)
    total = logsumexp(log_w, axis=1, keepdims=True)
    w = np.exp(log_w - np.where(np.isfinite(total), total, 0.0))  # w~_m = w_m / sum_m w_m
    # z_bar = sum_m w~_m [p_m; vr_m]     (11)
    z_bar = np.einsum("bm,bmk->bk", w, scan.z)
    return Scan.single(z_bar, present, time=scan.time)


def pseudo_measurement_covariance(scan: Scan, predicted: np.ndarray, sigma_g: float = 500.0, sigma_vr: float = 15.0,
                                  pfa: float = 1e-6, sigma_vr_meas: float = 2.0,
                                  radar: RadarParameters = RadarParameters(),
                                  doppler_mismatch: bool = False) -> tuple[Scan, np.ndarray]:
    """The pseudo-measurement of eqs 9-11 with the PDA-like noise ``R_bar`` of the brief's alternative.

    ``R_bar = sum_m w~_m R_m + sum_m w~_m (z_m - z_bar)(z_m - z_bar)^T`` with
    ``R_m = diag(sigma_p,m^2, sigma_p,m^2, sigma_p,m^2, sigma_vr_meas^2)``, ``sigma_p,m`` from the detection's
    own SNR and range (:func:`position_sigma`, the same accuracy as method C's kernel).  An item without
    detections gets the identity (the filter ignores it).

    Shapes
    ------
    scan.z : (B, M, 4), scan.snr : (B, M) dB; predicted : (B, 6); returns (Scan (B, 1, 4), R_bar (B, 4, 4))
    """
    z_bar = weighted_mean_measurement(scan, predicted, sigma_g, sigma_vr, pfa)
    B = scan.batch
    R_bar = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
    if scan.z.shape[1] == 0:
        return z_bar, R_bar
    r2 = np.sum((scan.z[..., :3] - predicted[:, None, :3]) ** 2, axis=-1)
    dv = scan.z[..., 3] - radial_velocity(predicted)[:, None]
    snr_db = np.nan_to_num(scan.snr)
    log_w = log_detection_probability(from_db(snr_db), pfa) - 0.5 * r2 / sigma_g**2 - 0.5 * dv**2 / sigma_vr**2
    log_w = np.where(scan.valid, log_w, -np.inf)
    total = logsumexp(log_w, axis=1, keepdims=True)
    w = np.where(scan.valid, np.exp(log_w - np.where(np.isfinite(total), total, 0.0)), 0.0)
    # sum_m w~_m R_m: isotropic position variance at each detection's SNR, radial-velocity noise
    var_p = position_sigma(np.where(scan.valid, snr_db, 10.0), np.linalg.norm(scan.z[..., :3], axis=-1), radar) ** 2
    meas = np.zeros((B, 4, 4))
    meas[:, [0, 1, 2], [0, 1, 2]] = np.einsum("bm,bm->b", w, var_p)[:, None]
    meas[:, 3, 3] = sigma_vr_meas**2
    # + sum_m w~_m (z_m - z_bar)(z_m - z_bar)^T  (spread of the gated detections)
    d = scan.z - z_bar.z[:, :1, :]
    spread = np.einsum("bm,bmi,bmj->bij", w, d, d)
    if doppler_mismatch:
        spread[:, 3, 3] += (z_bar.z[:, 0, 3] - radial_velocity(predicted)) ** 2
    present = z_bar.valid[:, 0]
    R_bar[present] = (meas + spread)[present]
    return z_bar, R_bar


def whitened_model(model: MeasurementModel, z_bar: Scan, R_bar: np.ndarray) -> tuple[Scan, MeasurementModel]:
    """A measurement with its own noise ``R_bar (B, m, m)`` per batch item, for filters that take one ``R``.

    With ``R_bar = L L^T``: ``z' = L^-1 z``, ``h'(x) = L^-1 h(x)``, ``H' = L^-1 H`` and ``R' = I``, which gives
    the same likelihood ``N(z; h(x), R_bar)`` and the same (E)KF update.  ``model`` must have no angular
    components.  Shapes: z_bar (B, 1, m); R_bar (B, m, m).
    """
    if any(model.angular):
        raise InputError("whitened_model: angular measurement components are not supported")
    L_inv = np.linalg.inv(np.linalg.cholesky(R_bar))

    def h(x):
        y = model.h(x)
        return np.einsum("bij,bj->bi", L_inv, y) if y.ndim == 2 else np.einsum("bij,bnj->bni", L_inv, y)

    jac = None if model.jacobian is None else (lambda x: L_inv @ model.jacobian(x))
    white = MeasurementModel(name=f"{model.name}-whitened", h=h, R=np.eye(model.dim), jacobian=jac,
                             params=model.params)
    z = np.einsum("bij,bj->bi", L_inv, z_bar.z[:, 0])
    return Scan.single(z, z_bar.valid[:, 0], time=z_bar.time), white


# -- metrics (eqs 19-21) ------------------------------------------------------------------------------


def measurement_error(scan: Scan, true_position: np.ndarray) -> np.ndarray:
    """``M_error = (1/n) sum_j ||M_pos,j - R_pos||`` over the scan's valid detections (eq 19).

    NaN for an item without detections.  Shapes: scan (B, M, 4), true_position (B, 3) -> (B,).
    """
    d = np.linalg.norm(scan.z[..., :3] - np.asarray(true_position, dtype=float)[:, None, :], axis=-1)
    n = scan.valid.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sum(np.where(scan.valid, d, 0.0), axis=1) / n, np.nan)


def estimation_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``E_error = ||E_pos - R_pos||`` (eq 20).  Shapes: ``(..., >=3)`` twice -> ``(...)``."""
    return np.linalg.norm(np.asarray(estimate)[..., :3] - np.asarray(truth)[..., :3], axis=-1)


def lost_track(error: np.ndarray, limit: float = 3000.0, scans: int = 5) -> np.ndarray:
    """Whether each run's track was lost: ``E_error > limit`` for ``scans`` consecutive scans.

    Shapes: ``error (B, T) -> (B,)`` bool.  The trackers are never re-initialised; this only flags.
    """
    over = np.asarray(error) > limit
    run = np.zeros(over.shape[0], dtype=int)
    lost = np.zeros(over.shape[0], dtype=bool)
    for k in range(over.shape[1]):
        run = np.where(over[:, k], run + 1, 0)
        lost |= run >= scans
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


# -- the gated tracking loop ---------------------------------------------------------------------------


@dataclass(frozen=True)
class GatedRun:
    """What :func:`run_gated` records.

    Shapes
    ------
    mean, predicted : (B, T, 6); gated_count : (B, T); measurement_error : (B, T) (NaN for an empty gate)
    gated_points : (K, 6) rows ``[k, x, y, z, vr, origin]``: every gated detection of the recorded item
    """

    mean: np.ndarray
    predicted: np.ndarray
    gated_count: np.ndarray
    measurement_error: np.ndarray
    seconds: float
    diagnostics: dict
    gated_points: np.ndarray


def run_gated(spec: FilterSpec, prior: Gaussian, motion: MotionModel, model: MeasurementModel, scans: Scans,
              radius: float, rng: np.random.Generator, *, truth: np.ndarray | None = None,
              pseudo: Callable[[Scan, np.ndarray], Scan] | None = None, record_item: int = 0) -> GatedRun:
    """Track through ``scans`` with a gate of ``radius`` around each predicted position.

    Per scan: predict (from scan 1 on), gate around the predicted position ``F s_hat_{k-1|k-1}`` (the
    filter's estimate is taken once per scan, after the update), then update with the
    whole gated scan when the filter has the ``multi_measurement`` capability (method C), else with
    ``pseudo(gated, predicted_state)`` (methods A and B: :func:`weighted_mean_measurement`), which returns
    the pseudo-measurement Scan or ``(Scan, MeasurementModel)`` when its noise changes per scan
    (:func:`whitened_model`).
    ``truth (B, T, >=3)`` only feeds the measurement-error metric (eq 19); the filter never sees it.
    The gated detections of batch item ``record_item`` are kept (with their origin) for plotting.
    """
    multi = "multi_measurement" in spec.capabilities
    if not multi and pseudo is None:
        raise InputError(f"filter {spec.name!r} takes one measurement per scan: give run_gated a pseudo step")
    B, T = scans.batch, scans.steps
    mean = np.empty((B, T, prior.dim))
    pred = np.empty((B, T, prior.dim))
    count = np.zeros((B, T), dtype=int)
    m_err = np.full((B, T), np.nan)
    points = []
    start = time.perf_counter()
    state = spec.init(prior, rng)
    previous = spec.estimate(state).mean
    for k in range(T):
        if k > 0:
            state = spec.predict(state, motion, rng)
            # p_hat_{k|k-1} = F s_hat_{k-1|k-1}: the motion model's predicted mean (for a particle cloud the
            # expectation of its predicted mean), so the estimate is taken once per scan
            previous = previous @ motion.F.T
        pred[:, k] = previous
        gated = gate(scans.scan(k), pred[:, k, :3], radius)
        count[:, k] = gated.counts
        row = gated.valid[record_item]
        origin = gated.origin[record_item, row] if gated.origin is not None else np.full(int(row.sum()), -1)
        points.append(np.column_stack([np.full(int(row.sum()), k), gated.z[record_item, row], origin]))
        if truth is not None:
            m_err[:, k] = measurement_error(gated, truth[:, k, :3])
        step, step_model = gated.for_filter(), model
        if not multi:
            step = pseudo(gated.for_filter(), pred[:, k])
            if isinstance(step, tuple):  # (pseudo-measurement, its per-scan model)
                step, step_model = step
        state = spec.update(state, step, step_model, rng)
        previous = mean[:, k] = spec.estimate(state).mean
    seconds = time.perf_counter() - start
    diag = dict(spec.diagnostics(state)) if spec.diagnostics is not None else {}
    return GatedRun(mean, pred, count, m_err, seconds, diag, np.concatenate(points, axis=0))
