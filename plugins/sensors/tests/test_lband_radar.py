"""The ``lband-radar`` sensor: detections with SNR-dependent accuracy, the CFAR-style threshold, the Doppler, and the
detection model it declares (checked against its own simulated detections).  The radar equation, the accuracy
laws and the Swerling-0 detection probability are written out here from their documented formulas (and SciPy's
Rice distribution), so that the sensor is compared with an independent computation, not with itself."""

import numpy as np
import pytest
from scipy.stats import norm, rice

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing.radar import cartesian_to_spherical
from workbench.types import InputError, Truth

C = 299_792_458.0  # m/s
K_BOLTZMANN = 1.380649e-23  # J/K
T0 = 290.0  # K
#: The sensor's defaults (its documentation): Pt 10 kW, Gt = Gr = 35 dBi, f 1.3 GHz, tau 1 us, 100 pulses, F 10 dB,
#: L 6 dB, Pfa 1e-6.
DEFAULTS = dict(peak_power=10e3, gain_tx_db=35.0, gain_rx_db=35.0, frequency=1.3e9, pulse_width=1e-6, pulses=100,
                noise_figure_db=10.0, loss_db=6.0, pfa=1e-6)


def _snr_db(range_m, rcs_dbsm, **radar):
    """The radar equation, ``SNR = Pt Gt Gr lambda^2 sigma N / ((4 pi)^3 R^4 k T0 B F L)`` with ``B = 1/tau``, in dB."""
    r = {**DEFAULTS, **radar}
    lam = C / r["frequency"]
    num = r["peak_power"] * 10 ** (r["gain_tx_db"] / 10) * 10 ** (r["gain_rx_db"] / 10) * lam ** 2 \
        * 10 ** (np.asarray(rcs_dbsm, dtype=float) / 10) * r["pulses"]
    den = (4 * np.pi) ** 3 * np.asarray(range_m, dtype=float) ** 4 * K_BOLTZMANN * T0 / r["pulse_width"] \
        * 10 ** (r["noise_figure_db"] / 10) * 10 ** (r["loss_db"] / 10)
    return 10 * np.log10(num / den)


def _sigmas(snr_db, **radar):
    """``sigma_R = c tau / (2 sqrt(2 SNR))`` and ``sigma_ang = theta_3dB / (1.6 sqrt(2 SNR))`` with the beamwidth
    ``theta_3dB = sqrt(4 pi 0.65 / G_r)`` (the documented accuracy laws)."""
    r = {**DEFAULTS, **radar}
    snr = 10 ** (np.asarray(snr_db, dtype=float) / 10)
    theta = np.sqrt(4 * np.pi * 0.65 / 10 ** (r["gain_rx_db"] / 10))
    return C * r["pulse_width"] / (2 * np.sqrt(2 * snr)), theta / (1.6 * np.sqrt(2 * snr))


def _radial_velocity(state):
    p, v = state[..., :3], state[..., 3:6]
    return np.sum(p * v, axis=-1) / np.sqrt(np.sum(p * p, axis=-1))


@pytest.fixture(scope="module")
def sensor():
    return load_host().sensor("lband-radar")


def test_detections_accuracy_threshold_and_doppler(sensor):
    state = np.array([30e3, 4e3, 2e3, -150.0, 20.0, 0.0])
    truth = Truth(np.broadcast_to(state, (4000, 1, 6)).copy(), np.array([0.0]))
    scans = sensor.simulate(truth, generator(0, "sensor"), threshold_db=None)
    snr = scans.snr[:, 0, 0]
    nominal = _snr_db(np.linalg.norm(state[:3]), -20.0)
    assert np.mean(snr) == pytest.approx(nominal, abs=0.1) and np.std(snr) == pytest.approx(2.0, rel=0.05)
    sph = cartesian_to_spherical(scans.z[:, 0, 0, :3]) - cartesian_to_spherical(state[:3])
    sigma_r, sigma_ang = _sigmas(snr)
    # errors normalised by the SNR-dependent sigmas are standard normal
    for err, sigma in ((sph[:, 0], sigma_r), (sph[:, 1], sigma_ang), (sph[:, 2], sigma_ang)):
        assert np.mean((err / sigma) ** 2) == pytest.approx(1.0, abs=0.07)
    vr = scans.z[:, 0, 0, 3]
    assert np.mean(vr) == pytest.approx(_radial_velocity(state), abs=0.2) and np.std(vr) == pytest.approx(2.0, rel=0.06)
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
    np.testing.assert_allclose(model.h(state[None])[0], [*state[:3], _radial_velocity(state)])
    assert model.jacobian(state[None]).shape == (1, 4, 6) and model.detection.pfa == 1e-6
    assert model.frame == "position-doppler-3d" and model.detection.doppler_sigma == 2.0
    np.testing.assert_allclose(model.R, np.diag([300.0**2] * 3 + [10.0**2]))
    snrs = np.array([3.0, 8.0, 20.0])
    # Swerling 0: P_D = Q1(sqrt(2 SNR), sqrt(-2 ln Pfa)), Marcum's Q1(a, b) being the Rice survival function at b
    snr = 10 ** (snrs / 10)
    expected_pd = rice.sf(np.sqrt(-2 * np.log(1e-6)), np.sqrt(2 * snr))
    np.testing.assert_allclose(np.exp(model.detection.log_pd(snrs)), expected_pd, rtol=1e-9)
    # the isotropic position sigma sqrt(sigma_R^2 + (R sigma_ang)^2) from the documented accuracy laws
    sigma_r, sigma_ang = _sigmas(snrs)
    np.testing.assert_allclose(model.detection.position_sigma(snrs, 3e4), np.hypot(sigma_r, 3e4 * sigma_ang),
                               rtol=1e-12)
    # and by hand at 20 dB, 30 km: sigma_R = c 1 us / (2 sqrt(200)) = 10.60 m, theta = 0.05082 rad,
    # sigma_ang = theta / (1.6 sqrt(200)) = 2.246 mrad, 30 km x 2.246 mrad = 67.38 m: sigma_p = 68.21 m
    assert model.detection.position_sigma(np.array(20.0), 3e4) == pytest.approx(68.21, abs=0.01)


def test_a_configured_radar_declares_its_own_accuracy_and_detection_probability(sensor):
    # a narrower receive gain (wider beam), a longer pulse and another Pfa: the declared model follows them
    configured = sensor.configure(gain_rx_db=30.0, pulse_width=2e-6, pfa=1e-4)
    det = configured.measurement_model(**configured.params).detection
    snrs = np.array([3.0, 8.0, 20.0])
    sigma_r, sigma_ang = _sigmas(snrs, gain_rx_db=30.0, pulse_width=2e-6)
    np.testing.assert_allclose(det.position_sigma(snrs, 1e4), np.hypot(sigma_r, 1e4 * sigma_ang), rtol=1e-12)
    # by hand at 20 dB, 10 km: sigma_R = 21.20 m, theta = 0.09038 rad, 10 km x 3.994 mrad = 39.94 m: 45.22 m
    assert det.position_sigma(np.array(20.0), 1e4) == pytest.approx(45.22, abs=0.01)
    expected_pd = rice.sf(np.sqrt(-2 * np.log(1e-4)), np.sqrt(2 * 10 ** (snrs / 10)))
    np.testing.assert_allclose(np.exp(det.log_pd(snrs)), expected_pd, rtol=1e-9)


@pytest.mark.parametrize("rcs", [-20.0, -17.0])
def test_declared_design_target_matches_the_simulated_detections(sensor, rcs):
    # at ranges where the nominal SNR is 4, 5.5 and 7 dB: the declared P_D and SNR law against what the sensor does
    configured = sensor.configure(rcs_ref_dbsm=rcs, threshold_db=5.0)
    det = configured.measurement_model(**configured.params).detection
    wanted = np.array([4.0, 5.5, 7.0])
    ranges = 10 ** ((_snr_db(1.0, rcs) - wanted) / 40)  # SNR ~ R^-4
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
