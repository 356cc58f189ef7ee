"""The IMM filter (plugins/filters/imm.py): FilterPy's IMMEstimator, the plain Kalman filter, a hand computation of
the mixing, angles, wrong inputs, and the manoeuvring scenario."""

from __future__ import annotations

import functools
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from workbench.models import MotionModel, constant_velocity, coordinated_turn, linear_measurement, range_bearing
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking import run
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import Gaussian, InputError, Scan, Scans
from workbench_filters.imm import IMMState, imm_mode_probabilities, make_imm

HOST = load_host()
ROOT = Path(__file__).resolve().parents[3]


def _position_model(std=3.0):
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    return linear_measurement(H, np.diag([std**2, (1.5 * std) ** 2]), name="position", frame="cartesian-2d")


def _turning_scans(model, runs, steps, seed, start=(500.0, -200.0), velocity=(10.0, 15.0)):
    legs = [Leg("straight", steps / 3), Leg("turn", steps / 3, math.radians(4.0)), Leg("straight", steps / 3)]
    one = piecewise_trajectory(start, velocity, legs, 1.0)
    states = np.broadcast_to(one.states[0, :steps], (runs, steps, 4))
    rng = generator(seed, "test-imm")
    noise = rng.standard_normal((runs, steps, model.dim)) @ np.linalg.cholesky(model.R).T
    z = model.h(states) + noise
    z = np.where(model.angle_mask, (z + np.pi) % (2 * np.pi) - np.pi, z)
    return states, Scans(z[:, :, None, :], np.ones((runs, steps, 1), dtype=bool), one.times[:steps])


# -- FilterPy ---------------------------------------------------------------------------------------------


def test_equals_filterpy_imm_estimator_on_a_linear_two_mode_case():
    kalman = pytest.importorskip("filterpy.kalman")
    cv = constant_velocity(2, 1.0, 0.2)
    ct = coordinated_turn(1.0, math.radians(4.0), 0.8)
    M = np.array([[0.93, 0.07], [0.12, 0.88]])
    mu0 = np.array([0.7, 0.3])
    model = _position_model()
    B, T = 3, 8
    states, scans = _turning_scans(model, B, T, 1)
    rng = generator(2, "test-imm-prior")
    prior = Gaussian(states[:, 0] + rng.standard_normal((B, 4)) * [5.0, 5.0, 1.0, 1.0],
                     np.broadcast_to(np.diag([25.0, 30.0, 2.0, 3.0]), (B, 4, 4)).copy())
    spec = make_imm((cv, ct), M, "kf", mu0)
    state = spec.init(prior)
    peers = []
    for b in range(B):
        modes = []
        for motion in (cv, ct):
            f = kalman.KalmanFilter(dim_x=4, dim_z=2)
            f.x, f.P = prior.mean[b].copy(), prior.cov[b].copy()
            f.F, f.Q, f.H, f.R = motion.F, motion.Q, model.H, model.R
            modes.append(f)
        peers.append(kalman.IMMEstimator(modes, mu0.copy(), M))
    for k in range(T):
        state = spec.predict(state, cv)
        predicted = spec.estimate(state)
        for b, imm in enumerate(peers):
            imm.predict()
            for j in range(2):
                np.testing.assert_allclose(state.means[b, j], imm.filters[j].x, rtol=0, atol=1e-9)
                np.testing.assert_allclose(state.covs[b, j], imm.filters[j].P, rtol=0, atol=1e-9)
            # FilterPy keeps the predicted mode probabilities as cbar (its x_prior mixes with the last posterior's)
            np.testing.assert_allclose(state.probabilities[b], imm.cbar, rtol=0, atol=1e-12)
            expected = sum(imm.cbar[j] * imm.filters[j].x for j in range(2))
            np.testing.assert_allclose(predicted.mean[b], expected, rtol=0, atol=1e-9)
        state = spec.update(state, scans.scan(k).for_filter(), model)
        est = spec.estimate(state)
        for b, imm in enumerate(peers):
            imm.update(scans.z[b, k, 0])
            np.testing.assert_allclose(est.mean[b], imm.x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(est.cov[b], imm.P, rtol=0, atol=1e-9)
            np.testing.assert_allclose(imm_mode_probabilities(state)[b], imm.mu, rtol=0, atol=1e-12)
    # the target turned: the turn mode took over at some point
    assert imm_mode_probabilities(state).shape == (B, 2)


# -- one mode is the Kalman filter ------------------------------------------------------------------------


def test_one_mode_equals_the_plain_kalman_filter_exactly():
    cv = constant_velocity(2, 1.0, 0.5)
    model = _position_model()
    states, scans = _turning_scans(model, 5, 12, 3)
    valid = scans.valid.copy()
    valid[1, 3:6] = False  # missed scans too
    scans = Scans(scans.z, valid, scans.times)
    prior = Gaussian.broadcast(states[0, 0] + [3.0, -2.0, 0.5, 0.0], np.diag([16.0, 16.0, 4.0, 4.0]), 5)
    imm = make_imm((cv,), [[1.0]], "kf")
    ours = run(imm, scans, cv, model, prior=prior)
    plain = run(HOST.filter("kf"), scans, cv, model, prior=prior)
    np.testing.assert_array_equal(ours.mean, plain.mean)
    np.testing.assert_array_equal(ours.cov, plain.cov)


# -- the mixing by hand -------------------------------------------------------------------------------


def _scalar_model(name, q):
    return MotionModel(name, np.array([[1.0]]), np.array([[q]]), np.array([[math.sqrt(q)]]), 1.0)


def test_mixing_and_mode_probabilities_against_a_hand_computation():
    # two 1-D modes x_k = x_{k-1} + w (q = 0 and q = 0.25), measured directly (R = 1)
    a, b = _scalar_model("still", 0.0), _scalar_model("drift", 0.25)
    M = [[0.9, 0.1], [0.2, 0.8]]
    spec = make_imm((a, b), M, "kf")
    state = IMMState(np.array([[0.7, 0.3]]), np.array([[[1.0], [3.0]]]), np.array([[[[0.5]], [[2.0]]]]))
    predicted = spec.predict(state, a)
    # cbar = mu M: 0.7 * 0.9 + 0.3 * 0.2 = 0.69 and 0.7 * 0.1 + 0.3 * 0.8 = 0.31
    np.testing.assert_allclose(predicted.probabilities[0], [0.69, 0.31], rtol=1e-14)
    # w_{i|0} = (0.63, 0.06) / 0.69, w_{i|1} = (0.07, 0.24) / 0.31
    x0 = (0.63 * 1.0 + 0.06 * 3.0) / 0.69  # 1.17391...
    x1 = (0.07 * 1.0 + 0.24 * 3.0) / 0.31  # 2.54838...
    p0 = (0.63 * (0.5 + (1.0 - x0) ** 2) + 0.06 * (2.0 + (3.0 - x0) ** 2)) / 0.69
    p1 = (0.07 * (0.5 + (1.0 - x1) ** 2) + 0.24 * (2.0 + (3.0 - x1) ** 2)) / 0.31
    np.testing.assert_allclose(predicted.means[0, :, 0], [x0, x1], rtol=1e-14)
    np.testing.assert_allclose(predicted.covs[0, :, 0, 0], [p0, p1 + 0.25], rtol=1e-14)  # P- = P0 + q
    # the estimate mixes with the predicted probabilities
    est = spec.estimate(predicted)
    xm = 0.69 * x0 + 0.31 * x1
    np.testing.assert_allclose(est.mean[0, 0], xm, rtol=1e-14)
    np.testing.assert_allclose(est.cov[0, 0, 0], 0.69 * (p0 + (x0 - xm) ** 2) + 0.31 * (p1 + 0.25 + (x1 - xm) ** 2),
                               rtol=1e-13)
    # an update with z = 2: L_j = N(2; x_j, P_j + 1), mu_j = cbar_j L_j / sum
    model = linear_measurement([[1.0]], [[1.0]], name="direct")
    updated = spec.update(predicted, Scan(np.array([[[2.0]]]), np.array([[True]])), model)
    s0, s1 = p0 + 1.0, p1 + 0.25 + 1.0
    l0 = math.exp(-0.5 * (2.0 - x0) ** 2 / s0) / math.sqrt(2 * math.pi * s0)
    l1 = math.exp(-0.5 * (2.0 - x1) ** 2 / s1) / math.sqrt(2 * math.pi * s1)
    mu = np.array([0.69 * l0, 0.31 * l1]) / (0.69 * l0 + 0.31 * l1)
    np.testing.assert_allclose(imm_mode_probabilities(updated)[0], mu, rtol=1e-12)
    # mode 0's Kalman update: x = x0 + p0 / s0 (2 - x0)
    np.testing.assert_allclose(updated.means[0, 0, 0], x0 + p0 / s0 * (2.0 - x0), rtol=1e-12)
    # a missed scan leaves the probabilities as predicted
    missed = spec.update(predicted, Scan(np.array([[[2.0]]]), np.array([[False]])), model)
    np.testing.assert_array_equal(missed.probabilities, predicted.probabilities)
    expected = {"mode_probability_still": mu[0], "mode_probability_drift": mu[1]}
    assert spec.diagnostics(updated) == pytest.approx(expected)


def test_a_missed_scan_in_a_batch_leaves_only_that_item_as_predicted():
    cv, ct = constant_velocity(2, 1.0, 0.2), coordinated_turn(1.0, math.radians(4.0), 0.8)
    spec = make_imm((cv, ct), [[0.95, 0.05], [0.05, 0.95]], "kf", [0.5, 0.5])
    model = _position_model()
    states, scans = _turning_scans(model, 2, 3, 4)
    state = spec.predict(spec.init(Gaussian.broadcast(states[0, 0], np.diag([9.0, 9.0, 1.0, 1.0]), 2)), cv)
    scan = Scan(scans.z[:, 1], np.array([[True], [False]]))
    after = spec.update(state, scan, model)
    np.testing.assert_array_equal(after.probabilities[1], state.probabilities[1])
    np.testing.assert_array_equal(after.means[1], state.means[1])
    assert not np.array_equal(after.probabilities[0], state.probabilities[0])


# -- angles -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode_filter", ["ekf", "ukf"])
def test_bearings_across_pi_give_the_rotated_estimates(mode_filter):
    """A target crossing the negative x axis (bearings jump between +pi and -pi) and the same problem turned by pi
    about the sensor (bearings near 0): the estimates are the turned ones, and close to the truth."""
    model = range_bearing(2.0, 0.01)
    cv, ct = constant_velocity(2, 1.0, 0.1), coordinated_turn(1.0, math.radians(4.0), 0.5)
    spec = make_imm((cv, ct, coordinated_turn(1.0, -math.radians(4.0), 0.5)),
                    [[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]], mode_filter, [0.8, 0.1, 0.1])
    states, scans = _turning_scans(model, 4, 30, 5, start=(-800.0, -150.0), velocity=(0.0, 12.0))
    bearings = scans.z[..., 1]
    assert np.any(bearings > 3.0) and np.any(bearings < -3.0)  # the data do straddle +-pi
    turned = scans.z.copy()
    turned[..., 1] = (turned[..., 1] + 2 * np.pi) % (2 * np.pi) - np.pi  # + pi, wrapped
    turned_scans = Scans(turned, scans.valid, scans.times)
    P0 = np.diag([100.0, 100.0, 4.0, 4.0])
    prior = Gaussian.broadcast(states[0, 0] + [8.0, -6.0, 1.0, -1.0], P0, 4)
    turned_prior = Gaussian(-prior.mean, prior.cov)
    a = run(spec, scans, cv, model, prior=prior)
    b = run(spec, turned_scans, cv, model, prior=turned_prior)
    np.testing.assert_allclose(b.mean, -a.mean, rtol=0, atol=1e-6)
    np.testing.assert_allclose(b.cov, a.cov, rtol=1e-6, atol=1e-8)
    rmse = np.sqrt(np.mean(np.sum((a.mean[:, 5:, :2] - states[:, 5:, :2]) ** 2, axis=-1)))
    assert rmse < 10.0, rmse


# -- the registered filter -----------------------------------------------------------------------------


def test_registered_imm_honours_the_loop_model_and_its_interval():
    imm = HOST.filter("imm")
    assert {"gaussian", "manoeuvre_modes"} <= imm.capabilities
    model = _position_model()
    states, scans = _turning_scans(model, 3, 6, 6)
    prior = Gaussian.broadcast(states[0, 0], np.diag([9.0, 9.0, 1.0, 1.0]), 3)
    quiet, loud = constant_velocity(2, 1.0, 0.05), constant_velocity(2, 1.0, 3.0)
    a, b = run(imm, scans, quiet, model, prior=prior), run(imm, scans, loud, model, prior=prior)
    assert not np.allclose(a.cov, b.cov)  # the quiet mode is the loop's model
    # a 2 s step: the modes are rebuilt for it (the turn modes turn twice as far)
    state = imm.init(prior)
    one, two = imm.predict(state, quiet), imm.predict(state, quiet.for_interval(2.0))
    turn2 = coordinated_turn(2.0, imm.params["turn_rate"], imm.params["turn_sigma_a"])
    # mode 1 mixes from equal initial means, so its mean is the prior mean moved by F(2 s)
    np.testing.assert_allclose(two.means[:, 1], prior.mean @ turn2.F.T, rtol=1e-12)
    assert not np.allclose(one.means[:, 1], two.means[:, 1])
    configured = imm.configure(turn_rate="5 deg/s", mode_filter="ukf")
    assert configured.params["turn_rate"] == pytest.approx(math.radians(5.0))
    assert configured.name == "imm(mode_filter=ukf, turn_rate=0.08727)" or configured.name.startswith("imm(")


@pytest.mark.parametrize("build, message", [
    (lambda cv: make_imm((cv, constant_velocity(3, 1.0, 0.1)), np.eye(2)), "different state dimensions"),
    (lambda cv: make_imm((cv, cv), [[0.9, 0.2], [0.1, 0.9]]), "row 0 sums to 1.1"),
    (lambda cv: make_imm((cv, cv), [[1.2, -0.2], [0.1, 0.9]]), "probabilities in [0, 1]"),
    (lambda cv: make_imm((cv, cv), np.eye(3)), "must be 2 x 2"),
    (lambda cv: make_imm((cv, cv), np.eye(2), probabilities=[0.5, 0.6]), "sum to 1"),
    (lambda cv: make_imm((cv, cv), np.eye(2), probabilities=[1.0]), "2 numbers for 2 modes"),
    (lambda cv: make_imm((cv, cv), np.eye(2), mode_filter="kalmann"), "unknown mode filter 'kalmann' (Gaussian "
                                                                      "filters: "),
    (lambda cv: make_imm((cv, cv), np.eye(2), mode_filter="sir"), "'sir' is not a Gaussian filter"),
    (lambda cv: make_imm((cv, cv), np.eye(2), mode_filter=["kf"]), "1 mode filters for 2 modes"),
    (lambda cv: make_imm((cv, "cv"), np.eye(2)), "must be a MotionModel or 'loop'"),
    (lambda cv: make_imm((), np.eye(0)), "at least one mode"),
    (lambda cv: make_imm((cv,), [[1.0]], likelihood="exact"), "unknown likelihood 'exact'"),
])
def test_wrong_inputs_are_refused_by_name(build, message):
    with pytest.raises(InputError) as info:
        build(constant_velocity(2, 1.0, 0.1))
    assert message in str(info.value)
    if "kalmann" in message:  # the list names the Gaussian filters
        assert all(f" {name}," in str(info.value) for name in ("cdkf", "ekf", "kf")) and " ukf)" in str(info.value)


def test_wrong_models_at_run_time_are_refused_by_name():
    cv = constant_velocity(2, 1.0, 0.1)
    spec = make_imm((cv, coordinated_turn(1.0, 0.05, 0.5)), [[0.9, 0.1], [0.1, 0.9]], "kf")
    state = spec.init(Gaussian.broadcast(np.zeros(4), np.eye(4), 2))
    with pytest.raises(InputError, match="the loop's motion model 'cv3d' has state dimension 6"):
        spec.predict(state, constant_velocity(3, 1.0, 0.1))
    with pytest.raises(InputError, match="kf modes need a linear measurement model"):
        spec.update(spec.predict(state, cv), Scan(np.ones((2, 1, 2)), np.ones((2, 1), dtype=bool)),
                    range_bearing(1.0, 0.01))
    with pytest.raises(InputError, match=r"the prior has 6 state components, but its modes \(cv2d, ct\(0.05 rad/s\)\) have 4"):
        spec.init(Gaussian.broadcast(np.zeros(6), np.eye(6), 2))
    with pytest.raises(InputError, match="unknown parameter 'turn_rate'"):
        spec.configure(turn_rate=0.1)
    with pytest.raises(InputError, match="no build function"):  # make_imm's filters are built, not configured
        spec.configure(mode_filter="ukf")
    with pytest.raises(InputError, match="imm_mode_probabilities takes an IMM state"):
        imm_mode_probabilities(Gaussian.broadcast(np.zeros(4), np.eye(4), 1))


# -- the manoeuvring scenario ------------------------------------------------------------------------------


def _manoeuvring():
    spec = importlib.util.spec_from_file_location("manoeuvring", ROOT / "examples" / "scenarios" / "manoeuvring.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_manoeuvring_scenario_imm_beats_cv_in_the_turns_and_cv_nees_is_outside_its_band():
    m = _manoeuvring()
    scenario = m.load(HOST)
    res = m.evaluate(scenario, 100, 5, steps=110, host=HOST, only=("CV EKF", m.IMM))
    cv, imm = res["CV EKF"], res[m.IMM]
    lo, hi = cv["band"]
    assert imm["rmse_turns_m"] < 0.5 * cv["rmse_turns_m"], (imm, cv)
    assert not lo <= cv["mean_nees"] <= hi, cv
    assert imm["mean_nees"] < cv["mean_nees"] / 10.0, (imm, cv)


@pytest.mark.slow
def test_both_manoeuvring_scenario_files_load_agree_and_run(tmp_path):
    """The clean and the cluttered file differ only in the clutter and the tracker; both run through ``workbench run``
    and through the study's :func:`evaluate` (a few runs and scans), the cluttered one with the file's uniform
    range-bearing clutter in the scans."""
    from workbench.cli import main
    from workbench.types import CLUTTER

    m = _manoeuvring()
    clean, cluttered = m.load(HOST), m.load(HOST, clutter=True)
    assert not clean.clutter and clean.tracker == "direct"
    assert [c.plugin for c in cluttered.clutter] == ["uniform-clutter"] and cluttered.tracker == "nearest-neighbour"
    c = cluttered.clutter[0].params
    assert c["frame"] == "range-bearing" and c["range"] == (1000.0, 4500.0) and c["rate"] == 20.0
    for field in ("steps", "dt", "legs", "sensor", "filters"):
        assert getattr(clean, field) == getattr(cluttered, field), field
    for field in ("initial_state", "prior_mean", "prior_std"):
        np.testing.assert_array_equal(getattr(clean, field), getattr(cluttered, field))
    np.testing.assert_array_equal(clean.motion.F, cluttered.motion.F)
    np.testing.assert_array_equal(clean.motion.Q, cluttered.motion.Q)

    states, scans, prior, turning = m.simulate(cluttered, 3, 1, steps=12, host=HOST)
    clutter_rows = scans.valid & (scans.origin == CLUTTER)
    assert clutter_rows.sum() > 3 * 12 * 10  # 20 per scan on average
    z = scans.z[clutter_rows]
    assert z[:, 0].min() >= 1000.0 and z[:, 0].max() <= 4500.0 and z[:, 1].min() >= -1.3 and z[:, 1].max() <= 0.5
    for scenario in (clean, cluttered):
        res = m.evaluate(scenario, 4, 1, steps=50, host=HOST)
        assert set(res) == {"CV EKF", "CV UKF", "CT-only EKF (+4 deg/s)", m.IMM}  # the imm's turn_rate
        assert all(np.isfinite(f["rmse_m"]) for f in res.values()), res
        assert res[m.IMM]["rmse_m"] < 50.0, res[m.IMM]  # the IMM keeps the track; single models may lose it
        assert ("updated" in res[m.IMM]) == bool(scenario.clutter)

    for path in (m.SCENARIO_FILE, m.CLUTTER_FILE):
        text = path.read_text().replace("runs = 500", "runs = 2").replace("steps = 150", "steps = 10")
        small = tmp_path / path.name
        small.write_text(text)
        assert main(["run", str(small), "--out", str(small.with_suffix(""))]) == 0


def test_the_docs_usage_snippet_runs_and_finds_the_turn(capsys):
    text = (ROOT / "docs" / "imm.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]
    assert len(blocks) == 2  # the usage, then the innovations (which continues it)
    namespace: dict = {}
    exec(compile(blocks[0], "docs/imm.md", "exec"), namespace)  # noqa: S102 - the documented code itself
    probabilities = namespace["imm_mode_probabilities"](namespace["state"]).mean(axis=0)
    assert probabilities.argmax() == 1, probabilities  # the left turn (mode 1) leads after 30 s of it
    diagnostics = namespace["track"].diagnostics
    assert max(diagnostics, key=diagnostics.get).startswith("mode_probability_ct(0.05"), diagnostics
    np.testing.assert_allclose(sorted(diagnostics.values()), np.sort(probabilities), rtol=1e-9)
    assert "mode_probability" in capsys.readouterr().out
    exec(compile(blocks[1], "docs/imm.md", "exec"), namespace)  # noqa: S102 - the innovations example
    nis = np.array(namespace["nis"])  # (T, B) from the FilterPy-style loop
    T = namespace["scans"].steps
    assert nis.shape == (T, 20) and np.isfinite(nis).all()
    # the CV EKF is consistent on the straight leg and lags in the turn: its NIS there far above chi-square(2)'s 2
    assert 1.0 < nis[:20].mean() < 3.5 and nis[20:].mean() > 10.0, (nis[:20].mean(), nis[20:].mean())
    record = namespace["record"]
    assert record.nis.shape == (20, T) and record.present.all()
    # NIS against y and S recomputed with a plain solve
    y, S = record.y, record.S
    np.testing.assert_allclose(record.nis, np.einsum("bti,bti->bt", y, np.linalg.solve(S, y[..., None])[..., 0]),
                               rtol=1e-9)
    assert record.nis.mean() < nis.mean() / 3.0  # the IMM follows the turn


def test_ukf_modes_weigh_by_the_unscented_transform_with_the_mode_filters_own_weights():
    """The mode probabilities after an update with ukf modes (alpha 0.5, kappa 1, configured) against a plain
    unscented transform written out here, item by item, with scipy's normal density."""
    from scipy.stats import multivariate_normal

    alpha, beta, kappa = 0.5, 2.0, 1.0
    ukf = HOST.filter("ukf").configure(alpha=alpha, kappa=kappa)
    model = range_bearing(3.0, 0.02)
    cv, ct = constant_velocity(2, 1.0, 0.3), coordinated_turn(1.0, math.radians(6.0), 1.0)
    spec = make_imm((cv, ct), [[0.9, 0.1], [0.2, 0.8]], ukf, [0.6, 0.4])
    states, scans = _turning_scans(model, 3, 4, 8, start=(-300.0, 10.0), velocity=(5.0, -8.0))
    prior = Gaussian.broadcast(states[0, 0] + [4.0, -3.0, 0.5, 0.5], np.diag([30.0, 20.0, 3.0, 2.0]), 3)
    state = spec.update(spec.init(prior), scans.scan(0).for_filter(), model)
    predicted = spec.predict(state, cv)
    after = spec.update(predicted, scans.scan(1).for_filter(), model)
    n = 4
    lam = alpha**2 * (n + kappa) - n
    wm = [lam / (n + lam)] + [1 / (2 * (n + lam))] * (2 * n)
    wc = [wm[0] + 1 - alpha**2 + beta] + wm[1:]
    for b in range(3):
        z = scans.z[b, 1, 0]
        weights = []
        for j in range(2):
            x, P = predicted.means[b, j], predicted.covs[b, j]
            L = np.linalg.cholesky(P)
            points = [x] + [x + math.sqrt(n + lam) * L[:, i] for i in range(n)] + \
                     [x - math.sqrt(n + lam) * L[:, i] for i in range(n)]
            ys = [np.array([math.hypot(p[0], p[1]), math.atan2(p[1], p[0])]) for p in points]
            # bearings averaged as the first point's plus the weighted wrapped differences
            ref = ys[0][1]
            bearing = ref + sum(w * math.remainder(y[1] - ref, 2 * math.pi) for w, y in zip(wm, ys))
            y_hat = np.array([sum(w * y[0] for w, y in zip(wm, ys)), math.remainder(bearing, 2 * math.pi)])
            S = model.R.copy()
            for w, y in zip(wc, ys):
                d = np.array([y[0] - y_hat[0], math.remainder(y[1] - y_hat[1], 2 * math.pi)])
                S += w * np.outer(d, d)
            nu = np.array([z[0] - y_hat[0], math.remainder(z[1] - y_hat[1], 2 * math.pi)])
            weights.append(predicted.probabilities[b, j] * multivariate_normal(np.zeros(2), S).pdf(nu))
        np.testing.assert_allclose(after.probabilities[b], np.array(weights) / sum(weights), rtol=1e-9)


def test_turn_modes_build_the_turn_pairs_and_a_constant_rate_chain():
    """``turn_modes=2``: five modes (the loop's, +-turn_rate, +-turn_rate / 2), each turn the coordinated turn of
    its rate; the switching matrix over ``dt`` is the matrix exponential of the chain's generator (leaving each mode
    at one rate, to every other alike), whose leaving probability over 1 s is ``switch_probability``."""
    from scipy.linalg import expm

    rate, p = math.radians(4.0), 0.03
    imm = HOST.filter("imm").configure(turn_modes=2, turn_rate=rate, switch_probability=p, turn_sigma_a=0.3)
    assert "5 modes" in imm.summary
    prior = Gaussian.broadcast(np.array([100.0, 50.0, 10.0, -5.0]), np.diag([4.0, 4.0, 1.0, 1.0]), 1)
    cv = constant_velocity(2, 1.0, 0.1)
    for dt in (1.0, 2.5):
        state = imm.predict(imm.init(prior), cv.for_interval(dt))
        # mode j's mean after mixing equal means is the prior mean moved by that mode's own transition
        for j, w in enumerate((rate, -rate, rate / 2, -rate / 2), start=1):
            np.testing.assert_allclose(state.means[0, j], prior.mean[0] @ coordinated_turn(dt, w, 0.3).F.T,
                                       rtol=1e-12)
        # cbar = mu0 M(dt) with M(dt) = expm(G dt); the rate a to each other mode solves leave(1 s) = p
        a = -math.log(1.0 - 5.0 / 4.0 * p) / 5.0
        G = a * (np.ones((5, 5)) - 5.0 * np.eye(5))
        mu0 = np.array([0.9] + [0.025] * 4)
        np.testing.assert_allclose(state.probabilities[0], mu0 @ expm(G * dt), rtol=1e-12)
        if dt == 1.0:
            np.testing.assert_allclose(1.0 - expm(G)[0, 0], p, rtol=1e-12)


# -- gating on the modes' own predictions ---------------------------------------------------------------------


def _wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def test_mode_gated_candidate_equals_a_plain_loop_over_runs_candidates_and_modes():
    """The candidate chosen (inside some mode's gate, the largest sum_j cbar_j N(z; h(x_j), H_j P_j H_j^T + R)) and
    its log-likelihood, against scipy's normal density in plain loops; with one candidate per run placed inside a
    minor mode's gate but outside the mixture's, where the mixture-gated nearest neighbour finds nothing."""
    from scipy.stats import multivariate_normal

    from workbench.tracking.single import nearest_candidate, predicted_measurement
    from workbench_filters.imm import _combine, mode_gated_candidate

    model = range_bearing(5.0, 0.004)
    rng = generator(7, "test-imm-mode-gate")
    B, r, Mc, gate = 6, 3, 7, 13.8
    base = np.array([2000.0, -1500.0, -15.0, 20.0])
    means = base + rng.standard_normal((B, r, 4)) * [3.0, 3.0, 0.5, 0.5]
    means[:, 1, :2] += [120.0, 90.0]  # mode 1 predicts the target some 150 m away from the others
    A = rng.standard_normal((B, r, 4, 4)) * 0.3
    covs = A @ np.swapaxes(A, -1, -2) + np.diag([9.0, 9.0, 1.0, 1.0])
    mu = np.array([0.92, 0.03, 0.05]) * np.ones((B, 1))
    state = IMMState(mu, means, covs)
    z = model.h(means[:, :1, :]) + rng.standard_normal((B, Mc, 2)) * [40.0, 0.03]
    z[:, 0] = model.h(means[:, 1]) + rng.standard_normal((B, 2)) * [2.0, 0.001]  # inside mode 1's gate
    valid = rng.random((B, Mc)) < 0.8
    valid[:, 0] = True
    valid[0, 1:] = False  # run 0: only the detection near mode 1
    scan = Scan(z, valid, time=1.0)
    index, best = mode_gated_candidate(scan, state, model, gate)

    for b in range(B):
        scores = {}
        for i in range(Mc):
            if not valid[b, i]:
                continue
            inside, lik = False, 0.0
            for j in range(r):
                H = model.jacobian(means[b, j][None])[0]
                S = H @ covs[b, j] @ H.T + model.R
                nu = z[b, i] - model.h(means[b, j][None])[0]
                nu[1] = _wrap(nu[1])
                inside |= float(nu @ np.linalg.inv(S) @ nu) <= gate
                lik += mu[b, j] * multivariate_normal(np.zeros(2), S).pdf(nu)
            if inside:
                scores[i] = math.log(lik)
        want = max(scores, key=scores.get) if scores else -1
        assert index[b] == want, (b, index[b], scores)
        if scores:
            assert best[b] == pytest.approx(scores[want], rel=1e-9, abs=1e-9)
    # run 0: the mixture's gate misses the detection that mode 1 predicts; the mode gates keep it
    mix_z, mix_S = predicted_measurement(_combine(mu, means, covs), model)
    mix_index, _ = nearest_candidate(z, valid, mix_z, mix_S, model, gate)
    assert mix_index[0] == -1 and index[0] == 0


@functools.lru_cache(maxsize=1)
def _seed_23_lost_runs():
    """Runs 63 and 94 of seed 23 of the cluttered manoeuvring study (docs/imm.md): ``(scenario, states, scans,
    prior, model)``."""
    m = _manoeuvring()
    scenario = m.load(HOST, clutter=True)
    states, scans, prior, _ = m.simulate(scenario, 500, 23, host=HOST)
    pick = np.array([63, 94])
    model = HOST.sensor("range-bearing").configure(**scenario.sensor.params).measurement_model()
    return scenario, states[pick], scans.take(pick), prior.take(pick), model


def test_the_nearest_neighbour_gates_an_imm_on_its_modes_and_keeps_the_two_runs_the_mixture_gate_loses():
    """Seed 23 of the cluttered manoeuvring study (docs/imm.md): runs 63 and 94 end more than 200 m off with the
    nearest neighbour gated on the IMM's mixture (``filter_candidates=False``), and within 30 m with its default,
    which gates an IMM on its modes (the IMM declares ``FilterSpec.gate_candidates``), bit for bit what
    ModeGatedNearestNeighbour gives; ModeGatedNearestNeighbour refuses a filter without an IMM state by name."""
    from workbench.tracking import NearestNeighbour
    from workbench_filters.imm import ModeGatedNearestNeighbour

    scenario, states, scans, prior, model = _seed_23_lost_runs()
    imm = HOST.filter("imm")
    end, tracks = {}, {}
    for label, assoc in (("mixture", NearestNeighbour(scenario.gate, filter_candidates=False)),
                         ("default", NearestNeighbour(scenario.gate)), ("modes", ModeGatedNearestNeighbour(13.8))):
        tracks[label] = run(imm, scans, scenario.motion, model, association=assoc, prior=prior)
        end[label] = np.hypot(*(tracks[label].mean[:, -1, :2] - states[:, -1, :2]).T)
    assert scenario.gate == 13.8
    assert np.all(end["mixture"] > 200.0) and np.all(end["default"] < 30.0), end
    for key in ("mean", "cov", "predicted_mean"):
        np.testing.assert_array_equal(getattr(tracks["default"], key), getattr(tracks["modes"], key))
    for key, value in tracks["modes"].records.items():
        np.testing.assert_array_equal(tracks["default"].records[key], value)
    with pytest.raises(InputError, match="ModeGatedNearestNeighbour gates on an IMM's modes; filter 'ekf'"):
        run(HOST.filter("ekf"), scans, scenario.motion, model, association=ModeGatedNearestNeighbour(13.8),
            prior=prior)


def test_the_nearest_neighbour_on_an_imm_equals_a_plain_loop_choosing_on_its_modes():
    """The default nearest neighbour on the IMM (runs 63 and 94 of seed 23 in clutter, 150 scans of some 20
    detections) against the IMM driven scan by scan with each run's detection chosen in plain loops over
    candidates and modes: inside the gate of some mode (``d2_ij <= 13.8`` with that mode's own ``h``, Jacobian and
    wrapped residual), the largest ``sum_j cbar_j N(z_i; z^_j, S_j)``: the same choices at every scan, the same
    estimates."""
    from workbench.tracking import NearestNeighbour

    scenario, states, scans, prior, model = _seed_23_lost_runs()
    imm, gate = HOST.filter("imm"), scenario.gate
    track = run(imm, scans, scenario.motion, model, association=NearestNeighbour(gate), prior=prior)
    B, T = scans.batch, scans.steps
    state = imm.init(prior, None)
    chosen = np.full((B, T), -1)
    means = np.empty((B, T, 4))
    means[:, 0] = imm.estimate(state).mean
    times = scans.times
    for k in range(1, T):
        state = imm.predict(state, scenario.motion.at(float(times[k - 1]), float(times[k] - times[k - 1])), None)
        scan = scans.scan(k).for_filter()
        for b in range(B):
            modes = []  # per mode: z^_j = h(x_j), S_j^-1 and N's normaliser, H_j the Jacobian at x_j
            for j in range(state.means.shape[1]):
                x, P = state.means[b, j], state.covs[b, j]
                H = model.jacobian(x[None])[0]
                S = H @ P @ H.T + model.R
                modes.append((model.h(x[None])[0], np.linalg.inv(S), 1.0 / math.sqrt(np.linalg.det(2 * math.pi * S)),
                              state.probabilities[b, j]))
            best, best_lik = -1, -math.inf
            for i in np.flatnonzero(scan.valid[b]):
                inside, lik = False, 0.0
                for z_hat, S_inv, norm, cbar in modes:
                    nu = scan.z[b, i] - z_hat
                    nu[1] = _wrap(nu[1])
                    d2 = float(nu @ S_inv @ nu)
                    inside |= d2 <= gate
                    lik += cbar * norm * math.exp(-0.5 * d2)
                if inside and lik > best_lik:
                    best, best_lik = int(i), lik
            chosen[b, k] = best
        found = chosen[:, k] >= 0
        if found.any():
            rows = np.maximum(chosen[:, k], 0)
            density = None if scan.clutter_density is None else scan.clutter_density[np.arange(B), rows]
            step = Scan.single(scan.z[np.arange(B), rows], found, time=scan.time, clutter_density=density)
            state = imm.update(state, step, model, None)
        means[:, k] = imm.estimate(state).mean
    np.testing.assert_array_equal(track.records["chosen"][:, 1:], chosen[:, 1:])
    np.testing.assert_allclose(track.mean, means, rtol=1e-12, atol=1e-9)
