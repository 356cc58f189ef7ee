"""Trackers as a plugin role (``TrackerSpec``, hook ``workbench_trackers``) and the built-in GNN tracker: its
assignment against brute-force enumeration, its identities against greedy nearest neighbour on crossing targets,
the built-in ``mofn`` against the M-of-N tracker it wraps, and the host's references."""

import itertools

import numpy as np
import pytest

from workbench import hookimpl
from workbench.models import constant_velocity
from workbench.plugins import UnknownComponent, load_host
from workbench.rng import generator
from workbench.specs import TrackerSpec
from workbench.tracking import CONFIRMED, TrackerConfig, run_tracker
from workbench.tracking.assign import gnn_assign, greedy_assign
from workbench.tracking.gate import chi2_gate
from workbench.types import InputError, Scans

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)
MODEL = HOST.sensor("active-sonar").measurement_model(frame="cartesian", sigma_xy=1.0)


# -- the assignment ------------------------------------------------------------------------------------------


def _brute_force(rows, cols, cost, miss):
    """The least total cost over every one-to-one assignment of the given pairs, by enumeration: each track takes
    one of its pairs or none."""
    tracks = sorted(set(rows.tolist()))
    options = {t: [None] + [(int(c), float(x)) for r, c, x in zip(rows, cols, cost) if r == t] for t in tracks}
    best = np.inf
    for choice in itertools.product(*(options[t] for t in tracks)):
        used = [c[0] for c in choice if c is not None]
        if len(used) != len(set(used)):
            continue
        best = min(best, sum(miss if c is None else c[1] for c in choice))
    return best


def _total(rows, cols, cost, miss, a_r, a_c):
    """The total cost of an assignment, written out: the taken pairs' costs and a miss for every other track."""
    table = {(int(r), int(c)): float(x) for r, c, x in zip(rows, cols, cost)}
    return sum(table[(int(r), int(c))] for r, c in zip(a_r, a_c)) + miss * (len(set(rows.tolist())) - len(a_r))


def test_gnn_assignment_equals_brute_force_enumeration():
    rng = generator(21, "gnn brute force")
    for case in range(300):
        miss = 9.21 if case % 4 else 3.0  # 3: some pairs cost more than leaving the track without a detection
        K, M = int(rng.integers(1, 6)), int(rng.integers(1, 6))
        gated = rng.uniform(size=(K, M)) < rng.uniform(0.2, 0.9)
        rows, cols = np.nonzero(gated)
        rows, cols = rows + 3 * (case % 2), cols + 5 * (case % 3)  # labels need not start at 0
        cost = rng.uniform(0.0, 9.21, rows.size)
        if case % 5 == 0:
            cost = np.round(cost)  # ties
        a_r, a_c = gnn_assign(rows, cols, cost, miss)
        # a valid assignment: given pairs only, each track and detection once
        assert len(set(a_r.tolist())) == a_r.size and len(set(a_c.tolist())) == a_c.size
        assert set(zip(a_r.tolist(), a_c.tolist())) <= set(zip(rows.tolist(), cols.tolist()))
        assert _total(rows, cols, cost, miss, a_r, a_c) == pytest.approx(_brute_force(rows, cols, cost, miss),
                                                                         abs=1e-12), case


def test_gnn_takes_the_global_optimum_where_greedy_does_not():
    # tracks 0, 1; detections 0, 1: d2(0,0) = 1, d2(0,1) = 2, d2(1,0) = 1.5, track 1 cannot take detection 1.
    # Greedy takes (0,0) first and leaves track 1 without one: 1 + 9.21; GNN takes (0,1), (1,0): 3.5
    rows, cols, cost = np.array([0, 0, 1]), np.array([0, 1, 0]), np.array([1.0, 2.0, 1.5])
    g_r, g_c = greedy_assign(rows, cols, cost)
    assert sorted(zip(g_r.tolist(), g_c.tolist())) == [(0, 0)]
    a_r, a_c = gnn_assign(rows, cols, cost, 9.21)
    assert sorted(zip(a_r.tolist(), a_c.tolist())) == [(0, 1), (1, 0)]
    # a miss cheaper than the detour: track 0 keeps detection 0 and track 1 goes without (1 + 2 < 2 + 1.5)
    a_r, a_c = gnn_assign(rows, cols, cost, 2.0)
    assert sorted(zip(a_r.tolist(), a_c.tolist())) == [(0, 0)]
    assert gnn_assign(np.zeros(0, int), np.zeros(0, int), np.zeros(0), 9.21)[0].size == 0


def test_chi2_gate_is_the_closed_form_quantile():
    # chi-square with 2 dof: P(d2 <= g) = 1 - exp(-g / 2), so g = -2 ln(1 - p)
    for p in (0.5, 0.9, 0.99, 0.999):
        assert chi2_gate(p, 2) == pytest.approx(-2.0 * np.log1p(-p), rel=1e-12)
    # 1 dof: g = (Phi^-1((1 + p) / 2))^2, the two-sided normal quantile squared (1.959964 for 95 %)
    assert chi2_gate(0.95, 1) == pytest.approx(1.959963984540054**2, rel=1e-12)
    for bad in (0.0, 1.0, 1.5):
        with pytest.raises(InputError, match="gate probability"):
            chi2_gate(bad, 2)


# -- whole runs ----------------------------------------------------------------------------------------------


def _crossing(runs, seed=1, steps=24, clutter=2, sigma=0.7, climb=1.5):
    """Two targets at 4 per ping along x, one climbing and one descending by ``climb`` per ping, crossing half way;
    ``clutter`` uniform false detections per scan around them."""
    rng = generator(seed, "crossing")
    k = np.arange(float(steps))[:, None]
    truth = np.stack([k * [4.0, climb], [0.0, climb * (steps - 1)] + k * [4.0, -climb]])  # (2, T, 2)
    z = truth.transpose(1, 0, 2)[None] + sigma * rng.standard_normal((runs, steps, 2, 2))
    lo, hi = np.array([-10.0, -10.0]), np.array([4.0 * steps + 10.0, climb * steps + 10.0])
    z = np.concatenate([z, lo + (hi - lo) * rng.uniform(size=(runs, steps, clutter, 2))], axis=2)
    return Scans(z, np.ones(z.shape[:3], bool), np.arange(float(steps))), truth


def _identity_swaps(log, truth, radius=6.0):
    """How often a confirmed track changes the target it follows (the truth target nearest to its estimate,
    within ``radius``), over every track of every run."""
    c = log.status == CONFIRMED
    run, ping, tid, pos = log.run[c], log.ping[c], log.track_id[c], log.mean[c, :2]
    d = np.linalg.norm(pos[:, None, :] - truth[:, ping].transpose(1, 0, 2), axis=2)  # (rows, targets)
    target = np.where(d.min(axis=1) < radius, d.argmin(axis=1), -1)
    swaps = 0
    for r, t in set(zip(run.tolist(), tid.tolist())):
        mine = (run == r) & (tid == t) & (target >= 0)
        followed = target[mine][np.argsort(ping[mine])]
        swaps += int(np.sum(followed[1:] != followed[:-1]))
    return swaps


def test_gnn_keeps_crossing_targets_apart_better_than_greedy_nearest_neighbour():
    scans, truth = _crossing(20, steps=18)
    kf = HOST.filter("kf")
    greedy = HOST.tracker("mofn").run(scans, kf, MOTION, MODEL, seed=2)
    gnn = HOST.tracker("gnn").run(scans, kf, MOTION, MODEL, seed=2)
    # both hold the two targets most of the time
    for log in (greedy, gnn):
        assert np.mean(log.confirmed_counts()[:, 6:] == 2) > 0.8
    n_greedy, n_gnn = _identity_swaps(greedy, truth), _identity_swaps(gnn, truth)
    assert n_gnn < n_greedy, (n_gnn, n_greedy)  # 12 against 24 on this scene (20 runs)


def test_the_same_seed_gives_the_same_tracks_and_inputs_are_never_mutated():
    scans, _ = _crossing(3, seed=4, steps=10, clutter=15)
    before = {k: np.copy(getattr(scans, k)) for k in ("z", "valid", "times")}
    spec = HOST.tracker("gnn")
    sir = HOST.filter("sir(particles=200)")  # a filter that draws: the tracker's streams come from the seed
    a = spec.run(scans, sir, MOTION, MODEL, seed=5)
    b = spec.run(scans, sir, MOTION, MODEL, seed=5)
    c = spec.run(scans, sir, MOTION, MODEL, seed=6)
    for key, value in a.to_arrays().items():
        assert np.array_equal(value, b.to_arrays()[key]), key
    assert a.mean.shape != c.mean.shape or not np.array_equal(a.mean, c.mean)
    for key, value in before.items():
        assert np.array_equal(getattr(scans, key), value), key
    # a run's tracks do not depend on the other runs of the batch (its stream is keyed by its index)
    two = spec.run(Scans(scans.z[:2], scans.valid[:2], scans.times), sir, MOTION, MODEL, seed=5)
    assert np.array_equal(two.mean, a.select(a.run < 2).mean)


def test_mofn_spec_is_the_m_of_n_tracker_it_wraps_with_covariances():
    scans, truth = _crossing(4, seed=3, steps=12, clutter=5)
    kf = HOST.filter("kf")
    spec = HOST.tracker("mofn(gate=16, delete_misses=4)")
    assert spec.name == "mofn(gate=16, delete_misses=4)"
    log = spec.run(scans, kf, MOTION, MODEL, seed=7, key=("k",))
    ref = run_tracker(scans, kf, MOTION, MODEL, TrackerConfig(gate=16.0, delete_misses=4), seed=7, key=("k",))
    for key, value in ref.to_arrays().items():
        assert np.array_equal(value, log.to_arrays()[key]), key
    assert ref.cov is None and log.cov.shape == (log.mean.shape[0], 4, 4)
    assert np.allclose(log.cov, np.swapaxes(log.cov, 1, 2))
    assert np.all(np.linalg.eigvalsh(log.cov) > 0)


def test_logged_track_is_a_hand_written_kalman_filter_from_the_two_point_prior():
    # one target, no clutter, the Kalman filter on the linear model: the track started at ping 1 from the
    # detections of pings 0 and 1 is a plain Kalman filter from the two-point prior, updated with the target's
    # detection at every later ping; its logged mean and covariance are that filter's
    runs, steps = 3, 8
    rng = generator(8, "hand kf")
    truth = np.array([10.0, 20.0]) + np.arange(float(steps))[:, None] * [3.0, -2.0]
    z = truth[None, :, None, :] + rng.standard_normal((runs, steps, 1, 2))
    scans = Scans(z, np.ones(z.shape[:3], bool), np.arange(float(steps)))
    log = HOST.tracker("gnn").run(scans, HOST.filter("kf"), MOTION, MODEL, seed=1)
    F, Q, R = MOTION.F, MOTION.Q, MODEL.R
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    for b in range(runs):
        d = z[b, :, 0]
        x = np.concatenate([d[1], d[1] - d[0]])  # dt = 1
        P = np.block([[R, R], [R, 2.0 * R]])
        for k in range(1, steps):
            if k > 1:
                x, P = F @ x, F @ P @ F.T + Q
                S = H @ P @ H.T + R
                G = P @ H.T @ np.linalg.inv(S)
                x, P = x + G @ (d[k] - H @ x), (np.eye(4) - G @ H) @ P
            row = np.flatnonzero((log.run == b) & (log.ping == k) & (log.track_id == 0))
            assert row.size == 1 and log.hit[row[0]]
            assert np.allclose(log.mean[row[0]], x, rtol=0, atol=1e-9)
            assert np.allclose(log.cov[row[0]], P, rtol=0, atol=1e-9)
        assert np.all(log.track_id[log.run == b] == 0)  # no other track


# -- the plugin role -----------------------------------------------------------------------------------------


def test_host_lists_configures_and_refuses_trackers_by_name():
    assert {"mofn", "gnn"} <= set(HOST.trackers)
    assert HOST.plugin_of("workbench_trackers", "gnn").name == "trackers"
    spec = HOST.tracker("gnn(gate_probability=0.95)")
    assert spec.params["gate_probability"] == 0.95 and spec.name == "gnn(gate_probability=0.95)"
    assert HOST.tracker("gnn").params["gate_probability"] == 0.99  # the installed one is unchanged
    assert HOST.find("gnn(gate_probability=0.95)")[0][0] == "tracker"
    with pytest.raises(InputError, match="gate_probability"):
        HOST.tracker("gnn(gate_probability=2)")
    with pytest.raises(InputError, match="gate"):
        HOST.tracker("gnn(gate=9)")  # gnn declares a gate probability, not a gate
    with pytest.raises(UnknownComponent, match="no tracker named 'tomht'"):
        HOST.tracker("tomht")
    with pytest.raises(UnknownComponent, match="is a filter, not a tracker"):
        HOST.tracker("kf")
    # TrackerConfig's own rule, reached through the declared parameters
    with pytest.raises(InputError, match="confirm_hits <= confirm_window"):
        HOST.tracker("mofn(confirm_hits=6)").run(*_crossing(1, steps=3)[:1], HOST.filter("kf"), MOTION, MODEL)


class _ThirdParty:
    """A tracker from outside the project: everything tracked as one confirmed track at the first detection."""

    @staticmethod
    @hookimpl
    def workbench_trackers():
        from workbench.tracking import TrackLog

        def run(scans, filt, motion, model, *, seed=0, key=(), offset=0.0):
            B, T = scans.batch, scans.steps
            mean = np.zeros((B * T, motion.dim))
            mean[:, :2] = scans.z[:, :, 0, :2].reshape(B * T, 2) + offset
            return TrackLog(np.repeat(np.arange(B), T), np.tile(np.arange(T), B), np.zeros(B * T, int),
                            np.full(B * T, CONFIRMED, np.int8), np.ones(B * T, bool), mean, B, T)

        from workbench.params import Param

        return [TrackerSpec("first", "the first detection", run, params={"offset": 0.0},
                            parameters=(Param("offset", 0.0, "a shift", unit="length"),))]


class _Misspelt:
    @staticmethod
    @hookimpl
    def workbench_trackers():
        return [TrackerSpec("odd", "a misspelt capability", lambda *a, **k: None, capabilities=frozenset({"covarance"}))]


def test_a_third_party_tracker_registers_and_a_bad_one_is_broken():
    host = load_host(extra_plugins=[("third", _ThirdParty), ("misspelt", _Misspelt)])
    spec = host.tracker("first(offset=2 m)")
    scans, _ = _crossing(2, steps=3)
    log = spec.run(scans, host.filter("kf"), MOTION, MODEL, seed=0)
    assert np.array_equal(log.mean[:, :2], scans.z[:, :, 0].reshape(-1, 2) + 2.0)
    broken = {p.name: p for p in host.broken}
    assert "misspelt" in broken and "covarance" in broken["misspelt"].error
    assert ("tracker", "first") in next(p for p in host.plugins if p.name == "third").provides
