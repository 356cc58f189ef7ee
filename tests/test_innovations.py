"""Innovations out of the Kalman family and the IMM (issue 27 item 2): the innovation ``y``, its covariance ``S``,
NIS and the log-likelihood of every update, against FilterPy (``KalmanFilter``, ``ExtendedKalmanFilter``,
``IMMEstimator`` with a hand mixture of its modes) and a chi-square band, and refused by name where not declared."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from workbench.kalman_core import Innovations
from workbench.models import constant_velocity, coordinated_turn, linear_measurement, range_bearing
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking import run
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, InputError, Scans, Truth
from workbench_filters.imm import make_imm

HOST = load_host()


def _position_model(std=3.0):
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    return linear_measurement(H, np.diag([std**2, (1.5 * std) ** 2]), name="position", frame="cartesian-2d")


def _linear_problem(B, T, seed, motion, model, missing=()):
    """A constant-velocity truth drawn from ``motion``, position measurements with ``model.R``, each run's prior
    drawn around its truth; ``missing``: ``(b, k)`` items without a measurement."""
    rng = generator(seed, "test-innovations")
    P0 = np.diag([25.0, 25.0, 4.0, 4.0])
    x0 = np.array([100.0, -50.0, 5.0, 3.0]) + rng.standard_normal((B, 4)) @ np.linalg.cholesky(P0).T
    states = sample_motion(x0, motion, T, rng).states
    truth = Truth(states, np.arange(T) * motion.dt)
    z = states[..., :2] + rng.standard_normal((B, T, 2)) @ np.linalg.cholesky(model.R).T
    valid = np.ones((B, T, 1), dtype=bool)
    for b, k in missing:
        valid[b, k] = False
    prior_mean = x0 + rng.standard_normal((B, 4)) @ np.linalg.cholesky(P0).T
    return truth, Scans(z[:, :, None, :], valid, truth.times), Gaussian(prior_mean, np.broadcast_to(P0, (B, 4, 4)).copy())


def test_kf_innovations_equal_filterpy_kalman_filter_step_by_step():
    kalman = pytest.importorskip("filterpy.kalman")
    cv, model = constant_velocity(2, 1.0, 0.3), _position_model()
    B, T = 3, 12
    _, scans, prior = _linear_problem(B, T, 1, cv, model, missing=[(1, 4), (2, 7)])
    track = run(HOST.filter("kf"), scans, cv, model, prior=prior, innovations=True)
    rec = track.innovations
    assert isinstance(rec, Innovations) and rec.y.shape == (B, T, 2) and rec.S.shape == (B, T, 2, 2)
    assert rec.nis.shape == rec.log_likelihood.shape == rec.present.shape == (B, T)
    for b in range(B):
        f = kalman.KalmanFilter(dim_x=4, dim_z=2)
        f.x, f.P, f.F, f.Q, f.H, f.R = prior.mean[b].copy(), prior.cov[b].copy(), cv.F, cv.Q, model.H, model.R
        for k in range(T):
            if k:
                f.predict()
            if not scans.valid[b, k, 0]:
                f.update(None)
                assert not rec.present[b, k]
                assert np.isnan(rec.y[b, k]).all() and np.isnan(rec.nis[b, k]) and np.isnan(rec.log_likelihood[b, k])
                continue
            f.update(scans.z[b, k, 0])
            assert rec.present[b, k]
            np.testing.assert_allclose(rec.y[b, k], f.y, rtol=0, atol=1e-9)
            np.testing.assert_allclose(rec.S[b, k], f.S, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(rec.nis[b, k], f.mahalanobis**2, rtol=1e-9)
            np.testing.assert_allclose(rec.log_likelihood[b, k], f.log_likelihood, rtol=1e-9)
            np.testing.assert_allclose(track.mean[b, k], f.x, rtol=0, atol=1e-9)  # and the update is the same


def test_ekf_update_returns_the_innovations_filterpy_extended_kalman_filter_has():
    """The spec's own update with ``innovations=True`` (a FilterPy-style loop), range-bearing, angles wrapped."""
    kalman = pytest.importorskip("filterpy.kalman")
    ekf = HOST.filter("ekf")
    cv, model = constant_velocity(2, 1.0, 0.2), range_bearing(4.0, 0.01)
    B, T = 2, 10
    rng = generator(3, "test-innovations-ekf")
    x0 = np.array([[-800.0, 5.0, 10.0, -1.0], [-600.0, -3.0, 8.0, 2.0]])  # near bearing pi: residuals must wrap
    states = sample_motion(x0, cv, T, rng).states
    z = model.h(states) + rng.standard_normal((B, T, 2)) * [4.0, 0.01]
    z[..., 1] = (z[..., 1] + np.pi) % (2 * np.pi) - np.pi
    scans = Scans(z[:, :, None, :], np.ones((B, T, 1), dtype=bool), np.arange(T, dtype=float))
    P0 = np.diag([16.0, 16.0, 1.0, 1.0])
    state = ekf.init(Gaussian(x0 + [3.0, -2.0, 0.5, -0.5], np.broadcast_to(P0, (B, 4, 4)).copy()))
    peers = []
    for b in range(B):
        f = kalman.ExtendedKalmanFilter(dim_x=4, dim_z=2)
        f.x, f.P, f.F, f.Q, f.R = state.mean[b].copy(), P0.copy(), cv.F, cv.Q, model.R
        peers.append(f)
    for k in range(T):
        if k:
            state = ekf.predict(state, cv)
        state, got = ekf.update(state, scans.scan(k).for_filter(), model, innovations=True)
        for b, f in enumerate(peers):
            if k:
                f.predict()
            f.update(z[b, k], lambda x: model.jacobian(x[None])[0], lambda x: model.h(x),
                     residual=lambda a, c: model.residual(a, c))
            np.testing.assert_allclose(got.y[b], f.y, rtol=0, atol=1e-9)
            np.testing.assert_allclose(got.S[b], f.S, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(got.nis[b], f.mahalanobis**2, rtol=1e-8)
            np.testing.assert_allclose(got.log_likelihood[b], f.log_likelihood, rtol=1e-9)
    assert np.all(np.abs(got.y[:, 1]) < 0.1)  # wrapped, not ~2 pi


def test_imm_log_likelihood_is_filterpy_imm_estimators_mixture_of_its_modes():
    """FilterPy's IMMEstimator exposes each mode's likelihood and the predicted mode probabilities ``cbar``; the
    IMM's log-likelihood is ``log sum_j cbar_j L_j``, its ``y`` and ``S`` the moments of the modes' innovations."""
    kalman = pytest.importorskip("filterpy.kalman")
    cv, ct = constant_velocity(2, 1.0, 0.2), coordinated_turn(1.0, math.radians(4.0), 0.8)
    M, mu0 = np.array([[0.93, 0.07], [0.12, 0.88]]), np.array([0.7, 0.3])
    model = _position_model()
    B, T = 3, 9
    _, scans, prior = _linear_problem(B, T, 4, cv, model)  # (FilterPy mixes from mu, not cbar, after a skipped update)
    spec = make_imm((cv, ct), M, "kf", mu0)
    track = run(spec, scans, cv, model, prior=prior, predict_first=True, innovations=True)
    rec = track.innovations
    for b in range(B):
        modes = []
        for motion in (cv, ct):
            f = kalman.KalmanFilter(dim_x=4, dim_z=2)
            f.x, f.P, f.F, f.Q, f.H, f.R = prior.mean[b].copy(), prior.cov[b].copy(), motion.F, motion.Q, model.H, model.R
            modes.append(f)
        imm = kalman.IMMEstimator(modes, mu0.copy(), M)
        for k in range(T):
            imm.predict()
            cbar = imm.cbar.copy()  # the predicted mode probabilities (update recomputes cbar)
            imm.update(scans.z[b, k, 0])
            f0, f1 = imm.filters
            expected = math.log(cbar[0] * f0.likelihood + cbar[1] * f1.likelihood)
            np.testing.assert_allclose(rec.log_likelihood[b, k], expected, rtol=1e-9)
            y = cbar[0] * f0.y + cbar[1] * f1.y
            S = sum(c * (f.S + np.outer(f.y - y, f.y - y)) for c, f in zip(cbar, (f0, f1)))
            np.testing.assert_allclose(rec.y[b, k], y, rtol=0, atol=1e-9)
            np.testing.assert_allclose(rec.S[b, k], S, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(rec.nis[b, k], y @ np.linalg.solve(S, y), rtol=1e-8)
            np.testing.assert_allclose(track.mean[b, k], imm.x, rtol=0, atol=1e-9)


def test_kf_nis_mean_lies_in_its_chi_square_band_on_a_consistent_problem():
    """200 runs x 25 scans of a matched linear problem (fixed seed): the mean NIS inside the 99 % band of a mean of
    5,000 chi-square(2) values, and the mean log-likelihood that of a Gaussian with the recorded S."""
    cv, model = constant_velocity(2, 1.0, 0.5), _position_model()
    B, T = 200, 25
    _, scans, prior = _linear_problem(B, T, 5, cv, model)
    rec = run(HOST.filter("kf"), scans, cv, model, prior=prior, innovations=True).innovations
    count = B * T
    lo, hi = stats.chi2.ppf(0.005, 2 * count) / count, stats.chi2.ppf(0.995, 2 * count) / count
    assert rec.present.all()
    assert lo <= rec.nis.mean() <= hi, (rec.nis.mean(), lo, hi)
    # per item and scan: log N = -(NIS + log det S + 2 log 2 pi) / 2 with scipy's density
    b, k = 17, 11
    expected = stats.multivariate_normal(np.zeros(2), rec.S[b, k]).logpdf(rec.y[b, k])
    np.testing.assert_allclose(rec.log_likelihood[b, k], expected, rtol=1e-10)


def test_a_one_mode_imm_records_the_kalman_filters_innovations():
    cv, model = constant_velocity(2, 1.0, 0.3), _position_model()
    _, scans, prior = _linear_problem(4, 8, 6, cv, model, missing=[(3, 2)])
    a = run(HOST.filter("kf"), scans, cv, model, prior=prior, innovations=True).innovations
    b = run(make_imm((cv,), [[1.0]], "kf"), scans, cv, model, prior=prior, innovations=True).innovations
    for name in ("y", "S", "nis", "log_likelihood", "present"):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=1e-9, atol=1e-9, err_msg=name)


def test_innovations_are_refused_by_name_where_not_declared():
    cv, model = constant_velocity(2, 1.0, 0.3), _position_model()
    _, scans, prior = _linear_problem(2, 3, 7, cv, model)
    with pytest.raises(InputError, match="filter 'sir' does not record innovations"):
        run(HOST.filter("sir"), scans, cv, model, prior=prior, rng=generator(1, "sir"), innovations=True)
    assert run(HOST.filter("kf"), scans, cv, model, prior=prior).innovations is None  # only when asked
