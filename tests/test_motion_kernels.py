"""The compiled coordinated turn with the rate in the state (workbench/kernels/motion_numba.py): held to its NumPy
twin to 1e-12 on both sides of omega = 0, to an integration of the turn's differential equation and to finite
differences; chosen by the backend policy."""

import importlib.util

import numpy as np
import pytest

from workbench.kernels.backend import using
from workbench.models import CoordinatedTurnRate, coordinated_turn_rate
from workbench.types import InputError

needs_numba = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")

T = 0.8
#: Turn rates (rad/s) on both sides of 0: exactly 0, inside the series band |omega T| < 0.1, at its edge
#: (0.1 / T, just below and just above), and well outside it.
RATES = np.array([0.0, 1e-12, -1e-12, 1e-6, -1e-6, 0.01, -0.03, 0.1 / T * (1 - 1e-9), -0.1 / T * (1 - 1e-9),
                  0.1 / T, -0.1 / T, 0.1 / T * (1 + 1e-9), 0.3, -0.7, 2.5, -4.0])


def _states(rng, shape=None) -> np.ndarray:
    """Positions in km, speeds up to 40 m/s, every rate of RATES (repeated over ``shape``)."""
    k = RATES.size if shape is None else int(np.prod(shape))
    x = np.column_stack([rng.uniform(-3e3, 3e3, k), rng.uniform(-3e3, 3e3, k), rng.uniform(-40, 40, k),
                         rng.uniform(-40, 40, k), np.resize(RATES, k)])
    return x if shape is None else x.reshape(tuple(shape) + (5,))


@needs_numba
@pytest.mark.parametrize("shape", [None, (3, 11), (2, 7, 16)])
def test_compiled_f_and_jacobian_equal_the_numpy_twins(shape):
    model = coordinated_turn_rate(T, 0.5, 0.01)
    x = _states(np.random.default_rng(1), shape)
    with using("cpu"):
        f, J = model.f(x), model.jacobian(x)
    assert f.shape == x.shape and J.shape == x.shape + (5,)
    np.testing.assert_allclose(f, model.f_numpy(x), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(J, model.jacobian_numpy(x), rtol=1e-12, atol=1e-12)
    # the explicit interval is the one used, not the bound step
    np.testing.assert_allclose(model.f(x, dt=2.0), model.f_numpy(x, dt=2.0), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(model.jacobian(x, 0.0, 2.0), model.jacobian_numpy(x, 0.0, 2.0), rtol=1e-12,
                               atol=1e-12)


@needs_numba
def test_compiled_f_reads_a_strided_cloud_and_leaves_it_unchanged():
    # a particle cloud stored component-major ((n, B, N) in memory, seen as (B, N, n)) arrives as a strided view
    model = coordinated_turn_rate(T, 0.5, 0.01)
    rng = np.random.default_rng(2)
    rows = np.ascontiguousarray(np.moveaxis(_states(rng, (4, 32)), -1, 0))
    cloud = np.moveaxis(rows, 0, -1)
    assert not cloud.flags.c_contiguous
    before = cloud.copy()
    np.testing.assert_allclose(model.f(cloud), model.f_numpy(before), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(cloud, before)
    # the result keeps the input's memory order: the filter copies it back into its component-major cloud
    flat = cloud.reshape(-1, 5)
    assert flat.flags.f_contiguous and model.f(flat).flags.f_contiguous
    assert model.f(before.reshape(-1, 5)).flags.c_contiguous


def _turn_ode(x: np.ndarray, T: float, steps: int = 2000) -> np.ndarray:
    """The turn's differential equation (p' = v, v' = omega J v, omega' = 0) integrated by classical RK4."""
    def rate(s):
        return np.column_stack([s[:, 2], s[:, 3], -s[:, 4] * s[:, 3], s[:, 4] * s[:, 2], np.zeros(len(s))])

    h = T / steps
    s = x.copy()
    for _ in range(steps):
        k1 = rate(s)
        k2 = rate(s + 0.5 * h * k1)
        k3 = rate(s + 0.5 * h * k2)
        k4 = rate(s + h * k3)
        s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s


def test_f_follows_the_turn_and_its_jacobian_the_finite_differences_on_both_sides_of_zero():
    model = coordinated_turn_rate(T, 0.5, 0.01)
    x = _states(np.random.default_rng(3))
    f = model.f(x)  # the policy's choice: compiled with Numba
    np.testing.assert_allclose(f, _turn_ode(x, T), rtol=0, atol=1e-8)
    np.testing.assert_array_equal(f[RATES == 0.0][:, :2], x[RATES == 0.0][:, :2] + T * x[RATES == 0.0][:, 2:4])
    J = model.jacobian(x)
    h = 1e-6
    for j in range(5):
        step = np.zeros(5)
        step[j] = h
        column = (model.f_numpy(x + step) - model.f_numpy(x - step)) / (2 * h)
        np.testing.assert_allclose(J[:, :, j], column, rtol=1e-6, atol=2e-6)


@needs_numba
def test_the_backend_policy_chooses_the_compiled_loop_on_the_cpu_and_the_numpy_twin_elsewhere(monkeypatch):
    from workbench.kernels import motion_numba

    calls = []
    real_f, real_j = motion_numba.ct_rate_f, motion_numba.ct_rate_jacobian
    monkeypatch.setattr(motion_numba, "ct_rate_f", lambda *a: calls.append("f") or real_f(*a))
    monkeypatch.setattr(motion_numba, "ct_rate_jacobian", lambda *a: calls.append("jacobian") or real_j(*a))
    model = coordinated_turn_rate(T, 0.5, 0.01)
    x = _states(np.random.default_rng(4))
    with using("cpu"):
        f_cpu, j_cpu = model.f(x), model.jacobian(x)
    assert calls == ["f", "jacobian"]
    with using("cuda"):  # no Taichi version: the NumPy twin runs off the CPU
        f_gpu, j_gpu = model.f(x), model.jacobian(x)
    assert calls == ["f", "jacobian"]
    np.testing.assert_allclose(f_gpu, f_cpu, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(j_gpu, j_cpu, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("bad", [np.zeros((3, 4)), np.zeros(6), np.float64(1.0)])
@pytest.mark.parametrize("method", ["f", "jacobian", "f_numpy", "jacobian_numpy"])
def test_states_of_another_dimension_are_refused_with_one_line(bad, method):
    model = coordinated_turn_rate(T, 0.5, 0.01)
    assert isinstance(model, CoordinatedTurnRate)
    with pytest.raises(InputError, match=r"'ct-rate'.*\(\.\.\., 5\).*got shape"):
        getattr(model, method)(bad)
