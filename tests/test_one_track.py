"""One track (B = 1) through the compiled Kalman and UKF paths: the same numbers as their NumPy twins (the backend
policy's ``"numpy"``), as FilterPy's EKF and as the equations written out here, and every check that protects the
user still made there.  The compiled paths fall back to NumPy silently, so each comparison asserts which code ran
(``backend_counts``): two runs of the same NumPy code would agree trivially."""

from dataclasses import dataclass

import numpy as np
import pytest

from workbench import kalman_core
from workbench.kernels import backend
from workbench.models import MeasurementModel, MotionModel, random_walk_velocity, range_bearing
from workbench.types import Gaussian, InputError, Scan, Scans, _validated
from workbench_filters import sigma_point

pytestmark = pytest.mark.skipif(not backend.numba_available(), reason="Numba is not installed")

STEPS = 40


def _track(steps=STEPS, seed=5):
    """Paper 003's range-bearing problem, one run: prior, motion, model and the scans (one measurement each)."""
    rng = np.random.default_rng(seed)
    motion = random_walk_velocity(2, 1.0, 0.1)
    model = range_bearing(1.0, 0.1)
    x = np.array([100.0, 50.0, -1.0, 1.0])
    z = np.empty((steps, 2))
    for k in range(steps):
        x = motion.F @ x + np.linalg.cholesky(motion.Q + 1e-12 * np.eye(4)) @ rng.standard_normal(4)
        z[k] = model.h(x[None])[0] + rng.standard_normal(2) * [1.0, 0.1]
    z[:, 1] = (z[:, 1] + np.pi) % (2 * np.pi) - np.pi
    scans = Scans(z[None, :, None, :], np.ones((1, steps, 1), dtype=bool), np.arange(steps, dtype=float))
    prior = Gaussian(np.array([[110.0, 40.0, 0.0, 0.0]]), np.diag([100.0, 100.0, 4.0, 4.0])[None])
    return prior, motion, model, [scans.scan(k).for_filter() for k in range(steps)]


def _run(spec, prior, motion, model, scans):
    """Predict + update through the filter's public functions, as a user writes a one-track loop."""
    state = spec.init(prior, None)
    means, covs = [], []
    for scan in scans:
        state = spec.update(spec.predict(state, motion, None), scan, model, None)
        out = spec.estimate(state)
        means.append(out.mean[0])
        covs.append(out.cov[0])
    return np.array(means), np.array(covs)


def _counts_during(counts, fn):
    before = counts()
    out = fn()
    after = counts()
    return out, {k: after.get(k, 0) - before.get(k, 0) for k in set(after) | set(before)}


@pytest.mark.parametrize("name", ["ekf", "ukf"])
def test_one_track_equals_the_numpy_twin_to_1e_12(name):
    from workbench.plugins import load_host

    spec = load_host().filter(name)
    counts = kalman_core.backend_counts if name == "ekf" else sigma_point.backend_counts
    track = _track()
    fast, ran = _counts_during(counts, lambda: _run(spec, *track))
    assert ran.get("numpy", 0) == 0 and ran.get("numba", 0) == 2 * STEPS, ran  # every predict and update compiled
    with backend.preferring("numpy"):
        slow, ran = _counts_during(counts, lambda: _run(spec, *track))
    assert ran.get("numba", 0) == 0 and ran.get("numpy", 0) == 2 * STEPS, ran
    for a, b in zip(fast, slow):
        scale = np.abs(b).max(axis=tuple(range(1, b.ndim)), keepdims=True)  # per step
        worst = float((np.abs(a - b) / scale).max())
        assert worst <= 1e-12, worst


def test_one_track_ekf_equals_filterpys_ekf():
    filterpy = pytest.importorskip("filterpy.kalman")
    from workbench.plugins import load_host

    prior, motion, model, scans = _track()
    means, covs = _run(load_host().filter("ekf"), prior, motion, model, scans)
    assert kalman_core.last_backend() == "numba"
    ekf = filterpy.ExtendedKalmanFilter(4, 2)
    ekf.x, ekf.P = prior.mean[0].copy(), prior.cov[0].copy()
    ekf.F, ekf.Q, ekf.R = motion.F, motion.Q, model.R
    for k, scan in enumerate(scans):
        ekf.predict()
        ekf.update(scan.z[0, 0], lambda x: model.jacobian(x[None])[0], lambda x: model.h(x),
                   residual=lambda a, b: model.residual(a, b))
        np.testing.assert_allclose(means[k], ekf.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(covs[k], ekf.P, rtol=1e-8, atol=1e-9)


@dataclass(frozen=True)
class ClippedResidual(MeasurementModel):
    """A model with a residual of its own (a robust, clipped one): the compiled update must use it, not wrap."""

    def residual(self, a, b):
        return np.clip(np.asarray(a, dtype=float) - np.asarray(b, dtype=float), -0.5, 0.5)


def test_a_models_own_residual_is_honoured_on_the_compiled_path():
    base = range_bearing(1.0, 0.1)
    model = ClippedResidual(name="clipped", h=base.h, R=base.R, jacobian=base.jacobian, angular=(False, True))
    g = Gaussian(np.array([[100.0, 50.0, 1.0, -1.0]]), np.diag([30.0, 20.0, 4.0, 4.0])[None])
    z = base.h(g.mean) + np.array([[3.0, -0.2]])  # the range residual is clipped to 0.5
    scan = Scan.single(z)
    out = kalman_core.ekf_update(g, scan, model)
    assert kalman_core.last_backend() == "numba"
    with backend.preferring("numpy"):
        twin = kalman_core.ekf_update(g, scan, model)
    assert kalman_core.last_backend() == "numpy"
    np.testing.assert_allclose(out.mean, twin.mean, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(out.cov, twin.cov, rtol=1e-12, atol=1e-12)
    # written out: nu = clip(z - h(x), -0.5, 0.5), K = P H^T S^-1
    H, P = base.jacobian(g.mean)[0], g.cov[0]
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + base.R)
    nu = np.clip(z[0] - base.h(g.mean)[0], -0.5, 0.5)
    np.testing.assert_allclose(out.mean[0], g.mean[0] + K @ nu, rtol=1e-12)


def test_bearing_residuals_wrap_across_pi_on_the_compiled_path():
    model = range_bearing(1.0, 0.1)
    # a target just above the -x axis (bearing pi - 0.005) measured just below it (-pi + 0.01): wrap(z - h) = 0.015
    g = Gaussian(np.array([[-100.0, 0.5, 1.0, -1.0]]), np.diag([30.0, 20.0, 4.0, 4.0])[None])
    z = np.array([[99.0, -np.pi + 0.01]])
    out = kalman_core.ekf_update(g, Scan.single(z), model)
    assert kalman_core.last_backend() == "numba"
    with backend.preferring("numpy"):
        twin = kalman_core.ekf_update(g, Scan.single(z), model)
    np.testing.assert_allclose(out.mean, twin.mean, rtol=1e-13, atol=1e-12)
    H, P = model.jacobian(g.mean)[0], g.cov[0]
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + model.R)
    hx = np.array([np.hypot(-100.0, 0.5), np.arctan2(0.5, -100.0)])
    nu = np.array([z[0, 0] - hx[0], z[0, 1] - hx[1] + 2 * np.pi])  # the short way round
    assert abs(nu[1] - (0.01 + np.arctan2(0.5, 100.0))) < 1e-12
    np.testing.assert_allclose(out.mean[0], g.mean[0] + K @ nu, rtol=1e-12)


def test_a_non_finite_result_is_refused_by_name_on_the_compiled_path():
    g = Gaussian(np.array([[100.0, 50.0, 1.0, -1.0]]), np.diag([30.0, 20.0, 4.0, 4.0])[None])
    F = 1e200 * np.eye(4)  # P- = F P F^T overflows
    huge = MotionModel("huge", F, np.eye(4), np.eye(4), 1.0)
    fast = kalman_core._compiled()
    assert not fast.predict_items(g.mean, g.cov, F, np.eye(4), np.empty((1, 4)), np.empty((1, 4, 4)))
    for preferred in ("auto", "numpy"):
        with backend.preferring(preferred), np.errstate(over="ignore"), \
                pytest.raises(InputError, match="Gaussian.cov holds a non-finite"):
            kalman_core.linear_predict(g, huge)
    base = range_bearing(1.0, 0.1)
    nan_h = MeasurementModel(name="nan-h", h=lambda x: np.full(x.shape[:-1] + (2,), np.nan), R=base.R,
                             jacobian=base.jacobian, angular=(False, True))
    for preferred in ("auto", "numpy"):
        with backend.preferring(preferred), pytest.raises(InputError, match="Gaussian.mean holds a non-finite"):
            kalman_core.ekf_update(g, Scan.single(np.array([[110.0, 0.4]])), nan_h)


def test_a_jacobian_of_the_wrong_shape_is_refused_by_name():
    base = range_bearing(1.0, 0.1)
    short = MeasurementModel(name="short-jacobian", h=base.h, R=base.R, jacobian=lambda x: base.jacobian(x)[..., :3],
                             angular=(False, True))
    g = Gaussian(np.array([[100.0, 50.0, 1.0, -1.0]]), np.diag([30.0, 20.0, 4.0, 4.0])[None])
    for preferred in ("auto", "numpy"):
        with backend.preferring(preferred), pytest.raises(InputError, match="'short-jacobian' gave H .* shape"):
            kalman_core.ekf_update(g, Scan.single(np.array([[110.0, 0.4]])), short)


def test_a_non_finite_measurement_is_refused_by_name_on_the_compiled_ukf_path():
    from workbench.plugins import load_host

    spec = load_host().filter("ukf")
    g = Gaussian(np.array([[100.0, 50.0, 1.0, -1.0]]), np.diag([30.0, 20.0, 4.0, 4.0])[None])
    # a scan that skipped its checks (Scan itself refuses NaN in a valid row): the filter still refuses it
    scan = _validated(Scan, z=np.array([[[np.nan, 0.4]]]), valid=np.ones((1, 1), bool), snr=None, doppler=None,
                      origin=None, time=0.0, cov=None, clutter_density=None)
    for preferred in ("auto", "numpy"):
        with backend.preferring(preferred), pytest.raises(InputError, match="measurement of batch item 0 is not fin"):
            spec.update(spec.init(g), scan, range_bearing(1.0, 0.1), None)


class WrittenOutLinear(MotionModel):
    """``f(x) = x F^T`` written out, not declared linear: the UKF takes its generic compiled predict."""

    def f(self, x, t=None, dt=None):
        return np.asarray(x, dtype=float) @ self.F.T


def test_the_fused_linear_ukf_predict_equals_the_generic_compiled_one_and_the_numpy_twin():
    from workbench.plugins import load_host

    spec = load_host().filter("ukf")
    motion = random_walk_velocity(2, 1.0, 0.3)
    written = WrittenOutLinear(motion.name, motion.F, motion.Q, motion.Q_sqrt, motion.dt)
    assert motion.linear and not written.linear
    rng = np.random.default_rng(2)
    a = rng.normal(size=(3, 4, 4))
    state = spec.init(Gaussian(rng.normal(size=(3, 4)) * 40, a @ np.swapaxes(a, 1, 2) + np.eye(4)))
    fused = spec.predict(state, motion, None)
    generic = spec.predict(state, written, None)
    assert sigma_point.last_backend() == "numba"
    with backend.preferring("numpy"):
        twin = spec.predict(state, motion, None)
    assert sigma_point.last_backend() == "numpy"
    for other in (generic, twin):
        np.testing.assert_allclose(fused.mean, other.mean, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(fused.cov, other.cov, rtol=1e-12, atol=1e-12)
    # the unscented transform of a linear map is exact: F x, F P F^T + Q
    np.testing.assert_allclose(fused.mean, state.mean @ motion.F.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fused.cov, motion.F @ state.cov @ motion.F.T + motion.Q, rtol=1e-11, atol=1e-11)


def test_a_scan_cut_from_a_batch_hands_the_kernels_a_contiguous_mask():
    """``single_measurement`` gives ``present`` contiguous whether the scan is one track or a column of a (B, T, M)
    batch (there a strided view): a compiled update then sees one array layout, so one compilation serves both
    (a strided mask had compiled the Kalman and unscented updates a second time in every process)."""
    from workbench.filtering import single_measurement

    rng = np.random.default_rng(3)
    valid = rng.random((5, 4, 1)) < 0.7
    scans = Scans(rng.standard_normal((5, 4, 1, 2)), valid, np.arange(4, dtype=float))
    for k in range(4):
        scan = scans.scan(k).for_filter()
        z, present = single_measurement(scan)
        assert present.flags.c_contiguous and present.dtype == bool
        np.testing.assert_array_equal(present, valid[:, k, 0])
        np.testing.assert_array_equal(z, scans.z[:, k, 0])
