"""The JIPDA / JPDA trackers (``plugins/trackers/jipda.py``) and their association maths
(:mod:`workbench.tracking.jpda`): marginals against brute-force enumeration of every joint event, loopy belief
propagation's error stated and bounded, one track against the PDA and IPDA closed forms written out here, a crossing
scene in clutter against M-of-N under GOSPA, reproducibility, refusals, and Stone Soup's JPDA on one shared scan."""

import itertools
import math

import numpy as np
import pytest
from scipy.stats import chi2

from workbench.metrics.ospa import track_gospa
from workbench.models import constant_velocity
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking.jpda import clusters, exact_marginals, lbp_marginals, marginals
from workbench.types import InputError, Scans

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)
MODEL = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)
KF = HOST.filter("kf")


# -- the marginals -------------------------------------------------------------------------------------------


def _brute_force(miss, rows, cols, w):
    """Every joint event written out: each track takes its miss or one of its pairs, no detection twice; an event's
    weight is the product of its choices' weights.  Returns beta0 (K,), beta (P,)."""
    K = len(miss)
    options = [[None] + [p for p in range(len(rows)) if rows[p] == t] for t in range(K)]
    total, b0, b = 0.0, [0.0] * K, [0.0] * len(rows)
    for event in itertools.product(*options):
        taken = [cols[p] for p in event if p is not None]
        if len(taken) != len(set(taken)):
            continue
        weight = 1.0
        for t, p in enumerate(event):
            weight *= miss[t] if p is None else w[p]
        total += weight
        for t, p in enumerate(event):
            if p is None:
                b0[t] += weight
            else:
                b[p] += weight
    return np.array(b0) / total, np.array(b) / total


def _random_case(rng):
    """2-3 tracks, 0-4 detections, most pairs gated (overlapping gates), weights as JIPDA makes them."""
    K, D = int(rng.integers(2, 4)), int(rng.integers(0, 5))
    rows, cols = np.nonzero(rng.uniform(size=(K, D)) < 0.8)
    r = rng.uniform(0.05, 1.0, K)
    miss = 1.0 - 0.9 * 0.99 * r  # 1 - P_D P_G r
    w = r[rows] * 0.9 * rng.uniform(0.02, 3.0, rows.size)  # r P_D g / rho
    return miss, rows, cols, w


def test_marginals_equal_brute_force_enumeration_and_lbp_error_is_bounded():
    rng = generator(31, "jipda brute force")
    errors = []
    for case in range(150):
        miss, rows, cols, w = _random_case(rng)
        ref0, ref = _brute_force(miss.tolist(), rows.tolist(), cols.tolist(), w.tolist())
        b0, b = exact_marginals(miss, rows, cols, w)
        assert np.allclose(b0, ref0, rtol=0, atol=1e-12) and np.allclose(b, ref, rtol=0, atol=1e-12), case
        # the tracker's entry point (closed form for lone tracks, enumeration for the rest) gives the same
        m0, m, exact = marginals(miss, rows, cols + 7, w)  # detection labels need not start at 0
        assert exact.all()
        assert np.allclose(m0, ref0, rtol=0, atol=1e-12) and np.allclose(m, ref, rtol=0, atol=1e-12), case
        # each track's marginals sum to one
        assert np.allclose(m0 + np.bincount(rows, weights=m, minlength=miss.size), 1.0, rtol=0, atol=1e-12)
        # loopy belief propagation on the same case: approximate
        l0, lb, _ = lbp_marginals(miss, rows, cols, w)
        errors.append(max(np.max(np.abs(l0 - ref0)), np.max(np.abs(lb - ref), initial=0.0)))
        # forced through belief propagation by the declared limits
        f0, f, exact = marginals(miss, rows, cols, w, max_exact_tracks=1)
        assert np.allclose(f0[exact], ref0[exact], rtol=0, atol=1e-12)  # lone tracks: the closed form
        shared = np.bincount(clusters(miss.size, rows, cols))[clusters(miss.size, rows, cols)] > 1
        assert np.array_equal(~exact, shared)
    errors = np.array(errors)
    # the stated error of loopy BP against enumeration on these small dense clusters (2-3 tracks, 0-4 detections,
    # 80 % of pairs gated): at most 0.08 on any marginal (0.060 measured over these 150 cases; 0.104 over 300), 0.01
    # on average (0.0053 measured); exact on a tree (see below)
    assert errors.max() < 0.08 and errors.mean() < 0.01, (errors.max(), errors.mean())
    assert errors.max() > 1e-4  # the cases do hold loops on which BP is not exact


def test_lbp_is_exact_on_a_tree():
    # a chain: track 0 - det 0 - track 1 - det 1 - track 2 (no loop): BP's marginals are the exact ones
    miss = np.array([0.4, 0.7, 0.2])
    rows, cols, w = np.array([0, 1, 1, 2]), np.array([0, 0, 1, 1]), np.array([1.3, 0.6, 2.2, 0.9])
    ref0, ref = _brute_force(miss.tolist(), rows.tolist(), cols.tolist(), w.tolist())
    l0, lb, _ = lbp_marginals(miss, rows, cols, w)
    assert np.allclose(l0, ref0, rtol=0, atol=1e-12) and np.allclose(lb, ref, rtol=0, atol=1e-12)


def test_lbp_of_a_cluster_does_not_depend_on_the_clusters_given_with_it():
    # two loopy clusters (each 2 tracks x 2 shared detections), one slow to converge: together, each gets exactly
    # the messages it gets alone (each cluster stops on its own), so a run's tracks never depend on another run's
    a = (np.array([0.3, 0.5]), np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1]), np.array([2.0, 1.5, 1.7, 2.5]))
    b = (np.array([0.01, 0.02]), np.array([0, 0, 1, 1]), np.array([5, 6, 5, 6]), np.array([30.0, 29.0, 28.0, 31.0]))
    alone = [lbp_marginals(*c) for c in (a, b)]
    both = lbp_marginals(np.concatenate([a[0], b[0]]), np.concatenate([a[1], b[1] + 2]), np.concatenate([a[2], b[2]]),
                         np.concatenate([a[3], b[3]]))
    assert alone[0][2] != alone[1][2]  # they need different numbers of rounds
    assert np.array_equal(both[0], np.concatenate([alone[0][0], alone[1][0]]))
    assert np.array_equal(both[1], np.concatenate([alone[0][1], alone[1][1]]))


def test_marginals_refuse_bad_weights_by_name():
    with pytest.raises(InputError, match="given twice"):
        marginals(np.ones(2), np.array([0, 0]), np.array([1, 1]), np.ones(2))
    with pytest.raises(InputError, match="finite and >= 0"):
        marginals(np.ones(2), np.array([0]), np.array([1]), np.array([np.nan]))


# -- one track: the PDA and IPDA closed forms ------------------------------------------------------------------


def _one_track_scene(ping1, rho, first=(10.0, 20.0)):
    """Ping 0: one detection (it starts track 0); ping 1: the detections ``ping1``."""
    ping1 = np.asarray(ping1, dtype=float).reshape(-1, 2)
    M = max(1, ping1.shape[0])
    z = np.zeros((1, 2, M, 2))
    valid = np.zeros((1, 2, M), dtype=bool)
    z[0, 0, 0], valid[0, 0, 0] = first, True
    z[0, 1, :ping1.shape[0]], valid[0, 1, :ping1.shape[0]] = ping1, True
    return Scans(z, valid, np.array([0.0, 1.0]))


@pytest.mark.parametrize("clutter", ["declared", "scan", "gate"])
@pytest.mark.parametrize("tracker, r0", [("jipda", 0.2), ("jpda", 0.95)])  # jpda: a confirmed track (r- = 1)
@pytest.mark.parametrize("ping1", [[[13.0, 21.0], [9.0, 24.0], [15.5, 17.0]], [[12.0, 19.0]], [[80.0, 80.0]],
                                   [[13.0, 21.0], [60.0, 95.0]]])
def test_one_track_is_the_pda_and_its_existence_the_ipda_closed_form(ping1, tracker, r0, clutter):
    pd, pg, ps, sv = 0.85, 0.99, 0.97, 3.0
    scans = _one_track_scene(ping1, 0.01)
    density = "clutter_density=0.01" if clutter == "declared" else f"clutter_estimate={clutter}"
    spec = HOST.tracker(f"{tracker}(p_detection={pd}, gate_probability={pg}, survival={ps}, init_existence={r0}, "
                        f"velocity_sigma={sv}, {density}, delete_existence=0.0001)")
    log = spec.run(scans, KF, MOTION, MODEL, seed=1)
    row = np.flatnonzero((log.ping == 1) & (log.track_id == 0))
    assert row.size == 1
    assert log.status[row[0]] == (1 if r0 >= 0.9 else 0)
    # the PDA written out: Kalman prediction from the one-point prior, gate, association probabilities, update
    R, F, Q = MODEL.R, MOTION.F, MOTION.Q
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    x = np.array([10.0, 20.0, 0.0, 0.0])
    P = np.diag([R[0, 0], R[1, 1], sv**2, sv**2])
    P[:2, :2] = R
    x, P = F @ x, F @ P @ F.T + Q
    S = H @ P @ H.T + R
    G = P @ H.T @ np.linalg.inv(S)
    gate = chi2.ppf(pg, 2)
    nus = [np.asarray(z) - H @ x for z in ping1]
    nus = [nu for nu in nus if nu @ np.linalg.solve(S, nu) <= gate]
    # the clutter density: declared; or the detections not expected from the track (P_D r-) over the box bounding
    # them; or, with fewer than two detections or "gate", the gated detections over the gate's area pi gate sqrt|S|
    box = np.ptp(np.asarray(ping1, dtype=float), axis=0).prod()
    if clutter == "declared":
        rho = 0.01
    elif clutter == "scan" and len(ping1) > 1:
        rho = max(len(ping1) - pd * ps * r0, 1.0) / box
    else:
        rho = len(nus) / (math.pi * gate * math.sqrt(np.linalg.det(S))) if nus else 1.0
    lik = [math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / (2 * math.pi * math.sqrt(np.linalg.det(S))) for nu in nus]
    L = [pd * g / rho for g in lik]
    beta0 = (1 - pd * pg) / (1 - pd * pg + sum(L))
    betas = [v / (1 - pd * pg + sum(L)) for v in L]
    nu = sum((b * n for b, n in zip(betas, nus)), np.zeros(2))
    spread = sum((b * np.outer(n, n) for b, n in zip(betas, nus)), np.zeros((2, 2))) - np.outer(nu, nu)
    x_pda = x + G @ nu
    P_pda = beta0 * P + (1 - beta0) * (P - G @ S @ G.T) + G @ spread @ G.T
    assert np.allclose(log.mean[row[0]], x_pda, rtol=0, atol=1e-9)
    assert np.allclose(log.cov[row[0]], P_pda, rtol=0, atol=1e-9)
    # IPDA: r = (1 - delta) r- / (1 - delta r-),  delta = P_D P_G - P_D sum_j g_j / rho,  r- = p_S r0
    r_pred = ps * r0
    delta = pd * pg - pd * sum(lik) / rho
    assert log.existence[row[0]] == pytest.approx((1 - delta) * r_pred / (1 - delta * r_pred), rel=0, abs=1e-12)
    assert log.hit[row[0]] == bool(nus)


def test_initiation_honours_initiate_below_and_the_one_point_prior():
    scans = _one_track_scene([[13.0, 21.0], [9.0, 24.0], [15.5, 17.0], [80.0, 80.0]], 0.01)
    base = "p_detection=0.85, init_existence=0.2, velocity_sigma=3, clutter_density=0.01, delete_existence=0.0001"
    logs = {below: HOST.tracker(f"jipda({base}, initiate_below={below})").run(scans, KF, MOTION, MODEL, seed=1)
            for below in (1e-9, 1.0)}
    # (80, 80) is outside the gate (claimed with probability 0): a new track either way; the three gated detections
    # are claimed with probabilities in (0, 1): new tracks only when initiate_below = 1
    new = {b: sorted(log.mean[(log.ping == 1) & (log.track_id > 0), :2].round(6).tolist()) for b, log in logs.items()}
    assert new[1e-9] == [[80.0, 80.0]]
    assert new[1.0] == [[9.0, 24.0], [13.0, 21.0], [15.5, 17.0], [80.0, 80.0]]
    # the one-point prior: the detection's position with R, velocity 0 with velocity_sigma^2, existence init_existence
    log = logs[1e-9]
    row = np.flatnonzero((log.ping == 1) & (log.track_id == 1))[0]
    P = np.zeros((4, 4))
    P[:2, :2], P[2, 2], P[3, 3] = MODEL.R, 9.0, 9.0
    assert np.allclose(log.mean[row], [80.0, 80.0, 0.0, 0.0]) and np.allclose(log.cov[row], P)
    assert log.existence[row] == 0.2 and log.hit[row]


# -- whole runs ----------------------------------------------------------------------------------------------


def _crossing(runs, seed=3, steps=16, clutter=20, sigma=0.7, climb=1.5, pd=0.9):
    """Two targets at 4 per ping along x, one climbing and one descending by ``climb`` per ping, crossing half way,
    each detected with probability ``pd``; ``clutter`` uniform false detections per scan around them."""
    rng = generator(seed, "jipda crossing")
    k = np.arange(float(steps))[:, None]
    truth = np.stack([k * [4.0, climb], [0.0, climb * (steps - 1)] + k * [4.0, -climb]])  # (2, T, 2)
    z = truth.transpose(1, 0, 2)[None] + sigma * rng.standard_normal((runs, steps, 2, 2))
    lo, hi = np.array([-10.0, -10.0]), np.array([4.0 * steps + 10.0, climb * steps + 10.0])
    z = np.concatenate([z, lo + (hi - lo) * rng.uniform(size=(runs, steps, clutter, 2))], axis=2)
    valid = np.ones(z.shape[:3], bool)
    valid[:, :, :2] = rng.uniform(size=(runs, steps, 2)) < pd
    truth_b = np.broadcast_to(truth.transpose(1, 0, 2)[None], (runs, steps, 2, 2))
    return Scans(z, valid, np.arange(float(steps))), truth_b


def test_crossing_targets_in_clutter_gospa_below_bound_and_better_than_mofn():
    scans, truth = _crossing(6, steps=24)
    jipda = HOST.tracker("jipda(survival=0.99, velocity_sigma=5)").run(scans, KF, MOTION, MODEL, seed=2)
    mofn = HOST.tracker("mofn").run(scans, KF, MOTION, MODEL, seed=2)
    d_jipda = track_gospa(jipda, truth, c=10.0, p=2.0).distance
    g_jipda, g_mofn = float(np.mean(d_jipda)), float(np.mean(track_gospa(mofn, truth, c=10.0, p=2.0).distance))
    # measured: JIPDA 5.14 (3.52 from ping 6 on, once confirmed), M-of-N 7.17 (c = 10, p = 2; no track at all: 10)
    assert g_jipda < 6.0 and float(np.mean(d_jipda[:, 6:])) < 4.5, (g_jipda, float(np.mean(d_jipda[:, 6:])))
    assert g_jipda < g_mofn - 1.0, (g_jipda, g_mofn)
    # the log: covariances symmetric positive definite, existence in (0, 1]
    assert jipda.cov.shape == (jipda.mean.shape[0], 4, 4) and jipda.existence.shape == jipda.run.shape
    assert np.allclose(jipda.cov, np.swapaxes(jipda.cov, 1, 2)) and np.all(np.linalg.eigvalsh(jipda.cov) > 0)
    assert np.all((jipda.existence > 0) & (jipda.existence <= 1))


def test_same_seed_same_log_inputs_untouched_runs_independent():
    scans, _ = _crossing(3, seed=4, steps=8, clutter=10)
    before = {k: np.copy(getattr(scans, k)) for k in ("z", "valid", "times")}
    spec = HOST.tracker("jipda(survival=0.99, velocity_sigma=5)")
    a = spec.run(scans, KF, MOTION, MODEL, seed=5)
    b = spec.run(scans, KF, MOTION, MODEL, seed=5)
    for key, value in a.to_arrays().items():
        assert np.array_equal(value, b.to_arrays()[key]), key
    for key, value in before.items():
        assert np.array_equal(getattr(scans, key), value), key
    # a run's tracks do not depend on the other runs of the batch
    two = spec.run(Scans(scans.z[:2], scans.valid[:2], scans.times), KF, MOTION, MODEL, seed=5)
    sub = a.select(a.run < 2)
    assert np.array_equal(two.track_id, sub.track_id) and np.allclose(two.mean, sub.mean, rtol=0, atol=1e-9)
    # a Gaussian filter other than the Kalman filter runs the same tracker (the filter's own update)
    ukf = spec.run(scans, HOST.filter("ukf"), MOTION, MODEL, seed=5)
    assert ukf.mean.shape[1] == 4 and ukf.existence is not None


def test_refusals_name_the_problem():
    scans, _ = _crossing(1, steps=3, clutter=2)
    with pytest.raises(InputError, match="sir.*not a deterministic Gaussian filter"):
        HOST.tracker("jipda").run(scans, HOST.filter("sir(particles=100)"), MOTION, MODEL, seed=1)
    with pytest.raises(InputError, match="gate_probability must be in"):
        HOST.tracker("jipda").run(scans, KF, MOTION, MODEL, seed=1, gate_probability=1.0)
    z = scans.z.copy()
    z[0, 1, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN or inf"):  # refused where the scans are made
        HOST.tracker("jpda").run(Scans(z, scans.valid, scans.times), KF, MOTION, MODEL, seed=1)
    dens = Scans(scans.z, scans.valid, scans.times, clutter_density=np.full(scans.valid.shape, 0.01))
    with pytest.raises(InputError, match="give one of the two"):
        HOST.tracker("jipda(clutter_density=0.02)").run(dens, KF, MOTION, MODEL, seed=1)


# -- Stone Soup's JPDA on one shared scan ------------------------------------------------------------------------


def test_jpda_matches_stone_soup_jpda_on_one_shared_scan():
    pytest.importorskip("stonesoup")
    from datetime import datetime, timedelta

    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.functions import gm_reduce_single
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    pd, pg, rho, sv = 0.9, 0.99, 0.004, 3.0
    starts = np.array([[0.0, 0.0], [6.0, 0.0], [3.0, 5.0]])  # ping 0: three tracks, overlapping gates at ping 1
    shared = np.array([[1.0, 1.5], [4.0, 1.0], [3.5, 4.0], [7.0, -1.0], [-2.0, 3.0]])  # ping 1
    z = np.zeros((1, 2, 5, 2))
    valid = np.zeros((1, 2, 5), dtype=bool)
    z[0, 0, :3], valid[0, 0, :3] = starts, True
    z[0, 1], valid[0, 1] = shared, True
    scans = Scans(z, valid, np.array([0.0, 1.0]))
    # new tracks confirmed at once (init_existence >= confirm_existence): JPDA takes them to exist
    log = HOST.tracker(f"jpda(p_detection={pd}, gate_probability={pg}, clutter_density={rho}, velocity_sigma={sv}, "
                       f"init_existence=0.95, delete_existence=0.0001, initiate_below=0.0001)"
                       ).run(scans, KF, MOTION, MODEL, seed=1)
    # the predicted tracks at ping 1 (the same predict on both sides: Stone Soup gets them at the scan's time)
    R = MODEL.R
    order = [0, 2, 1, 3]  # ours [x, y, vx, vy] -> Stone Soup's [x, vx, y, vy]
    t1 = datetime(2024, 1, 1) + timedelta(seconds=1)
    tracks, predicted = [], []
    for p in starts:
        x = np.array([*p, 0.0, 0.0])
        P = np.diag([R[0, 0], R[1, 1], sv**2, sv**2])
        P[:2, :2] = R
        x, P = MOTION.F @ x, MOTION.F @ P @ MOTION.F.T + MOTION.Q
        predicted.append((x, P))
        tracks.append(Track([GaussianState(x[order][:, None], P[np.ix_(order, order)], timestamp=t1)]))
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.0), ConstantVelocity(0.0)])  # dt = 0
    measurement = LinearGaussian(4, [0, 2], R)
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    hyp = PDAHypothesiser(predictor, updater, clutter_spatial_density=rho, prob_detect=pd, prob_gate=pg)
    detections = [Detection(d[:, None], timestamp=t1, measurement_model=measurement) for d in shared]
    result = JPDA(hyp).associate(set(tracks), set(detections), t1)
    # our marginals from the same weights: miss 1 - P_D P_G, pair P_D N(nu; 0, S) / rho for the gated pairs
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    rows, cols, w = [], [], []
    for t, (x, P) in enumerate(predicted):
        S = H @ P @ H.T + R
        for j, d in enumerate(shared):
            nu = d - H @ x
            d2 = nu @ np.linalg.solve(S, nu)
            if d2 <= chi2.ppf(pg, 2):
                rows.append(t)
                cols.append(j)
                w.append(pd * math.exp(-0.5 * d2) / (2 * math.pi * math.sqrt(np.linalg.det(S))) / rho)
    rows, cols = np.array(rows), np.array(cols)
    assert np.bincount(clusters(3, rows, cols)).max() == 3  # one cluster of all three tracks
    b0, b, exact = marginals(np.full(3, 1 - pd * pg), rows, cols, np.array(w))
    assert exact.all()
    for t, track in enumerate(tracks):
        theirs = {(-1 if not h.measurement else detections.index(h.measurement)): float(h.probability)
                  for h in result[track]}
        ours = {-1: b0[t], **{int(c): b[p] for p, c in enumerate(cols) if rows[p] == t}}
        assert set(theirs) == set(ours), t
        for j in ours:
            assert ours[j] == pytest.approx(theirs[j], rel=1e-9, abs=1e-12), (t, j)
        # the updated state: Stone Soup's Gaussian mixture of its updates, reduced
        means, covs, weights = [], [], []
        for h in result[track]:
            post = updater.update(h) if h.measurement else h.prediction
            means.append(np.asarray(post.state_vector, dtype=float))
            covs.append(np.asarray(post.covar, dtype=float))
            weights.append(float(h.probability))
        m, c = gm_reduce_single(np.hstack(means), np.stack(covs, axis=2), np.array(weights))  # (n, C), (n, n, C)
        row = np.flatnonzero((log.ping == 1) & (log.track_id == t))[0]
        back = np.argsort(order)
        assert np.allclose(np.asarray(m, dtype=float).ravel()[back], log.mean[row], rtol=0, atol=1e-9), t
        assert np.allclose(np.asarray(c, dtype=float)[np.ix_(back, back)], log.cov[row], rtol=0, atol=1e-9), t
