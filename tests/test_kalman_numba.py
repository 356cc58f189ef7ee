"""The compiled Kalman loops (workbench.kernels.kalman_numba) against their NumPy twin, the batched
code of workbench.kalman_core (taken when the backend policy has no Numba, as on a GPU arch), and both against the
Kalman equations written out item by item here.  kalman_core falls back to NumPy silently, so every comparison
asserts which code ran (kalman_core.last_backend): two runs of the same NumPy code would agree trivially."""

import numpy as np
import pytest

from workbench import kalman_core
from workbench.kernels import backend
from workbench.models import constant_velocity, linear_measurement, range_bearing
from workbench.types import Gaussian, Scan

pytestmark = pytest.mark.skipif(not backend.numba_available(), reason="Numba is not installed")


def _random_gaussian(rng, B, n):
    a = rng.normal(size=(B, n, n))
    return Gaussian(rng.normal(size=(B, n)) * 50 + 100, a @ np.swapaxes(a, 1, 2) + np.eye(n))


def _both(fn):
    compiled = fn()
    assert kalman_core.last_backend() == "numba"  # the compiled loops ran, not the silent fallback
    with backend.using("vulkan"):  # no Numba there: the NumPy twin
        reference = fn()
    assert kalman_core.last_backend() == "numpy"
    return compiled, reference


@pytest.mark.parametrize("B", [1, 5, 63, 3000])
def test_predict_matches_the_numpy_twin(B):
    rng = np.random.default_rng(B)
    g = _random_gaussian(rng, B, 4)
    motion = constant_velocity(2, 0.7, 1.3)
    compiled, reference = _both(lambda: kalman_core.linear_predict(g, motion))
    np.testing.assert_allclose(compiled.mean, reference.mean, rtol=1e-13, atol=1e-11)
    np.testing.assert_allclose(compiled.cov, reference.cov, rtol=1e-12, atol=1e-10)
    np.testing.assert_array_equal(compiled.cov, np.swapaxes(compiled.cov, 1, 2))  # exactly symmetric
    # the prediction written out item by item: x- = F x, P- = F P F^T + Q
    F, Q = motion.F, motion.Q
    for b in range(B):
        np.testing.assert_allclose(compiled.mean[b], F.dot(g.mean[b]), rtol=1e-13, atol=1e-11)
        np.testing.assert_allclose(compiled.cov[b], F.dot(g.cov[b]).dot(F.T) + Q, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("B", [1, 7, 500])
def test_ekf_update_matches_the_numpy_twin_with_wrapping_missing_items_and_own_covariances(B):
    rng = np.random.default_rng(10 + B)
    g = _random_gaussian(rng, B, 4)
    model = range_bearing(2.0, 0.05)
    z = model.h(g.mean) + rng.normal(size=(B, 2)) * [2.0, 0.05]
    z[:, 1] = np.where(np.arange(B) % 2 == 0, np.pi - 0.01, z[:, 1])  # bearings near +-pi: the residual wraps
    present = np.arange(B) % 3 != 2 if B > 1 else np.ones(1, bool)
    cov = np.broadcast_to(np.diag([4.0, 0.01]), (B, 1, 2, 2)) * rng.uniform(0.5, 2.0, (B, 1, 1, 1))
    for scan in (Scan(z[:, None], present[:, None]), Scan(z[:, None], present[:, None], cov=cov)):
        H = model.jacobian(g.mean)
        compiled, reference = _both(lambda: kalman_core.kalman_update(g, scan, model, H, "ekf"))
        np.testing.assert_allclose(compiled.mean, reference.mean, rtol=1e-11, atol=1e-9)
        np.testing.assert_allclose(compiled.cov, reference.cov, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(compiled.mean[~present], g.mean[~present])  # no measurement: unchanged
        # the EKF update written out item by item, with an explicit inverse (fine at these sizes)
        Rs = np.broadcast_to(model.R, (B, 2, 2)) if scan.cov is None else scan.cov[:, 0]
        for b in np.flatnonzero(present):
            Hb, Pb = H[b], g.cov[b]
            S = Hb.dot(Pb).dot(Hb.T) + Rs[b]
            K = Pb.dot(Hb.T).dot(np.linalg.inv(S))
            nu = z[b] - model.h(g.mean[b:b + 1])[0]
            nu[1] = (nu[1] + np.pi) % (2 * np.pi) - np.pi  # the bearing residual wraps
            IKH = np.eye(4) - K.dot(Hb)
            np.testing.assert_allclose(compiled.mean[b], g.mean[b] + K.dot(nu), rtol=1e-10, atol=1e-8)
            np.testing.assert_allclose(compiled.cov[b], IKH.dot(Pb).dot(IKH.T) + K.dot(Rs[b]).dot(K.T),
                                       rtol=1e-8, atol=1e-8)


def test_a_non_positive_definite_innovation_falls_back_to_the_numpy_path():
    # an indefinite prior (only reachable through the unchecked constructor) gives S = diag(2, -2)
    g = Gaussian.trusted(np.zeros((1, 2)), np.diag([1.0, -3.0])[None])
    model = linear_measurement(np.eye(2), np.eye(2))
    fast = kalman_core._compiled()
    out_x, out_p = np.empty((1, 2)), np.empty((1, 2, 2))
    assert not fast.update_items(g.mean, g.cov, np.ones((1, 2)), np.zeros((1, 2)), np.zeros(2, bool), np.eye(2)[None],
                                 np.eye(2)[None], np.ones(1, bool), out_x, out_p)
    result = kalman_core.kalman_update(g, Scan.single(np.ones((1, 2))), model, np.eye(2)[None], "kf")
    assert kalman_core.last_backend() == "numpy"  # the NumPy path's general solve took over
    assert np.all(np.isfinite(result.mean))


def test_every_batch_size_takes_the_compiled_loops_where_numba_is():
    rng = np.random.default_rng(3)
    motion = constant_velocity(2, 0.7, 1.3)
    for B in (1, 63, 64, 3000):
        before = kalman_core.backend_counts()
        kalman_core.linear_predict(_random_gaussian(rng, B, 4), motion)
        after = kalman_core.backend_counts()
        assert after.get("numba", 0) == before.get("numba", 0) + 1, B


def test_a_read_only_jacobian_takes_the_same_compiled_update_as_a_writable_one(monkeypatch):
    """A model's cached H is often read-only; Numba types a read-only array apart, so handing it on as it is compiled
    the update a second time in every process that met both (about 3 s each).  The kernel gets a writable H either
    way, and the numbers are those of the writable one."""
    from workbench.kernels import kalman_numba

    rng = np.random.default_rng(11)
    B = 7
    g = _random_gaussian(rng, B, 4)
    model = linear_measurement(np.eye(2, 4), 9.0 * np.eye(2))
    scan = Scan(rng.normal(size=(B, 1, 2)) * 50 + 100, np.ones((B, 1), dtype=bool))
    seen = []
    original = kalman_numba.update_items

    def recording(x, P, z, hx, angular, H, *rest):
        seen.append(H.flags.writeable)
        return original(x, P, z, hx, angular, H, *rest)

    monkeypatch.setattr(kalman_numba, "update_items", recording)
    H = np.ascontiguousarray(np.broadcast_to(np.eye(2, 4), (B, 2, 4)))
    frozen = H.copy()
    frozen.flags.writeable = False
    writable_out = kalman_core.kalman_update(g, scan, model, H, "test")
    frozen_out = kalman_core.kalman_update(g, scan, model, frozen, "test")
    assert kalman_core.last_backend() == "numba"
    assert seen == [True, True]
    np.testing.assert_array_equal(frozen_out.mean, writable_out.mean)
    np.testing.assert_array_equal(frozen_out.cov, writable_out.cov)
