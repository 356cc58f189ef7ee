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


# -- the particle filter's compiled propagation through the model (particle_propagator) ---------------------------


def _cloud(rng, B=2, N=700):
    """A ``(B, N, 5)`` cloud stored component-major (as the particle filter keeps it), every rate of RATES."""
    from workbench import particle_core as core

    x = core.component_major(B, N, 5)
    x[...] = _states(rng, (B, N))
    return x


@needs_numba
@pytest.mark.parametrize("dt", [T, 2.5])
def test_compiled_propagation_equals_the_numpy_path_bit_for_bit_and_follows_f(dt):
    from workbench import particle_core as core
    from workbench.types import Particles

    model = coordinated_turn_rate(T, [0.5, 2.0], 0.01).at(3.0, dt)
    x = _cloud(np.random.default_rng(5))
    state = core.ParticleState(Particles.trusted(x, np.full(x.shape[:2], -np.log(x.shape[1]))))
    before = x.copy()
    a, b, c = np.random.default_rng(9), np.random.default_rng(9), np.random.default_rng(9)
    with using("cpu"):
        ref = core.predict(state, model, a, backend="numpy").cloud.particles
        got = core.predict(state, model, b, backend="numba").cloud.particles
    np.testing.assert_array_equal(got, ref)  # the NumPy twin, bit for bit
    assert a.random() == b.random()  # the generator left where NumPy leaves it
    np.testing.assert_array_equal(x, before)
    assert np.moveaxis(got, 2, 0).flags.c_contiguous  # component-major, as the filter keeps it
    # an independent reference: the model's NumPy f plus Q_sqrt's non-zero columns times NumPy's draws
    G = core.noise_columns(model)
    e = c.standard_normal(x.shape[:2] + (G.shape[1],))
    np.testing.assert_allclose(got, model.f_numpy(before) + e @ G.T, rtol=1e-12, atol=1e-9)


@needs_numba
def test_the_particle_filter_runs_the_declared_loop_only_where_the_policy_runs_numba_and_f_is_the_models(monkeypatch):
    from workbench import particle_core as core
    from workbench.kernels import motion_numba
    from workbench.kernels.backend import preferring
    from workbench.types import Particles

    calls = []
    real = motion_numba.ct_rate_propagate
    monkeypatch.setattr(motion_numba, "ct_rate_propagate", lambda *a: calls.append(1) or real(*a))
    model = coordinated_turn_rate(T, 0.5, 0.01)
    x = _cloud(np.random.default_rng(6), 1, 64)
    state = core.ParticleState(Particles.trusted(x, np.zeros((1, 64))))
    with using("cpu"):
        core.predict(state, model, np.random.default_rng(1), backend="auto")
        assert len(calls) == 1
        core.predict(state, model, np.random.default_rng(1), backend="numpy")
        with preferring("numpy"):  # WORKBENCH_BACKEND=numpy: "auto" is the NumPy twin
            core.predict(state, model, np.random.default_rng(1), backend="auto")
        assert len(calls) == 1
    with using("cuda"):  # no Taichi version: the NumPy path off the CPU
        core.predict(state, model, np.random.default_rng(1), backend="auto")
    assert len(calls) == 1

    class Drift(CoordinatedTurnRate):  # a user's own f is what the filter follows, never the compiled turn
        def f(self, x, t=None, dt=None):
            return np.asarray(x, dtype=float) + 1.0

    drift = Drift(model.name, model.F, model.Q, model.Q_sqrt, model.dt)
    assert drift.particle_propagator() is None
    with using("cpu"):
        moved = core.predict(state, drift, np.random.default_rng(2), backend="numba").cloud.particles
    G = core.noise_columns(drift)
    e = np.random.default_rng(2).standard_normal((1, 64, G.shape[1]))
    np.testing.assert_allclose(moved, x + 1.0 + e @ G.T, rtol=1e-12, atol=1e-12)
    assert len(calls) == 1
