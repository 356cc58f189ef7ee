"""L-band surveillance radar of paper 000: 3-D position, Doppler and SNR per detection.

Per scan and run: the target's SNR follows the radar equation with an aspect-dependent RCS (front,
top, side by phase of the path) that fluctuates by ``rcs_sigma_db`` (dB, one draw per scan); the
target is detected when that SNR reaches ``threshold_db`` (CFAR-style: 12/9/7/5/3 dB in the paper).
A detection is drawn in spherical coordinates with SNR-dependent accuracy,
``sigma_R = c tau / (2 sqrt(2 SNR))`` and ``sigma_ang = theta_3dB / (1.6 sqrt(2 SNR))``, converted to
Cartesian, and carries the radial velocity ``vr = (p . v) / |p|`` (positive receding) plus noise.

Measurement vector ``z = [x, y, z, vr]``; ``Scans.snr`` holds the measured SNR (dB) and
``Scans.doppler`` the radial velocity again.  The published measurement model is
``h(s) = [x, y, z, (p . v)/|p|]`` with its Jacobian and a fixed ``R = diag(s_p^2, s_p^2, s_p^2, s_vr^2)``
(the brief's default pseudo-measurement noise; the paper-000 recipe replaces it per scan by the PDA-like
``R_bar`` of its pseudo-measurement step); it declares the position-doppler-3d frame and how its detections'
quality follows their SNR (``detection``: ``log P_D`` by Marcum Q, the position sigma at that SNR and range, the
radial-velocity sigma), for filters that weight detections by their own SNR.  Its design target is the
front-aspect (reference, ``rcs_ref_dbsm``) RCS: the detection model also declares that target's nominal SNR at a
position, the threshold detector's ``P_D = Phi((SNR - threshold) / rcs_sigma_db)`` and the law of a detection's
measured SNR (Gaussian in dB about the nominal, cut at the threshold), so that a filter can weigh how target-like a
detection's strength is.  The brighter top and side aspects are not part of the declared target (a filter does not
know the aspect); their detections are stronger than declared.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.models import MeasurementModel
from workbench.params import Param, defaults
from workbench.sensing.radar import (RadarParameters, angle_accuracy, aspect_rcs_db, cartesian_to_spherical, db,
                                     detection_model, from_db, position_radial_velocity,
                                     position_radial_velocity_jacobian, radar_snr, radial_velocity, range_accuracy,
                                     spherical_to_cartesian)
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth

RADAR_KEYS = tuple(RadarParameters().as_dict())

PARAMETERS = (
    Param("frequency", 1.3e9, "carrier frequency", unit="frequency", above=0.0),
    Param("peak_power", 10e3, "peak transmit power", unit="power", above=0.0),
    Param("pulse_width", 1e-6, "pulse width (bandwidth 1/tau)", unit="time", above=0.0),
    Param("pulses", 100, "pulses integrated coherently", "int", unit="dimensionless", minimum=1, maximum=10**9),
    Param("gain_tx_db", 35.0, "transmit antenna gain", unit="decibel"),
    Param("gain_rx_db", 35.0, "receive antenna gain", unit="decibel"),
    Param("noise_figure_db", 10.0, "receiver noise figure", unit="decibel", minimum=0.0),
    Param("loss_db", 6.0, "system losses", unit="decibel", minimum=0.0),
    Param("pfa", 1e-6, "false-alarm probability per cell", unit="dimensionless", above=0.0, maximum=1.0),
    Param("threshold_db", 5.0, "SNR detection threshold (none keeps every target return)", "float?",
          unit="decibel"),
    Param("rcs_ref_dbsm", -20.0, "front-aspect RCS (the paper's Ref)", unit="decibel"),
    # the aspects are not part of the declared target (a filter does not know the aspect): simulation only
    Param("rcs_offsets_db", (0.0, 5.0, 3.0), "RCS of the front, top and side aspects relative to Ref", "vector",
          unit="decibel", affects="simulation"),
    Param("aspect_change_times", (100.0, 160.0), "times at which the aspect changes (front -> top -> side)",
          "vector", unit="time", minimum=0.0, affects="simulation"),
    Param("rcs_sigma_db", 2.0, "RCS fluctuation, one draw per scan", unit="decibel", minimum=0.0),
    Param("sigma_vr", 2.0, "radial-velocity noise", unit="speed", minimum=0.0),
    Param("pseudo_sigma_pos", 300.0, "position sigma of the published R (the brief's pseudo-measurement noise)",
          unit="length", above=0.0, affects="noise"),
    Param("pseudo_sigma_vr", 10.0, "radial-velocity sigma of the published R", unit="speed", above=0.0,
          affects="noise"),
)
PARAMS = defaults(PARAMETERS)


def _radar(params: dict) -> RadarParameters:
    return RadarParameters(**{k: params[k] for k in RADAR_KEYS})


def _checked(params: dict) -> dict:
    unknown = set(params) - set(PARAMS)
    if unknown:
        raise InputError(f"lband-radar: unknown parameter(s) {sorted(unknown)}; known: {sorted(PARAMS)}")
    return {**PARAMS, **params}


def nominal_snr_db(truth: Truth, **params) -> np.ndarray:
    """The target's SNR (dB) without RCS fluctuation along the truth, ``(B, T)``."""
    p = _checked(params)
    rng_m = np.linalg.norm(truth.states[..., :3], axis=-1)
    rcs = aspect_rcs_db(truth.times, p["rcs_ref_dbsm"], p["rcs_offsets_db"], p["aspect_change_times"])
    return db(radar_snr(rng_m, from_db(rcs)[None, :], _radar(p)))


def simulate(truth: Truth, rng: np.random.Generator, **params) -> Scans:
    """Target detections for every run and scan: ``z (B, T, 1, 4)``, ``origin`` 0 (the target)."""
    p = _checked(params)
    radar = _radar(p)
    x = truth.states
    if x.shape[-1] != 6:
        raise InputError(f"lband-radar needs 3-D states [x, y, z, vx, vy, vz], got dimension {x.shape[-1]}")
    B, T, _ = x.shape
    # SNR with RCS fluctuation: snr_dB = SNR_k + N(0, sigma_RCS^2)
    snr_db = nominal_snr_db(truth, **params) + p["rcs_sigma_db"] * rng.standard_normal((B, T))
    snr = from_db(snr_db)
    sph = cartesian_to_spherical(x[..., :3])
    e = rng.standard_normal((B, T, 4))
    sph[..., 0] += range_accuracy(snr, radar.pulse_width) * e[..., 0]
    sph[..., 1:] += angle_accuracy(snr, radar.beamwidth)[..., None] * e[..., 1:3]
    vr = radial_velocity(x) + p["sigma_vr"] * e[..., 3]
    z = np.concatenate([spherical_to_cartesian(sph), vr[..., None]], axis=-1)
    detected = np.ones((B, T), dtype=bool) if p["threshold_db"] is None else snr_db >= p["threshold_db"]
    return Scans(z[:, :, None, :], detected[:, :, None], truth.times, snr=snr_db[:, :, None],
                 doppler=vr[:, :, None], origin=np.zeros((B, T, 1), dtype=int))


def _spherical_jacobian(sph: np.ndarray) -> np.ndarray:
    """``d[x, y, z] / d[range, azimuth, elevation]`` at ``sph (..., 3)``, ``(..., 3, 3)``."""
    r, az, el = sph[..., 0], sph[..., 1], sph[..., 2]
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    J = np.zeros(sph.shape[:-1] + (3, 3))
    # x = r cos(el) cos(az), y = r cos(el) sin(az), z = r sin(el)
    J[..., 0, 0], J[..., 0, 1], J[..., 0, 2] = ce * ca, -r * ce * sa, -r * se * ca
    J[..., 1, 0], J[..., 1, 1], J[..., 1, 2] = ce * sa, r * ce * ca, -r * se * sa
    J[..., 2, 0], J[..., 2, 2] = se, r * ce
    return J


def noise_cov(truth: Truth, scans: Scans, **params) -> np.ndarray:
    """The simulation noise of each detection, ``(B, T, M, 4, 4)``: the spherical accuracies at the detection's own
    SNR (``scans.snr``, the SNR its noise was drawn with), ``S = diag(sigma_R^2, sigma_ang^2, sigma_ang^2)``, carried
    to Cartesian by the Jacobian ``J`` of the spherical-to-Cartesian map at the true position (first order), and
    ``sigma_vr^2`` for the radial velocity.  The published ``R`` is the filters' pseudo-measurement noise instead."""
    p = _checked(params)
    radar = _radar(p)
    snr = from_db(scans.snr)
    sigma = np.stack([range_accuracy(snr, radar.pulse_width), angle_accuracy(snr, radar.beamwidth),
                      angle_accuracy(snr, radar.beamwidth)], axis=-1)
    J = _spherical_jacobian(cartesian_to_spherical(truth.states[:, :, None, :3]))
    cov = np.zeros(scans.z.shape + (4,))
    # C_pos = J S J^T
    cov[..., :3, :3] = (J * sigma[..., None, :] ** 2) @ np.swapaxes(J, -1, -2)
    cov[..., 3, 3] = p["sigma_vr"] ** 2
    return cov


def measurement_model(**params) -> MeasurementModel:
    """``h(s) = [x, y, z, (p . v)/|p|]``, its Jacobian and the pseudo-measurement noise ``R``."""
    p = _checked(params)
    R = np.diag([p["pseudo_sigma_pos"] ** 2] * 3 + [p["pseudo_sigma_vr"] ** 2])
    return MeasurementModel(
        name="position-radial-velocity",
        h=position_radial_velocity,
        R=R,
        jacobian=position_radial_velocity_jacobian,
        frame="position-doppler-3d",
        std=(p["pseudo_sigma_pos"],) * 3 + (p["pseudo_sigma_vr"],),
        sensor_position=(0.0, 0.0, 0.0),
        detection=detection_model(_radar(p), p["sigma_vr"], rcs_dbsm=p["rcs_ref_dbsm"],
                                  snr_sigma_db=p["rcs_sigma_db"] if p["rcs_sigma_db"] > 0 else None,
                                  threshold_db=p["threshold_db"]),
    )


LBAND_RADAR = SensorSpec(
    name="lband-radar",
    summary="L-band radar: 3-D position + Doppler + SNR, aspect-dependent fluctuating RCS, SNR threshold",
    measurement_model=measurement_model,
    simulate=simulate,
    params=PARAMS,
    parameters=PARAMETERS,
    frame="position-doppler-3d",
    noise_cov=noise_cov,
)


@hookimpl
def workbench_sensors():
    return [LBAND_RADAR]
