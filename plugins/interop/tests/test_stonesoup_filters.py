"""Stone Soup's filters through the adapter: the filter test kit, agreement with Stone Soup driven directly, the
model conversions, and a quiet plugin without Stone Soup."""

import pytest

pytest.importorskip("stonesoup", reason="Stone Soup is not installed: pip install -e '.[stonesoup]'")

from workbench.testing import parametrize_with_checks  # noqa: E402
from workbench_interop.stonesoup_filters import filters  # noqa: E402

SPECS = filters()


@parametrize_with_checks(SPECS)
def test_conformance(spec, check):
    check(spec)


# -- against Stone Soup driven directly -----------------------------------------------------------------

import numpy as np  # noqa: E402
from dataclasses import replace  # noqa: E402
from datetime import datetime, timedelta  # noqa: E402

from workbench.filtering import run_filter  # noqa: E402
from workbench.models import MotionModel, linear_measurement, range_bearing  # noqa: E402
from workbench.plugins import load_host  # noqa: E402
from workbench.rng import generator  # noqa: E402
from workbench.types import Gaussian, InputError, Scans  # noqa: E402
from workbench_interop.stonesoup_filters import make_gaussian, make_particle  # noqa: E402

# Stone Soup's ConstantVelocity orders a 2-D state [x, vx, y, vy]; the workbench [x, y, vx, vy]
PERM = np.array([0, 2, 1, 3])


def _stonesoup_cv(q):
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity

    return CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])


def _cv_matrices(q, dt):
    """Stone Soup's own ConstantVelocity F, Q for an interval, in the workbench's order."""
    ss = _stonesoup_cv(q)
    F = np.asarray(ss.matrix(time_interval=timedelta(seconds=dt)))[np.ix_(PERM, PERM)]
    Q = np.asarray(ss.covar(time_interval=timedelta(seconds=dt)))[np.ix_(PERM, PERM)]
    return F, Q


def _motion_from_stonesoup(q, dt):
    """A workbench motion model whose F, Q are Stone Soup's ConstantVelocity matrices for each interval."""
    F, Q = _cv_matrices(q, dt)
    return MotionModel("stonesoup-cv", F, Q, np.linalg.cholesky(Q), dt,
                       rebuild=lambda step: _motion_from_stonesoup(q, step))


def _bearing_range_problem(runs=3, steps=12, y0=-40.0):
    """A target crossing the -x axis (bearings around +-pi; with y0 > 0 it stays above it), irregular times, one
    missed detection."""
    rng = generator(5, "stonesoup-direct")
    # irregular intervals in whole milliseconds (Stone Soup's time stamps resolve microseconds)
    times = np.concatenate([[0.0], np.cumsum(np.round(rng.uniform(0.5, 2.0, size=steps - 1), 3))])
    x0 = np.array([-1500.0, y0, 3.0, 8.0])
    states = x0 + np.outer(times, [x0[2], x0[3], 0, 0])  # straight line
    r = np.hypot(states[:, 0], states[:, 1])
    b = np.arctan2(states[:, 1], states[:, 0])
    z = np.stack([r + rng.normal(scale=5.0, size=(runs, steps)),
                  np.angle(np.exp(1j * (b + rng.normal(scale=0.01, size=(runs, steps)))))], axis=-1)
    valid = np.ones((runs, steps, 1), dtype=bool)
    valid[:, 4] = False
    prior = Gaussian.broadcast(x0 + [20.0, -10.0, 0.5, -0.5], np.diag([400.0, 400.0, 4.0, 4.0]), runs)
    return Scans(z[:, :, None, :], valid, times), prior


def _stonesoup_direct(kind, scans, prior, q, sr, sb):
    """The same filter driven by Stone Soup itself: its CartesianToBearingRange measurement model (z = [phi,
    rho]), its predictor and updater, real time stamps.  The state keeps the workbench's
    order (the unscented transform's sigma points depend on it), so the transition of each interval is Stone Soup's
    ConstantVelocity matrices reordered."""
    import stonesoup.predictor.kalman as pk
    import stonesoup.updater.kalman as uk
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
    from stonesoup.types.angle import Bearing
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState

    class AnalyticBearingRange(CartesianToBearingRange):
        """Stone Soup's model with the Jacobian written out: its own is a forward difference whose rounding noise
        (steps of 1e-8 at negative coordinates) is 1e-5 relative here, which would make two runs that differ in the
        last bit of the state part at that level."""

        def jacobian(self, state, **kwargs):
            x, y = (float(v) for v in np.asarray(state.state_vector, dtype=float)[:2, 0])
            r2 = x * x + y * y
            # d(phi, rho)/d(x, y) = [[-y / r^2, x / r^2], [x / r, y / r]]
            return np.array([[-y / r2, x / r2, 0.0, 0.0], [x / np.sqrt(r2), y / np.sqrt(r2), 0.0, 0.0]])

    mm = AnalyticBearingRange(ndim_state=4, mapping=(0, 1), noise_covar=np.diag([sb ** 2, sr ** 2]))
    updater = getattr(uk, f"{kind}KalmanUpdater")(mm)
    t0 = datetime(2024, 1, 1)
    stamps = [t0 + timedelta(seconds=float(t)) for t in scans.times]
    out = np.empty(scans.z.shape[:2] + (4,))
    for b in range(scans.batch):
        state = GaussianState(prior.mean[b][:, None], prior.cov[b], timestamp=t0)
        for k in range(scans.steps):
            if k > 0:
                F, Q = _cv_matrices(q, (stamps[k] - stamps[k - 1]).total_seconds())
                model = LinearGaussianTimeInvariantTransitionModel(transition_matrix=F, covariance_matrix=Q)
                state = getattr(pk, f"{kind}KalmanPredictor")(model).predict(state, timestamp=stamps[k])
            if scans.valid[b, k, 0]:
                rho, phi = scans.z[b, k, 0]
                det = Detection(np.array([[Bearing(phi)], [rho]]), timestamp=stamps[k], measurement_model=mm)
                state = updater.update(SingleHypothesis(state, det))
            out[b, k] = np.asarray(state.state_vector, dtype=float)[:, 0]
    return out


@pytest.mark.parametrize("kind, name", [("Extended", "ss-ekf"), ("Unscented", "ss-ukf")])
def test_the_adapter_equals_stonesoup_driven_directly(kind, name):
    q, sr, sb = 0.5, 5.0, 0.01
    scans, prior = _bearing_range_problem()
    track = run_filter(make_gaussian(name), prior, _motion_from_stonesoup(q, 1.0), range_bearing(sr, sb), scans,
                       generator(0, "x"))
    direct = _stonesoup_direct(kind, scans, prior, q, sr, sb)
    assert np.any(scans.z[..., 0, 1] > 3.0) and np.any(scans.z[..., 0, 1] < -3.0)  # bearings across +-pi
    err = np.max(np.abs(track.mean - direct) / (1.0 + np.abs(direct)))
    assert err < 1e-9, f"{name} differs from Stone Soup's own {kind} filter by {err:.3g}"


def test_a_model_without_a_jacobian_gets_stonesoups_numerical_one():
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.types.state import GaussianState

    from workbench_interop.stonesoup_models import measurement_model

    state = GaussianState(np.array([[-1500.0], [-40.0], [3.0], [8.0]]), np.eye(4))
    ours = measurement_model(replace(range_bearing(5.0, 0.01), jacobian=None), 4).jacobian(state)
    theirs = CartesianToBearingRange(ndim_state=4, mapping=(0, 1), noise_covar=np.eye(2)).jacobian(state)
    assert np.array_equal(ours, np.asarray(theirs)[::-1])  # Stone Soup measures [phi, rho], the workbench [r, b]
    # Stone Soup's forward-difference step is max(1e8 spacing(x), 1e-8), which is 1e-8 for a negative x: its
    # rounding noise at x = -1500 m is 2e-13 / 1e-8: up to 4e-4 relative to the analytic Jacobian here
    analytic = measurement_model(range_bearing(5.0, 0.01), 4).jacobian(state)
    assert np.allclose(analytic, ours, rtol=1e-3, atol=1e-12)


def test_ss_ekf_with_the_analytic_jacobian_equals_the_builtin_ekf():
    scans, prior = _bearing_range_problem()
    motion, model = _motion_from_stonesoup(0.5, 1.0), range_bearing(5.0, 0.01)
    ours = run_filter(make_gaussian("ss-ekf"), prior, motion, model, scans, generator(0, "x"))
    builtin = run_filter(load_host().filter("ekf"), prior, motion, model, scans, generator(0, "x"))
    assert np.allclose(ours.mean, builtin.mean, rtol=1e-9, atol=1e-9)
    assert np.allclose(ours.cov, builtin.cov, rtol=1e-9, atol=1e-9)


def test_ss_kf_with_each_detections_own_covariance_equals_the_builtin_kf():
    host = load_host()
    rng = generator(6, "ss-kf-cov")
    B, T = 4, 10
    motion = _motion_from_stonesoup(0.3, 1.0)
    model = linear_measurement(np.eye(2, 4), np.diag([9.0, 9.0]), frame="cartesian-2d")
    truth = np.cumsum(rng.normal(size=(B, T, 2)), axis=1) * 3
    a = rng.normal(size=(B, T, 1, 2, 2))
    cov = a @ np.swapaxes(a, -1, -2) + np.eye(2)
    valid = rng.random((B, T, 1)) < 0.85
    scans = Scans(truth[:, :, None, :] + rng.normal(size=(B, T, 1, 2)) * 2, valid, np.arange(T) * 1.0, cov=cov)
    prior = Gaussian.broadcast([0.0, 0.0, 0.0, 0.0], np.diag([25.0, 25.0, 4.0, 4.0]), B)
    ours = run_filter(make_gaussian("ss-kf"), prior, motion, model, scans, generator(0, "a"))
    builtin = run_filter(host.filter("kf"), prior, motion, model, scans, generator(0, "a"))
    assert np.allclose(ours.mean, builtin.mean, rtol=1e-9, atol=1e-9)
    assert np.allclose(ours.cov, builtin.cov, rtol=1e-9, atol=1e-9)


def test_parameters_configure_and_refusals_are_clear():
    ukf = make_gaussian("ss-ukf")
    wide = ukf.configure(alpha=1.0, kappa=1.0)
    assert wide.name == "ss-ukf(alpha=1, kappa=1)" and wide.params["alpha"] == 1.0
    scans, prior = _bearing_range_problem(runs=1, steps=6)
    motion, model = _motion_from_stonesoup(0.5, 1.0), range_bearing(5.0, 0.01)
    a = run_filter(ukf, prior, motion, model, scans, generator(0, "a")).mean
    b = run_filter(wide, prior, motion, model, scans, generator(0, "a")).mean
    assert not np.allclose(a, b, rtol=1e-12, atol=0)  # the spread reaches Stone Soup's UKF
    with pytest.raises(InputError, match="linear measurement model"):
        run_filter(make_gaussian("ss-kf"), prior, motion, model, scans, generator(0, "a"))
    with pytest.raises(InputError, match="alpha"):
        ukf.configure(alpha=-1.0)
    pf = make_particle().configure(particles=200)
    assert pf.name == "ss-pf(particles=200)"
    state = pf.init(prior, generator(0, "p"))
    assert state.particles.shape == (1, 200, 4)
