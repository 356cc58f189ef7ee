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
``R_bar`` of :func:`workbench.radar.pseudo_measurement_covariance`); its ``params`` carry the radar
parameters for filters that weight detections by their own SNR (method C and ``R_bar``).
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.models import MeasurementModel
from workbench.radar import (RadarParameters, angle_accuracy, aspect_rcs_db, cartesian_to_spherical, db, from_db,
                             position_radial_velocity, position_radial_velocity_jacobian, radar_snr,
                             radial_velocity, range_accuracy, spherical_to_cartesian)
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth

RADAR_KEYS = tuple(RadarParameters().as_dict())

PARAMS = {
    **RadarParameters().as_dict(),
    "threshold_db": 5.0,  # SNR threshold; None keeps every target return
    "rcs_ref_dbsm": -20.0,  # front-aspect RCS (the paper's "Ref")
    "rcs_offsets_db": (0.0, 5.0, 3.0),  # front, top, side relative to Ref (Table 2)
    "aspect_change_times": (100.0, 160.0),  # front for t <= 100 s, top for t <= 160 s, then side
    "rcs_sigma_db": 2.0,  # RCS fluctuation, one draw per scan
    "sigma_vr": 2.0,  # radial-velocity noise (m/s)
    "pseudo_sigma_pos": 300.0,  # R of the pseudo-measurement (methods A/B), position (m)
    "pseudo_sigma_vr": 10.0,  # and radial velocity (m/s)
}


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


def measurement_model(**params) -> MeasurementModel:
    """``h(s) = [x, y, z, (p . v)/|p|]``, its Jacobian and the pseudo-measurement noise ``R``."""
    p = _checked(params)
    R = np.diag([p["pseudo_sigma_pos"] ** 2] * 3 + [p["pseudo_sigma_vr"] ** 2])
    return MeasurementModel(
        name="position-radial-velocity",
        h=position_radial_velocity,
        R=R,
        jacobian=position_radial_velocity_jacobian,
        params={**{k: p[k] for k in RADAR_KEYS}, "beamwidth": _radar(p).beamwidth, "sigma_vr": p["sigma_vr"]},
    )


LBAND_RADAR = SensorSpec(
    name="lband-radar",
    summary="L-band radar: 3-D position + Doppler + SNR, aspect-dependent fluctuating RCS, SNR threshold",
    measurement_model=measurement_model,
    simulate=simulate,
    params=PARAMS,
)


@hookimpl
def workbench_sensors():
    return [LBAND_RADAR]
