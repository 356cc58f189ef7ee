"""Paper 000 (TBD particle filter, L-band radar): radar maths, sensor, clutter, gating, filters, recipe."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import integrate
from scipy.special import i0e

from workbench.models import constant_velocity
from workbench.plugins import load_host
from workbench.sensing.radar import (RadarParameters, angle_accuracy, cartesian_to_spherical, clutter_pass_fraction,
                                     detection_probability, from_db, log_detection_probability, marcum_q,
                                     north_detection_probability, position_radial_velocity,
                                     position_radial_velocity_jacobian, radial_velocity, range_accuracy,
                                     spherical_to_cartesian, position_sigma)
from workbench.tracking import radius_gate
from workbench_papers.paper000.pipeline import (estimation_error, lost_track, measurement_error,
                                                pseudo_measurement_covariance, weighted_mean_measurement,
                                                whitened_model)
from workbench_papers.paper000 import recipe as paper000
from workbench.resampling import systematic_resample
from workbench.rng import generator
from workbench.specs import RecipeOptions, TaskContext
from workbench.types import CLUTTER, Gaussian, Particles, Scan, Truth


@pytest.fixture(scope="module")
def host():
    return load_host()


# -- radar maths ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("snr_db", "pd", "tol"), [(3, 0.0009, 0.00005), (5, 0.0046, 0.00005), (7, 0.025, 0.0005),
                                                   (9, 0.12, 0.005), (12, 0.68, 0.005), (13.2, 0.90, 0.005),
                                                   (15, 0.997, 0.0005)])
def test_detection_probability_matches_the_brief(snr_db, pd, tol):
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


def test_snr_checkpoints_along_the_scenario(host):
    truth = paper000.scenario_truth(1)
    assert truth.steps == 300
    res = paper000._scenario_task(TaskContext({"runs": 2, "thresholds": [5.0]}, seed=0, host=host))
    want = {0: 2.3, 50: 5.7, 100: 9.9, 130: 18.0, 160: 22.0, 200: 19.6, 299: 12.5}
    got = res["nominal_snr_db"]
    for k, snr in want.items():
        assert got[k] == pytest.approx(snr, abs=0.15), k
    # the path: approach along x, descent 3.0 -> 0.6 km, 90 deg turn, exit along +y
    s = truth.states[0]
    assert s[100, 2] == pytest.approx(3000.0) and s[160, 2] == pytest.approx(600.0)
    np.testing.assert_allclose(s[-1, 3:], [0.0, 200.0, 0.0], atol=1e-9)


def test_accuracies_and_coordinates():
    radar = RadarParameters()
    assert np.rad2deg(radar.beamwidth) == pytest.approx(2.9, abs=0.05)
    assert angle_accuracy(from_db(10.0), radar.beamwidth) == pytest.approx(7.1e-3, abs=1e-4)
    assert range_accuracy(from_db(10.0), radar.pulse_width) == pytest.approx(299792458e-6 / (2 * np.sqrt(20)))
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


# -- sensor and clutter -----------------------------------------------------------------------------------


def test_sensor_detections_accuracy_threshold_and_doppler(host):
    sensor = host.sensor("lband-radar")
    state = np.array([30e3, 4e3, 2e3, -150.0, 20.0, 0.0])
    truth = Truth(np.broadcast_to(state, (4000, 1, 6)).copy(), np.array([0.0]))
    scans = sensor.simulate(truth, generator(0, "sensor"), threshold_db=None)
    snr = scans.snr[:, 0, 0]
    assert np.std(snr) == pytest.approx(2.0, rel=0.05)  # RCS fluctuation
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
    model = sensor.measurement_model()
    np.testing.assert_allclose(model.h(state[None])[0], [*state[:3], radial_velocity(state)])
    assert model.jacobian(state[None]).shape == (1, 4, 6) and model.detection.pfa == 1e-6
    assert model.frame == "position-doppler-3d" and model.detection.doppler_sigma == 2.0
    # the declared detection quality is the radar's: Marcum-Q P_D and the SNR-dependent position sigma
    snrs = np.array([3.0, 8.0, 20.0])
    np.testing.assert_allclose(np.exp(model.detection.log_pd(snrs)), detection_probability(from_db(snrs)), rtol=1e-9)
    np.testing.assert_allclose(model.detection.position_sigma(snrs, 3e4), position_sigma(snrs, 3e4), rtol=1e-12)
    with pytest.raises(ValueError, match="unknown parameter"):
        sensor.simulate(truth, generator(0), threshold=5)


@pytest.mark.parametrize(("threshold", "count"), [(3.0, 370), (5.0, 206), (7.0, 82), (9.0, 19), (12.0, 0.4)])
def test_clutter_count_per_threshold_follows_the_amplitude_law(threshold, count):
    assert 1000 * clutter_pass_fraction(threshold) == pytest.approx(count, rel=0.02, abs=0.05)


def test_clutter_generator_counts_power_and_doppler(host):
    gen = host.clutter_generator("radar-clutter")
    truth = Truth(np.broadcast_to([20e3, 0.0, 3e3, 0, 0, 0], (50, 40, 6)).copy(), np.arange(40.0))
    wide = gen.generate(truth, generator(0, "clutter"), z_min=-1e9, z_max=1e9)
    per_scan = wide.valid.sum(axis=2)
    assert per_scan.mean() == pytest.approx(205.7, abs=3 * np.sqrt(205.7 / per_scan.size) + 0.5)
    assert per_scan.var() == pytest.approx(205.7, rel=0.1)  # Poisson
    snr = wide.snr[wide.valid]
    assert snr.min() >= 5.0
    # memoryless thinning: P(power >= 7 dB | power >= 5 dB) = exp(-(10^0.7 - 10^0.5) / 2)
    assert np.mean(snr >= 7.0) == pytest.approx(np.exp(-(from_db(7.0) - from_db(5.0)) / 2), abs=0.01)
    pos = wide.z[wide.valid][:, :3] - [20e3, 0.0, 3e3]
    assert np.all(np.abs(pos) <= 5000.0) and np.all(wide.origin[wide.valid] == CLUTTER)
    assert np.abs(wide.doppler[wide.valid]).max() <= 300.0
    band = gen.generate(truth, generator(0, "clutter"))
    kept = band.z[band.valid][:, 2]
    assert kept.min() >= 0.0 and kept.max() <= 6000.0
    assert band.valid.sum(axis=2).mean() == pytest.approx(205.7 * 0.6, rel=0.03)  # z in [-2, 8] km, band 0..6


# -- gating, pseudo-measurement, metrics ------------------------------------------------------------------


def test_gate_keeps_detections_inside_the_radius_batch_first():
    z = np.zeros((2, 5, 4))
    z[0, :, 0] = [0.0, 900.0, 1100.0, -2400.0, 2600.0]
    z[1, :, 1] = [5000.0, 6000.0, 0.0, 0.0, 0.0]
    valid = np.array([[True] * 5, [True, True, False, False, False]])
    scan = Scan(z, valid, snr=np.full((2, 5), 6.0), origin=np.array([[0, -1, -1, -1, -1]] * 2))
    g1, keep1 = radius_gate(scan, np.zeros((2, 3)), 1000.0)
    assert g1.counts.tolist() == [2, 0] and g1.z.shape == (2, 2, 4)
    np.testing.assert_array_equal(g1.z[0, :2, 0], [0.0, 900.0])
    assert keep1.tolist() == [[True, True, False, False, False], [False] * 5]
    g25, _ = radius_gate(scan, np.zeros((2, 3)), 2500.0)
    assert g25.counts.tolist() == [4, 0]
    assert g25.origin[0, 0] == 0 and np.all(g25.snr[0, :4] == 6.0)


def test_weighted_mean_measurement_eqs_9_to_11(host):
    model = host.sensor("lband-radar").measurement_model()
    pred = np.array([[1e4, 0.0, 0.0, -100.0, 0.0, 0.0]] * 3)
    z = np.array([[[1e4 + 300, 0.0, 0.0, -100.0], [1e4 - 300, 0.0, 0.0, -100.0]]] * 3)
    snr = np.array([[8.0, 8.0], [8.0, 14.0], [8.0, 8.0]])
    valid = np.array([[True, True], [True, True], [False, False]])
    out = weighted_mean_measurement(Scan(z, valid, snr=snr), pred, model, 500.0, 15.0)
    assert out.valid[:, 0].tolist() == [True, True, False]
    np.testing.assert_allclose(out.z[0, 0], [1e4, 0.0, 0.0, -100.0])  # symmetric: the midpoint
    w = detection_probability(from_db(np.array([8.0, 14.0])))
    np.testing.assert_allclose(out.z[1, 0, 0], (w[0] * (1e4 + 300) + w[1] * (1e4 - 300)) / w.sum())
    single = weighted_mean_measurement(Scan(z[:1, :1], valid[:1, :1], snr=snr[:1, :1]), pred[:1], model)
    np.testing.assert_allclose(single.z[0, 0], z[0, 0])


def test_pseudo_measurement_covariance_is_the_pda_like_r_bar(host):
    model = host.sensor("lband-radar").measurement_model()
    pred = np.array([[3e4, 0.0, 0.0, -100.0, 0.0, 0.0]] * 3)
    z = np.array([[[3e4 + 300, 0.0, 0.0, -100.0], [3e4 - 300, 0.0, 0.0, -100.0]]] * 3)
    z[2, 0, 3] = 20.0  # a lone detection with a Doppler 120 m/s off the prediction
    snr = np.array([[8.0, 8.0], [8.0, 8.0], [8.0, 8.0]])
    valid = np.array([[True, True], [False, False], [True, False]])
    z_bar, r_bar = pseudo_measurement_covariance(Scan(z, valid, snr=snr), pred, model, 500.0, 15.0,
                                                 doppler_mismatch=True)
    var_p = position_sigma(8.0, np.linalg.norm(z[0, :, :3], axis=-1)) ** 2
    # two symmetric detections of equal weight: sum w R_m + spread (300 m along x)
    want = np.diag([var_p.mean() + 300.0**2, var_p.mean(), var_p.mean(), 2.0**2])
    np.testing.assert_allclose(r_bar[0], want, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(r_bar[1], np.eye(4))  # no detection: identity, ignored by the filter
    # the lone detection: its own accuracy, and the Doppler mismatch to the prediction in the vr variance
    var_2 = position_sigma(8.0, np.linalg.norm(z[2, 0, :3])) ** 2
    np.testing.assert_allclose(r_bar[2], np.diag([var_2] * 3 + [2.0**2 + 120.0**2]), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(z_bar.z[2, 0], z[2, 0])


def test_whitened_model_gives_the_ekf_update_with_r_bar(host):
    model = host.sensor("lband-radar").measurement_model()
    rng = np.random.default_rng(3)
    mean = np.array([[3e4, 1e3, 2e3, -200.0, 10.0, 0.0], [2e4, -5e3, 1e3, 50.0, 150.0, -5.0]])
    a = rng.normal(size=(2, 6, 6))
    cov = a @ np.swapaxes(a, 1, 2) * 100.0 + np.eye(6) * 1e4
    z = model.h(mean) + rng.normal(size=(2, 4)) * [300.0, 300.0, 300.0, 5.0]
    b = rng.normal(size=(2, 4, 4))
    r_bar = b @ np.swapaxes(b, 1, 2) * 1e3 + np.diag([1e5, 1e5, 1e5, 10.0])
    scan, white = whitened_model(model, Scan.single(z), r_bar)
    out = host.filter("ekf").update(Gaussian(mean, cov), scan, white, None)
    for i in range(2):  # the textbook EKF update with R_bar, item by item
        H = model.jacobian(mean[i:i + 1])[0]
        S = H @ cov[i] @ H.T + r_bar[i]
        K = cov[i] @ H.T @ np.linalg.inv(S)
        np.testing.assert_allclose(out.mean[i], mean[i] + K @ (z[i] - model.h(mean[i])), rtol=1e-9)
        np.testing.assert_allclose(out.cov[i], (np.eye(6) - K @ H) @ cov[i], rtol=1e-6, atol=1e-6)
    # the particle likelihood is N(z; h(x), R_bar) up to a constant per item
    particles = mean[:, None, :] + rng.normal(size=(2, 5, 6)) * 100.0
    nu = scan.z[:, 0][:, None, :] - white.h(particles)
    got = -0.5 * np.sum(nu**2, axis=-1)
    d = z[:, None, :] - model.h(particles)
    want = -0.5 * np.einsum("bni,bni->bn", d, np.linalg.solve(r_bar[:, None], d[..., None])[..., 0])
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_error_metrics_and_lost_flag():
    z = np.array([[[3.0, 4.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]], [[0.0] * 4, [0.0] * 4]])
    m = measurement_error(z, np.array([[True, True], [False, False]]), np.zeros((2, 3)))
    assert m[0] == pytest.approx(2.5) and np.isnan(m[1])
    assert estimation_error(np.array([[3.0, 4.0, 12.0, 9.0]]), np.zeros((1, 6)))[0] == pytest.approx(13.0)
    err = np.array([[0, 4e3, 4e3, 4e3, 4e3, 0, 0], [0, 4e3, 4e3, 4e3, 4e3, 4e3, 0], [5e3] * 7])
    assert lost_track(err, 3000.0, 5).tolist() == [False, True, True]


def test_systematic_resampling_counts_are_floor_or_ceil():
    w = np.array([[0.5, 0.25, 0.125, 0.0625, 0.0625, 0.0]])
    for seed in range(20):
        with np.errstate(divide="ignore"):
            idx = systematic_resample(np.log(w), np.random.default_rng(seed), count=16)
        counts = np.bincount(idx[0], minlength=6)
        expected = 16 * w[0]
        assert np.all((counts == np.floor(expected)) | (counts == np.ceil(expected)))


# -- method C filter --------------------------------------------------------------------------------------


def _cloud(host, n=400, seed=0):
    spec = paper000.with_particles(host.filter("tbd-pf"), n)
    prior = Gaussian.broadcast([30e3, 2e3, 2e3, -200.0, 0.0, 0.0], np.diag([300.0, 300, 300, 20, 20, 5]) ** 2, 2)
    return spec, spec.init(prior, generator(seed, "cloud"))


def test_tbd_filter_moves_towards_a_consistent_detection(host):
    spec, state = _cloud(host)
    model = host.sensor("lband-radar").measurement_model()
    assert "multi_measurement" in spec.capabilities and spec.params["particles"] == 400
    target = np.array([30.2e3, 2e3, 2e3, -199.0])
    z = np.stack([np.stack([target, [30e3, 2.5e3, 2e3, 150.0]])] * 2)  # + a Doppler-inconsistent clutter point
    scan = Scan(z, np.array([[True, True], [False, False]]), snr=np.full((2, 2), 15.0))
    new = spec.update(state, scan, model, generator(1))
    before, after = spec.estimate(state).mean, spec.estimate(new).mean
    assert after[0, 0] - before[0, 0] > 100.0  # pulled towards x = 30.2 km
    np.testing.assert_array_equal(new.cloud.particles[1], state.cloud.particles[1])  # empty gate: unchanged
    np.testing.assert_array_equal(new.cloud.log_weights[1], state.cloud.log_weights[1])
    again = spec.update(state, scan, model, generator(1))
    np.testing.assert_array_equal(again.cloud.particles, new.cloud.particles)  # same seed, same numbers


def test_tbd_filter_weights_finite_when_every_likelihood_underflows(host):
    spec, state = _cloud(host)
    model = host.sensor("lband-radar").measurement_model()
    z = np.array([[[400e3, 0.0, 0.0, 100.0]]] * 2)
    scan = Scan(z, np.ones((2, 1), bool), snr=np.full((2, 1), 25.0))
    for name in ("tbd-pf", "tbd-pf-eps0"):
        spec = paper000.with_particles(host.filter(name), 400)
        new = spec.update(state, scan, model, generator(2))
        lw = new.cloud.log_weights
        assert np.all(np.isfinite(lw)) and np.allclose(np.exp(lw).sum(axis=1), 1.0)


def test_tbd_filter_backends_agree(host):
    from workbench_filters.tbd import make_tbd_pf

    model = host.sensor("lband-radar").measurement_model()
    rng = np.random.default_rng(4)
    z = np.concatenate([rng.normal(size=(2, 6, 3)) * 500 + [30e3, 2e3, 2e3], rng.normal(size=(2, 6, 1)) * 50 - 200],
                       axis=2)
    scan = Scan(z, rng.random((2, 6)) < 0.8, snr=rng.uniform(5, 15, (2, 6)))
    _, state = _cloud(host)
    outs = [make_tbd_pf(400, backend=be, threshold=0.0).update(state, scan, model, generator(3)).cloud.log_weights
            for be in ("numpy", "taichi", "auto")]
    np.testing.assert_allclose(outs[1], outs[0], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(outs[2], outs[0], rtol=1e-10, atol=1e-10)


# -- manoeuvre handling shared by methods A, B and C ---------------------------------------------------------


def test_jump_markov_prediction_switches_modes_and_scales_the_noise():
    from workbench.particle_core import ParticleState
    from workbench_filters.tbd import ModeState, predict_jump_markov

    motion = constant_velocity(3, 1.0, (10.0, 10.0, 5.0))
    B, N = 2, 20000
    x = np.zeros((B, N, 6))
    mode = np.zeros((B, N))
    mode[:, : N // 2] = 1.0
    state = ModeState(Particles(x, np.full((B, N), -np.log(N))), 0, 0, mode)
    out = predict_jump_markov(state, motion, generator(0, "jm"), switch_on=0.05, switch_off=0.2, scale=4.0)
    new = out.mode
    # quiet -> manoeuvre with 0.05, manoeuvre -> quiet with 0.2 (binomial, 5 standard errors)
    for old, want in ((0.0, 0.05), (1.0, 0.8)):
        frac = new[mode == old].mean()
        assert abs(frac - want) < 5 * np.sqrt(want * (1 - want) / (B * N / 2))
    # the noise: W in the quiet mode, scale^2 W in the manoeuvre mode (sample covariance, 10 % band)
    for m, factor in ((0.0, 1.0), (1.0, 16.0)):
        d = out.cloud.particles[new == m]
        np.testing.assert_allclose(np.cov(d.T), factor * motion.Q, rtol=0.1, atol=0.02 * factor * motion.Q.max())
    # a plain particle state starts quiet
    plain = ParticleState(Particles(x, np.full((B, N), -np.log(N))))
    assert predict_jump_markov(plain, motion, generator(1), switch_on=0.0, switch_off=0.2, scale=4.0).mode.sum() == 0


def test_resampling_carries_each_particle_s_mode(host):
    from workbench_filters.tbd import ModeState, make_sir_jm

    model = host.sensor("lband-radar").measurement_model()
    rng = np.random.default_rng(5)
    x = np.array([3e4, 1e3, 2e3, -200.0, 0.0, 0.0]) + rng.normal(size=(2, 500, 6)) * [400, 400, 300, 30, 30, 10]
    mode = (x[..., 0] > 3e4).astype(float)  # a function of the particle, so it must survive resampling with it
    state = ModeState(Particles(x, np.full((2, 500), -np.log(500))), 0, 0, mode)
    z = model.h(np.array([[3.03e4, 1e3, 2e3, -200.0, 0.0, 0.0]] * 2))
    spec = make_sir_jm(500, threshold=1.0)
    new = spec.update(state, Scan.single(z), model, generator(2))
    assert new.resamples == 2
    np.testing.assert_array_equal(new.mode, (new.cloud.particles[..., 0] > 3e4).astype(float))
    # without resampling: log w_i + log N(z; h(x_i), R), normalised (NumPy reference), modes untouched
    kept = make_sir_jm(500, threshold=0.0).update(state, Scan.single(z), model, generator(2))
    d = z[:, None, :] - model.h(x)
    log_w = -0.5 * np.einsum("bni,ij,bnj->bn", d, np.linalg.inv(model.R), d)
    want = log_w - np.log(np.exp(log_w - log_w.max(1, keepdims=True)).sum(1, keepdims=True)) - log_w.max(1, keepdims=True)
    np.testing.assert_allclose(kept.cloud.log_weights, want, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(kept.mode, mode)


def test_moment_matched_noise_of_the_ekf():
    from workbench_papers.paper000.pipeline import moment_matched_scale

    # stationary share on / (on + off) = 0.2; variance factor 0.8 + 0.2 * 16 = 4
    assert moment_matched_scale(0.05, 0.2, 4.0) == pytest.approx(2.0)
    assert moment_matched_scale(0.0, 0.2, 4.0) == pytest.approx(1.0)


def test_ekf_nis_switches_its_noise_on_a_large_innovation(host):
    from workbench_filters.tbd import make_ekf_nis

    spec = make_ekf_nis()
    model = host.sensor("lband-radar").measurement_model()
    motion = constant_velocity(3, 1.0, (10.0, 10.0, 5.0))
    mean = np.array([[3e4, 1e3, 2e3, -200.0, 0.0, 0.0]] * 3)
    prior = Gaussian(mean, np.broadcast_to(np.diag([100.0, 100, 100, 10, 10, 5]) ** 2, (3, 6, 6)).copy())
    state = spec.init(prior, None)
    z = model.h(mean) + np.array([[30.0, 0, 0, 1.0], [3000.0, 0, 0, 1.0], [0.0, 0, 0, 0]])
    scan = Scan(z[:, None, :], np.array([[True], [True], [False]]))
    new = spec.update(state, scan, model, None)
    assert new.manoeuvre.tolist() == [False, True, False]  # NIS 0.1 vs about 1000 (chi2_4 99 % = 13.3)
    # the update itself is the EKF's
    ekf = host.filter("ekf").update(prior, scan, model, None)
    np.testing.assert_allclose(spec.estimate(new).mean, ekf.mean)
    # next prediction: Q for quiet items, scale^2 Q for the flagged one
    pred = spec.predict(new, motion, None).gaussian
    base = host.filter("ekf").predict(ekf, motion, None)
    np.testing.assert_allclose(pred.cov[0], base.cov[0], rtol=1e-12)
    np.testing.assert_allclose(pred.cov[1], base.cov[1] + 15.0 * motion.Q, rtol=1e-9)


def test_every_method_runs_with_the_quiet_noise_and_others_with_the_moment_match(host):
    quiet = paper000.motion_for(host.filter("tbd-pf"), host.filter("tbd-pf"))
    np.testing.assert_allclose(quiet.Q, constant_velocity(3, 1.0, paper000.SIGMA_A).Q)
    np.testing.assert_allclose(paper000.motion_for(host.filter("ekf-nis"), host.filter("tbd-pf")).Q, quiet.Q)
    plain = paper000.motion_for(host.filter("ekf"), host.filter("tbd-pf"))
    np.testing.assert_allclose(plain.Q, 4.0 * quiet.Q)


# -- the report recipe ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def results(host):
    recipe = host.recipe("000")
    values = {"runs": 2, "path_particles": [100, 600], "radii": [2500.0, 1000.0], "sweep_particles": [100, 600]}
    options = RecipeOptions(size="test", values=values, seed=1, filters=recipe.default_filters)
    tasks = recipe.tasks(options)
    keys = [t.key for t in tasks]
    assert len(keys) == len(set(keys))
    return {t.key: {k: np.asarray(v) for k, v in t.run(TaskContext(t.params, seed=1, host=host)).items()}
            for t in tasks}


def test_recipe_tasks_cover_the_grid_and_honour_filters(host):
    recipe = host.recipe("000")
    options = RecipeOptions("full", recipe.sizes["full"], 0, ("ekf-nis", "sir-jm", "tbd-pf", "ukf"))
    keys = {t.key for t in recipe.tasks(options)}
    assert "track-ukf-N600-R1000" in keys and "track-tbd-pf-N50-R1000" in keys and "track-tbd-pf-N100-R2500" in keys
    assert recipe.sizes["full"]["runs"] == 20 and len(recipe.sizes["full"]["sweep_particles"]) == 9


def test_report_figures_hold_the_scenario_and_the_runs(host, results):
    recipe = host.recipe("000")
    figs = {f.id: f.data(results) for f in recipe.figures}
    assert {"fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "fig11", "fig12",
            "fig13"} <= set(figs)
    np.testing.assert_allclose(figs["fig2"]["truth_km"][0], [56.0, 2.0, 3.0])
    assert figs["fig3"]["thresholds_db"].tolist() == [12.0, 9.0, 7.0, 5.0, 3.0]
    counts = results["scenario"]["count_per_scan"].mean(axis=1)
    assert np.all(np.diff(counts) > 0)  # lower threshold, more detections
    np.testing.assert_array_equal(figs["fig5_counts"]["count_per_scan"], results["scenario"]["count_per_scan"])
    assert figs["fig5_counts"]["k"].shape[0] == figs["fig5_counts"]["count_per_scan"].shape[1]
    assert results["scenario"]["clutter_per_scan"][3] == pytest.approx(results["scenario"]["clutter_expected"][3],
                                                                      rel=0.05)
    tgt = figs["fig7"]["gated_target_R1000"]
    assert tgt.any() and figs["fig7"]["gated_km_R2500"].shape[0] > figs["fig7"]["gated_km_R1000"].shape[0]
    assert figs["fig9"]["estimate_km_R1000"].shape == (300, 3)
    assert figs["fig12"]["particles"].tolist() == [100, 600] and figs["fig12"]["e_avg_mean"].shape == (2,)
    assert set(figs["fig13"]["filters"]) == {"ekf-nis", "sir-jm", "tbd-pf", "tbd-pf-eps0"}
    e = results["track-tbd-pf-N600-R1000"]["error"]
    np.testing.assert_allclose(figs["fig10"]["e_error_R1000"], e.mean(axis=0))
    from matplotlib.figure import Figure

    for spec in recipe.figures:
        fig = Figure()
        spec.draw(figs[spec.id], fig)
        assert fig.axes, spec.id


def test_report_table3_and_criteria_are_computed(host, results):
    recipe = host.recipe("000")
    table = next(t for t in recipe.tables if t.id == "table3").make(results)
    rows = {r[0]: r for r in table.rows}
    assert rows["(A) ekf-nis"][3:5] == (332.0, 236.0) and rows["(B) sir-jm"][3:5] == (291.0, 214.0)
    assert rows["(C) tbd-pf"][3:5] == (221.0, 124.0)
    e = results["track-tbd-pf-N600-R1000"]["error"]
    assert rows["(C) tbd-pf"][1] == pytest.approx(round(e[:, 1:101].mean(), 1))
    assert rows["(C) tbd-pf"][2] == pytest.approx(round(e[:, 1:].mean(), 1))
    crit = recipe.criteria(results)
    assert [c.id for c in crit] == ["1", "2", "3", "4", "5", "6"]
    a = results["track-ekf-nis-N600-R1000"]["error"][:, 1:].mean()
    ratio = a / e[:, 1:].mean()
    assert crit[1].met == (ratio >= 1.3) and f"{ratio:.2f}" in crit[1].detail
    clutter = next(t for t in recipe.tables if t.id == "table_clutter").make(results)
    assert [r[1] for r in clutter.rows] == [0.4, 18.8, 81.6, 205.7, 368.8]
    assert "sigma_a" in recipe.notes and recipe.published["table3_whole_m"]["C"] == 124.0


# -- lost-track remedies: regularised resampling (C), clutter floor / PDA update (A, B) ---------------------


def test_regularisation_bandwidth_and_jitter_follow_the_kernel_covariance():
    from workbench_filters.tbd import regularisation_bandwidth, regularise

    # h_opt = (4 / (N (n + 2)))^(1 / (n + 4)): n = 1 gives Silverman's 1.06 N^(-1/5)
    assert regularisation_bandwidth(600, 6) == pytest.approx((4.0 / 4800.0) ** 0.1)
    assert regularisation_bandwidth(1000, 1) == pytest.approx((4.0 / 3.0) ** 0.2 * 1000 ** -0.2)
    B, N = 2, 40000
    cov = np.diag([400.0, 400.0, 300.0, 30.0, 30.0, 10.0]) ** 2
    x = np.zeros((B, N, 6))
    rows = np.array([True, False])
    out = regularise(x, np.broadcast_to(cov, (B, 6, 6)), rows, 0.5, generator(0, "reg"))
    h = 0.5 * regularisation_bandwidth(N, 6)
    # the jitter of a resampled row is N(0, h^2 cov) (sample covariance, 5 % band); other rows untouched
    np.testing.assert_allclose(np.cov(out[0].T), h**2 * cov, rtol=0.05, atol=0.01 * h**2 * cov.max())
    np.testing.assert_array_equal(out[1], x[1])
    np.testing.assert_array_equal(regularise(x, cov[None].repeat(2, 0), rows, 0.0, generator(0)), x)


def test_tbd_filter_regularises_only_after_resampling(host):
    from workbench_filters.tbd import make_tbd_pf

    model = host.sensor("lband-radar").measurement_model()
    _, state = _cloud(host)
    z = np.array([[[30.1e3, 2e3, 2e3, -200.0]]] * 2)
    scan = Scan(z, np.array([[True], [False]]), snr=np.full((2, 1), 15.0))
    plain = make_tbd_pf(400, regularisation=0.0).update(state, scan, model, generator(3))
    jittered = make_tbd_pf(400, regularisation=0.5).update(state, scan, model, generator(3))
    assert plain.resamples == jittered.resamples == 1  # the sharp detection collapses item 0's N_eff
    n_distinct = lambda s: len(np.unique(s.cloud.particles[0, :, 0]))  # noqa: E731
    assert n_distinct(plain) < 400 and n_distinct(jittered) == 400  # copies made distinct
    np.testing.assert_array_equal(jittered.cloud.particles[1], state.cloud.particles[1])  # empty gate
    assert make_tbd_pf().params["regularisation"] == 0.5


def test_sir_clutter_floor_is_the_mixture_likelihood(host):
    from scipy.stats import multivariate_normal

    from workbench_filters.tbd import make_sir_jm

    model = host.sensor("lband-radar").measurement_model()
    rng = np.random.default_rng(6)
    x = np.array([3e4, 1e3, 2e3, -200.0, 0.0, 0.0]) + rng.normal(size=(2, 300, 6)) * [400, 400, 300, 30, 30, 10]
    from workbench_filters.tbd import ModeState

    state = ModeState(Particles(x, np.full((2, 300), -np.log(300))), 0, 0, np.zeros((2, 300)))
    z_bar = np.array([[3.1e4, 1.2e3, 2e3, 150.0], [3.0e4, 1e3, 2e3, -200.0]])
    r_bar = np.stack([np.diag([600.0, 600, 600, 120]) ** 2, np.diag([300.0, 300, 300, 10]) ** 2])
    lam = 3.5e-12
    step = Scan.single(z_bar, cov=r_bar, clutter_density=np.full(2, lam))
    new = make_sir_jm(300, threshold=0.0).update(state, step, model, generator(1))
    # NumPy/SciPy reference on the un-whitened pseudo-measurement: w_i ∝ lambda + N(z_bar; h(x_i), R_bar)
    for b in range(2):
        lik = lam + multivariate_normal(z_bar[b], r_bar[b]).pdf(model.h(x[b]))
        np.testing.assert_allclose(np.exp(new.cloud.log_weights[b]), lik / lik.sum(), rtol=1e-9)
    # a Doppler-inconsistent (clutter) pseudo-measurement hardly moves the weights; without the floor it does
    bare = make_sir_jm(300, threshold=0.0).update(state, Scan.single(z_bar, cov=r_bar), model, generator(1))
    spread = lambda lw: np.exp(lw.max() - lw.min())  # noqa: E731
    assert spread(new.cloud.log_weights[0]) < 30.0 < spread(bare.cloud.log_weights[0])


def test_ekf_pda_update_against_the_textbook_pdaf(host):
    from scipy.stats import multivariate_normal

    from workbench_filters.tbd import make_ekf_nis

    model = host.sensor("lband-radar").measurement_model()
    mean = np.array([[3e4, 1e3, 2e3, -200.0, 0.0, 0.0]] * 3)
    P = np.broadcast_to(np.diag([300.0, 300, 300, 20, 20, 10]) ** 2, (3, 6, 6)).copy()
    prior = Gaussian(mean, P)
    z = model.h(mean) + np.array([[100.0, 0, 0, 2.0], [1500.0, -900.0, 0, 250.0], [0.0, 0, 0, 0]])
    valid = np.array([True, True, False])
    lam = 3.5e-12
    spec = make_ekf_nis()
    density = np.full((3, 1), lam)
    new = spec.update(spec.init(prior, None), Scan(z[:, None, :], valid[:, None], clutter_density=density), model,
                      None)
    ekf = host.filter("ekf").update(prior, Scan(z[:, None, :], valid[:, None]), model, None)
    for b in range(2):
        H = model.jacobian(mean[b:b + 1])[0]
        S = H @ P[b] @ H.T + model.R
        nu = z[b] - model.h(mean[b])
        beta0 = lam / (lam + multivariate_normal(np.zeros(4), S).pdf(nu))
        K = P[b] @ H.T @ np.linalg.inv(S)
        want_mean = mean[b] + (1 - beta0) * K @ nu
        want_cov = beta0 * P[b] + (1 - beta0) * ekf.cov[b] + beta0 * (1 - beta0) * np.outer(K @ nu, K @ nu)
        np.testing.assert_allclose(new.gaussian.mean[b], want_mean, rtol=1e-9)
        np.testing.assert_allclose(new.gaussian.cov[b], want_cov, rtol=1e-7, atol=1e-6)
    assert np.linalg.norm(new.gaussian.mean[1] - mean[1]) < 1.0  # the clutter-like measurement is ignored
    np.testing.assert_array_equal(new.gaussian.mean[2], mean[2])  # no measurement: unchanged
    assert new.manoeuvre.tolist() == [False, False, False]  # clutter does not switch the manoeuvre noise on
    # the measurement's own covariance (the pipeline's R_bar) equal to the model's R gives the same update
    r_bar = np.broadcast_to(model.R, (3, 1, 4, 4)).copy()
    again = spec.update(spec.init(prior, None), Scan(z[:, None, :], valid[:, None], cov=r_bar, clutter_density=density),
                        model, None)
    np.testing.assert_allclose(again.gaussian.mean[:2], new.gaussian.mean[:2], rtol=1e-9)


def test_recipe_clutter_floor_from_the_clutter_and_sensor_models(host):
    from scipy.stats import norm

    b, lam, pd = paper000.clutter_floor(host)
    # lambda = rate exp(-t / mu) / cube^3 / (2 vr_max) at 5 dB: 205.7 per (10 km)^3, Doppler over 600 m/s
    assert lam == pytest.approx(1000 * np.exp(-from_db(5.0) / 2) / 1e12 / 600.0, rel=1e-12)
    snr0 = 10 * np.log10(float(paper000.radar_snr(np.linalg.norm(paper000.START_POSITION), from_db(-20.0))))
    assert snr0 == pytest.approx(2.3, abs=0.1)  # the brief's SNR at k = 0
    assert pd == pytest.approx(norm.cdf((snr0 - 5.0) / 2.0)) and b == pytest.approx(lam * (1 - pd) / pd)
    assert "clutter_density" in host.filter("sir-jm").capabilities  # A and B read the scan's clutter density
    assert "clutter_density" not in host.filter("tbd-pf").capabilities
    # amplitude ratio: 1 at the threshold, exp(-(p - t) / mu) above it, from the strongest gated detection
    snr = np.array([[5.0, 3.0], [12.0, 6.0], [0.0, 0.0]])
    gated = Scan(np.zeros((3, 2, 4)), np.array([[True, False], [True, True], [False, False]]), snr=snr)
    ratio = paper000.clutter_amplitude_ratio(gated, 2.0, 5.0)
    np.testing.assert_allclose(ratio, [1.0, np.exp(-(from_db(12.0) - from_db(5.0)) / 2.0), 1.0])
