"""The fused filter step (FilterSpec.step): the bootstrap filter's one-pass propagation and likelihood
(particle_numba.propagate_range_bearing) against the two kernels it fuses and the NumPy likelihood, the sir step
against its three calls through the filter kit's check, the kit check against broken steps, and the time loop's
use of the step."""

import dataclasses
from functools import partial

import numpy as np
import pytest

from workbench import particle_core as core
from workbench.kernels.backend import numba_available
from workbench.models import random_walk_velocity, range_bearing
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.testing.kit import check_step_matches_three_calls
from workbench.tracking import Direct, Gated, run
from workbench.types import Gaussian, Particles, Scan, Scans

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba is not installed")
HOST = load_host()


def _cloud(rng, B, N):
    x = core.component_major(B, N, 4)
    x[...] = rng.normal(size=(B, N, 4)) * [30.0, 30.0, 2.0, 2.0] + [100.0, 50.0, -1.0, 1.0]
    return x


def _problem(batch=3, steps=6, seed=0):
    """A target moving by random-walk velocity, seen in range and bearing from the origin."""
    rng = generator(seed, "test-fused-step")
    motion = random_walk_velocity(2, 1.0, 0.1)
    model = range_bearing(1.0, 0.1)
    x = np.tile([100.0, 50.0, -1.0, 1.0], (batch, 1))
    z = []
    for _ in range(steps):
        x = x @ motion.F.T + rng.standard_normal((batch, 4)) @ motion.Q_sqrt.T
        z.append(model.h(x) + rng.standard_normal((batch, 2)) * [1.0, 0.1])
    scans = Scans(np.stack(z, axis=1)[:, :, None, :], np.ones((batch, steps, 1), dtype=bool),
                  np.arange(steps, dtype=float))
    prior = Gaussian.broadcast(np.array([110.0, 40.0, 0.0, 0.0]), np.diag([100.0, 100.0, 4.0, 4.0]), batch)
    return scans, prior, motion, model


@needs_numba
def test_one_pass_propagation_and_likelihood_equal_the_two_kernels_bit_for_bit():
    from workbench.kernels import particle_numba as k

    B, N = 3, 2500  # N not a multiple of the tile
    rng = np.random.default_rng(4)
    x = _cloud(rng, B, N)
    x[2, 7, 0] = np.nan  # a NaN particle: its weight is NaN, and so is its item's max
    prev = rng.normal(size=(B, N)) - np.log(N)
    motion, model = random_walk_velocity(2, 1.0, 0.3), range_bearing(2.0, 0.05)
    z = np.array([[110.0, 0.4], [90.0, -3.1], [120.0, 3.14]])
    present = np.array([True, False, True])
    matrix, kk = core._propagation(motion)
    plan = core._plan_arrays(matrix.tobytes(), *matrix.shape)
    rows = np.ascontiguousarray(x.transpose(2, 0, 1))
    a, b = np.random.default_rng(8), np.random.default_rng(8)
    moved = np.empty((4, B, N))
    k.propagate(moved.reshape(4, B * N), rows.reshape(4, B * N), a, kk, *plan)
    weights = np.empty((B, N))
    linv = core._inverse_cholesky(model.R)
    k.range_bearing_log_weights(moved[0], moved[1], z, np.zeros(2), linv, prev, weights)
    out, log_w, top = np.empty((4, B, N)), np.empty((B, N)), np.full(B, -7.0)
    k.propagate_range_bearing(out.reshape(4, B * N), rows.reshape(4, B * N), b, kk, *plan, present, z, np.zeros(2),
                              linv, prev, log_w, top)
    np.testing.assert_array_equal(out, moved)
    assert a.random() == b.random()  # the same draws in the same order
    np.testing.assert_array_equal(log_w[present], weights[present])
    np.testing.assert_array_equal(log_w[~present], prev[~present])  # an item without a measurement keeps its weights
    assert top[0] == np.max(weights[0]) and np.isnan(top[2]) and top[1] == -7.0
    # and against the plain NumPy likelihood of the model (another formula for atan2 and the wrap)
    ref = core.log_likelihood(z, moved.transpose(1, 2, 0), model) + prev
    np.testing.assert_allclose(log_w[0], ref[0], rtol=1e-12, atol=1e-9)


@needs_numba
def test_the_particle_core_pass_is_taken_only_where_it_applies():
    rng = np.random.default_rng(1)
    state = core.ParticleState(Particles.trusted(_cloud(rng, 2, 300), np.full((2, 300), -np.log(300))))
    z, present = np.array([[110.0, 0.4], [100.0, 0.3]]), np.ones(2, dtype=bool)
    motion, model = random_walk_velocity(2, 1.0, 0.1), range_bearing(1.0, 0.1)
    args = (z, present)
    assert core.predict_log_weights(state, motion, np.random.default_rng(0), *args, model, "numba") is not None
    assert core.predict_log_weights(state, motion, np.random.default_rng(0), *args, model, "numpy") is None
    position = dataclasses.replace(model, frame="cartesian-2d")  # not the range-bearing frame: the two calls
    assert core.predict_log_weights(state, motion, np.random.default_rng(0), *args, position, "numba") is None


@pytest.mark.parametrize("configure", [{}, {"threshold": 2.0}, {"backend": "numpy"}])
def test_the_sir_step_equals_its_three_calls_through_the_kit(configure):
    spec = HOST.filter("sir").configure(particles=300, **configure)
    assert spec.step is not None
    assert "bit for bit" in check_step_matches_three_calls(spec)


@needs_numba
@pytest.mark.parametrize("threshold", [2.0, 0.0])
def test_a_state_from_the_step_never_shares_the_reused_work_array(threshold):
    # threshold > 1: the predicted particles live in a work array that the next step overwrites; 0: never resampled,
    # the predicted particles are the new state's
    spec = HOST.filter("sir").configure(particles=500, threshold=threshold)
    scans, prior, motion, model = _problem()
    rng = generator(2, "test")
    state = spec.update(spec.init(prior, rng), scans.scan(0).for_filter(), model, rng)
    first, _, predicted = spec.step(state, motion, scans.scan(1).for_filter(), model, rng, predicted=True)
    kept = first.cloud.particles.copy()
    for k in range(2, 5):
        spec.step(first, motion, scans.scan(k).for_filter(), model, rng)
    np.testing.assert_array_equal(first.cloud.particles, kept)


def _broken(spec, how):
    real = spec.step
    calls = []

    def step(state, motion, scan, model, rng, predicted=False):
        calls.append(1)
        if how in ("extra draw", "extra draw at the end"):
            out = real(state, motion, scan, model, rng, predicted=predicted)
            if how == "extra draw" or len(calls) == 5:  # the kit's first problem has five steps after the first scan
                rng.random()
            return out
        if how == "always predicted":
            return real(state, motion, scan, model, rng, predicted=True)
        if how == "estimate before update":
            moved = spec.predict(state, motion, rng)
            est = spec.estimate(moved)
            return spec.update(moved, scan, model, rng), est, (est if predicted else None)
        raise AssertionError(how)

    return dataclasses.replace(spec, step=step)


@pytest.mark.parametrize("how, message", [
    ("extra draw", r"step's state differs from predict \+ update \(its problem, scan 2"),
    ("extra draw at the end", "left the generator elsewhere"),
    ("always predicted", "predicted estimate without predicted=True"),
    ("estimate before update", "step's estimate differs"),
])
def test_the_kit_check_fails_a_step_that_is_not_the_three_calls(how, message):
    spec = HOST.filter("sir").configure(particles=200)
    with pytest.raises(AssertionError, match=message):
        check_step_matches_three_calls(_broken(spec, how))
    # a step whose threshold is not the update's resamples otherwise: its state differs
    with pytest.raises(AssertionError, match="step's state differs"):
        check_step_matches_three_calls(dataclasses.replace(spec, step=partial(spec.step.func, threshold=2.0,
                                                                              backend="auto")))


def test_the_time_loop_uses_the_step_with_the_same_track():
    spec = HOST.filter("sir").configure(particles=400)
    calls = []

    def counted(*args, **kwargs):
        calls.append(kwargs.get("predicted"))
        return spec.step(*args, **kwargs)

    scans, prior, motion, model = _problem(steps=7)
    fused = run(dataclasses.replace(spec, step=counted), scans, motion, model, prior=prior, rng=generator(5, "r"))
    assert calls == [True] * 6  # every scan after the first, asking for the predicted estimate (the Track's)
    plain = run(dataclasses.replace(spec, step=None), scans, motion, model, prior=prior, rng=generator(5, "r"))
    for name in ("mean", "cov", "predicted_mean"):
        np.testing.assert_array_equal(getattr(fused, name), getattr(plain, name))
    assert fused.diagnostics == plain.diagnostics

    class Shifted(Direct):  # reads the prediction its own way: the two calls, its override honoured
        def predicted_mean(self, carry, k):
            return super().predicted_mean(carry, k) + 1.0

    calls.clear()
    shifted = run(dataclasses.replace(spec, step=counted), scans, motion, model, association=Shifted(), prior=prior,
                  rng=generator(5, "r"))
    assert calls == []
    np.testing.assert_array_equal(shifted.predicted_mean[:, 1:], plain.predicted_mean[:, 1:] + 1.0)
    # a role that chooses the update from the prediction (gating) never gets the step
    run(dataclasses.replace(spec, step=counted, capabilities=spec.capabilities | {"multi_measurement"}), scans,
        motion, model, association=Gated(1e6, dims=2), prior=prior, rng=generator(5, "r"))
    assert calls == []


def test_an_empty_scan_in_the_step_leaves_the_prediction():
    spec = HOST.filter("sir").configure(particles=300)
    scans, prior, motion, model = _problem()
    a, b = generator(6, "r"), generator(6, "r")
    state = spec.init(prior, a)
    spec.init(prior, b)
    moved = spec.predict(state, motion, a)
    after, est, pred = spec.step(state, motion, Scan.empty(3, 2), model, b, predicted=True)
    np.testing.assert_array_equal(after.cloud.particles, moved.cloud.particles)
    np.testing.assert_array_equal(est.mean, pred.mean)


def _served_turn(spec):
    """``spec`` declaring that it serves the coordinated turn with the rate in the state, seen in range and bearing:
    the kit then draws its truths from that model (5-D, nonlinear) and weighs them in range and bearing."""
    return dataclasses.replace(spec, motion_models=("ct-rate",),
                               capabilities=spec.capabilities | {"range_bearing_input"})


@needs_numba
@pytest.mark.parametrize("configure", [{}, {"threshold": 2.0}])
def test_the_sir_step_with_the_coordinated_turn_takes_the_fused_pass_and_equals_its_three_calls(configure,
                                                                                                monkeypatch):
    from workbench.kernels import motion_numba

    calls = []
    real = motion_numba.ct_rate_propagate_range_bearing
    monkeypatch.setattr(motion_numba, "ct_rate_propagate_range_bearing", lambda *a: calls.append(1) or real(*a))
    spec = _served_turn(HOST.filter("sir").configure(particles=300, **configure))
    assert "bit for bit" in check_step_matches_three_calls(spec)
    assert len(calls) == 4  # the steps with a measurement (the kit's third scan is empty)


@needs_numba
def test_the_kit_check_fails_a_fused_turn_pass_that_is_not_the_two_calls(monkeypatch):
    from workbench.kernels import motion_numba

    real = motion_numba.ct_rate_propagate_range_bearing

    def off_by_an_ulp(*args):  # the log-weights one ulp up: a pass that is not predict + likelihood bit for bit
        out = real(*args)
        log_w = args[-2]
        log_w[...] = np.nextafter(log_w, np.inf)
        return out

    monkeypatch.setattr(motion_numba, "ct_rate_propagate_range_bearing", off_by_an_ulp)
    with pytest.raises(AssertionError, match="step's state differs from predict"):
        check_step_matches_three_calls(_served_turn(HOST.filter("sir").configure(particles=300)))


@needs_numba
def test_the_gather_with_the_estimate_s_sums_is_taken_and_equals_the_three_calls_over_several_tiles(monkeypatch):
    # resampling at every update: the estimate's sums are taken in the gather (particle_core.reweight_estimate),
    # tile by tile; more particles than two tiles of those sums, the last tile partial
    from workbench.kernels import particle_numba

    import workbench_filters.particle as sir_module

    taken = []
    real = core.reweight_estimate

    def spy(*args, **kwargs):
        out = real(*args, **kwargs)
        taken.append(out is not None)
        return out

    monkeypatch.setattr(sir_module, "reweight_estimate", spy)
    spec = HOST.filter("sir").configure(particles=2 * particle_numba.MOMENT_TILE + 300, threshold=2.0)
    assert "bit for bit" in check_step_matches_three_calls(spec)
    assert taken == [True, False, True, True]  # range-bearing scans 1, 4, 5; scan 2 is partly measured (reweight)
    # where it does not apply it declines: the NumPy backend, a threshold that may keep the weights, an item without
    # a measurement
    rng = np.random.default_rng(1)
    x = _cloud(rng, 2, 300)
    log_w, prev = np.log(rng.random((2, 300))), np.full((2, 300), -np.log(300))
    for args in [(2.0, "numpy", [True, True]), (0.5, "numba", [True, True]), (2.0, "numba", [True, False])]:
        assert real(x, log_w, prev, np.array(args[2]), args[0], rng, args[1]) is None


@needs_numba
def test_the_kit_check_fails_a_gather_whose_estimate_is_not_the_estimate_s(monkeypatch):
    from workbench.kernels import particle_numba

    real = particle_numba.systematic_gather_moments

    def off_by_an_ulp(*args):  # the covariance one ulp up: sums that are not the estimate's bit for bit
        out = real(*args)
        args[-1][...] = np.nextafter(args[-1], np.inf)
        return out

    monkeypatch.setattr(particle_numba, "systematic_gather_moments", off_by_an_ulp)
    with pytest.raises(AssertionError, match="step's estimate differs"):
        check_step_matches_three_calls(HOST.filter("sir").configure(particles=300, threshold=2.0))
