"""The ``dtv-pbr`` sensor (DTV passive bistatic radar, detection level): statistics, sign convention, map limits,
and a measurement model built from its parameters.

References: the bistatic geometry of ``workbench.sensing.bistatic`` (tested on its own), binomial and sample-std
bounds, and the sign convention ``Rdot = -lambda f_D``.
"""

import numpy as np
import pytest

from workbench.plugins import load_host
from workbench.rng import generator
from workbench.sensing.bistatic import bistatic_range, bistatic_range_rate, range_rate_to_doppler, wavelength
from workbench.types import InputError, Truth

TX = np.array([0.0, -8400.0, 420.0])
RX = np.array([0.0, 0.0, 60.0])
LAM = wavelength(701e6)


@pytest.fixture(scope="module")
def sensor():
    return load_host().sensor("dtv-pbr")


def _straight(B=400, T=20, p=(300.0, 50.0, 60.0), v=(3.0, -2.0, 0.0)):
    states = np.zeros((B, T, 6))
    states[..., :3] = p
    states[..., 3:] = v
    states[..., :3] += states[..., 3:] * 0.5 * np.arange(T)[None, :, None]
    return Truth(states, 0.5 * np.arange(T))


def test_candidates_have_the_stated_detection_probability_and_noise(sensor):
    truth = _straight()
    scans = sensor.simulate(truth, generator(3, "s"))
    n = truth.batch * truth.steps
    assert abs(scans.valid.sum() - 0.9 * n) < 4 * np.sqrt(n * 0.09)
    states = truth.states
    x = np.stack([bistatic_range(states[..., :3], TX, RX), bistatic_range_rate(states[..., :3], states[..., 3:], TX, RX)],
                 -1)
    err = (scans.z[:, :, 0] - x)[scans.valid[:, :, 0]]
    # sample std within 5 % of the parameter (n ~ 7200: the std's own sd is ~0.8 %)
    assert np.std(err[:, 0]) == pytest.approx(sensor.params["sigma_range"], rel=0.05)
    assert np.std(err[:, 1]) == pytest.approx(sensor.params["sigma_range_rate"], rel=0.05)
    assert abs(np.mean(err[:, 0])) < 4 * 15.0 / np.sqrt(err.shape[0])
    assert np.all(scans.origin == 0)
    np.testing.assert_allclose(scans.doppler[scans.valid], range_rate_to_doppler(scans.z[..., 1][scans.valid], LAM))
    strength = scans.snr[scans.valid]
    assert np.mean(strength) == pytest.approx(18.0, abs=0.2)


def test_parameters_change_what_is_simulated_and_the_model(sensor):
    truth = _straight(B=200)
    certain = sensor.simulate(truth, generator(4, "s"), pd=1.0, sigma_range=0.0, sigma_range_rate=0.0)
    assert certain.valid.all()
    x = np.stack([bistatic_range(truth.states[..., :3], TX, RX),
                  bistatic_range_rate(truth.states[..., :3], truth.states[..., 3:], TX, RX)], -1)
    np.testing.assert_allclose(certain.z[:, :, 0], x)
    # another transmitter moves every bistatic range by the geometry, nothing else
    moved = sensor.simulate(truth, generator(4, "s"), pd=1.0, sigma_range=0.0, sigma_range_rate=0.0,
                            tx=(1000.0, -8000.0, 400.0))
    np.testing.assert_allclose(moved.z[:, :, 0, 0], bistatic_range(truth.states[..., :3], [1000.0, -8000.0, 400.0], RX))
    model = sensor.measurement_model(model_sigma_range=20.0, model_sigma_range_rate=0.3)
    np.testing.assert_allclose(model.H, np.eye(2))
    np.testing.assert_allclose(model.R, np.diag([400.0, 0.09]))
    assert model.frame == "bistatic-range-rate" and sensor.detection_frame() == "bistatic-range-rate"
    with pytest.raises(InputError, match="unknown parameter"):
        sensor.simulate(truth, generator(0), tx_position=(0, 0, 0))
    with pytest.raises(InputError, match="pd"):
        sensor.simulate(truth, generator(0), pd=1.5)


def test_targets_outside_the_map_are_not_detected(sensor):
    far = _straight(B=50, T=4, p=(0.0, 4000.0, 60.0), v=(0.0, 1.0, 0.0))  # bistatic range ~ 6 km > 3 km
    assert bistatic_range(far.states[0, 0, :3], TX, RX) > 3000.0
    assert not sensor.simulate(far, generator(5), pd=1.0).valid.any()
    fast = _straight(B=50, T=4, p=(600.0, 0.0, 60.0), v=(60.0, 0.0, 0.0))  # |Rdot| > 50 m/s
    assert not sensor.simulate(fast, generator(5), pd=1.0).valid.any()


def test_approaching_target_end_to_end_has_positive_doppler(sensor):
    # a drone flying straight at the receiver from the east
    p = np.array([600.0, 100.0, 60.0])
    v = -8.0 * (p - RX) / np.linalg.norm(p - RX)
    states = np.concatenate([p + v * 0.5 * np.arange(10)[:, None], np.broadcast_to(v, (10, 3))], axis=1)[None]
    scans = sensor.simulate(Truth(states, 0.5 * np.arange(10)), generator(0, "t"), pd=1.0)
    assert np.all(scans.doppler[scans.valid] > 0) and np.all(scans.z[..., 1][scans.valid] < 0)
