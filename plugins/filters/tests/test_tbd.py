"""The track-before-detect filters (``workbench_filters.tbd``): the direct-weight particle filter and its floors, the
two-mode prediction, regularised resampling, the clutter-aware bootstrap filter and the PDA/NIS EKF.

The models are built from the core's radar physics (``workbench.sensing.radar``), not from a sensor plugin; every
weight is checked against a reference written with SciPy's densities."""

import tracemalloc
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from workbench.models import MeasurementModel, constant_velocity
from workbench.particle_core import ParticleState
from workbench.rng import generator
from workbench.sensing.radar import (RadarParameters, detection_model, detection_probability,
                                     exponential_power_log_density, from_db, position_radial_velocity,
                                     position_radial_velocity_jacobian, position_sigma, radar_snr, radial_velocity)
from workbench.types import Gaussian, InputError, Particles, Scan
from workbench_filters.tbd import (FLOOR_SCALE, ModeState, log_likelihood, make_ekf_nis, make_sir_jm, make_tbd_pf,
                                   predict_jump_markov, regularisation_bandwidth, regularise)

RADAR = RadarParameters()
RCS, SIGMA_RCS, THRESHOLD, MEAN_POWER = -20.0, 2.0, 5.0, 2.0


def _model(target: bool = True, clutter: bool = True) -> MeasurementModel:
    """``h(s) = [x, y, z, vr]`` with R = diag(300^2 I, 10^2), declaring the radar's detection quality, its design
    target (-20 dBsm, 2 dB fluctuation, 5 dB threshold) and the clutter's exponential power law."""
    kw = dict(rcs_dbsm=RCS, snr_sigma_db=SIGMA_RCS, threshold_db=THRESHOLD) if target else {}
    det = detection_model(RADAR, 2.0, **kw)
    if clutter:
        det = replace(det, clutter_log_snr_density=partial(exponential_power_log_density, mean_power=MEAN_POWER,
                                                           threshold_db=THRESHOLD))
    return MeasurementModel("position-doppler", position_radial_velocity, np.diag([300.0**2] * 3 + [10.0**2]),
                            position_radial_velocity_jacobian, frame="position-doppler-3d", detection=det)


def _cloud(n=400, batch=2, seed=0, mean=(30e3, 2e3, 2e3, -200.0, 0.0, 0.0), sd=(300.0, 300, 300, 20, 20, 5)):
    spec = make_tbd_pf(n)
    prior = Gaussian.broadcast(list(mean), np.diag(sd) ** 2, batch)
    return spec, spec.init(prior, generator(seed, "cloud"))


# -- the weights -------------------------------------------------------------------------------------------


def _reference_log_sum(x, scan, sigma_vr):
    """log sum_m P_D(snr_m) N(p_m; p_i, sigma_p,m^2 I) N(vr_m; vr_i, sigma_vr^2), from SciPy densities."""
    B, N, _ = x.shape
    out = np.full((B, N), -np.inf)
    for b in range(B):
        total = np.zeros(N)
        for m in np.flatnonzero(scan.valid[b]):
            z, snr = scan.z[b, m], scan.snr[b, m]
            sp = position_sigma(snr, np.linalg.norm(z[:3]), RADAR)
            w = detection_probability(from_db(snr)) * np.prod(norm.pdf(z[:3], x[b, :, :3], sp), axis=1)
            total += w * norm.pdf(z[3], radial_velocity(x[b]), sigma_vr)
        if scan.valid[b].any():
            out[b] = np.log(total)
    return out


def _scan(seed=4, batch=3, m=3):
    rng = np.random.default_rng(seed)
    z = np.concatenate([rng.normal(size=(batch, m, 3)) * 400 + [30e3, 2e3, 2e3], rng.normal(size=(batch, m, 1)) * 15
                        - 200], axis=2)
    valid = np.ones((batch, m), bool)
    valid[-1] = False  # an item without detections
    snr = np.array([[6.0, 9.0, 7.0], [16.0, 6.0, 5.5], [8.0, 8.0, 8.0]])[:batch, :m]
    density = np.full((batch, m), 3.4e-13)
    return Scan(z, valid, snr=snr, clutter_density=density)


def test_weights_without_a_floor_are_eqs_13_and_14():
    _, state = _cloud(batch=3)
    scan = _scan()
    x, model = state.cloud.particles, _model()
    got = log_likelihood(x, scan, model, 15.0, floor="none")
    np.testing.assert_allclose(got, _reference_log_sum(x, scan, 15.0), rtol=1e-9)
    assert np.all(got[2] == -np.inf)


def test_flat_floor_is_the_previous_one():
    _, state = _cloud(batch=3)
    scan = _scan()
    x, model = state.cloud.particles, _model()
    got = log_likelihood(x, scan, model, 15.0, 5e-11, floor="flat")
    top = detection_probability(from_db(np.max(np.where(scan.valid, scan.snr, -np.inf), axis=1)[:2]))
    eps = 5e-11 * top * norm.pdf(0.0, 0.0, 15.0)
    want = np.log(eps[:, None] + np.exp(_reference_log_sum(x, scan, 15.0)[:2]))
    np.testing.assert_allclose(got[:2], want, rtol=1e-9)


def test_amplitude_floor_against_a_scipy_reference():
    _, state = _cloud(batch=3)
    scan = _scan()
    x, model = state.cloud.particles, _model()
    log_w = state.cloud.log_weights
    kappa = 16.0
    got = log_likelihood(x, scan, model, 15.0, floor="amplitude", floor_scale=kappa, log_weights=log_w,
                         missed=None)
    for b in range(2):
        star = int(np.argmax(scan.snr[b]))
        s = scan.snr[b, star]
        centre = np.exp(log_w[b]) @ x[b, :, :3]
        n = 10 * np.log10(radar_snr(np.linalg.norm(centre), from_db(RCS), RADAR))
        pd_t = norm.cdf((n - THRESHOLD) / SIGMA_RCS)
        f_t = norm.pdf(s, n, SIGMA_RCS) / pd_t
        p, t = from_db(s), from_db(THRESHOLD)
        f_c = np.exp(-(p - t) / MEAN_POWER) / MEAN_POWER * p * np.log(10) / 10
        eps = kappa * 3.4e-13 * detection_probability(from_db(s)) / max(1.0, f_t / f_c)
        want = np.log(eps + np.exp(_reference_log_sum(x, scan, 15.0)[b]))
        np.testing.assert_allclose(got[b], want, rtol=1e-9, err_msg=f"item {b}")
        # with the missed-detection factor at the cloud's predicted position
        from workbench_filters.tbd import log_missed

        missed = log_missed(model, x, log_w)
        assert missed.shape == (3, 1) and np.exp(missed[b, 0]) == pytest.approx(1 - pd_t, rel=1e-9)
    # the 16 dB detection of item 1 is far stronger than clutter makes: its floor is the smaller one
    assert got[1].min() > np.log(kappa * 3.4e-13) - 60
    # without declarations: no clutter density -> no floor (eqs 13-14); no laws -> l = 1, no 1 - P_D
    bare = log_likelihood(x, replace(scan, clutter_density=None), model, 15.0, floor="amplitude", log_weights=log_w)
    np.testing.assert_allclose(bare, log_likelihood(x, scan, model, 15.0, floor="none"), rtol=1e-12)
    plain = log_likelihood(x, scan, _model(target=False, clutter=False), 15.0, floor="amplitude", floor_scale=kappa,
                           log_weights=log_w)
    top = detection_probability(from_db(np.max(scan.snr[:2], axis=1)))
    np.testing.assert_allclose(plain[:2], np.log(kappa * 3.4e-13 * top[:, None]
                                                 + np.exp(_reference_log_sum(x, scan, 15.0)[:2])), rtol=1e-9)


def test_the_amplitude_floor_lets_a_lagging_cloud_follow_a_strong_detection():
    # a cloud 350 m (6 cloud sigmas) behind a 20 dB detection (sigma_p ~ 50 m at 20 km): a floor that ignores
    # signal strength swamps the detection's kernel, the amplitude-aware floor does not
    model = _model()
    truth = np.array([20e3, 1e3, 1e3, 0.0, 200.0, 0.0])
    spec, state = _cloud(n=2000, batch=1, mean=truth - [0, 350, 0, 0, 0, 0], sd=(60, 60, 30, 20, 20, 5))
    z = model.h(truth[None])[None]
    scan = Scan(z, np.ones((1, 1), bool), snr=np.full((1, 1), 20.0), clutter_density=np.full((1, 1), 3.4e-13))
    before = spec.estimate(state).mean[0, 1]
    moves = {}
    for floor in ("flat", "amplitude"):
        f = make_tbd_pf(2000, floor=floor, threshold=0.0)
        moves[floor] = f.estimate(f.update(state, scan, model, generator(1))).mean[0, 1] - before
    assert moves["amplitude"] > 100.0 > 20.0 > moves["flat"]


def test_empty_gate_and_the_missed_detection_factor():
    model = _model()
    spec, state = _cloud(batch=2)
    empty = Scan(np.zeros((2, 1, 4)), np.zeros((2, 1), bool), snr=np.zeros((2, 1)))
    new = spec.update(state, empty, model, generator(2))  # factor at the cloud: a constant, nothing changes
    np.testing.assert_array_equal(new.cloud.log_weights, state.cloud.log_weights)
    np.testing.assert_array_equal(new.cloud.particles, state.cloud.particles)
    per = make_tbd_pf(400, missed_detection="particle", threshold=0.0)
    got = per.update(state, empty, model, generator(2)).cloud.log_weights
    x = state.cloud.particles
    n = 10 * np.log10(radar_snr(np.linalg.norm(x[..., :3], axis=-1), from_db(RCS), RADAR))
    w = np.exp(state.cloud.log_weights) * norm.sf((n - THRESHOLD) / SIGMA_RCS)  # (1 - P_D(s_i))
    np.testing.assert_allclose(np.exp(got), w / w.sum(axis=1, keepdims=True), rtol=1e-9)


def test_tbd_filter_moves_towards_a_consistent_detection():
    spec, state = _cloud()
    model = _model()
    assert "multi_measurement" in spec.capabilities and spec.params["particles"] == 400
    assert spec.params["floor"] == "amplitude" and spec.params["floor_scale"] == FLOOR_SCALE
    target = np.array([30.2e3, 2e3, 2e3, -199.0])
    z = np.stack([np.stack([target, [30e3, 2.5e3, 2e3, 150.0]])] * 2)  # + a Doppler-inconsistent clutter point
    scan = Scan(z, np.array([[True, True], [False, False]]), snr=np.full((2, 2), 15.0),
                clutter_density=np.full((2, 2), 3.4e-13))
    new = spec.update(state, scan, model, generator(1))
    before, after = spec.estimate(state).mean, spec.estimate(new).mean
    assert after[0, 0] - before[0, 0] > 100.0  # pulled towards x = 30.2 km
    np.testing.assert_array_equal(new.cloud.particles[1], state.cloud.particles[1])  # empty gate: unchanged
    np.testing.assert_array_equal(new.cloud.log_weights[1], state.cloud.log_weights[1])
    again = spec.update(state, scan, model, generator(1))
    np.testing.assert_array_equal(again.cloud.particles, new.cloud.particles)  # same seed, same numbers


@pytest.mark.parametrize("floor", ["amplitude", "flat", "none"])
def test_tbd_filter_weights_finite_when_every_likelihood_underflows(floor):
    spec, state = _cloud()
    z = np.array([[[400e3, 0.0, 0.0, 100.0]]] * 2)
    scan = Scan(z, np.ones((2, 1), bool), snr=np.full((2, 1), 25.0), clutter_density=np.full((2, 1), 3.4e-13))
    new = make_tbd_pf(400, floor=floor).update(state, scan, _model(), generator(2))
    lw = new.cloud.log_weights
    assert np.all(np.isfinite(lw)) and np.allclose(np.exp(lw).sum(axis=1), 1.0)


def test_tbd_filter_backends_agree():
    model = _model()
    rng = np.random.default_rng(4)
    z = np.concatenate([rng.normal(size=(2, 6, 3)) * 500 + [30e3, 2e3, 2e3], rng.normal(size=(2, 6, 1)) * 50 - 200],
                       axis=2)
    scan = Scan(z, rng.random((2, 6)) < 0.8, snr=rng.uniform(5, 15, (2, 6)), clutter_density=np.full((2, 6), 3e-13))
    _, state = _cloud()
    outs = [make_tbd_pf(400, backend=be, threshold=0.0).update(state, scan, model, generator(3)).cloud.log_weights
            for be in ("numpy", "taichi", "auto")]
    np.testing.assert_allclose(outs[1], outs[0], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(outs[2], outs[0], rtol=1e-10, atol=1e-10)


def test_weights_stay_linear_in_particles_plus_detections_in_memory():
    # N = 20,000 particles against M = 400 detections: a (B, N, M) float64 array would take 64 MB
    rng = np.random.default_rng(5)
    x = np.array([30e3, 2e3, 2e3, -200.0, 0.0, 0.0]) + rng.normal(size=(1, 20_000, 6)) * [500, 500, 300, 30, 30, 10]
    z = np.concatenate([rng.normal(size=(1, 400, 3)) * 800 + [30e3, 2e3, 2e3], rng.uniform(-300, 300, (1, 400, 1))],
                       axis=2)
    scan = Scan(z, np.ones((1, 400), bool), snr=rng.uniform(5, 12, (1, 400)), clutter_density=np.full((1, 400), 3e-13))
    model = _model()
    # the measured call once before the trace: whatever it compiles or loads (a fresh Numba cache, a kernel picked
    # by the size) is not the weights' memory
    log_likelihood(x, scan, model, 15.0, floor="amplitude", floor_scale=16.0,
                   log_weights=np.full((1, 20_000), -np.log(20_000)))
    tracemalloc.start()
    log_likelihood(x, scan, model, 15.0, floor="amplitude", floor_scale=16.0,
                   log_weights=np.full((1, 20_000), -np.log(20_000)))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 8e6, peak


def test_tbd_filter_rejects_bad_settings():
    with pytest.raises(InputError, match="floor"):
        make_tbd_pf(floor="sometimes")
    with pytest.raises(InputError, match="missed_detection"):
        make_tbd_pf(missed_detection="never")
    with pytest.raises(InputError):
        make_tbd_pf().configure(floor_scale=0.0)
    assert make_tbd_pf().configure(floor="flat").params["floor"] == "flat"


# -- manoeuvre handling ----------------------------------------------------------------------------------------


def test_jump_markov_prediction_switches_modes_and_scales_the_noise():
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


def test_resampling_carries_each_particle_s_mode():
    model = _model()
    rng = np.random.default_rng(5)
    x = np.array([3e4, 1e3, 2e3, -200.0, 0.0, 0.0]) + rng.normal(size=(2, 500, 6)) * [400, 400, 300, 30, 30, 10]
    mode = (x[..., 0] > 3e4).astype(float)  # a function of the particle, so it must survive resampling with it
    state = ModeState(Particles(x, np.full((2, 500), -np.log(500))), 0, 0, mode)
    z = model.h(np.array([[3.03e4, 1e3, 2e3, -200.0, 0.0, 0.0]] * 2))
    spec = make_sir_jm(500, threshold=1.0, regularisation=0.0)  # no jitter: the mode stays a function of x
    new = spec.update(state, Scan.single(z), model, generator(2))
    assert new.resamples == 2
    np.testing.assert_array_equal(new.mode, (new.cloud.particles[..., 0] > 3e4).astype(float))
    # without resampling: log w_i + log N(z; h(x_i), R), normalised (SciPy reference), modes untouched
    kept = make_sir_jm(500, threshold=0.0).update(state, Scan.single(z), model, generator(2))
    for b in range(2):
        lik = multivariate_normal(z[b], model.R).pdf(model.h(x[b]))
        np.testing.assert_allclose(np.exp(kept.cloud.log_weights[b]), lik / lik.sum(), rtol=1e-9)
    np.testing.assert_array_equal(kept.mode, mode)


def test_ekf_nis_switches_its_noise_on_a_large_innovation():
    spec = make_ekf_nis()
    model = _model()
    motion = constant_velocity(3, 1.0, (10.0, 10.0, 5.0))
    mean = np.array([[3e4, 1e3, 2e3, -200.0, 0.0, 0.0]] * 3)
    P = np.broadcast_to(np.diag([100.0, 100, 100, 10, 10, 5]) ** 2, (3, 6, 6)).copy()
    state = spec.init(Gaussian(mean, P), None)
    z = model.h(mean) + np.array([[30.0, 0, 0, 1.0], [3000.0, 0, 0, 1.0], [0.0, 0, 0, 0]])
    scan = Scan(z[:, None, :], np.array([[True], [True], [False]]))
    new = spec.update(state, scan, model, None)
    assert new.manoeuvre.tolist() == [False, True, False]  # NIS 0.1 vs about 1000 (chi2_4 99 % = 13.3)
    # the update itself is the textbook EKF's
    for b in range(2):
        H = model.jacobian(mean[b:b + 1])[0]
        K = P[b] @ H.T @ np.linalg.inv(H @ P[b] @ H.T + model.R)
        np.testing.assert_allclose(new.gaussian.mean[b], mean[b] + K @ (z[b] - model.h(mean[b])), rtol=1e-9)
    np.testing.assert_array_equal(new.gaussian.mean[2], mean[2])
    # next prediction: Q for quiet items, scale^2 Q for the flagged one
    pred = spec.predict(new, motion, None).gaussian
    np.testing.assert_allclose(pred.cov[0], motion.F @ new.gaussian.cov[0] @ motion.F.T + motion.Q, rtol=1e-9)
    np.testing.assert_allclose(pred.cov[1], motion.F @ new.gaussian.cov[1] @ motion.F.T + 16.0 * motion.Q, rtol=1e-9)


# -- regularised resampling ------------------------------------------------------------------------------------


def test_regularisation_bandwidth_and_jitter_follow_the_kernel_covariance():
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


def test_tbd_filter_regularises_only_after_resampling():
    model = _model()
    _, state = _cloud()
    z = np.array([[[30.1e3, 2e3, 2e3, -200.0]]] * 2)
    scan = Scan(z, np.array([[True], [False]]), snr=np.full((2, 1), 15.0), clutter_density=np.full((2, 1), 3e-13))
    plain = make_tbd_pf(400, regularisation=0.0).update(state, scan, model, generator(3))
    jittered = make_tbd_pf(400, regularisation=0.5).update(state, scan, model, generator(3))
    assert plain.resamples == jittered.resamples == 1  # the sharp detection collapses item 0's N_eff
    n_distinct = lambda s: len(np.unique(s.cloud.particles[0, :, 0]))  # noqa: E731
    assert n_distinct(plain) < 400 and n_distinct(jittered) == 400  # copies made distinct
    np.testing.assert_array_equal(jittered.cloud.particles[1], state.cloud.particles[1])  # empty gate


# -- clutter terms of the pseudo-measurement filters -------------------------------------------------------------


def test_sir_clutter_floor_is_the_mixture_likelihood():
    model = _model()
    rng = np.random.default_rng(6)
    x = np.array([3e4, 1e3, 2e3, -200.0, 0.0, 0.0]) + rng.normal(size=(2, 300, 6)) * [400, 400, 300, 30, 30, 10]
    state = ModeState(Particles(x, np.full((2, 300), -np.log(300))), 0, 0, np.zeros((2, 300)))
    z_bar = np.array([[3.1e4, 1.2e3, 2e3, 150.0], [3.0e4, 1e3, 2e3, -200.0]])
    r_bar = np.stack([np.diag([600.0, 600, 600, 120]) ** 2, np.diag([300.0, 300, 300, 10]) ** 2])
    lam = 3.5e-12
    step = Scan.single(z_bar, cov=r_bar, clutter_density=np.full(2, lam))
    new = make_sir_jm(300, threshold=0.0).update(state, step, model, generator(1))
    # SciPy reference: w_i ∝ lambda + N(z_bar; h(x_i), R_bar)
    for b in range(2):
        lik = lam + multivariate_normal(z_bar[b], r_bar[b]).pdf(model.h(x[b]))
        np.testing.assert_allclose(np.exp(new.cloud.log_weights[b]), lik / lik.sum(), rtol=1e-9)
    # a Doppler-inconsistent (clutter) pseudo-measurement hardly moves the weights; without the floor it does
    bare = make_sir_jm(300, threshold=0.0).update(state, Scan.single(z_bar, cov=r_bar), model, generator(1))
    spread = lambda lw: np.exp(lw.max() - lw.min())  # noqa: E731
    assert spread(new.cloud.log_weights[0]) < 30.0 < spread(bare.cloud.log_weights[0])


def test_ekf_pda_update_against_the_textbook_pdaf():
    model = _model()
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
    for b in range(2):
        H = model.jacobian(mean[b:b + 1])[0]
        S = H @ P[b] @ H.T + model.R
        nu = z[b] - model.h(mean[b])
        beta0 = lam / (lam + multivariate_normal(np.zeros(4), S).pdf(nu))
        K = P[b] @ H.T @ np.linalg.inv(S)
        P_plus = (np.eye(6) - K @ H) @ P[b]
        want_mean = mean[b] + (1 - beta0) * K @ nu
        want_cov = beta0 * P[b] + (1 - beta0) * P_plus + beta0 * (1 - beta0) * np.outer(K @ nu, K @ nu)
        np.testing.assert_allclose(new.gaussian.mean[b], want_mean, rtol=1e-9)
        np.testing.assert_allclose(new.gaussian.cov[b], want_cov, rtol=1e-6, atol=1e-6)
    assert np.linalg.norm(new.gaussian.mean[1] - mean[1]) < 1.0  # the clutter-like measurement is ignored
    np.testing.assert_array_equal(new.gaussian.mean[2], mean[2])  # no measurement: unchanged
    assert new.manoeuvre.tolist() == [False, False, False]  # clutter does not switch the manoeuvre noise on
    # the measurement's own covariance equal to the model's R gives the same update
    r_bar = np.broadcast_to(model.R, (3, 1, 4, 4)).copy()
    again = spec.update(spec.init(prior, None), Scan(z[:, None, :], valid[:, None], cov=r_bar, clutter_density=density),
                        model, None)
    np.testing.assert_allclose(again.gaussian.mean[:2], new.gaussian.mean[:2], rtol=1e-9)


def test_progressive_correction_applies_the_whole_likelihood_in_powers():
    # without resampling between the powers the particles do not move: K powers L^(1/K) give L itself (without a
    # floor: the amplitude floor is taken at the cloud's current centre, which the earlier powers move)
    spec, state = _cloud(batch=3)
    scan = _scan()
    model = _model()
    once = make_tbd_pf(400, threshold=0.0, floor="none").update(state, scan, model, generator(5))
    four = make_tbd_pf(400, threshold=0.0, floor="none", tempering=4).update(state, scan, model, generator(5))
    np.testing.assert_allclose(four.cloud.log_weights, once.cloud.log_weights, rtol=1e-9, atol=1e-9)
    # with resampling between the powers a sharp 2 m/s Doppler kernel keeps more distinct particles
    sharp = dict(sigma_vr=2.0, regularisation=0.5)
    z = np.array([[[30.1e3, 2e3, 2e3, -195.0]]] * 3)
    strong = Scan(z, np.ones((3, 1), bool), snr=np.full((3, 1), 12.0), clutter_density=np.full((3, 1), 3e-13))
    plain = make_tbd_pf(400, **sharp).update(state, strong, model, generator(6))
    tempered = make_tbd_pf(400, tempering=4, **sharp).update(state, strong, model, generator(6))
    assert tempered.resamples > plain.resamples
    with pytest.raises(InputError, match="tempering"):
        make_tbd_pf(tempering=0)


# -- the compiled steps against their NumPy twins ------------------------------------------------------------------


def _generators(seed: int):
    """Two PCG64 generators (``wb.generator``) in the same state."""
    return generator(seed, "twins"), generator(seed, "twins")


def _same_position(g1, g2) -> bool:
    """Whether two generators stand at the same place of their stream (their next raw words)."""
    return np.array_equal(g1.bit_generator.random_raw(4), g2.bit_generator.random_raw(4))


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


@pytest.mark.parametrize("bits, B, N, nonlinear, plain", [
    ("pcg64", 3, 4000, False, False),  # 48 000 draws: the PCG64 stream in registers
    ("pcg64", 2, 50, False, True),  # a few hundred draws: Numba's Generator; a state without modes
    ("philox", 2, 700, False, False),  # another bit generator: Numba's Generator
    ("pcg64", 2, 3000, True, False),  # a model that overrides f (the coordinated turn with its rate)
])
def test_compiled_jump_markov_prediction_is_the_numpy_one_bit_for_bit(bits, B, N, nonlinear, plain):
    from workbench.models.motion import coordinated_turn_rate
    from workbench_filters.tbd import predict_jump_markov_numpy

    motion = coordinated_turn_rate(1.0, 3.0, 0.02) if nonlinear else constant_velocity(3, 1.0, (8.0, 8.0, 4.0))
    n = motion.Q.shape[0]
    rng = np.random.default_rng(11)
    x = rng.normal(size=(B, N, n)) * 50.0
    if nonlinear:
        x[..., 4] = rng.normal(size=(B, N)) * 0.05
    cloud = Particles(x, np.full((B, N), -np.log(N)))
    state = ParticleState(cloud) if plain else ModeState(cloud, 0, 0, (rng.random((B, N)) < 0.3).astype(float))
    def make():
        return generator(4, "twins") if bits == "pcg64" else np.random.Generator(np.random.Philox(4))

    g1, g2 = make(), make()
    kw = dict(switch_on=0.05, switch_off=0.2, scale=4.0)
    fast = predict_jump_markov(state, motion, g1, backend="numba", **kw)
    ref = predict_jump_markov_numpy(state, motion, g2, **kw)
    assert _same_bits(fast.cloud.particles, ref.cloud.particles)
    assert _same_bits(fast.mode, ref.mode) and 0 < fast.mode.mean() < 1
    assert fast.cloud.log_weights is state.cloud.log_weights
    assert _same_position(g1, g2)  # the generator left where NumPy leaves it
    # the NumPy backend is the NumPy twin
    assert _same_bits(predict_jump_markov(state, motion, make(), backend="numpy", **kw).cloud.particles,
                      ref.cloud.particles)


@pytest.mark.parametrize("N, component_major", [(3000, True), (40, False)])
def test_compiled_regularisation_is_the_numpy_one_bit_for_bit(N, component_major):
    B, n = 4, 6
    rng = np.random.default_rng(2)
    x = rng.normal(size=(B, N, n)) * [400, 400, 300, 30, 30, 10]
    if component_major:
        x = np.ascontiguousarray(x.transpose(2, 0, 1)).transpose(1, 2, 0)
    cov = np.stack([np.cov(x[b].T) for b in range(B)])
    rows = np.array([True, False, True, True])
    g1, g2 = _generators(9)
    fast = regularise(x, cov, rows, 0.5, g1, backend="numba")
    ref = regularise(x, cov, rows, 0.5, g2, backend="numpy")
    assert _same_bits(fast, ref) and fast.strides == ref.strides
    assert _same_position(g1, g2)
    assert not np.array_equal(fast[0], x[0]) and np.array_equal(fast[1], x[1])


def test_compiled_floor_sum_is_numpys_logaddexp_bit_for_bit():
    from workbench_filters.tbd import tbd_pf_numba

    rng = np.random.default_rng(3)
    B, N = 8, 400
    log_sum = rng.normal(size=(B, N)) * 40.0 - 30.0
    wide = rng.normal(size=(B, N)) * 40.0 - 30.0
    narrow = rng.normal(size=(B, 1)) * 10.0 - 30.0
    # the shortcut's edges: gaps just either side of 50 with the larger term near 2^-10, and ordinary numbers
    a = np.array([2.0**-10, 2.0**-10 * 0.999, 1.0, -1.0, 3.0**-7, 0.0, -0.0])
    for i, d in enumerate((49.9, 50.0, 50.1, 30.0, 60.0)):
        wide[i, : a.size], log_sum[i, : a.size] = a, a - d
        wide[i, a.size: 2 * a.size], log_sum[i, a.size: 2 * a.size] = a - d, a
    log_sum[5, :6] = [np.inf, -np.inf, np.nan, -0.0, 0.0, wide[5, 5]]
    wide[6, :4] = [np.inf, -np.inf, np.nan, -np.inf]
    log_sum[6, :4] = [np.inf, -np.inf, 1.0, 2.0]
    narrow[7] = -np.inf
    present = np.ones(B, dtype=bool)
    present[4] = False
    for log_eps in (wide, narrow):
        with np.errstate(invalid="ignore"):
            want = np.where(present[:, None], np.logaddexp(log_eps, log_sum), -np.inf)
        got = tbd_pf_numba.log_add_floor(log_eps, log_sum, present, np.empty((B, N)))
        assert _same_bits(got, want)
