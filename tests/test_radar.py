"""Monostatic radar physics (``workbench.sensing.radar``): radar equation, Marcum-Q detection, accuracies,
coordinates, radial velocity, the amplitude laws of a fluctuating target and of exponential-power clutter, and the
detection model a radar declares."""

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.special import i0e

from workbench.sensing.radar import (BOLTZMANN, SPEED_OF_LIGHT, T0, RadarParameters, angle_accuracy, aspect_rcs_db,
                                     cartesian_to_spherical, clutter_pass_fraction, db, detection_model,
                                     detection_probability, exponential_power_log_density, fluctuating_log_detection,
                                     fluctuating_snr_log_density, from_db, log_detection_probability, marcum_q,
                                     north_detection_probability, position_radial_velocity,
                                     position_radial_velocity_jacobian, position_sigma, radar_snr, radial_velocity,
                                     range_accuracy, spherical_to_cartesian)


@pytest.mark.parametrize(("snr_db", "pd", "tol"), [(3, 0.0009, 0.00005), (5, 0.0046, 0.00005), (7, 0.025, 0.0005),
                                                   (9, 0.12, 0.005), (12, 0.68, 0.005), (13.2, 0.90, 0.005),
                                                   (15, 0.997, 0.0005)])
def test_detection_probability_matches_the_brief_table(snr_db, pd, tol):
    assert detection_probability(from_db(snr_db), 1e-6) == pytest.approx(pd, abs=tol)


def test_marcum_q_against_its_integral_and_north():
    # Q1(a, b) = int_b^inf x exp(-(x^2 + a^2)/2) I0(a x) dx, with I0 scaled to avoid overflow
    for a, b in [(0.5, 1.0), (3.0, 5.26), (6.0, 5.26), (2.0, 0.1)]:
        integral, _ = integrate.quad(lambda x: x * np.exp(-(x - a) ** 2 / 2) * i0e(a * x), b, np.inf)
        assert marcum_q(a, b) == pytest.approx(integral, rel=1e-8)
    snr = from_db(np.linspace(3, 18, 31))
    assert np.max(np.abs(north_detection_probability(snr) - detection_probability(snr))) < 0.02
    assert north_detection_probability(from_db(13.2)) == pytest.approx(0.90, abs=0.01)
    np.testing.assert_allclose(log_detection_probability(snr), np.log(detection_probability(snr)), rtol=1e-10,
                               atol=1e-14)
    assert detection_probability(0.0) == pytest.approx(1e-6, rel=1e-6)  # no signal: P_D = Pfa


def test_radar_equation_by_hand():
    r = RadarParameters()
    # SNR = Pt Gt Gr lambda^2 sigma N / ((4 pi)^3 R^4 k T0 B F L), written out for 30 km and 0.01 m^2
    lam = SPEED_OF_LIGHT / 1.3e9
    want = (10e3 * 10**3.5 * 10**3.5 * lam**2 * 0.01 * 100) / ((4 * np.pi) ** 3 * 30e3**4 * BOLTZMANN * T0 * 1e6 * 10
                                                                * 10**0.6)
    assert radar_snr(30e3, 0.01, r) == pytest.approx(want, rel=1e-12)
    assert db(radar_snr(15e3, 0.01, r)) - db(radar_snr(30e3, 0.01, r)) == pytest.approx(40 * np.log10(2), rel=1e-12)


def test_accuracies_and_coordinates():
    radar = RadarParameters()
    assert np.rad2deg(radar.beamwidth) == pytest.approx(2.9, abs=0.05)
    assert angle_accuracy(from_db(10.0), radar.beamwidth) == pytest.approx(7.1e-3, abs=1e-4)
    assert range_accuracy(from_db(10.0), radar.pulse_width) == pytest.approx(299792458e-6 / (2 * np.sqrt(20)))
    # the isotropic sigma is the root-sum-square of range and cross-range sigmas
    s = position_sigma(10.0, 3e4, radar)
    assert s == pytest.approx(np.hypot(range_accuracy(10.0, radar.pulse_width),
                                       3e4 * angle_accuracy(10.0, radar.beamwidth)), rel=1e-12)
    p = np.random.default_rng(0).normal(size=(50, 3)) * 2e4
    np.testing.assert_allclose(spherical_to_cartesian(cartesian_to_spherical(p)), p, atol=1e-7)
    sph = cartesian_to_spherical(np.array([[0.0, 1.0, 1.0]]))[0]
    np.testing.assert_allclose(sph, [np.sqrt(2), np.pi / 2, np.pi / 4])


def test_radial_velocity_sign_and_jacobian():
    receding = np.array([10e3, 0.0, 0.0, 50.0, 0.0, 0.0])
    approaching = np.array([10e3, 0.0, 0.0, -50.0, 3.0, 0.0])
    assert radial_velocity(receding) == pytest.approx(50.0) and radial_velocity(approaching) == pytest.approx(-50.0)
    x = np.random.default_rng(1).normal(size=(4, 6)) * [2e4, 2e4, 3e3, 200, 200, 20]
    jac = position_radial_velocity_jacobian(x)
    step = 1e-4 * np.maximum(np.abs(x), 1.0)
    for j in range(6):
        dx = np.zeros_like(x)
        dx[:, j] = step[:, j]
        fd = (position_radial_velocity(x + dx) - position_radial_velocity(x - dx)) / (2 * step[:, j:j + 1])
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=1e-6, atol=1e-9)


def test_aspect_schedule_keeps_the_change_time_in_the_earlier_phase():
    rcs = aspect_rcs_db(np.array([0.0, 100.0, 100.5, 160.0, 161.0]), -20.0, (0.0, 5.0, 3.0), (100.0, 160.0))
    np.testing.assert_allclose(rcs, [-20.0, -20.0, -15.0, -15.0, -17.0])


@pytest.mark.parametrize(("threshold", "count"), [(3.0, 370), (5.0, 206), (7.0, 82), (9.0, 19), (12.0, 0.4)])
def test_clutter_pass_fraction_gives_the_brief_counts(threshold, count):
    assert 1000 * clutter_pass_fraction(threshold) == pytest.approx(count, rel=0.02, abs=0.05)


def test_exponential_power_law_is_a_density_with_the_memoryless_tail():
    mu, t_db = 2.0, 5.0
    f = lambda s: np.exp(exponential_power_log_density(s, mu, t_db))  # noqa: E731
    total, _ = integrate.quad(f, t_db, 40.0, limit=200)
    assert total == pytest.approx(1.0, abs=1e-9)
    # P(SNR >= s | passed) = exp(-(p - t) / mu): the tail of the exponential above the threshold
    for s in (6.0, 9.0, 12.0):
        tail, _ = integrate.quad(f, s, 40.0, limit=200)
        assert tail == pytest.approx(np.exp(-(from_db(s) - from_db(t_db)) / mu), rel=1e-7)
    assert exponential_power_log_density(4.9, mu, t_db) == -np.inf
    # against sampled powers: Exp(mu) above t, in dB
    p = from_db(t_db) + np.random.default_rng(2).exponential(mu, 200_000)
    hist, edges = np.histogram(db(p), bins=np.linspace(t_db, 12.0, 29))
    expected = p.size * np.array([integrate.quad(f, a, b)[0] for a, b in zip(edges[:-1], edges[1:])])
    assert np.all(np.abs(hist - expected) < 5 * np.sqrt(expected) + 1)  # Poisson counts, 5 sigma


def test_fluctuating_detector_law_against_simulation():
    rng = np.random.default_rng(3)
    nominal, sigma, t = 6.0, 2.0, 5.0
    measured = nominal + sigma * rng.standard_normal(400_000)
    detected = measured[measured >= t]
    assert np.exp(fluctuating_log_detection(nominal, sigma, t)) == pytest.approx(detected.size / measured.size,
                                                                                abs=0.003)
    assert np.exp(fluctuating_log_detection(40.0, sigma, t)) == 1.0
    assert fluctuating_log_detection(-30.0, sigma, t) == pytest.approx(stats.norm.logcdf(-17.5), rel=1e-12)
    assert fluctuating_log_detection(np.array([0.0, 3.0]), sigma, None).tolist() == [0.0, 0.0]
    # the conditional density integrates to one above the threshold and matches the detected histogram
    f = lambda s: np.exp(fluctuating_snr_log_density(s, nominal, sigma, t))  # noqa: E731
    assert integrate.quad(f, t, 30.0)[0] == pytest.approx(1.0, abs=1e-9)
    hist, edges = np.histogram(detected, bins=np.linspace(t, 11.0, 25))
    expected = detected.size * np.array([integrate.quad(f, a, b)[0] for a, b in zip(edges[:-1], edges[1:])])
    assert np.all(np.abs(hist - expected) < 5 * np.sqrt(expected) + 1)  # Poisson counts, 5 sigma
    assert fluctuating_snr_log_density(4.0, nominal, sigma, t) == -np.inf


def test_detection_model_declares_the_design_target():
    radar = RadarParameters()
    bare = detection_model(radar, 2.0)
    assert bare.nominal_snr_db is None and bare.log_detection is None and bare.log_snr_density is None
    model = detection_model(radar, 2.0, rcs_dbsm=-20.0, snr_sigma_db=2.0, threshold_db=5.0)
    p = np.array([[56e3, 2e3, 3e3], [20e3, 0.0, 1e3]])
    np.testing.assert_allclose(model.nominal_snr_db(p), db(radar_snr(np.linalg.norm(p, axis=1), from_db(-20.0), radar)),
                               rtol=1e-12)
    assert np.exp(model.log_detection(np.array(5.0))) == pytest.approx(0.5)
    np.testing.assert_allclose(model.log_snr_density(np.array([7.0]), np.array([6.0])),
                               stats.norm.logpdf(7.0, 6.0, 2.0) - stats.norm.logcdf(0.5), rtol=1e-12)
    assert model.clutter_log_snr_density is None  # the sensor does not know its environment
    assert model.doppler_sigma == 2.0 and model.pfa == radar.pfa
