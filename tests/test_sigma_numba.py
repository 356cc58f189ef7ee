"""The UKF's compiled loops (workbench_filters.sigma_point.sigma_numba) against the filter's NumPy code.  sigma_point falls back
to NumPy silently, so each comparison asserts which code ran (sigma_point.backend_counts): two runs of the same
NumPy code would agree trivially."""

import numpy as np
import pytest

from workbench.filtering import run_filter
from workbench.kernels import backend
from workbench.kernels.backend import numba_available
from workbench.models import linear_measurement, random_walk_velocity, range_bearing
from workbench.rng import generator
from workbench.trajectory import sample_motion
from workbench.types import Gaussian, Scans
from workbench_filters import sigma_point

pytestmark = pytest.mark.skipif(not numba_available(), reason="Numba is not installed")


def _difference(after: dict, before: dict) -> dict:
    return {k: after.get(k, 0) - before.get(k, 0) for k in set(after) | set(before)}


def _scenario(model, B=40, steps=30, seed=0):
    rng = generator(seed, "sigma-numba")
    motion = random_walk_velocity(2, 1.0, 0.3)
    truth = sample_motion(np.tile([100.0, -20.0, -1.0, 2.0], (B, 1)), motion, steps, rng)
    z = model.h(truth.states) + rng.standard_normal(truth.states.shape[:2] + (model.dim,)) @ np.linalg.cholesky(model.R).T
    valid = rng.random((B, steps)) > 0.1  # missed detections: absent items keep their state
    scans = Scans(z[:, :, None, :], valid[:, :, None], np.arange(steps, dtype=float))
    prior = Gaussian.broadcast([110.0, -10.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), B)
    return prior, motion, scans


@pytest.mark.parametrize("model", [range_bearing(1.0, 0.1, sensor=(3.0, -2.0)),
                                   linear_measurement(np.eye(2, 4), np.diag([2.0, 3.0]))],
                         ids=["range-bearing", "linear"])
@pytest.mark.parametrize("B", [40, 64], ids=["serial", "threaded"])  # below and at sigma_numba.PARALLEL_MIN
@pytest.mark.parametrize("name", ["ukf", "cdkf"])
def test_compiled_ukf_equals_the_numpy_ukf(monkeypatch, model, B, name):
    # the UKF's and the CDKF's compiled loops against their NumPy code
    from workbench_filters.sigma_point import sigma_numba
    from workbench.plugins import load_host

    assert (B >= sigma_numba.PARALLEL_MIN) == (B == 64)
    spec = load_host().filter(name)
    prior, motion, scans = _scenario(model, B=B)
    before = sigma_point.backend_counts()
    fast = run_filter(spec, prior, motion, model, scans, None)
    ran = _difference(sigma_point.backend_counts(), before)
    assert ran.get("numpy", 0) == 0 and ran.get("numba", 0) >= 2 * scans.steps - 1, ran  # every step compiled
    before = sigma_point.backend_counts()
    with backend.preferring("numpy"):  # the policy's NumPy twin, asked through the policy
        slow = run_filter(spec, prior, motion, model, scans, None)
    ran = _difference(sigma_point.backend_counts(), before)
    assert ran.get("numba", 0) == 0 and ran.get("numpy", 0) >= 2 * scans.steps - 1, ran
    assert np.allclose(fast.mean, slow.mean, rtol=1e-10, atol=1e-9)
    assert np.allclose(fast.cov, slow.cov, rtol=1e-9, atol=1e-9)
    if model.H is not None:  # linear motion and measurement: the unscented transform is exact, the UKF is the KF
        mean, cov = _kalman_filter(prior, motion, model, scans)
        np.testing.assert_allclose(fast.mean, mean, rtol=1e-9, atol=1e-7)
        np.testing.assert_allclose(fast.cov, cov, rtol=1e-8, atol=1e-8)


def _kalman_filter(prior, motion, model, scans):
    """The Kalman filter written out item by item (explicit inverse): update with scan 0, then predict/update."""
    F, Q, H, R = motion.F, motion.Q, model.H, model.R
    B, T = scans.valid.shape[:2]
    means, covs = np.empty((B, T, 4)), np.empty((B, T, 4, 4))
    for b in range(B):
        x, P = prior.mean[b].copy(), prior.cov[b].copy()
        for k in range(T):
            if k:
                x, P = F.dot(x), F.dot(P).dot(F.T) + Q
            if scans.valid[b, k, 0]:
                K = P.dot(H.T).dot(np.linalg.inv(H.dot(P).dot(H.T) + R))
                x, P = x + K.dot(scans.z[b, k, 0] - H.dot(x)), (np.eye(4) - K.dot(H)).dot(P)
            means[b, k], covs[b, k] = x, P
    return means, covs


def test_compiled_update_declines_a_covariance_that_is_not_positive_definite():
    from workbench_filters.sigma_point import sigma_numba

    x = np.zeros((2, 4))
    P = np.tile(np.eye(4), (2, 1, 1))
    P[1, 2, 2] = -1.0
    X, S = np.empty((2, 9, 4)), np.empty((2, 4, 4))
    assert not sigma_numba.chol_sigma(x, P, 2.0, X, S)
    assert sigma_numba.chol_sigma(x[:1], P[:1], 2.0, X[:1], S[:1]) and np.allclose(S[0], np.eye(4))
    assert np.allclose(X[0, 1:5], 2.0 * np.eye(4)) and np.allclose(X[0, 5:], -2.0 * np.eye(4))


@pytest.mark.parametrize("name", ["sr-ukf", "sr-cdkf"])
@pytest.mark.parametrize("model", [range_bearing(1.0, 0.1, sensor=(3.0, -2.0)),
                                   linear_measurement(np.eye(2, 4), np.diag([2.0, 3.0]))],
                         ids=["range-bearing", "linear"])
@pytest.mark.parametrize("B", [1, 64], ids=["one-track", "threaded"])
def test_compiled_square_root_forms_equal_the_numpy_square_root_forms(name, model, B):
    # the compiled QR (Householder) and rank-1 sweeps of the SR-UKF and SR-CDKF against the NumPy forms (LAPACK's
    # QR, workbench.linalg.cholupdate), and both against the full-covariance filter run in NumPy
    from workbench.plugins import load_host

    host = load_host()
    spec = host.filter(name)
    prior, motion, scans = _scenario(model, B=B, seed=3)
    before = sigma_point.backend_counts()
    fast = run_filter(spec, prior, motion, model, scans, None)
    ran = _difference(sigma_point.backend_counts(), before)
    assert ran.get("numpy", 0) == 0 and ran.get("numba", 0) >= scans.steps, ran  # every predict and update compiled
    assert fast.diagnostics["downdate_fallbacks"] == 0
    with backend.preferring("numpy"):
        before = sigma_point.backend_counts()
        slow = run_filter(spec, prior, motion, model, scans, None)
        ran = _difference(sigma_point.backend_counts(), before)
        assert ran.get("numba", 0) == 0 and ran.get("numpy", 0) >= scans.steps, ran
        full = run_filter(host.filter(name[3:]), prior, motion, model, scans, None)
    np.testing.assert_allclose(fast.mean, slow.mean, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(fast.cov, slow.cov, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fast.mean, full.mean, rtol=1e-8, atol=1e-7)
    np.testing.assert_allclose(fast.cov, full.cov, rtol=1e-7, atol=1e-7)


def test_compiled_square_root_pieces_against_their_definitions():
    # tria: the lower factor of A A^T with a non-negative diagonal (A of rank n, and a zero column);
    # cholupdate: S S^T + sign u u^T; a downdate past positive definiteness is declined
    from workbench_filters.sigma_point import sigma_numba

    rng = np.random.default_rng(7)
    A = rng.normal(size=(4, 11))
    S = np.empty((4, 4))
    sigma_numba.tria_into(np.ascontiguousarray(A.T), S)
    np.testing.assert_allclose(S, np.linalg.cholesky(A @ A.T), rtol=1e-12, atol=1e-12)
    A[:, 3] = 0.0
    sigma_numba.tria_into(np.ascontiguousarray(A.T), S)
    np.testing.assert_allclose(S @ S.T, A @ A.T, rtol=1e-12, atol=1e-12)
    assert np.all(np.diag(S) >= 0.0) and np.allclose(np.triu(S, 1), 0.0)
    L = np.linalg.cholesky(A @ A.T + np.eye(4))
    u = rng.normal(size=4)
    for sign in (0.7, -0.05):
        T = L.copy()
        assert sigma_numba.cholupdate_into(T, u, sign)
        np.testing.assert_allclose(T @ T.T, L @ L.T + sign * np.outer(u, u), rtol=1e-12, atol=1e-12)
    T = L.copy()
    assert not sigma_numba.cholupdate_into(T, 10.0 * np.linalg.norm(L) * u / np.linalg.norm(u), -1.0)
