"""Monostatic radar physics shared by radar sensor, clutter and filter plugins.

Radar equation, Swerling-0 detection probability (Marcum Q), SNR-dependent accuracies, spherical and
Cartesian coordinates, radial velocity (positive when receding), an aspect-dependent RCS and the pass
fraction of exponential (Rayleigh-amplitude) clutter power at a threshold.

Shapes
------
Positions ``(..., 3)``, states ``[x, y, z, vx, vy, vz]`` ``(..., 6)``, measurements
``[x, y, z, vr]`` ``(..., 4)``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.special import chndtr, erfc, log_ndtr
from scipy.stats import ncx2

from ..models import DetectionModel
from ..types import InputError

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
    "exponential_power_log_density",
    "fluctuating_log_detection",
    "fluctuating_snr_log_density",
    "detection_model",
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
    """The parameters of a pulsed monostatic radar; the defaults are an L-band surveillance radar.

    Defaults: N = 100 pulses integrated, Gt = Gr = 35 dBi, F = 10 dB, f = 1.3 GHz, Pt = 10 kW, tau = 1 us
    (B = 1/tau), L = 6 dB, Pfa = 1e-6.
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
    """``log P_D`` of :func:`detection_probability` (no underflow at low SNR, where ``P_D -> Pfa``).

    ``log(1 - F(b^2))`` with ``F`` the noncentral chi-square CDF (``scipy.special.chndtr``, a plain ufunc: this
    runs once per scan in the filters); where ``P_D`` is below ``1e-9`` the difference would lose digits, and
    ``ncx2.logsf`` is used instead.
    """
    snr = np.maximum(np.asarray(snr, dtype=float), 0.0)
    b2 = -2.0 * np.log(pfa)
    sf = 1.0 - chndtr(b2, 2.0, 2.0 * snr)
    with np.errstate(divide="ignore"):
        out = np.log(sf)
    small = sf < 1e-9
    if np.any(small):
        out = np.where(small, ncx2.logsf(b2, 2, 2.0 * snr), out)
    return out


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
    """Isotropic position sigma (m) of a detection of a given SNR at a given range.

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


def exponential_power_log_density(snr_db, mean_power: float = 2.0, threshold_db: float | None = None) -> np.ndarray:
    """Log density (per dB) of the SNR of a return with exponential power (Rayleigh amplitude), given that it
    passed ``threshold_db``.

    With ``p = 10^(s/10)`` and the threshold ``t = 10^(threshold_db/10)`` (``t = 0`` for no threshold), the power
    above the threshold is ``t + Exp(mean_power)`` (memoryless), so per unit of ``s`` (dB)::

        f(s) = exp(-(p - t) / mu) / mu * dp/ds,   dp/ds = p ln(10) / 10,   s >= threshold_db

    and ``-inf`` below the threshold.  Shapes: as ``snr_db``.
    """
    s = np.asarray(snr_db, dtype=float)
    p = 10.0 ** (s / 10.0)
    t = 0.0 if threshold_db is None else float(10.0 ** (threshold_db / 10.0))
    # log f = -(p - t) / mu - log mu + log(p ln 10 / 10)
    log_f = -(p - t) / mean_power - np.log(mean_power) + s * (np.log(10.0) / 10.0) + np.log(np.log(10.0) / 10.0)
    if threshold_db is None:
        return log_f
    return np.where(s >= threshold_db, log_f, -np.inf)


def fluctuating_log_detection(nominal_snr_db, sigma_db: float, threshold_db: float | None) -> np.ndarray:
    """``log P_D`` of a detector that reports a return when its measured SNR, the nominal SNR plus a Gaussian
    fluctuation of ``sigma_db`` (dB), reaches ``threshold_db``::

        P_D = Phi((SNR_nominal - threshold) / sigma)

    ``threshold_db`` None (every return reported) gives ``log P_D = 0``.  Shapes: as ``nominal_snr_db``.
    """
    n = np.asarray(nominal_snr_db, dtype=float)
    if threshold_db is None:
        return np.zeros_like(n)
    if not sigma_db > 0:
        raise InputError(f"fluctuating_log_detection needs sigma_db > 0, got {sigma_db}")
    return log_ndtr((n - threshold_db) / sigma_db)


def fluctuating_snr_log_density(snr_db, nominal_snr_db, sigma_db: float, threshold_db: float | None) -> np.ndarray:
    """Log density (per dB) of the measured SNR ``s`` of a detected return whose nominal SNR is ``n``, for the
    detector of :func:`fluctuating_log_detection`::

        f(s | n, detected) = N(s; n, sigma^2) / P_D(n),   s >= threshold   (-inf below)

    Shapes: broadcast of ``snr_db`` and ``nominal_snr_db``.
    """
    if not sigma_db > 0:
        raise InputError(f"fluctuating_snr_log_density needs sigma_db > 0, got {sigma_db}")
    s = np.asarray(snr_db, dtype=float)
    n = np.asarray(nominal_snr_db, dtype=float)
    z = (s - n) / sigma_db
    # log N(s; n, sigma^2) - log P_D(n)
    log_f = -0.5 * z * z - np.log(sigma_db * np.sqrt(2.0 * np.pi)) - fluctuating_log_detection(n, sigma_db,
                                                                                                threshold_db)
    if threshold_db is None:
        return log_f
    return np.where(s >= threshold_db, log_f, -np.inf)


def detection_model(radar: RadarParameters, sigma_vr: float, *, rcs_dbsm: float | None = None,
                    snr_sigma_db: float | None = None, threshold_db: float | None = None) -> DetectionModel:
    """What a monostatic radar declares about its detections (:class:`~workbench.models.DetectionModel`):
    ``log P_D`` of a return of a given SNR by Marcum Q at the radar's ``Pfa``, the isotropic position sigma of
    :func:`position_sigma` at that SNR and range, and the radial-velocity sigma ``sigma_vr`` (m/s).

    With a design target of ``rcs_dbsm`` (dBsm) whose measured SNR fluctuates by ``snr_sigma_db`` (> 0) about the
    radar equation's, and a detector that reports returns reaching ``threshold_db`` (None: every return), it also
    declares the target's nominal SNR at a position (:func:`radar_snr`), the detector's ``P_D`` of that target
    (:func:`fluctuating_log_detection`) and the law of a detection's measured SNR
    (:func:`fluctuating_snr_log_density`).
    """
    target = {}
    if rcs_dbsm is not None and snr_sigma_db is not None and snr_sigma_db > 0:
        rcs = float(from_db(rcs_dbsm))
        sigma = float(snr_sigma_db)
        target = dict(
            nominal_snr_db=lambda position: db(radar_snr(np.linalg.norm(np.asarray(position, dtype=float), axis=-1),
                                                         rcs, radar)),
            log_detection=lambda nominal_db: fluctuating_log_detection(nominal_db, sigma, threshold_db),
            log_snr_density=lambda snr_db, nominal_db: fluctuating_snr_log_density(snr_db, nominal_db, sigma,
                                                                                   threshold_db),
        )
    return DetectionModel(
        log_pd=lambda snr_db: log_detection_probability(from_db(snr_db), radar.pfa),
        position_sigma=lambda snr_db, range_m: position_sigma(snr_db, range_m, radar),
        doppler_sigma=float(sigma_vr),
        pfa=float(radar.pfa),
        **target,
    )
