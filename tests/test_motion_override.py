"""A motion model whose ``f`` is overridden is honoured or refused by name by every built-in filter, never
silently replaced by its ``F`` (issue 23, item 3).

The nonlinear model is a coordinated turn with the turn rate in the state, ``[x, y, vx, vy, w]``, written here
by subclassing :class:`workbench.models.MotionModel`; its ``F`` is that of constant velocity (the rate held), so
a filter that reads ``F`` instead of ``f`` predicts a straight line, metres away from the turn.  The expected
predictions are computed item by item with ``math`` (:func:`turn_step`), independently of the model's vectorised
``f``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fixtures.wrong_motion import CoordinatedTurn

from workbench import load_host
from workbench.filtering import run_filter
from workbench.models import MotionModel, constant_velocity, linear_measurement, range_bearing
from workbench.plugins import BUILTIN_DISTRIBUTION
from workbench.rng import generator
from workbench.tracking import Gated, run
from workbench.types import Gaussian, InputError, Scans

DT = 1.0
N_STATE = 5


def turn_step(state, dt=DT):
    """One coordinated-turn step of one state ``[x, y, vx, vy, w]`` (plain Python, the reference)."""
    x, y, vx, vy, w = (float(v) for v in state)
    if abs(w) < 1e-12:
        return [x + dt * vx, y + dt * vy, vx, vy, w]
    s, c = math.sin(w * dt), math.cos(w * dt)
    return [x + (s * vx - (1.0 - c) * vy) / w, y + ((1.0 - c) * vx + s * vy) / w, c * vx - s * vy, s * vx + c * vy, w]


def reference_f(x):
    x = np.asarray(x, dtype=float)
    return np.array([turn_step(row) for row in x.reshape(-1, N_STATE)]).reshape(x.shape)


class Turn(CoordinatedTurn):
    """The coordinated turn of the motion-model kit's fixtures, with its analytic Jacobian (the kit checks it
    against central differences; the test below checks f against :func:`turn_step`)."""


class TurnNoJacobian(MotionModel):
    """The same turn without a Jacobian."""

    _terms = CoordinatedTurn._terms
    f = CoordinatedTurn.f


def _cv_with_rate(q_scale: float):
    """``F`` of constant velocity with the rate held, and a ``Q`` (zero for ``q_scale = 0``)."""
    F = np.eye(N_STATE)
    F[0, 2] = F[1, 3] = DT
    G = np.zeros((N_STATE, 3))
    G[0, 0] = G[1, 1] = DT * DT / 2
    G[2, 0] = G[3, 1] = DT
    G[4, 2] = 0.01
    G *= q_scale
    return F, G @ G.T, G  # Q_sqrt (n, 3): G G^T = Q


def turn_model(cls=Turn, q_scale: float = 0.0, name: str = "ct-test"):
    F, Q, G = _cv_with_rate(q_scale)
    Q_sqrt = np.zeros((N_STATE, N_STATE))
    Q_sqrt[:, :3] = G
    return cls(name, F, Q, Q_sqrt, DT)


#: three states turning at 0.1, -0.2 and 0.05 rad/s: f and F x differ by metres
MEANS = np.array([[100.0, -50.0, 30.0, 10.0, 0.1], [-2000.0, 400.0, -15.0, 25.0, -0.2],
                  [5.0, 5.0, 60.0, -40.0, 0.05]])


def builtin_filters():
    host = load_host()
    return host, sorted(n for n in host.filters if host.plugin_of("workbench_filters", n).distribution
                        == BUILTIN_DISTRIBUTION)


HOST, BUILTIN = builtin_filters()

#: filters that can follow a model with a Jacobian (the rest may refuse it, by name)
FOLLOW_WITH_JACOBIAN = {"ekf", "cmkf-l", "ekf-nis", "ukf", "cdkf", "sr-ukf", "sr-cdkf", "sir", "sir-jm", "tbd-pf"}
#: filters that propagate with F only (the exact Kalman filter, the Stone Soup adapters, which hand Stone Soup F and Q):
#: they may refuse a model that overrides f even when it is linear, by name
NEEDS_F = {"kf", "ss-kf", "ss-ekf", "ss-ukf", "ss-ckf", "ss-pf"}
#: ... and without one
FOLLOW_WITHOUT_JACOBIAN = {"ukf", "cdkf", "sr-ukf", "sr-cdkf", "sir", "sir-jm", "tbd-pf"}


def test_the_test_model_is_a_coordinated_turn_with_a_correct_jacobian():
    model = turn_model()
    assert not model.linear and model.has_jacobian and not turn_model(TurnNoJacobian).has_jacobian
    np.testing.assert_allclose(model.f(MEANS), reference_f(MEANS), rtol=1e-13, atol=1e-9)
    # F x is a straight line: metres from the turn, so a filter reading F is seen
    assert np.min(np.abs(MEANS @ model.F.T - reference_f(MEANS))[:, :2].max(axis=1)) > 1.0
    eps = 1e-6
    fd = np.stack([(reference_f(MEANS + eps * e) - reference_f(MEANS - eps * e)) / (2 * eps)
                   for e in np.eye(N_STATE)], axis=-1)
    np.testing.assert_allclose(model.jacobian(MEANS), fd, rtol=1e-6, atol=1e-6)
    with pytest.raises(InputError, match="ct-test.*jacobian"):
        turn_model(TurnNoJacobian).jacobian(MEANS)


def _predicted(name: str, model: MotionModel, prior: Gaussian):
    spec = HOST.filters[name]
    rng = generator(7, "motion-override", name)
    state = spec.init(prior, rng)
    return spec, state, spec.predict(state, model, rng)


def _follows_or_refuses(name: str, model: MotionModel) -> bool:
    """True when filter ``name`` follows ``f`` over one predict, False when it refuses by name; fails otherwise."""
    prior = Gaussian(MEANS, np.broadcast_to(np.diag([1e-12] * 4 + [1e-14]), (3, N_STATE, N_STATE)).copy())
    spec = HOST.filters[name]
    rng = generator(7, "motion-override", name)
    try:
        state = spec.init(prior, rng)
    except InputError as exc:
        # init never sees the motion model: a filter whose own modes cannot serve this state refuses there, naming
        # itself and the state's dimension
        message = str(exc)
        assert repr(name) in message or f"{name}:" in message, f"{name} refused without naming itself: {message}"
        assert f"{N_STATE} state components" in message, f"{name} refused without naming the dimension: {message}"
        return False
    try:
        predicted = spec.predict(state, model, rng)
    except InputError as exc:
        message = str(exc)
        assert repr(name) in message or f"{name}:" in message, f"{name} refused without naming itself: {message}"
        assert repr(model.name) in message, f"{name} refused without naming the model: {message}"
        return False
    got = spec.estimate(predicted).mean
    # the prior's spread is 1e-6: a filter that follows f predicts f(mean) to ~1e-6; F x is metres off
    np.testing.assert_allclose(got, reference_f(MEANS), rtol=0, atol=1e-4, err_msg=f"{name} does not follow f")
    return True


@pytest.mark.parametrize("name", BUILTIN)
def test_every_builtin_filter_follows_f_or_refuses_by_name(name):
    with_jacobian = _follows_or_refuses(name, turn_model(Turn))
    without = _follows_or_refuses(name, turn_model(TurnNoJacobian))
    if name in FOLLOW_WITH_JACOBIAN:
        assert with_jacobian, f"{name} should follow a nonlinear model with a Jacobian"
    if name in FOLLOW_WITHOUT_JACOBIAN:
        assert without, f"{name} should follow a nonlinear model without a Jacobian"
    if without:
        assert with_jacobian


def test_the_exact_and_extended_kalman_filters_refuse_by_name():
    prior = Gaussian(MEANS, np.broadcast_to(np.eye(N_STATE), (3, N_STATE, N_STATE)).copy())
    with pytest.raises(InputError, match=r"filter 'kf' needs a linear motion model.*'ct-test'.*overrides f"):
        _predicted("kf", turn_model(Turn), prior)
    with pytest.raises(InputError, match=r"filter 'ekf' needs the Jacobian of motion model 'ct-test'.*jacobian\(x\)"):
        _predicted("ekf", turn_model(TurnNoJacobian), prior)
    for name in ("crpf-100",):
        with pytest.raises(InputError, match=rf"filter '{name}'.*'ct-test'"):
            _predicted(name, turn_model(Turn), prior)


@pytest.mark.parametrize("name", ["ekf", "cmkf-l", "ekf-nis"])
def test_extended_predict_is_f_and_the_linearised_covariance(name):
    model = turn_model(Turn, q_scale=0.3)
    rng = np.random.default_rng(3)
    A = rng.standard_normal((3, N_STATE, N_STATE))
    P = A @ np.swapaxes(A, 1, 2) + np.eye(N_STATE)
    spec, _, predicted = _predicted(name, model, Gaussian(MEANS, P))
    est = spec.estimate(predicted)
    eps = 1e-6
    J = np.stack([(reference_f(MEANS + eps * e) - reference_f(MEANS - eps * e)) / (2 * eps)
                  for e in np.eye(N_STATE)], axis=-1)  # central differences of the reference f
    np.testing.assert_allclose(est.mean, reference_f(MEANS), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(est.cov, J @ P @ np.swapaxes(J, 1, 2) + model.Q, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", [n for n in BUILTIN if n in FOLLOW_WITHOUT_JACOBIAN and n in
                                  {"sir", "sir-jm", "tbd-pf"}])
def test_particle_filters_move_every_particle_through_f(name):
    model = turn_model(TurnNoJacobian)  # Q = 0: no draws, so each particle must be exactly f of its prior
    prior = Gaussian(MEANS, np.broadcast_to(np.diag([25.0, 25.0, 4.0, 4.0, 1e-3]), (3, N_STATE, N_STATE)).copy())
    _, state, predicted = _predicted(name, model, prior)
    before, after = state.cloud.particles, predicted.cloud.particles
    np.testing.assert_allclose(after, reference_f(before), rtol=1e-12, atol=1e-9)
    assert np.abs(after - before @ model.F.T).max() > 1.0


class LinearByHand(MotionModel):
    """Constant velocity in 2-D, ``f`` written out component by component (the same map as ``x F^T``)."""

    def f(self, x):
        x = np.asarray(x, dtype=float)
        T = self.dt
        return np.stack([x[..., 0] + T * x[..., 2], x[..., 1] + T * x[..., 3], x[..., 2], x[..., 3]], axis=-1)

    def jacobian(self, x):
        x = np.asarray(x, dtype=float)
        return np.broadcast_to(self.F, x.shape + (4,))


class DeclaredLinear(LinearByHand):
    linear = True


def _as(cls, model):
    return cls(model.name, model.F, model.Q, model.Q_sqrt, model.dt, model.rebuild, model.state_names,
               model.state_units)


def _scans_and_prior(name: str):
    """A constant-velocity truth seen in range and bearing (positions with noise 5 m for the exact KF)."""
    rng = generator(11, "motion-override", "truth")
    B, T = 4, 12
    cv = constant_velocity(2, DT, 0.5)
    x = np.tile([[800.0, 300.0, -20.0, 15.0]], (B, 1)) + rng.standard_normal((B, 4)) * [10, 10, 1, 1]
    states = []
    for _ in range(T):
        states.append(x)
        x = x @ cv.F.T + rng.standard_normal((B, 4)) @ cv.Q_sqrt.T
    states = np.stack(states, axis=1)
    if "linear_only" in HOST.filters[name].capabilities:  # a filter for a linear measurement model (kf, ss-kf)
        sensor = linear_measurement(np.eye(2, 4), 25.0 * np.eye(2))
        z = states[..., :2] + rng.standard_normal((B, T, 2)) * 5.0
    else:
        sensor = range_bearing(5.0, 0.01)
        z = sensor.h(states) + rng.standard_normal((B, T, 2)) * [5.0, 0.01]
    scans = Scans(z[:, :, None, :], np.ones((B, T, 1), dtype=bool), np.arange(T) * DT)
    prior = Gaussian(states[:, 0] + rng.standard_normal((B, 4)) * [10, 10, 1, 1],
                     np.broadcast_to(np.diag([100.0, 100.0, 1.0, 1.0]), (B, 4, 4)).copy())
    return cv, sensor, scans, prior


#: the built-in filters a range-bearing run takes (tbd-pf needs a position-doppler-3d sensor)
RUNNABLE = [n for n in BUILTIN if n != "tbd-pf"]
#: filters whose predict calls f for a linear model too: an f written out by hand may round differently
CALLS_F = {"ukf", "cdkf", "sr-ukf", "sr-cdkf"}


@pytest.mark.parametrize("name", RUNNABLE)
def test_a_linear_override_declared_linear_runs_the_old_code_and_an_undeclared_one_agrees(name):
    cv, sensor, scans, prior = _scans_and_prior(name)
    spec = HOST.filters[name]
    ref = run_filter(spec, prior, cv, sensor, scans, generator(5, "run"))
    declared = run_filter(spec, prior, _as(DeclaredLinear, cv), sensor, scans, generator(5, "run"))
    assert _as(DeclaredLinear, cv).linear and not _as(LinearByHand, cv).linear
    if name in CALLS_F:
        np.testing.assert_allclose(declared.mean, ref.mean, rtol=1e-10, atol=1e-10)
    else:  # the same code path: bit for bit
        np.testing.assert_array_equal(declared.mean, ref.mean)
        np.testing.assert_array_equal(declared.cov, ref.cov)
    try:
        undeclared = run_filter(spec, prior, _as(LinearByHand, cv), sensor, scans, generator(5, "run"))
    except InputError as exc:  # a filter that needs F refuses the override by name
        assert name in NEEDS_F or name.startswith("crpf"), f"{name} refused a linear override: {exc}"
        assert repr(name) in str(exc) and repr(cv.name) in str(exc)
        return
    # the override is followed (f, its Jacobian, the same noise draws): the same map, so the same track
    np.testing.assert_allclose(undeclared.mean, ref.mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(undeclared.cov, ref.cov, rtol=1e-8, atol=1e-8)


def test_the_gate_of_a_nonlinear_model_is_centred_on_the_filters_prediction():
    model = turn_model(Turn, q_scale=0.1)
    B, T = 3, 3
    truth = [MEANS]
    for _ in range(T - 1):
        truth.append(reference_f(truth[-1]))
    truth = np.stack(truth, axis=1)
    H = np.zeros((2, N_STATE))
    H[0, 0] = H[1, 1] = 1.0
    sensor = linear_measurement(H, np.eye(2))
    scans = Scans(truth[:, :, None, :2].copy(), np.ones((B, T, 1), dtype=bool), np.arange(T) * DT)
    prior = Gaussian(MEANS, np.broadcast_to(np.diag([1.0, 1.0, 1.0, 1.0, 1e-4]), (B, N_STATE, N_STATE)).copy())
    spec = HOST.filters["ukf"]
    track = run(spec, scans, model, sensor, association=Gated(1e4, pseudo=lambda gated, predicted, rng: gated,
                                                              dims=2),
                prior=prior, rng=generator(1, "gate"))
    # the filter's own prediction from its estimate at scan 0
    state = spec.init(Gaussian(track.mean[:, 0], track.cov[:, 0]), None)
    expected = spec.estimate(spec.predict(state, model, None)).mean
    np.testing.assert_allclose(track.predicted_mean[:, 1], expected, rtol=1e-12, atol=1e-9)
    assert np.abs(track.predicted_mean[:, 1] - track.mean[:, 0] @ model.F.T)[:, :2].max() > 1.0


def test_truth_is_sampled_through_the_models_f():
    from workbench.trajectory import sample_motion

    truth = sample_motion(MEANS, turn_model(q_scale=0.0), steps=4, rng=generator(0, "truth"))
    expected = MEANS.copy()
    for k in range(1, 4):
        expected = reference_f(expected)
        np.testing.assert_allclose(truth.states[:, k], expected, rtol=1e-12, atol=1e-9)


def test_the_example_third_party_filter_refuses_a_nonlinear_model_by_name():
    pytest.importorskip("alpha_beta_filter")
    spec = load_host().filter("alpha-beta")
    prior = Gaussian.broadcast(MEANS[0], np.eye(N_STATE), batch=1)
    with pytest.raises(InputError, match=r"alpha-beta.*ct-test"):
        spec.predict(spec.init(prior), turn_model())
