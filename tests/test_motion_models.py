"""The built-in motion models (issue 23, item 2) and the time protocol (item 1): every model passes the
motion-model kit; each is held to an independent reference (closed forms, ``scipy.linalg.expm`` and a numerical
integral of the continuous-time noise, a plain loop); the time loop and ``sample_motion`` bind the absolute time
of every step."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

import workbench as wb
from workbench.models import (CoordinatedTurnRate, ExactLinearModel, MotionModel, constant_acceleration,
                              constant_velocity, coordinated_turn, coordinated_turn_rate, growth_model,
                              quadratic_measurement, singer)
from workbench.testing import run_checks

MODELS = {
    "ca1d": lambda: constant_acceleration(1, 1.0, 0.5),
    "ca2d": lambda: constant_acceleration(2, 0.5, (0.2, 2.0)),
    "ca3d-short": lambda: constant_acceleration(3, 0.01, (0.1, 1.0, 3.0)),
    "singer2d": lambda: singer(2, 1.0, 3.0, 10.0),
    "singer3d-slow": lambda: singer(3, 0.1, 2.0, 1e6),
    "singer2d-fast": lambda: singer(2, 5.0, 2.0, 0.5),
    "singer2d-inf": lambda: singer(2, 1.0, 1.0, math.inf),
    "ct-known": lambda: coordinated_turn(1.0, 0.1, 0.5),
    "ct-known-zero": lambda: coordinated_turn(2.0, 0.0, 0.5),
    "ct-known-cw": lambda: coordinated_turn(0.5, -0.3, (0.1, 1.0)),
    "ct-rate": lambda: coordinated_turn_rate(1.0, 0.5, 0.01),
    "ct-rate-fast": lambda: coordinated_turn_rate(0.1, 2.0, 0.1),
    "growth": lambda: growth_model(),
}


@pytest.mark.parametrize("label", sorted(MODELS))
def test_every_new_model_passes_the_motion_model_kit(label):
    model = MODELS[label]()
    outcomes = {o.check: o for o in run_checks(model)}
    failed = {k: o.message for k, o in outcomes.items() if o.status not in ("passed", "skipped")}
    assert not failed, failed
    # what applies follows what the model declares
    assert outcomes["check_jacobian"].status == "passed"
    if isinstance(model, ExactLinearModel):
        assert outcomes["check_noise_composes"].status == "passed"
    if not model.linear:
        assert outcomes["check_transition_composes"].status == "skipped"


# -- closed forms ------------------------------------------------------------------------------------------------


def _continuous(A: np.ndarray, L: np.ndarray, T: float, intervals: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """``e^{A T}`` and ``int_0^T e^{A s} L L^T e^{A^T s} ds`` by a composite Simpson sum over ``intervals``
    (even) intervals, ``e^{A s}`` at the nodes from ``scipy.linalg.expm`` of one interval, raised to powers."""
    step = expm(A * (T / intervals))  # e^{A s_k} = (e^{A h})^k
    G = [L]
    for _ in range(intervals):
        G.append(step @ G[-1])
    G = np.stack(G)  # (K, n, r)
    integrand = G @ np.swapaxes(G, 1, 2)
    w = np.ones(intervals + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return expm(A * T), np.einsum("k,kij->ij", w, integrand) * (T / intervals) / 3.0


def _axis(model: MotionModel, axis: int, dims: int) -> tuple[np.ndarray, np.ndarray]:
    idx = [axis, dims + axis, 2 * dims + axis]
    return model.F[np.ix_(idx, idx)], model.Q[np.ix_(idx, idx)]


@pytest.mark.parametrize("T", [0.01, 1.0, 4.0])
def test_constant_acceleration_is_white_jerk_integrated(T):
    sigma = (0.3, 2.0)
    model = constant_acceleration(2, T, sigma)
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    for axis, s in enumerate(sigma):
        F_ref, Q_ref = _continuous(A, np.array([[0.0], [0.0], [s]]), T)
        F, Q = _axis(model, axis, 2)
        np.testing.assert_allclose(F, F_ref, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(Q, Q_ref, rtol=1e-9, atol=0.0)
    # the axes are independent and the layout is [p..., v..., a...]
    assert model.state_names == ("x", "y", "vx", "vy", "ax", "ay")
    assert model.state_units == ("m", "m", "m/s", "m/s", "m/s^2", "m/s^2") and model.position_dims == 2
    assert model.Q[0, 1] == 0.0 and model.Q[2, 5] == 0.0


# (T, tau): alpha T from 1e-4 (series) across the switch at 1 (0.999, 1.001) to 10 (closed form)
SINGER_CASES = [(0.1, 1000.0), (1.0, 20.0), (0.999, 1.0), (1.001, 1.0), (2.0, 0.8), (5.0, 0.5)]


@pytest.mark.parametrize("T, tau", SINGER_CASES)
def test_singer_is_its_continuous_time_model_discretised(T, tau):
    sigma_m = 3.0
    model = singer(1, T, sigma_m, tau)
    alpha = 1.0 / tau
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -alpha]])
    q = 2.0 * alpha * sigma_m**2  # white noise density that gives the acceleration variance sigma_m^2
    F_ref, Q_ref = _continuous(A, np.array([[0.0], [0.0], [math.sqrt(q)]]), T)
    np.testing.assert_allclose(model.F, F_ref, rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(model.Q, Q_ref, rtol=1e-8, atol=0.0)
    # the stationary acceleration variance: a started at N(0, sigma_m^2) keeps it
    assert model.F[2, 2] ** 2 * sigma_m**2 + model.Q[2, 2] == pytest.approx(sigma_m**2, rel=1e-12)


def test_singer_tends_to_constant_acceleration_for_long_time_constants():
    """``tau -> inf``: ``F`` that of constant acceleration and ``Q / q`` its white-jerk ``Q`` (``q = 2 sigma^2 /
    tau``); ``tau = inf`` is the limit itself (no noise), with no 0/0 anywhere."""
    T, sigma = 2.0, 1.5
    ca = constant_acceleration(1, T, 1.0)
    for tau in (1e6, 1e9, 1e12):
        model = singer(1, T, sigma, tau)
        np.testing.assert_allclose(model.F, ca.F, rtol=T / tau * 2, atol=0.0)
        np.testing.assert_allclose(model.Q / (2.0 * sigma**2 / tau), ca.Q, rtol=10 * T / tau)
    limit = singer(1, T, sigma, math.inf)
    np.testing.assert_array_equal(limit.F, ca.F)
    assert np.all(limit.Q == 0.0) and np.all(np.isfinite(limit.Q_sqrt))


def test_known_rate_turn_closes_the_circle_and_keeps_the_speed():
    omega, sigma = 0.25, 0.5
    x0 = np.array([100.0, -20.0, 6.0, 8.0])
    full = coordinated_turn(2.0 * math.pi / omega, omega, sigma)
    np.testing.assert_allclose(full.f(x0), x0, rtol=0.0, atol=1e-12 * 100.0)
    # step by step: 40 steps of a 40th of the circle; the speed is kept and the centre of the turn is fixed
    step = coordinated_turn(2.0 * math.pi / omega / 40.0, omega, sigma)
    centre = x0[:2] + np.array([-x0[3], x0[2]]) / omega
    x = x0.copy()
    for _ in range(40):
        x = step.f(x)
        assert np.hypot(x[2], x[3]) == pytest.approx(10.0, rel=1e-13)
        assert np.hypot(*(x[:2] - centre)) == pytest.approx(10.0 / omega, rel=1e-12)
    np.testing.assert_allclose(x, x0, atol=1e-9)
    # clockwise: the velocity turns the other way (a quarter turn takes (6, 8) to (8, -6))
    quarter = coordinated_turn(math.pi / 2.0 / omega, -omega, sigma)
    np.testing.assert_allclose(quarter.f(x0)[2:], [8.0, -6.0], atol=1e-12)
    # omega = 0 is constant velocity, bit for bit (F and Q)
    cv, still = constant_velocity(2, 1.5, sigma), coordinated_turn(1.5, 0.0, sigma)
    np.testing.assert_array_equal(still.F, cv.F)
    np.testing.assert_array_equal(still.Q, cv.Q)


def test_rate_in_state_turn_matches_the_known_rate_and_constant_velocity():
    T = 1.3
    model = coordinated_turn_rate(T, 0.5, 0.02)
    rng = wb.generator(5, "ct-rate")
    states = rng.standard_normal((6, 4)) * [100.0, 100.0, 10.0, 10.0]
    for omega in (0.3, -0.05, 1e-3, 0.07):  # across the series switch |omega T| = 0.1
        x = np.concatenate([states, np.full((6, 1), omega)], axis=1)
        want = states @ coordinated_turn(T, omega, 0.5).F.T
        np.testing.assert_allclose(model.f(x)[:, :4], want, rtol=1e-12, atol=1e-10)
        np.testing.assert_array_equal(model.f(x)[:, 4], omega)
    x0 = np.concatenate([states, np.zeros((6, 1))], axis=1)
    np.testing.assert_allclose(model.f(x0)[:, :4], states @ constant_velocity(2, T, 0.5).F.T, rtol=1e-15, atol=1e-12)
    # the Jacobian is continuous across omega = 0: at +-1e-9 rad/s it equals (to that order) the limit at 0
    J0 = model.jacobian(x0)
    for eps in (1e-9, -1e-9):
        Je = model.jacobian(x0 + eps * np.eye(5)[4])
        np.testing.assert_allclose(Je, J0, rtol=0.0, atol=1e-6)
    # and d x' / d omega at 0 is -T^2 vy / 2 (the closed-form limit)
    np.testing.assert_allclose(J0[:, 0, 4], -T * T * states[:, 3] / 2.0, rtol=1e-14)
    np.testing.assert_allclose(J0[:, 1, 4], T * T * states[:, 2] / 2.0, rtol=1e-14)
    # Q: the DWNA block and a random-walk rate of density sigma_omega^2
    cv = constant_velocity(2, T, 0.5)
    np.testing.assert_allclose(model.Q[:4, :4], cv.Q, rtol=1e-15)
    assert model.Q[4, 4] == pytest.approx(0.02**2 * T, rel=1e-15) and not np.any(model.Q[4, :4])


def test_growth_model_and_quadratic_measurement_follow_their_equations():
    model = growth_model()
    assert model.Q[0, 0] == pytest.approx(10.0) and model.dt == 1.0 and model.state_units == ("1",)
    x = np.array([[-3.0], [0.0], [0.5], [12.0]])
    for t in (0.0, 4.0, 17.0):
        k = t + 1.0
        want = x / 2 + 25 * x / (1 + x**2) + 8 * math.cos(1.2 * k)
        np.testing.assert_allclose(model.at(t).f(x), want, rtol=1e-15)
        np.testing.assert_allclose(model.f(x, t, 1.0), want, rtol=1e-15)
    h = quadratic_measurement()
    np.testing.assert_allclose(h.h(x), x**2 / 20.0)
    np.testing.assert_allclose(h.jacobian(x)[:, 0, 0], x[:, 0] / 10.0)
    assert h.R.shape == (1, 1) and h.frame == ""
    with pytest.raises(wb.InputError, match="built for steps of 1.0 s"):
        model.for_interval(0.5)


@pytest.mark.parametrize("call, match", [
    (lambda: singer(2, 1.0, 1.0, 0.0), "singer needs tau > 0"),
    (lambda: singer(2, 1.0, -1.0, 5.0), "sigma_m"),
    (lambda: constant_acceleration(0, 1.0, 1.0), "dims >= 1"),
    (lambda: constant_acceleration(2, -1.0, 1.0), "dt > 0"),
    (lambda: coordinated_turn(1.0, float("nan"), 0.5), "finite turn rate omega"),
    (lambda: coordinated_turn_rate(1.0, 0.5, -0.1), "sigma_omega"),
    (lambda: quadratic_measurement(scale=0.0), "non-zero scale"),
])
def test_bad_parameters_are_refused_by_name(call, match):
    with pytest.raises(wb.InputError, match=match):
        call()


# -- the time protocol -------------------------------------------------------------------------------------------


def test_at_binds_time_and_interval_and_is_cheap_when_nothing_changes():
    cv = constant_velocity(2, 1.0, 0.5)
    assert cv.at(0.0) is cv and cv.at(0.0, 1.0) is cv
    bound = cv.at(12.5, 2.0)
    assert bound.t == 12.5 and bound.dt == 2.0
    np.testing.assert_array_equal(bound.F, constant_velocity(2, 2.0, 0.5).F)
    assert bound.for_interval(3.0).t == 12.5  # rebuilding keeps the bound start time
    x = np.arange(8.0).reshape(2, 4)
    np.testing.assert_array_equal(cv.f(x, 7.0, 2.0), bound.f(x))
    np.testing.assert_array_equal(cv.jacobian(x, dt=2.0), np.broadcast_to(bound.F, (2, 4, 4)))
    ct = coordinated_turn_rate(1.0, 0.5, 0.01)
    xs = np.array([[0.0, 0.0, 5.0, 1.0, 0.2]])
    np.testing.assert_allclose(ct.f(xs, dt=2.5), ct.at(3.0, 2.5).f(xs), rtol=1e-15)
    assert type(ct.at(3.0, 2.5)) is CoordinatedTurnRate
    with pytest.raises(wb.InputError, match="start time of a step must be finite"):
        cv.at(float("nan"))


class _Drift(MotionModel):
    """A time-varying test model: ``x' = x + cos(t) - cos(t + dt)`` (the integral of ``sin`` over the step),
    with random-walk noise of density ``q``; rebuilt for any interval."""

    def f(self, x, t=None, dt=None):
        t, dt = self._step(t, dt)
        return np.asarray(x, dtype=float) + (math.cos(t) - math.cos(t + dt))

    def jacobian(self, x, t=None, dt=None):
        return np.ones(np.shape(x) + (1,))


def _drift(dt: float, q: float = 0.04) -> _Drift:
    return _Drift("drift", np.eye(1), np.array([[q * dt]]), np.array([[math.sqrt(q * dt)]]), float(dt),
                  rebuild=lambda step: _drift(step, q), state_names=("x",), state_units=("m",))


@pytest.mark.parametrize("predict_first", [False, True])
def test_the_loop_binds_each_steps_start_time_and_interval(predict_first):
    """The EKF through ``wb.run`` on irregular time stamps against a Kalman filter written out here with the
    offset ``cos(t_{k-1}) - cos(t_k)`` and ``Q = q (t_k - t_{k-1})``: equal only if every predict saw
    ``t = times[k-1]`` and its interval (and, predicting first, ``t_0 - dt`` over ``dt``)."""
    times = np.array([0.3, 1.1, 1.6, 3.9, 4.0, 6.2])
    B, T, r, q = 3, times.size, 0.25, 0.04
    rng = wb.generator(11, "drift")
    z = rng.standard_normal((B, T, 1, 1)) * 2.0
    scans = wb.Scans(z, np.ones((B, T, 1), bool), times)
    motion = _drift(1.0, q)
    model = wb.linear_measurement([[1.0]], [[r]])
    prior = wb.Gaussian.broadcast([0.5], [[2.0]], batch=B)
    track = wb.run(wb.load_host().filter("ekf"), scans, motion, model, prior=prior, predict_first=predict_first)
    m, P = np.full(B, 0.5), np.full(B, 2.0)
    want = []
    for k in range(T):
        if k > 0 or predict_first:
            t0, t1 = (times[k - 1], times[k]) if k > 0 else (times[0] - 1.0, times[0])
            m, P = m + math.cos(t0) - math.cos(t1), P + q * (t1 - t0)
        gain = P / (P + r)
        m, P = m + gain * (z[:, k, 0, 0] - m), (1 - gain) * P
        want.append(m.copy())
    np.testing.assert_allclose(track.mean[:, :, 0], np.stack(want, axis=1), rtol=1e-12, atol=1e-12)
    # the same filter on a model that ignored the time would differ: the offsets are not small
    assert np.max(np.abs(np.diff(np.cos(times)))) > 0.5


def test_an_old_style_model_with_f_of_x_alone_keeps_working():
    """A subclass written before the time protocol (``def f(self, x)``) runs through the loop unchanged."""

    class OldCV(MotionModel):
        def f(self, x):
            x = np.asarray(x, dtype=float)
            return np.concatenate([x[..., :2] + self.dt * x[..., 2:], x[..., 2:]], axis=-1)

    def old_cv(dt):
        cv = constant_velocity(2, dt, 0.5)
        return OldCV("old-cv", cv.F, cv.Q, cv.Q_sqrt, cv.dt, rebuild=old_cv, state_names=cv.state_names,
                     state_units=cv.state_units)

    cv, old = constant_velocity(2, 1.0, 0.5), old_cv(1.0)
    times = np.array([0.0, 1.0, 2.5, 3.0])
    truth = wb.Truth(np.zeros((2, 4, 4)) + np.array([0.0, 0.0, 1.0, 2.0]), times)
    truth = wb.Truth(truth.states + times[None, :, None] * np.array([1.0, 2.0, 0.0, 0.0]), times)
    z = truth.states[:, :, None, :2] + 0.1
    scans = wb.Scans(z, np.ones((2, 4, 1), bool), times)
    model = wb.linear_measurement(np.eye(2, 4), np.eye(2))
    prior = wb.Gaussian.broadcast([0.0, 0.0, 1.0, 2.0], np.eye(4), batch=2)
    ukf = wb.load_host().filter("ukf")
    got = wb.run(ukf, scans, old, model, prior=prior).mean
    want = wb.run(ukf, scans, cv, model, prior=prior).mean
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def test_sample_motion_follows_the_growth_models_time_term():
    """Without noise, ``sample_motion`` is the growth recursion with ``8 cos(1.2 k)`` at ``k = t0 + 1, t0 + 2,
    ...``, written out here; a model that ignored the bound time would give ``cos(1.2)`` at every step."""
    model = growth_model(sigma_v=0.0)
    x0 = np.array([[0.1], [-2.0]])
    for t0 in (0.0, 7.0):
        truth = wb.sample_motion(x0, model, 12, wb.generator(0, "growth"), t0=t0)
        np.testing.assert_array_equal(truth.times, t0 + np.arange(12.0))
        x = x0[:, 0].copy()
        for k in range(1, 12):
            x = 0.5 * x + 25.0 * x / (1.0 + x * x) + 8.0 * math.cos(1.2 * (t0 + k))
            np.testing.assert_allclose(truth.states[:, k, 0], x, rtol=1e-12, atol=1e-12)
    # with noise, the draws follow Q (sigma_v^2 = 10) around the recursion
    noisy = wb.sample_motion(np.zeros((4000, 1)), growth_model(), 2, wb.generator(1, "growth"))
    resid = noisy.states[:, 1, 0] - model.f(np.zeros((1,)))[0]
    assert abs(resid.mean()) < 4.0 * math.sqrt(10.0 / 4000)
    assert abs(resid.var() / 10.0 - 1.0) < 4.0 * math.sqrt(2.0 / 4000)
