"""CMKF-L (paper 001): conversion covariance against Monte Carlo, the bearing convention, and the update
against a hand-written Kalman filter."""

import numpy as np
import pytest

from workbench.models import constant_velocity, linear_measurement, range_bearing
from workbench.rng import generator
from workbench.tracking.multi import position_covariance
from workbench.types import Gaussian, InputError, Scan
from workbench_filters.cmkf import CMKF_L, converted_covariance, polar_to_cartesian


@pytest.mark.parametrize("r, b, sigma_r, sigma_b", [(150.0, 0.6, 0.5, np.deg2rad(1.0)),
                                                    (80.0, 2.5, 2.0, np.deg2rad(0.5)),
                                                    (220.0, -1.2, 1.0, np.deg2rad(0.3))])
def test_conversion_covariance_matches_monte_carlo(r, b, sigma_r, sigma_b):
    rng = generator(1, "cmkf-mc", r)
    n = 400_000
    polar = np.stack([r + sigma_r * rng.standard_normal(n), b + sigma_b * rng.standard_normal(n)], axis=1)
    xy = polar_to_cartesian(polar)
    mc = np.cov(xy.T)
    lin = converted_covariance(np.array(r), np.array(b), sigma_r, sigma_b)
    # small sigma_b: the linearisation is accurate to a few per cent of the largest variance
    scale = np.abs(mc).max()
    assert np.max(np.abs(lin - mc)) / scale < 0.02, (lin, mc)


def test_math_bearing_convention():
    # bearing from the +x axis, counter-clockwise: b = atan2(y, x), x = r cos b, y = r sin b
    xy = np.array([[30.0, 40.0], [-10.0, 5.0], [0.0, -7.0]])
    r, b = np.hypot(xy[:, 0], xy[:, 1]), np.arctan2(xy[:, 1], xy[:, 0])
    assert np.allclose(polar_to_cartesian(np.stack([r, b], axis=1)), xy)
    # on the x axis the range error lies along x; on the y axis along y (a compass bearing would swap them)
    on_x = converted_covariance(np.array(100.0), np.array(0.0), 0.5, 0.01)
    on_y = converted_covariance(np.array(100.0), np.array(np.pi / 2), 0.5, 0.01)
    assert np.allclose(on_x, np.diag([0.25, 1.0]), atol=1e-12)
    assert np.allclose(on_y, np.diag([1.0, 0.25]), atol=1e-12)
    model = range_bearing(0.5, 0.01)
    assert np.allclose(model.h(np.array([[0.0, 100.0, 0, 0]]))[0], [100.0, np.pi / 2])


def test_closed_form_equals_the_generic_inverse_jacobian_form():
    model = range_bearing(0.5, np.deg2rad(1.0))
    rng = generator(2, "cmkf-generic")
    p = rng.uniform(-200, 200, (50, 2))
    r, b = np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])
    assert np.allclose(position_covariance(model, p, 4), converted_covariance(r, b, 0.5, np.deg2rad(1.0)))


def test_update_equals_a_hand_written_kalman_step():
    rng = generator(3, "cmkf-kf")
    B = 5
    mean = np.column_stack([rng.uniform(50, 200, (B, 2)), rng.normal(0, 3, (B, 2))])
    A = rng.normal(size=(B, 4, 4))
    cov = A @ np.swapaxes(A, 1, 2) + 4 * np.eye(4)
    prior = Gaussian(mean, cov)
    model = range_bearing(0.5, np.deg2rad(1.0))
    z = model.h(mean + rng.normal(0, 2, (B, 4)))
    present = np.array([True, True, False, True, True])
    post = CMKF_L.update(prior, Scan(z[:, None, :], present[:, None]), model, None)
    H = np.eye(2, 4)
    for i in range(B):
        if not present[i]:
            assert np.array_equal(post.mean[i], mean[i]) and np.array_equal(post.cov[i], cov[i])
            continue
        r, b = z[i]
        x = np.array([r * np.cos(b), r * np.sin(b)])
        R = np.array([[0.25 * np.cos(b) ** 2 + r * r * np.deg2rad(1) ** 2 * np.sin(b) ** 2,
                       (0.25 - r * r * np.deg2rad(1) ** 2) * np.sin(b) * np.cos(b)],
                      [(0.25 - r * r * np.deg2rad(1) ** 2) * np.sin(b) * np.cos(b),
                       0.25 * np.sin(b) ** 2 + r * r * np.deg2rad(1) ** 2 * np.cos(b) ** 2]])
        K = cov[i] @ H.T @ np.linalg.inv(H @ cov[i] @ H.T + R)
        assert np.allclose(post.mean[i], mean[i] + K @ (x - H @ mean[i]))
        assert np.allclose(post.cov[i], (np.eye(4) - K @ H) @ cov[i], atol=1e-9)


def test_predict_is_the_linear_model_and_inputs_are_checked():
    motion = constant_velocity(2, 1.0, 0.1)
    g = Gaussian(np.array([[1.0, 2.0, 3.0, 4.0]]), np.eye(4)[None])
    p = CMKF_L.predict(g, motion, None)
    assert np.allclose(p.mean, g.mean @ motion.F.T)
    assert np.allclose(p.cov, motion.F @ g.cov @ motion.F.T + motion.Q)
    with pytest.raises(InputError, match="range-bearing"):
        CMKF_L.update(g, Scan(np.ones((1, 1, 2)), np.ones((1, 1), bool)), linear_measurement(np.eye(2, 4), np.eye(2)),
                      None)
    assert "range_bearing_input" in CMKF_L.capabilities


def test_detection_covariance_is_converted_like_the_model_noise():
    # a scan carrying each detection's own polar covariance C: R_c = A C A^T.  (1) with C = diag(sigma_r^2,
    # sigma_b^2) the update equals the model-noise update; (2) with C = J_h (4 I) J_h^T (a position accuracy of 2
    # mapped into (r, b)) the update equals a Kalman filter on positions with R = 4 I
    from workbench.tracking.multi import detection_covariance
    from workbench_filters.kalman import KF

    rng = generator(5, "cmkf-cov")
    B = 6
    mean = np.column_stack([rng.uniform(50, 200, (B, 2)), rng.normal(0, 3, (B, 2))])
    A = rng.normal(size=(B, 4, 4))
    prior = Gaussian(mean, A @ np.swapaxes(A, 1, 2) + 4 * np.eye(4))
    model = range_bearing(0.5, np.deg2rad(1.0))
    z = model.h(mean + rng.normal(0, 2, (B, 4)))
    present = np.array([True, True, False, True, True, True])
    plain = CMKF_L.update(prior, Scan(z[:, None, :], present[:, None]), model, None)
    same = np.broadcast_to(np.diag([0.25, np.deg2rad(1.0) ** 2]), (B, 1, 2, 2))
    with_cov = CMKF_L.update(prior, Scan(z[:, None, :], present[:, None], cov=same), model, None)
    assert np.allclose(with_cov.mean, plain.mean) and np.allclose(with_cov.cov, plain.cov)
    xy = polar_to_cartesian(z)
    C = detection_covariance(model, xy, 4, 2.0)[:, None]
    stated = CMKF_L.update(prior, Scan(z[:, None, :], present[:, None], cov=C), model, None)
    cart = linear_measurement(np.eye(2, 4), 4.0 * np.eye(2))
    kf = KF.update(prior, Scan(xy[:, None, :], present[:, None]), cart, None)
    assert np.allclose(stated.mean, kf.mean) and np.allclose(stated.cov, kf.cov)
    assert "detection_covariance" in CMKF_L.capabilities
