"""The GM-PHD tracker plugin (``gm-phd``, plugins/trackers/gmphd.py): its one-step update against the closed form
written out here, pruning and merging on hand cases, the PHD's mass against the expected number of targets,
GOSPA and label stability on two crossing targets in clutter, reproducibility, untouched inputs, refusals, and one
update against Stone Soup's GM-PHD parts where Stone Soup is installed."""

import numpy as np
import pytest

from workbench.metrics.ospa import gospa, track_positions
from workbench.models import constant_velocity
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.types import Gaussian, InputError, Scan, Scans, _validated
from workbench_trackers.gmphd import Mixture, phd_update, prune_merge

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)
MODEL = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)  # z = [x, y] + N(0, I)
KF = HOST.filter("kf")


# -- the update against the closed form ----------------------------------------------------------------------


def _closed_form(weights, means, covs, zs, H, R, p_d, kappa):
    """Vo & Ma (2006) eqs. 26-30, written out component by component and detection by detection: the missed
    terms, then for each detection every component's Kalman update and weight."""
    out = [(w * (1 - p_d), m, P, j, False) for j, (w, m, P) in enumerate(zip(weights, means, covs))]
    for z in zs:
        terms = []
        for j, (w, m, P) in enumerate(zip(weights, means, covs)):
            S = H @ P @ H.T + R
            nu = z - H @ m
            q = np.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / np.sqrt(np.linalg.det(2 * np.pi * S))
            K = P @ H.T @ np.linalg.inv(S)
            terms.append([p_d * w * q, m + K @ nu, (np.eye(len(m)) - K @ H) @ P, j, True])
        total = sum(t[0] for t in terms)
        for t in terms:
            t[0] = t[0] / (kappa + total)
        out.extend(tuple(t) for t in terms)
    return out


def _by_weight(rows):
    return sorted(rows, key=lambda r: r[0])


def test_one_step_update_is_the_closed_form():
    # a 2-component prior and 3 detections in run 1; run 0 (other detections, one component) must not mix in
    weights = [0.7, 0.4]
    means = [np.array([0.0, 0.0, 1.0, 0.5]), np.array([3.0, 1.0, -0.5, 0.0])]
    covs = [np.diag([2.0, 1.5, 0.5, 0.5]), np.array([[1.0, 0.3, 0.1, 0.0], [0.3, 2.0, 0.0, 0.2],
                                                      [0.1, 0.0, 0.4, 0.0], [0.0, 0.2, 0.0, 0.3]])]
    zs = [np.array([0.4, -0.3]), np.array([2.5, 1.6]), np.array([1.5, 0.5])]
    p_d, kappa = 0.85, 0.02
    mix = Mixture(np.array([1, 1, 0]), np.array(weights + [0.9]), np.stack(means + [np.array([50.0, 50, 0, 0])]),
                  np.stack(covs + [np.eye(4)]), np.array([4, 7, 0]), np.zeros(3, bool))
    z = np.zeros((2, 3, 2))
    z[1] = zs
    z[0, 0] = [50.5, 49.0]
    valid = np.array([[True, False, False], [True, True, True]])
    state = KF.init(Gaussian(mix.mean, mix.cov), generator(0, "t"))
    got = phd_update(mix, state, Scan(z, valid), MODEL, KF, generator(0, "t"), p_detection=p_d,
                     clutter_density=kappa, gate=None)
    mine = got.take(np.flatnonzero(got.run == 1))
    want = _closed_form(weights, means, covs, zs, np.asarray(MODEL.H), np.asarray(MODEL.R), p_d, kappa)
    assert mine.size == len(want) == 2 + 2 * 3
    label_of = {0: 4, 1: 7}
    for g, w in zip(_by_weight(zip(mine.weight, mine.mean, mine.cov, mine.label, mine.hit)), _by_weight(want)):
        assert g[0] == pytest.approx(w[0], rel=1e-12)
        np.testing.assert_allclose(g[1], w[1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(g[2], w[2], rtol=0, atol=1e-12)
        assert g[3] == label_of[w[3]] and bool(g[4]) == w[4]
    # run 0 saw its own detection only: a missed term and one detection term, which explains it almost wholly
    other = got.take(np.flatnonzero(got.run == 0))
    assert other.size == 2 and set(other.label) == {0}
    assert sorted(other.weight)[0] == pytest.approx(0.9 * (1 - p_d), rel=1e-12)


def test_the_tracker_s_first_scan_is_the_closed_form_update_of_its_fixed_birth():
    # fixed birth at scan 0 = a prior of two components of weight birth_rate / 2; no pruning, merging nor threshold:
    # the log holds every updated component, its weight as existence
    means = [np.array([0.0, 0.0, 1.0, 0.0]), np.array([4.0, 2.0, 0.0, 1.0])]
    std = np.array([1.5, 1.0, 0.7, 0.7])
    zs = np.array([[[0.5, -0.2], [3.0, 2.5], [9.0, 9.0]]])
    scans = Scans(zs[:, None], np.ones((1, 1, 3), bool), np.array([0.0]))
    log = HOST.tracker("gm-phd").run(scans, KF, MOTION, MODEL, seed=0, birth="fixed",
                                     birth_mean=tuple(np.concatenate(means)), birth_std=tuple(std), birth_rate=1.2,
                                     p_detection=0.8, clutter_density=0.01, gate_probability=None, prune=0.0,
                                     merge=0.0, extract=0.0)
    want = _closed_form([0.6, 0.6], means, [np.diag(std ** 2)] * 2, zs[0], np.asarray(MODEL.H),
                        np.asarray(MODEL.R), 0.8, 0.01)
    assert log.existence.size == len(want) == 8
    for g, w in zip(_by_weight(zip(log.existence, log.mean, log.cov)), _by_weight(want)):
        assert g[0] == pytest.approx(w[0], rel=1e-12)
        np.testing.assert_allclose(g[1], w[1], atol=1e-12)
        np.testing.assert_allclose(g[2], w[2], atol=1e-12)
    assert len(set(log.track_id.tolist())) == log.track_id.size  # labels unique within the run


# -- pruning and merging ---------------------------------------------------------------------------------------


def _mix(run, weight, mean, cov, label=None):
    k = len(weight)
    return Mixture(np.asarray(run), np.asarray(weight, float), np.asarray(mean, float), np.asarray(cov, float),
                   np.arange(k) if label is None else np.asarray(label), np.arange(k) % 2 == 0)


def test_merge_is_the_moment_match_of_the_heaviest_and_its_neighbours():
    I2 = np.eye(2)
    # run 0: A (heaviest) and B within the threshold of A (measured with B's covariance), C within B's reach but
    # not A's (so not merged: the group is A's), D light enough to be pruned; run 1: E alone
    mean = [[0.0, 0.0], [1.0, 1.0], [2.0, 1.5], [0.1, 0.0], [0.0, 0.0]]
    cov = [I2, 0.5 * I2, I2, I2, I2]
    weight = [0.6, 0.3, 0.2, 1e-6, 0.5]
    mix = _mix([0, 0, 0, 0, 1], weight, mean, cov, label=[10, 11, 12, 13, 14])
    # B to A: d2 = 2 / 0.5 = 4 <= 4.5; C to A: 2^2 + 1.5^2 = 6.25 > 4.5, C to B: 1.25 (but B does not lead)
    out = prune_merge(mix, prune=1e-5, merge=4.5, max_components=10)
    assert out.size == 3
    ab = np.flatnonzero(out.label == 10)[0]
    W = 0.6 + 0.3
    m = (0.6 * np.array([0.0, 0.0]) + 0.3 * np.array([1.0, 1.0])) / W
    P = (0.6 * (I2 + np.outer(m - mean[0], m - mean[0]))
         + 0.3 * (0.5 * I2 + np.outer(m - mean[1], m - mean[1]))) / W
    assert out.weight[ab] == pytest.approx(W, rel=1e-14)
    np.testing.assert_allclose(out.mean[ab], m, atol=1e-14)
    np.testing.assert_allclose(out.cov[ab], P, atol=1e-14)
    assert out.hit[ab] == mix.hit[0]  # the heaviest's flag and label
    c = np.flatnonzero(out.label == 12)[0]
    assert out.weight[c] == pytest.approx(0.2, rel=1e-14) and out.run[c] == 0
    np.testing.assert_allclose(out.mean[c], mean[2], atol=1e-14)
    e = np.flatnonzero(out.label == 14)[0]
    # run 1's component never merges with run 0's at the origin
    assert out.run[e] == 1 and out.weight[e] == pytest.approx(0.5, rel=1e-14)
    # the weight sum is preserved, less the pruned component
    assert out.weight.sum() == pytest.approx(sum(weight) - 1e-6, rel=1e-14)
    # without pruning the light component at (0.1, 0) joins A's group (d2 = 0.01)
    kept = prune_merge(mix, prune=0.0, merge=4.5, max_components=10)
    assert kept.weight.sum() == pytest.approx(sum(weight), rel=1e-14)
    assert kept.weight[kept.label == 10][0] == pytest.approx(0.6 + 0.3 + 1e-6, rel=1e-14)


def test_the_merge_distance_is_measured_with_the_absorbed_component_s_covariance():
    # B is 3 away from A: with B's covariance 4 I, d2 = 9 / 4 = 2.25 <= 4 (merged); with A's I it would be 9
    mix = _mix([0, 0], [0.8, 0.3], [[0.0, 0.0], [3.0, 0.0]], [np.eye(2), 4 * np.eye(2)])
    assert prune_merge(mix, 0.0, 4.0, 10).size == 1
    # the other way round (A wide, B tight): not merged
    mix = _mix([0, 0], [0.8, 0.3], [[0.0, 0.0], [3.0, 0.0]], [4 * np.eye(2), np.eye(2)])
    assert prune_merge(mix, 0.0, 4.0, 10).size == 2


def test_at_most_max_components_are_kept_per_run_the_heaviest():
    rng = generator(3, "gm-phd cap")
    far = 100.0 * np.arange(12)[:, None] * np.array([1.0, 0.0])  # never within the threshold
    weight = rng.uniform(0.01, 1.0, 12)
    mix = _mix(np.repeat([0, 1], 6), weight, far, np.broadcast_to(np.eye(2), (12, 2, 2)))
    out = prune_merge(mix, 0.0, 4.0, 4)
    for r in (0, 1):
        mine = np.sort(out.weight[out.run == r])
        np.testing.assert_array_equal(mine, np.sort(weight[6 * r:6 * r + 6])[-4:])


# -- whole runs -----------------------------------------------------------------------------------------------


def _crossing(runs, seed=1, steps=16, clutter=5, sigma=0.5, p_d=0.95, climb=2.0):
    """Two targets at 4 per scan along x, one climbing and one descending by ``climb`` per scan, crossing half way;
    each detected with ``p_d``; ``clutter`` uniform false detections per scan over the region around them.
    Returns the scans, the truth positions (2, T, 2) and the clutter intensity per unit area."""
    rng = generator(seed, "gm-phd crossing")
    k = np.arange(float(steps))[:, None]
    truth = np.stack([k * [4.0, climb], [0.0, climb * (steps - 1)] + k * [4.0, -climb]])
    detected = rng.uniform(size=(runs, steps, 2)) < p_d
    z = truth.transpose(1, 0, 2)[None] + sigma * rng.standard_normal((runs, steps, 2, 2))
    lo, hi = np.array([-10.0, -10.0]), np.array([4.0 * steps + 10.0, climb * steps + 10.0])
    false = lo + (hi - lo) * rng.uniform(size=(runs, steps, clutter, 2))
    valid = np.concatenate([detected, np.ones((runs, steps, clutter), bool)], axis=2)
    return Scans(np.concatenate([z, false], axis=2), valid, np.arange(float(steps))), truth, clutter / np.prod(hi - lo)


def test_the_phd_mass_follows_the_number_of_targets():
    scans, truth, kappa = _crossing(8, seed=7)
    log = HOST.tracker("gm-phd").run(scans, KF, MOTION, MODEL, seed=1, clutter_density=kappa, birth_rate=0.05,
                                     extract=0.0)  # every component in the log: its weights are the PHD's mass
    mass = np.zeros((log.runs, log.pings))
    np.add.at(mass, (log.run, log.ping), log.existence)
    # two targets throughout; adaptive birth needs a scan or two to find them
    assert mass[:, 0].max() < 0.2
    settled = mass[:, 4:].mean(axis=0)
    assert np.all(np.abs(settled - 2.0) < 0.5), settled


def _stable_runs(log, truth, start=4, radius=3.0, apart=8.0):
    """Per run: every target is followed by one identity at all the scans (from ``start``) where the targets are at
    least ``apart`` from each other (the nearest estimate within ``radius``), before and after the crossing."""
    sep = np.linalg.norm(truth[0] - truth[1], axis=1)
    out = []
    for r in range(log.runs):
        followed = []
        for t in range(2):
            seen = set()
            for k in range(start, log.pings):
                mine = (log.run == r) & (log.ping == k)
                if sep[k] < apart or not mine.any():
                    continue
                d = np.linalg.norm(log.mean[mine, :2] - truth[t, k], axis=1)
                if d.min() < radius:
                    seen.add(int(log.track_id[mine][d.argmin()]))
            followed.append(seen)
        out.append(all(len(s) == 1 for s in followed) and followed[0] != followed[1])
    return np.array(out)


def test_two_crossing_targets_in_clutter_gospa_and_stable_labels():
    runs = 10
    scans, truth, kappa = _crossing(runs)
    log = HOST.tracker("gm-phd").run(scans, KF, MOTION, MODEL, seed=1, clutter_density=kappa, birth_rate=0.05)
    assert log.cov is not None and log.existence is not None and log.cov.shape == (log.mean.shape[0], 4, 4)
    pos, valid = track_positions(log)
    g = gospa(pos, np.broadcast_to(truth.transpose(1, 0, 2), (runs, *truth.transpose(1, 0, 2).shape)), c=10.0, p=2.0,
              x_valid=valid)
    # measured 1.9 (GOSPA, c = 10, p = 2, from scan 4 on); 10 before any estimate, about 7 with one target missed
    assert g.distance[:, 4:].mean() < 3.0
    # measured: all 10 runs keep one identity per target across the crossing
    assert _stable_runs(log, truth).mean() >= 0.7


def test_a_linearised_range_bearing_model_through_the_ekf_and_the_ukf_with_a_fixed_birth():
    # one target from (20, 10) at (1, 0.5) per scan, range-bearing detections (sigma 0.5 m, 1 deg) and two clutter
    # points per scan; a fixed birth where it starts: each filter keeps one estimate on it
    rng = generator(11, "gm-phd polar")
    steps, runs = 10, 3
    polar = HOST.sensor("active-sonar").measurement_model(frame="polar")
    k = np.arange(float(steps))
    truth = np.stack([20 + k, 10 + 0.5 * k], axis=1)  # (T, 2)
    rb = np.stack([np.hypot(truth[:, 0], truth[:, 1]), np.arctan2(truth[:, 1], truth[:, 0])], axis=1)
    z = rb[None, :, None] + rng.standard_normal((runs, steps, 1, 2)) * [0.5, np.radians(1.0)]
    clutter = np.stack([rng.uniform(5, 60, (runs, steps, 2)), rng.uniform(-1.0, 1.0, (runs, steps, 2))], axis=-1)
    scans = Scans(np.concatenate([z, clutter], axis=2), np.ones((runs, steps, 3), bool), k)
    for name in ("ekf", "ukf"):
        log = HOST.tracker("gm-phd").run(scans, HOST.filter(name), MOTION, polar, seed=0, birth="fixed",
                                         birth_mean=(20.0, 10.0, 0.0, 0.0), birth_std=(2.0, 2.0, 2.0, 2.0),
                                         birth_rate=0.5, clutter_density=2 / (55 * 2.0))
        late = log.ping >= 4
        near = late & (np.linalg.norm(log.mean[:, :2] - truth[log.ping], axis=1) < 2.0)
        # the target held at every late scan of every run, by one identity per run; at most one false estimate
        assert np.array_equal(np.bincount(log.run[near], minlength=runs), np.full(runs, steps - 4)), name
        assert len(set(zip(log.run[near].tolist(), log.track_id[near].tolist()))) == runs, name
        assert np.sum(late & ~near) <= 1, name


def test_the_same_seed_gives_the_same_log_and_inputs_are_never_mutated():
    scans, _, kappa = _crossing(3, seed=4, steps=8)
    before = {k: np.copy(getattr(scans, k)) for k in ("z", "valid", "times")}
    spec = HOST.tracker("gm-phd(birth_rate=0.05)")
    a = spec.run(scans, KF, MOTION, MODEL, seed=5, clutter_density=kappa)
    b = spec.run(scans, KF, MOTION, MODEL, seed=5, clutter_density=kappa)
    assert a.mean.size > 0
    for key, value in a.to_arrays().items():
        assert np.array_equal(value, b.to_arrays()[key]), key
    for key, value in before.items():
        assert np.array_equal(getattr(scans, key), value), key
    # a run's estimates do not depend on the other runs of the batch
    two = spec.run(Scans(scans.z[:2], scans.valid[:2], scans.times), KF, MOTION, MODEL, seed=5,
                   clutter_density=kappa)
    np.testing.assert_array_equal(two.mean, a.select(a.run < 2).mean)
    np.testing.assert_array_equal(two.track_id, a.select(a.run < 2).track_id)


def test_the_scans_own_clutter_density_is_honoured_and_a_second_statement_refused():
    scans, _, kappa = _crossing(2, seed=5, steps=6)
    spec = HOST.tracker("gm-phd(birth_rate=0.05)")
    carrying = Scans(scans.z, scans.valid, scans.times, clutter_density=np.full(scans.valid.shape, kappa))
    declared = spec.run(scans, KF, MOTION, MODEL, seed=0, clutter_density=kappa)
    own = spec.run(carrying, KF, MOTION, MODEL, seed=0)
    assert own.mean.size > 0
    for key, value in declared.to_arrays().items():
        np.testing.assert_array_equal(value, own.to_arrays()[key], err_msg=key)
    # another number gives another log: the field is read, not ignored
    other = spec.run(Scans(scans.z, scans.valid, scans.times, clutter_density=np.full(scans.valid.shape, 50 * kappa)),
                     KF, MOTION, MODEL, seed=0)
    assert other.existence.sum() < own.existence.sum()
    with pytest.raises(InputError, match=r"gm-phd: the scans declare their clutter density .* give one of the two"):
        spec.run(carrying, KF, MOTION, MODEL, seed=0, clutter_density=kappa)


def test_empty_scans_give_an_empty_log():
    for M in (0, 3):  # no rows at all, and rows that are all padding
        scans = Scans(np.zeros((2, 4, M, 2)), np.zeros((2, 4, M), bool), np.arange(4.0))
        for kw in ({}, {"clutter_density": 1e-3}, {"birth": "fixed", "birth_mean": (0.0, 0.0, 1.0, 1.0),
                                                   "birth_std": (1.0, 1.0, 1.0, 1.0), "birth_rate": 0.9}):
            log = HOST.tracker("gm-phd").run(scans, KF, MOTION, MODEL, seed=0, **kw)
            assert (log.runs, log.pings) == (2, 4) and log.mean.shape == (0, 4), (M, kw)
        # the fixed birth, missed at the first scan, keeps (1 - P_D) of its weight
        log = HOST.tracker("gm-phd").run(scans, KF, MOTION, MODEL, seed=0, extract=0.05, **kw)
        first = log.ping == 0
        assert first.sum() == 2 and np.allclose(log.existence[first], 0.9 * (1 - 0.9), rtol=1e-12, atol=0)


def test_refusals_name_the_problem():
    scans, _, _ = _crossing(1, steps=3)
    spec = HOST.tracker("gm-phd")
    z = scans.z.copy()
    z[0, 2, 1, 0] = np.nan
    with pytest.raises(InputError, match=r"Scans.z holds NaN"):
        Scans(z, scans.valid, scans.times)
    unchecked = _validated(Scans, z=z, valid=scans.valid, times=scans.times, snr=None, doppler=None, origin=None,
                           cov=None, clutter_density=None)
    with pytest.raises(InputError, match=r"gm-phd: detection 1 of run 0 at scan 2 is not finite"):
        spec.run(unchecked, KF, MOTION, MODEL, seed=0)
    with pytest.raises(InputError, match=r"gm-phd: filter 'sir' is not a Gaussian filter"):
        spec.run(scans, HOST.filter("sir"), MOTION, MODEL, seed=0)
    polar = HOST.sensor("active-sonar").measurement_model(frame="polar")
    assert polar.H is None
    rb = Scans(np.abs(scans.z) + 1.0, scans.valid, scans.times)
    with pytest.raises(InputError, match=r"gm-phd: adaptive birth needs a linear measurement model"):
        spec.run(rb, HOST.filter("ekf"), MOTION, polar, seed=0)
    with pytest.raises(InputError, match=r"birth='fixed' needs birth_mean"):
        spec.run(scans, KF, MOTION, MODEL, seed=0, birth="fixed")
    with pytest.raises(InputError, match=r"birth_mean must hold a multiple of n = 4"):
        spec.run(scans, KF, MOTION, MODEL, seed=0, birth="fixed", birth_mean=(1.0, 2.0, 3.0),
                 birth_std=(1.0, 1.0, 1.0, 1.0))
    with pytest.raises(InputError, match=r"p_detection"):
        HOST.tracker("gm-phd(p_detection=1.5)")


# -- Stone Soup ---------------------------------------------------------------------------------------------------


def test_one_update_equals_stone_soup_s_gm_phd_updater():
    pytest.importorskip("stonesoup")
    from datetime import datetime

    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater

    # the same predicted mixture in both: Stone Soup's order is [x, vx, y, vy]; ours [x, y, vx, vy]
    perm = [0, 2, 1, 3]
    weights = [0.9, 0.5, 0.2]
    means = np.array([[0.0, 0.0, 1.0, 0.5], [3.0, 1.0, -0.5, 0.0], [-2.0, 4.0, 0.0, 0.0]])
    covs = np.stack([np.diag([2.0, 1.5, 0.5, 0.5]), np.diag([1.0, 2.0, 0.4, 0.3]), np.diag([3.0, 3.0, 1.0, 1.0])])
    zs = np.array([[0.4, -0.3], [2.5, 1.6], [1.5, 0.5], [-1.0, 3.0]])
    p_d, kappa = 0.9, 0.015

    t = datetime(2026, 1, 1)
    ss_model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.asarray(MODEL.R))
    predictor = KalmanPredictor(CombinedLinearGaussianTransitionModel([ConstantVelocity(0.01)] * 2))
    updater = KalmanUpdater(ss_model)
    hypothesiser = GaussianMixtureHypothesiser(
        DistanceHypothesiser(predictor, updater, measure=Mahalanobis(), missed_distance=1e9),
        order_by_detection=True)
    phd = PHDUpdater(updater, clutter_spatial_density=kappa, prob_detection=p_d, prob_survival=1.0)
    components = [TaggedWeightedGaussianState(m[perm][:, None], P[np.ix_(perm, perm)], weight=w, tag=str(j),
                                              timestamp=t)  # at the detections' time: the predict is the identity
                  for j, (w, m, P) in enumerate(zip(weights, means, covs))]
    detections = {Detection(z[:, None], timestamp=t, measurement_model=ss_model) for z in zs}
    theirs = phd.update(hypothesiser.hypothesise(components, detections, t))
    ss = sorted((float(c.weight), np.asarray(c.state_vector, float).ravel()[perm],
                 np.asarray(c.covar, float)[np.ix_(perm, perm)]) for c in theirs.components)

    mix = Mixture(np.zeros(3, int), np.array(weights), means, covs, np.arange(3), np.zeros(3, bool))
    state = KF.init(Gaussian(means, covs), generator(0, "t"))
    got = phd_update(mix, state, Scan(zs[None], np.ones((1, 4), bool)), MODEL, KF, generator(0, "t"),
                     p_detection=p_d, clutter_density=kappa, gate=None)
    ours = sorted(zip(got.weight.tolist(), got.mean, got.cov), key=lambda r: r[0])
    ss = sorted(ss, key=lambda r: r[0])
    assert len(ours) == len(ss) == 3 + 3 * 4
    # the same algebra in another order of operations: agreement to rounding (measured ~1e-16)
    for a, b in zip(ours, ss):
        assert a[0] == pytest.approx(b[0], rel=1e-9, abs=1e-15)
        np.testing.assert_allclose(a[1], b[1], atol=1e-9)
        np.testing.assert_allclose(a[2], b[2], atol=1e-9)


def test_the_merge_candidates_lose_no_pair_that_every_pair_evaluated_merges(monkeypatch):
    """prune_merge evaluates the merging distance only on the candidate pairs of ``_merge_candidates`` (a bound
    rules out the others): on runs of many 4-D components in tight and loose clusters, with covariances from
    round to strongly correlated, the output equals, bit for bit, the one with every pair of every run evaluated."""
    import workbench_trackers.gmphd as gmphd

    rng = generator(11, "gm-phd candidates")
    runs, per = 4, 70
    centre = rng.uniform(0.0, 60.0, (runs * per // 5, 4)).repeat(5, axis=0)
    mean = centre + rng.standard_normal((runs * per, 4)) * rng.choice([0.3, 1.0, 3.0], (runs * per, 1))
    L = rng.standard_normal((runs * per, 4, 4)) * rng.choice([0.2, 1.0, 2.5], (runs * per, 1, 1))
    cov = L @ np.swapaxes(L, 1, 2) + 0.05 * np.eye(4)
    # every other component round (P = s^2 I): there the bound is tight, pairs near the threshold sit at its radius
    cov[::2] = rng.choice([0.5, 1.0, 4.0], (runs * per // 2, 1, 1)) * np.eye(4)
    mix = Mixture(np.repeat(np.arange(runs), per), rng.uniform(0.01, 1.0, runs * per), mean, cov,
                  np.arange(runs * per), np.zeros(runs * per, bool))
    seen = {}

    def every_pair(m, A, lam, have, merge):
        r, i, j = [], [], []
        for run in range(have.shape[0]):
            idx = np.flatnonzero(have[run])
            ii, jj = np.meshgrid(idx, idx, indexing="ij")
            r.append(np.full(ii.size, run))
            i.append(ii.ravel())
            j.append(jj.ravel())
        return np.concatenate(r), np.concatenate(i), np.concatenate(j)

    def counted(m, A, lam, have, merge):
        out = candidates(m, A, lam, have, merge)
        seen["pairs"] = seen.get("pairs", 0) + out[0].size
        return out

    candidates = gmphd._merge_candidates
    for merge in (0.5, 4.0, 16.0):
        monkeypatch.setattr(gmphd, "_merge_candidates", counted)
        fast = prune_merge(mix, 0.0, merge, 1000)
        monkeypatch.setattr(gmphd, "_merge_candidates", every_pair)
        slow = prune_merge(mix, 0.0, merge, 1000)
        assert mix.size > fast.size > runs  # some merged, not all
        for field in ("run", "weight", "mean", "cov", "label", "hit"):
            np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field))
    assert seen["pairs"] < 0.5 * 3 * runs * per * per  # the bound rules most pairs out
