"""UKF, CDKF, SR-UKF and SR-CDKF against independent references (paper 003)."""

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench.models import (constant_velocity, linear_measurement, random_walk_velocity, range_bearing,
                              range_bearing_jacobian)
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, InputError, Scan, Scans
from workbench_filters.sigma_point import (central_difference_weights, make_cdkf, make_ukf, sigma_points,
                                           unscented_weights)

HOST = load_host()
FAMILY = ("ukf", "cdkf", "sr-ukf", "sr-cdkf")


def _linear_problem(batch=5, steps=20, seed=3):
    rng = generator(seed, "test-sigma-linear")
    motion = constant_velocity(2, 1.0, 0.7)
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    model = linear_measurement(H, np.array([[4.0, 1.0], [1.0, 9.0]]))
    x0 = np.array([10.0, -5.0, 1.0, 2.0])
    P0 = np.diag([25.0, 16.0, 4.0, 1.0])
    start = x0 + rng.standard_normal((batch, 4)) @ np.linalg.cholesky(P0).T
    truth = sample_motion(start, motion, steps, rng)
    z = truth.states @ H.T + rng.standard_normal((batch, steps, 2)) @ np.linalg.cholesky(model.R).T
    valid = np.ones((batch, steps, 1), dtype=bool)
    valid[:, 7] = False  # a missed detection: update equals predict
    valid[2, 11] = False
    return motion, model, Scans(z[:, :, None, :], valid, truth.times), Gaussian.broadcast(x0, P0, batch)


def _paper_problem(batch=20, steps=100, sigmas=(0.1, 1.0, 0.1), seed=4):
    st, sr, sa = sigmas
    rng = generator(seed, "test-sigma-paper")
    truth = sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (batch, 1)), random_walk_velocity(2, 1.0, sa), steps, rng)
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=sr, sigma_theta=st)
    prior = Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), batch)
    return truth, scans, prior, random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1)


def _rel(a, b):
    return np.max(np.abs(a - b) / (1.0 + np.abs(b)))


@pytest.mark.parametrize("name", FAMILY)
def test_equals_the_kalman_filter_on_a_linear_gaussian_model(name):
    motion, model, scans, prior = _linear_problem()
    ref = run_filter(HOST.filter("kf"), prior, motion, model, scans, None)
    got = run_filter(HOST.filter(name), prior, motion, model, scans, None)
    assert _rel(got.mean, ref.mean) < 1e-10
    assert _rel(got.cov, ref.cov) < 1e-10
    assert _rel(got.predicted_mean, ref.predicted_mean) < 1e-10


@pytest.mark.parametrize("name", FAMILY)
def test_time_update_equals_the_kalman_prediction_for_linear_f(name):
    rng = np.random.default_rng(0)
    A = rng.standard_normal((6, 4, 4))
    belief = Gaussian(rng.standard_normal((6, 4)) * 50, A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(4))
    motion = random_walk_velocity(2, 1.0, 0.3)  # singular Q: no position noise
    spec = HOST.filter(name)
    got = spec.estimate(spec.predict(spec.init(belief, None), motion, None))
    assert _rel(got.mean, belief.mean @ motion.F.T) < 1e-10
    assert _rel(got.cov, motion.F @ belief.cov @ motion.F.T + motion.Q) < 1e-10


@pytest.mark.parametrize("sigmas", [(0.1, 1.0, 0.1), (1.0, 10.0, 1.0)])
@pytest.mark.parametrize("base, square_root", [("ukf", "sr-ukf"), ("cdkf", "sr-cdkf")])
def test_square_root_forms_equal_the_full_forms(base, square_root, sigmas):
    truth, scans, prior, motion, model = _paper_problem(sigmas=sigmas)
    a = run_filter(HOST.filter(base), prior, motion, model, scans, None)
    b = run_filter(HOST.filter(square_root), prior, motion, model, scans, None)
    assert b.diagnostics["downdate_fallbacks"] == 0
    assert _rel(b.mean, a.mean) < 1e-8
    assert _rel(b.cov, a.cov) < 1e-8


def test_downdate_free_sr_cdkf_equals_cdkf():
    truth, scans, prior, motion, model = _paper_problem()
    a = run_filter(HOST.filter("cdkf"), prior, motion, model, scans, None)
    b = run_filter(make_cdkf(square_root=True, downdate="qr"), prior, motion, model, scans, None)
    assert _rel(b.mean, a.mean) < 1e-8 and _rel(b.cov, a.cov) < 1e-8


def test_square_root_state_is_a_lower_cholesky_factor_never_refactored():
    truth, scans, prior, motion, model = _paper_problem(batch=4, steps=10)
    spec = HOST.filter("sr-ukf")
    state = spec.init(prior, None)
    for k in range(10):
        state = spec.update(spec.predict(state, motion, None) if k else state, scans.scan(k).for_filter(), model, None)
        S = state.chol
        assert np.allclose(S, np.tril(S)) and np.all(np.diagonal(S, axis1=1, axis2=2) > 0)


@pytest.mark.parametrize("name", ["sr-ukf", "sr-cdkf"])
def test_failed_downdates_are_counted_not_hidden(name):
    # With R = 0 the update removes the whole position variance, so rank-1 downdates hit r^2 <= 0 by round-off.
    rng = np.random.default_rng(0)
    B = 100
    A = rng.standard_normal((B, 4, 4))
    prior = Gaussian(rng.standard_normal((B, 4)) * 10, A @ np.swapaxes(A, 1, 2) + np.eye(4))
    model = linear_measurement(np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]]), np.zeros((2, 2)))
    spec = HOST.filter(name)
    state = spec.update(spec.init(prior, None), Scan.single(rng.standard_normal((B, 2))), model, None)
    assert spec.diagnostics(state)["downdate_fallbacks"] > 0
    est = spec.estimate(state)
    assert np.all(np.isfinite(est.cov))
    # the position block collapses to (nearly) zero, as the exact update says
    assert np.max(np.abs(est.cov[:, :2, :2])) < 1e-5


def test_downdate_free_form_has_no_fallbacks():
    rng = np.random.default_rng(0)
    B = 100
    A = rng.standard_normal((B, 4, 4))
    prior = Gaussian(rng.standard_normal((B, 4)) * 10, A @ np.swapaxes(A, 1, 2) + np.eye(4))
    model = linear_measurement(np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]]), np.zeros((2, 2)))
    spec = make_cdkf(square_root=True, downdate="qr")
    state = spec.update(spec.init(prior, None), Scan.single(rng.standard_normal((B, 2))), model, None)
    assert spec.diagnostics(state)["downdate_fallbacks"] == 0


def test_weights_as_in_the_brief():
    w = unscented_weights(4, alpha=1.0, beta=2.0, kappa=0.0)
    assert w.spread == pytest.approx(2.0)  # gamma = sqrt(L + lam), lam = 0
    assert w.mean[0] == 0.0 and w.cov[0] == pytest.approx(2.0)
    assert np.allclose(w.mean[1:], 1 / 8) and np.allclose(w.cov[1:], 1 / 8)
    c = central_difference_weights(4, np.sqrt(3.0))
    assert c.mean[0] == pytest.approx(-1 / 3) and np.allclose(c.mean[1:], 1 / 6)
    assert c.c1 == pytest.approx(1 / 12) and c.c2 == pytest.approx(1 / 18)
    for weights in (w, c, unscented_weights(4, alpha=1e-3)):
        assert weights.mean.sum() == pytest.approx(1.0)


def test_sigma_points_reproduce_mean_and_covariance():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + np.eye(4)
    x = rng.standard_normal((3, 4))
    w = unscented_weights(4, alpha=0.7, beta=2.0, kappa=1.0)
    X = sigma_points(x, np.linalg.cholesky(P), w.spread)
    assert X.shape == (3, 9, 4)
    assert np.allclose(w.mean @ X, x)
    d = X - x[:, None, :]
    assert np.allclose(np.einsum("s,bsi,bsj->bij", w.cov, d, d), P)


def test_bad_parameters_are_refused():
    with pytest.raises(InputError, match="alpha"):
        make_ukf(alpha=0.0)
    with pytest.raises(InputError, match="cdkf: h: must be >= 1"):
        make_cdkf(h=0.5)
    with pytest.raises(InputError, match="downdate"):
        make_cdkf(square_root=True, downdate="chol")


def test_ekf_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    x = np.column_stack([rng.uniform(-300, 300, (50, 2)), rng.normal(0, 3, (50, 2))])
    x = x[np.hypot(x[:, 0], x[:, 1]) > 5.0]
    h = range_bearing(1.0, 0.1).h
    jac = range_bearing_jacobian(x)
    eps = 1e-5
    for j in range(4):
        step = np.zeros(4)
        step[j] = eps
        # central difference; the bearing difference is wrapped so that +-pi neighbours do not jump
        diff = h(x + step) - h(x - step)
        diff[:, 1] = np.angle(np.exp(1j * diff[:, 1]))
        assert np.allclose(jac[:, :, j], diff / (2 * eps), rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("name", ("ekf",) + FAMILY)
def test_bearing_wrap_across_the_negative_x_axis(name):
    # A target crossing the negative x axis: its bearing jumps from +pi to -pi.
    B, T = 10, 40
    rng = np.random.default_rng(3)
    motion = random_walk_velocity(2, 1.0, 0.01)
    truth = sample_motion(np.tile([-150.0, 20.0, 0.0, -1.0], (B, 1)), motion, T, rng)
    bearings = np.arctan2(truth.states[0, :, 1], truth.states[0, :, 0])
    assert bearings.max() > 3.0 and bearings.min() < -3.0  # the path crosses +-pi
    scans = HOST.sensor("range-bearing").simulate(truth, rng, sigma_r=0.5, sigma_theta=0.005)
    model = range_bearing(0.5, 0.005)
    prior = Gaussian.broadcast([-148.0, 22.0, 0.0, -1.0], np.diag([4.0, 4.0, 0.25, 0.25]), B)
    est = run_filter(HOST.filter(name), prior, motion, model, scans, None)
    err = np.hypot(*(est.mean[..., :2] - truth.states[..., :2]).transpose(2, 0, 1))
    # cross-range noise is 0.75 m here; an unwrapped 2 pi residual would throw the estimate hundreds of metres
    assert err.max() < 5.0
    assert np.all(np.abs(est.mean[..., :2]).max() < 300)


def test_sigma_point_bearing_mean_is_angle_aware():
    # Sigma points straddling +-pi: the predicted bearing must be near pi, not near 0.
    spec = HOST.filter("ukf")
    prior = Gaussian.broadcast([-100.0, 0.0, 0.0, 0.0], np.diag([25.0, 400.0, 1.0, 1.0]), 2)
    model = range_bearing(1.0, 0.05)
    z = np.array([[100.0, np.pi - 0.01], [100.0, -np.pi + 0.01]])
    est = spec.estimate(spec.update(spec.init(prior, None), Scan.single(z), model, None))
    assert np.all(est.mean[:, 0] < -95.0)  # still on the negative x axis
    assert est.mean[0, 1] > 0 > est.mean[1, 1]  # moved towards each measurement's side of the axis


def test_ukf_matches_filterpy_when_installed():
    # FilterPy (optional 'bench' extra) as an independent reference, with redrawn sigma points as in the brief
    fp = pytest.importorskip("filterpy.kalman")
    truth, scans, prior, motion, model = _paper_problem(batch=3, steps=40)
    ours = run_filter(HOST.filter("ukf"), prior, motion, model, scans, None)
    points = fp.MerweScaledSigmaPoints(4, alpha=1.0, beta=2.0, kappa=0.0)

    def z_mean(sigmas, wm):
        ref = sigmas[0, 1]
        return np.array([wm @ sigmas[:, 0], _wrap(ref + wm @ _wrap(sigmas[:, 1] - ref))])

    def residual_z(a, c):
        return np.array([a[0] - c[0], _wrap(a[1] - c[1])])

    for b in range(3):
        ukf = fp.UnscentedKalmanFilter(4, 2, 1.0, hx=model.h, fx=lambda x, dt: motion.F @ x, points=points,
                                       z_mean_fn=z_mean, residual_z=residual_z)
        ukf.x, ukf.P, ukf.Q, ukf.R = prior.mean[b].copy(), prior.cov[b].copy(), motion.Q, model.R
        for k in range(40):
            if k:
                ukf.predict()
            ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
            ukf.update(scans.z[b, k, 0])
            assert np.allclose(ukf.x, ours.mean[b, k], rtol=1e-9, atol=1e-9)
            assert np.allclose(ukf.P, ours.cov[b, k], rtol=1e-9, atol=1e-9)


def _wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def test_a_changed_declared_default_changes_the_built_filter(monkeypatch):
    """The sigma-point factories take their signature, checks and params from UKF_PARAMETERS / CDKF_PARAMETERS: a
    default changed there (and nowhere else) is the filter's default, in its params and its numbers."""
    import importlib.util
    import inspect
    import sys
    from pathlib import Path

    import workbench_filters.sigma_point as sp

    text = Path(sp.__file__).read_text(encoding="utf-8")
    changes = (('Param("alpha", 1.0,', 'Param("alpha", 0.5,'), ('Param("h", float(np.sqrt(3.0)),', 'Param("h", 2.0,'))
    for old, new in changes:
        assert text.count(old) == 1
        text = text.replace(old, new)
    name = "workbench_filters.sigma_point._patched"  # in the package: its relative import of the kernels resolves
    patched = importlib.util.module_from_spec(importlib.util.spec_from_loader(name, loader=None))
    monkeypatch.setitem(sys.modules, name, patched)
    exec(compile(text, sp.__file__, "exec"), patched.__dict__)
    motion = constant_velocity(2, 1.0, 0.7)
    prior = Gaussian.broadcast([10.0, -5.0, 1.0, 2.0], np.diag([25.0, 16.0, 4.0, 1.0]), 2)
    model = range_bearing(1.0, 0.05, sensor=(-30.0, 20.0))  # nonlinear: the spread shows in the numbers
    z = model.h(np.repeat(prior.mean[:, None], 6, axis=1)) + 0.01
    scans = Scans(z[:, :, None, :], np.ones((2, 6, 1), dtype=bool), np.arange(6.0))
    for make, key, value, factory in ((patched.make_ukf, "alpha", 0.5, make_ukf),
                                      (patched.make_cdkf, "h", 2.0, make_cdkf)):
        assert make().params[key] == value and inspect.signature(make).parameters[key].default == value
        ours = run_filter(make(), prior, motion, model, scans, None).mean
        np.testing.assert_array_equal(ours, run_filter(factory(**{key: value}), prior, motion, model, scans, None).mean)
        assert not np.allclose(ours, run_filter(factory(), prior, motion, model, scans, None).mean, rtol=0, atol=1e-9)


def test_unknown_sigma_point_parameters_are_refused_by_name():
    from workbench.params import defaults
    from workbench_filters.sigma_point import CDKF_PARAMETERS, UKF_PARAMETERS

    assert make_ukf().params == defaults(UKF_PARAMETERS) and make_cdkf().params == defaults(CDKF_PARAMETERS)
    assert make_ukf(0.5, 2.0, 1.0, True).params == {"alpha": 0.5, "beta": 2.0, "kappa": 1.0, "square_root": True}
    with pytest.raises(InputError, match=r"ukf: unknown parameter 'gamma' \(parameters: alpha, beta, kappa, "):
        make_ukf(gamma=2.0)
    with pytest.raises(InputError, match="cdkf: unknown parameter 'alpha'"):
        make_cdkf(alpha=1.0)
    with pytest.raises(InputError, match="unknown parameter 'step'"):
        HOST.filter("sr-cdkf").configure(step=2.0)
