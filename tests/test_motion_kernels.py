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


# -- the fused pass (propagation and range-bearing log-weights) and the compiled normals ---------------------------


@needs_numba
def test_the_series_bound_of_the_compiled_f_is_continuous_and_the_twins():
    # the compiled f sums the series below |omega T| = SERIES_BOUND and calls libm's sin and cos from there on; at,
    # just below and just above that bound and far beyond it (both signs, in one tile) it stays the twin's to 1e-12,
    # and the propagation's vectorised series with its fix-up beyond the bound is f's bit for bit
    from workbench import particle_core as core
    from workbench.kernels.motion_numba import SERIES_BOUND
    from workbench.types import Particles

    model = coordinated_turn_rate(T, 0.5, 0.01)
    edge = SERIES_BOUND / T
    rates = np.array([edge, -edge, edge * (1 - 1e-12), -edge * (1 - 1e-12), edge * (1 + 1e-12), 0.2, -0.9, 3.0,
                      -5.0])
    x = np.column_stack([np.full(9, 1e3), np.full(9, -2e3), np.full(9, 30.0), np.full(9, -20.0), rates])
    with using("cpu"):
        np.testing.assert_allclose(model.f(x), model.f_numpy(x), rtol=1e-12, atol=1e-12)
        cloud = core.component_major(1, 9, 5)
        cloud[0] = x
        state = core.ParticleState(Particles.trusted(cloud, np.zeros((1, 9))))
        a, b = np.random.default_rng(3), np.random.default_rng(3)
        got = core.predict(state, model, a, backend="numba").cloud.particles
        ref = core.predict(state, model, b, backend="numpy").cloud.particles
    np.testing.assert_array_equal(got, ref)


def _weighed(model, rng, B=3, N=700):
    """A ct-rate cloud ``(B, N, 5)`` (every rate of RATES, one NaN particle), previous log-weights, two measured
    items and one without, for the fused pass."""
    from workbench import particle_core as core
    from workbench.types import Particles

    x = _cloud(rng, B, N)
    x[2, 5, 0] = np.nan
    prev = rng.normal(size=(B, N)) - np.log(N)
    state = core.ParticleState(Particles.trusted(x, prev))
    z = np.array([[2.5e3, 0.4], [1.0e3, -3.1], [3.0e3, 3.14]])
    return state, z, np.array([True, False, True])


@needs_numba
@pytest.mark.parametrize("stream", ["pcg64 in registers", "numba's generator"])
def test_the_fused_pass_equals_predict_and_the_likelihood_bit_for_bit(stream, monkeypatch):
    from workbench import particle_core as core
    from workbench.kernels import motion_numba
    from workbench.models import range_bearing

    # 2,100 normals: below PCG_MIN_DRAWS Numba's Generator draws them; lowered, the PCG64 state steps in registers
    monkeypatch.setattr(motion_numba, "PCG_MIN_DRAWS", 0 if stream == "pcg64 in registers" else 10**9)
    calls = []
    real = motion_numba.ct_rate_propagate_range_bearing
    monkeypatch.setattr(motion_numba, "ct_rate_propagate_range_bearing", lambda *a: calls.append(1) or real(*a))
    model, sensor = coordinated_turn_rate(T, [0.5, 2.0], 0.01), range_bearing(5.0, 0.01)
    state, z, present = _weighed(model, np.random.default_rng(7))  # N = 700: not a multiple of the tile
    before = state.cloud.particles.copy()
    a, b = np.random.default_rng(11), np.random.default_rng(11)
    with using("cpu"):
        moved, log_w, top = core.predict_log_weights(state, model, a, z, present, sensor, "numba")
        two = core.predict(state, model, b, backend="numba").cloud.particles
        weights = core.weighted_log_likelihood(z, two, sensor, state.cloud.log_weights, "numba")
    assert calls == [1]
    np.testing.assert_array_equal(moved, two)
    assert a.random() == b.random()  # the same draws in the same order
    np.testing.assert_array_equal(log_w[present], weights[present])
    np.testing.assert_array_equal(log_w[~present], state.cloud.log_weights[~present])
    assert top[0] == np.max(weights[0]) and np.isnan(top[2]) and top[1] == -np.inf
    np.testing.assert_array_equal(state.cloud.particles, before)
    # and against plain references: the model's NumPy f plus NumPy's draws, the NumPy likelihood
    G = core.noise_columns(model)
    e = np.random.default_rng(11).standard_normal(before.shape[:2] + (G.shape[1],))
    np.testing.assert_allclose(moved, model.f_numpy(before) + e @ G.T, rtol=1e-12, atol=1e-9)
    ref = core.log_likelihood(z, moved, sensor) + state.cloud.log_weights
    np.testing.assert_allclose(log_w[0], ref[0], rtol=1e-12, atol=1e-9)


@needs_numba
def test_the_fused_pass_is_taken_only_where_the_model_declares_it():
    from workbench import particle_core as core
    from workbench.models import range_bearing

    model, sensor = coordinated_turn_rate(T, 0.5, 0.01), range_bearing(5.0, 0.01)
    state, z, present = _weighed(model, np.random.default_rng(8), 3, 64)
    assert model.fused_particle_propagator("range-bearing") is not None
    assert model.fused_particle_propagator("cartesian-2d") is None

    class Drift(CoordinatedTurnRate):  # its own f: no compiled pass, the two calls follow that f
        def f(self, x, t=None, dt=None):
            return np.asarray(x, dtype=float) + 1.0

    drift = Drift(model.name, model.F, model.Q, model.Q_sqrt, model.dt)
    with using("cpu"):
        assert core.predict_log_weights(state, model, np.random.default_rng(0), z, present, sensor, "numba") \
            is not None
        assert core.predict_log_weights(state, model, np.random.default_rng(0), z, present, sensor, "numpy") is None
        assert drift.fused_particle_propagator("range-bearing") is None
        assert core.predict_log_weights(state, drift, np.random.default_rng(0), z, present, sensor, "numba") is None
    with using("cuda"):  # no Taichi version: the two NumPy calls off the CPU
        assert core.predict_log_weights(state, model, np.random.default_rng(0), z, present, sensor, "auto") is None


@needs_numba
@pytest.mark.parametrize("bits", ["pcg64", "pcg64 holding a 32-bit half", "philox"])
def test_the_compiled_draws_are_numpys_on_every_bit_generator(bits):
    # PCG64 is stepped in registers (motion_numba.pcg64_stream: 1.2e5 normals, above PCG_MIN_DRAWS), any other bit
    # generator through Numba's Generator; they reach the ziggurat's wedges and tail; the generator is left where
    # NumPy leaves it
    from workbench import particle_core as core
    from workbench.types import Particles

    def make():
        if bits == "philox":
            return np.random.Generator(np.random.Philox(21))
        rng = np.random.default_rng(21)
        if bits != "pcg64":
            rng.integers(0, 2**32, size=3, dtype=np.uint32)  # an odd count: one 32-bit half waits in the state
            assert rng.bit_generator.state["has_uint32"] == 1
        return rng

    model = coordinated_turn_rate(T, 0.5, 0.01)
    from workbench.kernels.motion_numba import PCG_MIN_DRAWS

    x = _cloud(np.random.default_rng(9), 1, 40_000)
    assert 3 * 40_000 >= PCG_MIN_DRAWS
    state = core.ParticleState(Particles.trusted(x, np.zeros((1, 40_000))))
    a, b, c = make(), make(), make()
    with using("cpu"):
        got = core.predict(state, model, a, backend="numba").cloud.particles
        np.testing.assert_array_equal(got, core.predict(state, model, c, backend="numpy").cloud.particles)
    e = b.standard_normal((1, 40_000, 3))
    np.testing.assert_allclose(got, model.f_numpy(x) + e @ core.noise_columns(model).T, rtol=1e-12, atol=1e-9)
    # the waiting 32-bit half first (next_uint64 never touches it), then the stream itself
    np.testing.assert_array_equal(a.integers(0, 2**32, size=5, dtype=np.uint32),
                                  b.integers(0, 2**32, size=5, dtype=np.uint32))
    np.testing.assert_array_equal(a.random(8), b.random(8))
