"""The multi-target tracker (``workbench.tracking.multi``): its pieces against brute-force or closed-form
references, the M-of-N state machine against hand-worked cases, and whole runs against known truth."""

import dataclasses

import numpy as np
import pytest

from workbench.models import constant_velocity, linear_measurement, range_bearing
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking.multi import (CONFIRMED, TENTATIVE, TrackerConfig, TrackLog, box_pairs, detection_covariance,
                                      gated_pairs, greedy_assign, measurement_covariance, mofn_step,
                                      position_covariance, rectangular_pairs, run_tracker, speed_course_prior,
                                      two_point_prior)
from workbench.types import CLUTTER, Gaussian, InputError, Scans

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)


# -- M-of-N --------------------------------------------------------------------------------------------------


def _machine(hits, cfg=TrackerConfig(), slow=None):
    """Run the M-of-N machine over a hit sequence for one new track; returns statuses and the deletion ping."""
    h0 = cfg.initiation_hits
    h, m, a, s = np.array([(1 << h0) - 1]), np.array([0]), np.array([h0]), np.array([TENTATIVE], np.int8)
    states = []
    for i, hit in enumerate(hits):
        h, m, a, s, d = mofn_step(h, m, a, s, np.array([hit]), cfg, None if slow is None else np.array([slow[i]]))
        states.append(int(s[0]))
        if d[0]:
            return states, i
    return states, None


def test_mofn_initiation_detections_do_not_count():
    T, C = TENTATIVE, CONFIRMED
    # 3 hits after initiation confirm (5 detections in all); 2 do not
    assert _machine([1, 1, 1]) == ([T, T, C], None)
    assert _machine([1, 0, 1, 1]) == ([T, T, T, C], None)
    assert _machine([1, 0, 1, 0, 1]) == ([T, T, T, T, C], None)  # 3 of the first 5, exactly
    # tentative: deleted as soon as 3 hits in the first 5 pings are out of reach (hits + pings left < 3)
    assert _machine([1, 0, 0, 1, 0])[1] == 4  # 2 hits when the 5 pings are up
    assert _machine([0, 1, 0, 0]) == ([TENTATIVE] * 4, 3)  # 1 hit + 1 ping left, after only 2 misses
    assert _machine([0, 0, 1]) == ([TENTATIVE] * 3, None)  # 1 hit + 2 pings left: still possible
    assert _machine([0, 0, 0])[1] == 2
    # confirmed: 2 misses then a hit survive; 3 consecutive misses delete
    assert _machine([1, 1, 1, 0, 0, 1, 0, 0, 0]) == ([T, T, C, C, C, C, C, C, C], 8)


def test_mofn_counting_both_initiation_detections():
    cfg = TrackerConfig(initiation_hits=2)
    assert _machine([1], cfg) == ([CONFIRMED], None)  # hits at birth, birth-1 and now: 3 of 5
    assert _machine([0, 1], cfg) == ([TENTATIVE, CONFIRMED], None)
    assert _machine([0, 0, 1], cfg) == ([TENTATIVE, TENTATIVE, CONFIRMED], None)
    assert _machine([0, 0, 0], cfg) == ([TENTATIVE] * 3, 2)
    four = TrackerConfig(confirm_hits=4, confirm_window=5, delete_misses=5, initiation_hits=2)
    assert _machine([0, 1, 0], four)[1] == 2  # 3 hits with 1 ping left of 5 < 4


def test_mofn_min_speed():
    # hits enough, but slow: never confirmed, deleted after N pings; a confirmed track that slows is deleted
    assert _machine([1, 1, 1, 1, 1], slow=[True] * 5) == ([TENTATIVE] * 5, 4)
    assert _machine([1, 1, 1, 1], slow=[False, False, False, True]) == ([TENTATIVE, TENTATIVE, CONFIRMED, CONFIRMED], 3)


def test_config_checks():
    for bad, match in (({"gate_sigma": 0.0}, "gate_sigma"), ({"detection_sigma": -1.0}, "detection_sigma"),
                       ({"initiation_hits": 3}, "initiation_hits"), ({"prior": "flat"}, "prior"),
                       ({"min_speed": -1.0}, "min_speed"), ({"confirm_hits": 6}, "confirm_hits")):
        with pytest.raises(InputError, match=match):
            TrackerConfig(**bad)


# -- assignment and pairs ----------------------------------------------------------------------------------


def test_greedy_assign_equals_sequential_greedy():
    rng = generator(4, "greedy")
    for trial in range(40):
        n = rng.integers(1, 60)
        rows, cols = rng.integers(0, 9, n), rng.integers(0, 9, n)
        pairs = np.unique(np.stack([rows, cols], 1), axis=0)
        cost = rng.random(len(pairs))
        if trial % 2:
            cost = cost.round(1)  # ties on purpose: broken by row, then column
        got = set(zip(*greedy_assign(pairs[:, 0], pairs[:, 1], cost)))
        ref, used_r, used_c = set(), set(), set()
        for i in sorted(range(len(pairs)), key=lambda i: (cost[i], pairs[i, 0], pairs[i, 1])):
            r, c = pairs[i]
            if r not in used_r and c not in used_c:
                ref.add((r, c))
                used_r.add(r)
                used_c.add(c)
        assert {(int(a), int(b)) for a, b in got} == {(int(a), int(b)) for a, b in ref}


def test_box_pairs_equal_brute_force():
    rng = generator(7, "box")
    for trial in range(20):
        na, nb = rng.integers(0, 300), rng.integers(0, 300)
        a, b = rng.uniform(-50, 400, (na, 2)), rng.uniform(-50, 400, (nb, 2))
        if trial % 4 == 3:  # integer coordinates: pairs exactly on the box edges
            a, b, half = a.round(), b.round(), float(rng.integers(1, 20))
        else:
            half = rng.uniform(0.5, 40.0, (na, 2)) if trial % 2 else float(rng.uniform(1, 20))
        i, j = box_pairs(a, b, half, cell=None if trial % 3 else float(rng.uniform(0.3, 60)))
        h = np.broadcast_to(np.asarray(half, float), (na, 2)) if np.ndim(half) == 0 else half
        ref = np.nonzero(np.all(np.abs(a[:, None] - b[None]) <= h[:, None], axis=-1))
        assert sorted(zip(i.tolist(), j.tolist())) == sorted(zip(ref[0].tolist(), ref[1].tolist()))


def test_gate_dense_and_grid_paths_agree():
    rng = generator(5, "gate")
    K = 40
    mean = np.column_stack([rng.uniform(-230, 230, (K, 2)), rng.normal(0, 3, (K, 2))])
    mean[:5, :2] = np.column_stack([-rng.uniform(50, 200, 5), rng.normal(0, 2, 5)])  # bearings near +-pi
    cov = np.repeat(np.diag([9.0, 9.0, 4.0, 4.0])[None], K, 0)
    est = Gaussian(mean, cov)
    pos = rng.uniform(-250, 250, (600, 2))
    pos[:20] = mean[:5, :2].repeat(4, 0) + rng.normal(0, 3, (20, 2))
    for model in (range_bearing(0.5, np.deg2rad(1.0)), linear_measurement(np.eye(2, 4), 4 * np.eye(2))):
        zm = model.h(np.column_stack([pos, np.zeros((600, 2))]))
        for cfg in (TrackerConfig(), TrackerConfig(gate=25.0, gate_sigma=2.0), TrackerConfig(detection_sigma=2.0)):
            dense = gated_pairs(est, pos, zm, model, cfg)
            grid = gated_pairs(est, pos, zm, model, dataclasses.replace(cfg, dense_limit=0))
            assert sorted(zip(dense[0], dense[1])) == sorted(zip(grid[0], grid[1])) and len(dense[0]) > 0
            a = dict(zip(zip(dense[0], dense[1]), dense[2]))
            assert all(np.isclose(a[(r, c)], d, rtol=1e-12) for r, c, d in zip(*grid))
    i, j, d = rectangular_pairs(pos[:50], pos[50:], 8.0)
    i2, j2, _ = rectangular_pairs(pos[:50], pos[50:], 8.0, dense_limit=0)
    assert sorted(zip(i, j)) == sorted(zip(i2, j2))
    assert np.all(np.max(np.abs(pos[:50][i] - pos[50:][j]), axis=1) <= 8.0)


def test_gate_sigma_uses_the_stated_position_accuracy():
    # linear position model: gating with gate_sigma = s (or detection_sigma = s) is gating with R = s^2 I
    est = Gaussian(np.array([[0.0, 0.0, 1.0, 0.0]]), np.diag([1.0, 1.0, 1.0, 1.0])[None])
    pos = np.array([[3.0, 0.0], [0.0, 4.5], [6.0, 0.0]])
    small = linear_measurement(np.eye(2, 4), 0.25 * np.eye(2))
    big = linear_measurement(np.eye(2, 4), 4.0 * np.eye(2))
    _, _, d_small = gated_pairs(est, pos, pos, small, TrackerConfig(gate=1e9, gate_sigma=2.0))
    _, _, d_det = gated_pairs(est, pos, pos, small, TrackerConfig(gate=1e9, detection_sigma=2.0))
    _, _, d_big = gated_pairs(est, pos, pos, big, TrackerConfig(gate=1e9))
    assert np.allclose(d_small, d_big) and np.allclose(d_det, d_big)
    # P = I, R_g = 4 I: S = 5 I;  d2 = |z - H x-|^2 / 5
    assert np.allclose(d_small, np.sum(pos**2, axis=1) / 5.0)


# -- priors and covariances ----------------------------------------------------------------------------------


def test_two_point_prior_is_the_covariance_of_the_difference():
    # Monte Carlo of x0 = p1, v0 = (p1 - p0) / dt with p0 ~ N(m0, R0), p1 ~ N(m1, R1)
    rng = generator(9, "two-point")
    R0 = np.array([[4.0, 1.0], [1.0, 2.0]])
    R1 = np.array([[1.0, -0.5], [-0.5, 3.0]])
    dt = 2.0
    n = 400_000
    p0 = rng.multivariate_normal([10.0, 20.0], R0, n)
    p1 = rng.multivariate_normal([18.0, 24.0], R1, n)
    mc = np.cov(np.column_stack([p1, (p1 - p0) / dt]).T)
    g = two_point_prior(np.array([[10.0, 20.0]]), np.array([[18.0, 24.0]]), dt, R0[None], R1[None])
    assert np.allclose(g.mean, [[18.0, 24.0, 4.0, 2.0]])
    assert np.allclose(g.cov[0], mc, atol=0.02), (g.cov[0], mc)


def test_speed_course_prior():
    p0, p1 = np.array([[0.0, 0.0]]), np.array([[3.0, 0.0]])
    g = speed_course_prior(p0, p1, 1.0, 4.0 * np.eye(2)[None], sigma_v=1.0, sigma_c=0.5)
    assert np.allclose(g.mean, [[3.0, 0.0, 3.0, 0.0]])
    # course 0: along-track variance sigma_v^2, cross-track v^2 sigma_c^2
    assert np.allclose(g.cov[0], np.diag([4.0, 4.0, 1.0, 9.0 * 0.25]))
    g = speed_course_prior(p0, np.array([[0.0, 2.0]]), 1.0, np.eye(2)[None], 1.0, 1.0)
    assert np.allclose(g.cov[0, 2:, 2:], np.diag([4.0, 1.0]))


def test_position_and_detection_covariances_invert_each_other():
    # A R A^T with A = (dh/dp)^-1, and J_h (s^2 I) J_h^T: for the polar model the second maps s^2 I into (r, b)
    # and the first maps it back
    rng = generator(10, "covariances")
    p = rng.uniform(20, 200, (30, 2))
    model = range_bearing(0.5, np.deg2rad(1.0))
    C = detection_covariance(model, p, 4, 2.0)
    r = np.hypot(p[:, 0], p[:, 1])
    assert np.allclose(C[:, 0, 0], 4.0) and np.allclose(C[:, 1, 1], 4.0 / r**2) and np.allclose(C[:, 0, 1], 0.0)
    c = np.cos(np.arctan2(p[:, 1], p[:, 0]))
    s = np.sin(np.arctan2(p[:, 1], p[:, 0]))
    A = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], -2)
    assert np.allclose(A @ C @ np.swapaxes(A, -1, -2), 4.0 * np.eye(2), atol=1e-9)
    lin = linear_measurement(np.eye(2, 4), 4 * np.eye(2))
    assert np.allclose(position_covariance(lin, np.ones((3, 2)), 4), 4 * np.eye(2))


def test_take_and_join_filter_states():
    """The tracker's take / join of a declared state (workbench.specs.take_batch / join_batch): the declared
    batch-first fields are sliced and concatenated (nested records walked), everything else is the first state's."""
    from dataclasses import dataclass

    from workbench.specs import join_batch, take_batch
    from workbench.types import Particles

    @dataclass(frozen=True)
    class State:
        cloud: Particles
        count: int = 7

        batch_fields = ("cloud",)

    rng = generator(6, "tree")
    a = State(Particles(rng.normal(size=(3, 5, 4)), np.full((3, 5), -np.log(5))))
    b = State(Particles(rng.normal(size=(2, 5, 4)), np.full((2, 5), -np.log(5))), count=1)
    j = join_batch([a, b])
    assert j.cloud.particles.shape == (5, 5, 4) and j.count == 7
    t = take_batch(j, np.array([4, 0]))
    assert np.array_equal(t.cloud.particles, np.stack([b.cloud.particles[1], a.cloud.particles[0]]))
    g = Gaussian(np.arange(8.0).reshape(2, 4), np.repeat(np.eye(4)[None], 2, 0))
    assert np.array_equal(take_batch(g, np.array([1])).mean, g.mean[1:])
    assert np.array_equal(join_batch([g, g]).cov, np.concatenate([g.cov, g.cov]))


# -- whole runs ----------------------------------------------------------------------------------------------


def _two_targets(runs=3, clutter=0, seed=7, steps=15):
    rng = generator(seed, "two")
    k = np.arange(float(steps))[:, None]
    t1 = np.array([40.0, 40.0]) + k * [4.0, 2.0]
    t2 = np.array([200.0, 60.0]) + k * [-1.0, 4.0]
    z = np.stack([t1, t2], axis=1)[None] + 1.0 * rng.standard_normal((runs, steps, 2, 2))
    if clutter:
        z = np.concatenate([z, rng.uniform(0, 250, (runs, steps, clutter, 2))], axis=2)
    origin = np.concatenate([np.zeros((runs, steps, 1)), np.ones((runs, steps, 1)),
                             np.full((runs, steps, clutter), CLUTTER)], axis=2).astype(int)
    return Scans(z, np.ones(z.shape[:3], bool), np.arange(float(steps)), origin=origin), np.stack([t1, t2])


@pytest.mark.parametrize("name, frame, extra", [("kf", "cartesian", {}), ("cmkf-l", "polar", {}),
                                                ("ekf", "polar", {}), ("cmkf-l", "polar", {"detection_sigma": 1.0}),
                                                ("kf", "cartesian", {"prior": "speed-course", "initiation_hits": 2})])
def test_tracker_follows_two_targets_with_any_filter(name, frame, extra):
    scans, truth = _two_targets()
    sensor = HOST.sensor("active-sonar")
    model = sensor.measurement_model(frame=frame, sigma_xy=1.0, sigma_r=1.0, sigma_b_deg=0.5)
    cfg = TrackerConfig(**extra)
    log = run_tracker(scans, HOST.filter(name), MOTION, model, cfg, seed=1)
    counts = log.confirmed_counts()
    # confirmed at ping 4 (2 initiation detections + 3 hits), or at ping 2 when both initiation hits count
    first = 2 if cfg.initiation_hits == 2 else 4
    assert np.all(counts[:, first:] == 2) and np.all(counts[:, :first] == 0)
    for target in (0, 1):
        c = log.status == CONFIRMED
        d = np.linalg.norm(log.mean[c, :2] - truth[target][log.ping[c]], axis=1)
        pairs = np.unique(np.stack([log.run[c][d < 4.0], log.track_id[c][d < 4.0]]), axis=1)
        assert pairs.shape[1] == log.runs and set(pairs[0]) == set(range(log.runs))  # one track per run


def test_min_speed_keeps_a_stationary_object_unconfirmed():
    rng = generator(11, "stationary")
    steps = 15
    z = np.stack([np.array([40.0, 40.0]) + np.arange(steps)[:, None] * [4.0, 2.0],
                  np.full((steps, 2), 150.0)], axis=1)[None] + 0.5 * rng.standard_normal((1, steps, 2, 2))
    scans = Scans(z, np.ones(z.shape[:3], bool), np.arange(float(steps)))
    model = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=0.5)
    for min_speed, expected in ((None, 2), (2.0, 1)):
        log = run_tracker(scans, HOST.filter("kf"), MOTION, model, TrackerConfig(min_speed=min_speed), seed=2)
        assert log.confirmed_counts()[0, -1] == expected
        c = log.status == CONFIRMED
        assert np.all(np.hypot(log.mean[c, 2], log.mean[c, 3]) >= (min_speed or 0.0))


def test_tracker_never_reads_origin_is_reproducible_and_checks_its_input():
    scans, _ = _two_targets(runs=2, clutter=20)
    model = HOST.sensor("active-sonar").measurement_model(frame="polar")
    a = run_tracker(scans, HOST.filter("cmkf-l"), MOTION, model, seed=3)
    blind = Scans(scans.z, scans.valid, scans.times, origin=np.zeros_like(scans.origin))
    b = run_tracker(blind, HOST.filter("cmkf-l"), MOTION, model, seed=3)
    for key, value in a.to_arrays().items():
        assert np.array_equal(value, b.to_arrays()[key]), key
    assert np.array_equal(TrackLog.from_arrays(a.to_arrays()).mean, a.mean)
    with pytest.raises(InputError, match="Cartesian"):
        run_tracker(Scans(np.zeros((1, 2, 1, 3)), np.ones((1, 2, 1), bool), np.arange(2.0)), HOST.filter("kf"),
                    MOTION, model)
    with pytest.raises(InputError, match="detection_covariance"):
        run_tracker(scans, HOST.filter("ukf"), MOTION, model, TrackerConfig(detection_sigma=2.0))


# -- each detection's own covariance (Scan.cov) ---------------------------------------------------------------


def test_per_detection_gate_is_the_pairwise_mahalanobis_distance():
    # brute force: d2_kj = nu^T (J P J^T + J_h C_j J_h^T)^-1 nu, every pair, on both gate paths
    rng = generator(12, "own-cov gate")
    K, M = 15, 400
    mean = np.column_stack([rng.uniform(-200, 200, (K, 2)), rng.normal(0, 3, (K, 2))])
    est = Gaussian(mean, np.repeat(np.diag([9.0, 4.0, 4.0, 4.0])[None], K, 0))
    pos = rng.uniform(-220, 220, (M, 2))
    pos[:30] = mean[:, :2].repeat(2, 0) + rng.normal(0, 3, (30, 2))
    a = rng.normal(0, 1.5, (M, 2, 2))
    C = a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(2)  # each detection its own, correlated, covariance
    for model in (range_bearing(0.5, np.deg2rad(1.0)), linear_measurement(np.eye(2, 4), 4 * np.eye(2))):
        zm = model.h(np.column_stack([pos, np.zeros((M, 2))]))
        R = measurement_covariance(model, pos, 4, C)
        J = np.stack([model.jacobian(m[None])[0] if model.jacobian is not None else model.H for m in mean])
        ref = {}
        for k in range(K):
            for j in range(M):
                nu = model.residual(zm[j], model.h(mean[k][None])[0])
                S = J[k] @ est.cov[k] @ J[k].T + R[j]
                d2 = float(nu @ np.linalg.solve(S, nu))
                if d2 <= 9.21:
                    ref[(k, j)] = d2
        assert ref
        for cfg in (TrackerConfig(), TrackerConfig(dense_limit=0)):
            rows, cols, d2 = gated_pairs(est, pos, zm, model, cfg, R)
            got = dict(zip(zip(rows.tolist(), cols.tolist()), d2))
            assert got.keys() == ref.keys()
            assert all(np.isclose(got[p], ref[p], rtol=1e-9) for p in ref)


def test_scan_covariances_equal_to_a_stated_accuracy_track_as_detection_sigma():
    # C_j = s^2 I for every detection is detection_sigma = s: the same tracks, ping by ping
    scans, _ = _two_targets(runs=2, clutter=15)
    s = 1.5
    cov = np.broadcast_to(s * s * np.eye(2), (*scans.z.shape[:3], 2, 2)).copy()
    own = Scans(scans.z, scans.valid, scans.times, origin=scans.origin, cov=cov)
    sensor = HOST.sensor("active-sonar")
    for name, frame in (("kf", "cartesian"), ("cmkf-l", "polar")):
        model = sensor.measurement_model(frame=frame, sigma_xy=1.0)
        a = run_tracker(scans, HOST.filter(name), MOTION, model, TrackerConfig(detection_sigma=s), seed=4)
        b = run_tracker(own, HOST.filter(name), MOTION, model, TrackerConfig(), seed=4)
        for key, value in a.to_arrays().items():
            assert np.allclose(value, b.to_arrays()[key], rtol=1e-9, atol=1e-9), (name, key)
        # and they differ from tracking with the model's own R, so the covariances are read
        c = run_tracker(scans, HOST.filter(name), MOTION, model, TrackerConfig(), seed=4)
        assert c.mean.shape != b.mean.shape or not np.allclose(c.mean, b.mean)


def test_per_detection_covariance_weights_the_update():
    # one confirmed-path track, one detection a ping: a detection stated as 100x less accurate moves the
    # estimate 100x less (in the linear position model with a known prediction)
    scans, _ = _two_targets(runs=1, clutter=0)
    model = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)
    cov = np.broadcast_to(np.eye(2), (*scans.z.shape[:3], 2, 2)).copy()
    cov[0, -1] *= 1e6  # the last ping's detections are stated as 1 km accurate
    own = Scans(scans.z, scans.valid, scans.times, cov=cov)
    ref = Scans(scans.z, scans.valid, scans.times, cov=np.broadcast_to(np.eye(2), cov.shape).copy())
    a = run_tracker(own, HOST.filter("kf"), MOTION, model, TrackerConfig(gate=1e9), seed=5)
    b = run_tracker(ref, HOST.filter("kf"), MOTION, model, TrackerConfig(gate=1e9), seed=5)
    last = scans.steps - 1
    pa, pb = a.mean[a.ping == last], b.mean[b.ping == last]
    prev = b.mean[b.ping == last - 1]
    predicted = prev[:, :2] + prev[:, 2:]  # dt = 1
    # the inaccurate detection barely moves the estimate off the prediction; the accurate one pulls it in
    assert np.all(np.linalg.norm(pa[:, :2] - predicted, axis=1) < 1e-3 * np.linalg.norm(pb[:, :2] - predicted,
                                                                                       axis=1) + 1e-9)


def test_scan_covariances_are_refused_beside_detection_sigma_or_by_a_filter_that_ignores_them():
    scans, _ = _two_targets(runs=1, clutter=2)
    cov = np.broadcast_to(np.eye(2), (*scans.z.shape[:3], 2, 2)).copy()
    own = Scans(scans.z, scans.valid, scans.times, cov=cov)
    model = HOST.sensor("active-sonar").measurement_model(frame="cartesian")
    with pytest.raises(InputError, match="detection_sigma"):
        run_tracker(own, HOST.filter("kf"), MOTION, model, TrackerConfig(detection_sigma=2.0))
    with pytest.raises(InputError, match="detection_covariance"):
        run_tracker(own, HOST.filter("ukf"), MOTION, model)


# -- the module split ------------------------------------------------------------------------------------------


def test_multi_still_holds_every_name_it_held_before_the_split():
    import workbench.tracking.multi as multi
    from workbench.tracking import assign, gate, initiation, mofn, records

    before = ["TENTATIVE", "CONFIRMED", "TrackerConfig", "TrackTable", "TrackerState", "PingTracks", "TrackLog",
              "measurement_view", "position_covariance", "two_point_prior", "speed_course_prior",
              "detection_covariance", "measurement_covariance", "PRIORS", "box_pairs", "gate_covariance",
              "gated_pairs", "greedy_assign", "rectangular_pairs", "mofn_step", "initial_state", "tracker_step",
              "MofN", "run_tracker"]
    homes = (records, gate, assign, initiation, mofn)
    for name in before:
        assert name in multi.__all__, name
        obj = getattr(multi, name)
        assert any(getattr(home, name, None) is obj for home in homes), name  # re-exported, not a copy
        if callable(obj):
            assert obj.__module__ in {home.__name__ for home in homes}, name  # defined by its role's module


def test_track_log_keeps_covariances_through_arrays_and_selection():
    rng = generator(13, "log cov")
    R = 7
    a = rng.standard_normal((R, 4, 4))
    cov = a @ np.swapaxes(a, 1, 2)
    log = TrackLog(np.array([0, 0, 0, 1, 1, 1, 1]), np.array([0, 1, 2, 0, 1, 1, 2]), np.arange(R),
                   np.full(R, CONFIRMED, np.int8), np.ones(R, bool), rng.standard_normal((R, 4)), 2, 3, cov)
    back = TrackLog.from_arrays(log.to_arrays("x_"), "x_")
    assert np.array_equal(back.cov, cov) and np.array_equal(back.mean, log.mean)
    mask = log.run == 1
    assert np.array_equal(log.select(mask).cov, cov[3:])
    bare = TrackLog(log.run, log.ping, log.track_id, log.status, log.hit, log.mean, 2, 3)
    assert "cov" not in bare.to_arrays() and TrackLog.from_arrays(bare.to_arrays()).cov is None
    assert bare.select(mask).cov is None
