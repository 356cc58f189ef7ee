"""The plugin's own tests: the workbench conformance kit, plus one behaviour of its own."""

import numpy as np

from alpha_beta_filter import make_alpha_beta
from workbench.testing import parametrize_with_checks


@parametrize_with_checks([make_alpha_beta()])
def test_conformance(spec, check):
    check(spec)


def test_installed_and_discovered(workbench_host):
    assert workbench_host.filter("alpha-beta").params == {"alpha": 0.5, "beta": 0.2, "dt": 1.0}


def test_steady_state_gain_on_a_noise_free_ramp():
    """On a noise-free constant-velocity ramp the alpha-beta filter converges to the truth."""
    from workbench.models import constant_velocity, linear_measurement
    from workbench.types import Gaussian, Scan

    spec = make_alpha_beta()
    motion = constant_velocity(2, 1.0, 0.1)
    model = linear_measurement(np.eye(2, 4), np.eye(2))
    state = spec.init(Gaussian.broadcast([0, 0, 0, 0], np.eye(4), 1), None)
    for k in range(60):
        if k:
            state = spec.predict(state, motion, None)
        state = spec.update(state, Scan.single(np.array([[3.0 * k, -1.0 * k]])), model, None)
    np.testing.assert_allclose(state.mean[0], [177.0, -59.0, 3.0, -1.0], atol=1e-6)
