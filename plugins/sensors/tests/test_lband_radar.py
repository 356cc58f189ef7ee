"""The ``lband-radar`` sensor: detections with SNR-dependent accuracy, the CFAR-style threshold, the Doppler, and the
detection model it declares (checked against its own simulated detections)."""

import numpy as np
import pytest
from scipy.stats import norm

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing.radar import (RadarParameters, angle_accuracy, cartesian_to_spherical, db, detection_probability,
                                     from_db, position_sigma, radar_snr, radial_velocity, range_accuracy)
from workbench.types import InputError, Truth


@pytest.fixture(scope="module")
def sensor():
    return load_host().sensor("lband-radar")


def test_detections_accuracy_threshold_and_doppler(sensor):
    state = np.array([30e3, 4e3, 2e3, -150.0, 20.0, 0.0])
    truth = Truth(np.broadcast_to(state, (4000, 1, 6)).copy(), np.array([0.0]))
    scans = sensor.simulate(truth, generator(0, "sensor"), threshold_db=None)
    snr = scans.snr[:, 0, 0]
    nominal = db(radar_snr(np.linalg.norm(state[:3]), from_db(-20.0)))
    assert np.mean(snr) == pytest.approx(nominal, abs=0.1) and np.std(snr) == pytest.approx(2.0, rel=0.05)
    sph = cartesian_to_spherical(scans.z[:, 0, 0, :3]) - cartesian_to_spherical(state[:3])
    radar = RadarParameters()
    # errors normalised by the SNR-dependent sigmas are standard normal
    for err, sigma in ((sph[:, 0], range_accuracy(from_db(snr), radar.pulse_width)),
                       (sph[:, 1], angle_accuracy(from_db(snr), radar.beamwidth)),
                       (sph[:, 2], angle_accuracy(from_db(snr), radar.beamwidth))):
        assert np.mean((err / sigma) ** 2) == pytest.approx(1.0, abs=0.07)
    vr = scans.z[:, 0, 0, 3]
    assert np.mean(vr) == pytest.approx(radial_velocity(state), abs=0.2) and np.std(vr) == pytest.approx(2.0, rel=0.06)
    np.testing.assert_array_equal(scans.doppler[:, 0, 0], vr)
    cut = sensor.simulate(truth, generator(0, "sensor"), threshold_db=9.0)
    np.testing.assert_array_equal(cut.valid[:, 0, 0], snr >= 9.0)  # same draws, CFAR-style cut
    with pytest.raises(InputError, match="unknown parameter"):
        sensor.simulate(truth, generator(0), threshold=5)


def test_aspect_changes_the_rcs_by_the_offsets(sensor):
    state = np.array([30e3, 0.0, 2e3, -150.0, 0.0, 0.0])
    truth = Truth(np.broadcast_to(state, (3000, 3, 6)).copy(), np.array([50.0, 130.0, 200.0]))
    snr = sensor.simulate(truth, generator(1, "aspect"), threshold_db=None).snr[..., 0]
    # front Ref, top Ref + 5, side Ref + 3 dB
    np.testing.assert_allclose(snr.mean(axis=0) - snr.mean(axis=0)[0], [0.0, 5.0, 3.0], atol=0.15)


def test_measurement_model_and_declared_detection_quality(sensor):
    model = sensor.measurement_model(**sensor.params)
    state = np.array([30e3, 4e3, 2e3, -150.0, 20.0, 0.0])
    np.testing.assert_allclose(model.h(state[None])[0], [*state[:3], radial_velocity(state)])
    assert model.jacobian(state[None]).shape == (1, 4, 6) and model.detection.pfa == 1e-6
    assert model.frame == "position-doppler-3d" and model.detection.doppler_sigma == 2.0
    np.testing.assert_allclose(model.R, np.diag([300.0**2] * 3 + [10.0**2]))
    snrs = np.array([3.0, 8.0, 20.0])
    np.testing.assert_allclose(np.exp(model.detection.log_pd(snrs)), detection_probability(from_db(snrs)), rtol=1e-9)
    np.testing.assert_allclose(model.detection.position_sigma(snrs, 3e4), position_sigma(snrs, 3e4), rtol=1e-12)


@pytest.mark.parametrize("rcs", [-20.0, -17.0])
def test_declared_design_target_matches_the_simulated_detections(sensor, rcs):
    # at ranges where the nominal SNR is 4, 5.5 and 7 dB: the declared P_D and SNR law against what the sensor does
    configured = sensor.configure(rcs_ref_dbsm=rcs, threshold_db=5.0)
    det = configured.measurement_model(**configured.params).detection
    radar = RadarParameters()
    wanted = np.array([4.0, 5.5, 7.0])
    ranges = (radar_snr(1.0, from_db(rcs), radar) / from_db(wanted)) ** 0.25  # SNR ~ R^-4
    positions = np.column_stack([ranges, np.zeros(3), np.zeros(3)])
    np.testing.assert_allclose(det.nominal_snr_db(positions), wanted, atol=1e-9)
    states = np.concatenate([positions, np.zeros((3, 3))], axis=1)
    truth = Truth(np.broadcast_to(states[:, None, :], (3, 20000, 6)).transpose(1, 0, 2).copy(),
                  np.arange(3.0))  # 20000 runs, scan k at range k, all at the front aspect
    scans = configured.simulate(truth, generator(2, "design", rcs), **configured.params)
    detected = scans.valid[..., 0]
    np.testing.assert_allclose(detected.mean(axis=0), np.exp(det.log_detection(wanted)), atol=0.01)
    np.testing.assert_allclose(np.exp(det.log_detection(wanted)), norm.cdf((wanted - 5.0) / 2.0), rtol=1e-12)
    # the measured SNR of the detections: mean of the Gaussian cut at the threshold
    for k, n in enumerate(wanted):
        s = scans.snr[detected[:, k], k, 0]
        grid = np.linspace(5.0, n + 12.0, 4001)
        f = np.exp(det.log_snr_density(grid, n))
        assert np.trapezoid(f, grid) == pytest.approx(1.0, abs=1e-4)
        assert s.mean() == pytest.approx(np.trapezoid(grid * f, grid), abs=0.03)
        assert s.min() >= 5.0
    # a sensor that keeps every return declares P_D = 1
    every = sensor.configure(threshold_db=None)
    assert every.measurement_model(**every.params).detection.log_detection(np.array(-10.0)) == 0.0
