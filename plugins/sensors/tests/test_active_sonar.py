"""The active-sonar sensor: detection statistics, the polar and Cartesian measurement models, the bearing
convention."""

import numpy as np
import pytest

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import InputError, Truth

HOST = load_host()


def _truth(runs, steps=20):
    one = piecewise_trajectory((100.0, 100.0), (4.0, 2.0), [Leg("straight", steps - 1.0)], 1.0)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


def test_detection_statistics():
    sensor = HOST.sensor("active-sonar")
    truth = _truth(400)
    scans = sensor.simulate(truth, generator(1, "sonar"), **sensor.params)
    assert scans.z.shape == (400, 20, 1, 2) and np.all(scans.origin == 0)
    assert abs(scans.valid.mean() - 0.8) < 0.01
    err = (scans.z[..., 0, :] - truth.states[..., :2])[scans.valid[..., 0]]
    assert np.allclose(err.std(axis=0), 2.0, rtol=0.03) and np.allclose(err.mean(axis=0), 0.0, atol=0.05)
    assert abs(np.corrcoef(err.T)[0, 1]) < 5.0 / np.sqrt(err.shape[0])  # independent axes (5 sigma)
    assert abs(scans.snr.mean() - 20.0) < 0.01 and abs(scans.snr.std() - 0.1) < 0.005


def test_models_and_the_bearing_convention():
    sensor = HOST.sensor("active-sonar")
    polar = sensor.measurement_model(frame="polar")
    # math convention: bearing counter-clockwise from +x, (x, y) = (r cos b, r sin b)
    p = np.array([[0.0, 50.0, 0.0, 0.0], [30.0, -40.0, 0.0, 0.0]])
    r, b = polar.h(p).T
    assert np.allclose(r * np.cos(b), p[:, 0]) and np.allclose(r * np.sin(b), p[:, 1])
    assert np.isclose(b[0], np.pi / 2) and polar.frame == "range-bearing"
    # the stated accuracies the filters read: polar (sigma_r, sigma_b) and Cartesian (sigma_pos twice)
    assert np.allclose(polar.R, np.diag(np.square(polar.std)))
    cart = sensor.measurement_model(**sensor.params)
    assert np.allclose(cart.R, np.diag(np.square(cart.stated_std))) and np.allclose(cart.stated_std, 2.0)
    assert np.allclose(cart.h(p), p[:, :2])
    moved = sensor.measurement_model(frame="polar", sensor=(10.0, 0.0))
    assert np.allclose(moved.h(np.array([[10.0, 5.0, 0.0, 0.0]])), [[5.0, np.pi / 2]])
    with pytest.raises(InputError, match="frame"):
        sensor.measurement_model(frame="spherical")
    with pytest.raises(InputError, match="pd"):
        sensor.simulate(_truth(1), generator(0), pd=1.5)
