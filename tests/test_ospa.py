"""OSPA and GOSPA (workbench.metrics.ospa) against closed forms, a brute-force enumeration of every assignment,
the metric axioms, and Stone Soup's OSPAMetric and GOSPAMetric on the same tracks."""

import itertools
from datetime import datetime, timedelta

import numpy as np
import pytest

from workbench.metrics import gospa, ospa, track_gospa, track_ospa, track_positions
from workbench.tracking import CONFIRMED, TENTATIVE, TrackLog
from workbench.types import InputError


def _brute(x, y, c, p):
    """Both distances by enumerating every injection of the smaller set into the larger (no SciPy)."""
    m, n = len(x), len(y)
    if m == 0 and n == 0:
        return 0.0, 0.0
    small, large = (x, y) if m <= n else (y, x)
    best = np.inf
    for perm in itertools.permutations(range(len(large)), len(small)):
        total = sum(min(float(np.linalg.norm(small[i] - large[j])), c) ** p for i, j in enumerate(perm))
        best = min(best, total)
    big, diff = max(m, n), abs(n - m)
    d_ospa = ((best + c ** p * diff) / big) ** (1 / p)
    d_gospa = (best + c ** p / 2 * diff) ** (1 / p)
    return d_ospa, d_gospa


def _random_set(rng, k, spread=10.0):
    return rng.uniform(-spread, spread, size=(k, 2))


# -- closed forms -------------------------------------------------------------------------------------


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_empty_against_empty_is_zero(p):
    e = np.zeros((0, 2))
    assert float(ospa(e, e, 5.0, p).distance) == 0.0
    g = gospa(e, e, 5.0, p)
    assert float(g.distance) == 0.0 and int(g.n_missed) == 0 and int(g.n_false) == 0


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_one_missed_target_and_one_false_track(p):
    c = 7.0
    one, none = np.array([[3.0, 4.0]]), np.zeros((0, 2))
    # GOSPA alpha = 2: a missed target costs c^p / 2, so d = c / 2^(1/p); OSPA: the cut-off itself
    missed = gospa(none, one, c, p)
    assert float(missed.distance) == pytest.approx(c / 2 ** (1 / p), rel=1e-15)
    assert float(missed.missed) == pytest.approx(c ** p / 2) and float(missed.false) == 0.0
    assert int(missed.n_missed) == 1 and int(missed.n_false) == 0
    false = gospa(one, none, c, p)
    assert float(false.false) == pytest.approx(c ** p / 2) and int(false.n_false) == 1 and int(false.n_missed) == 0
    assert float(ospa(none, one, c, p).distance) == pytest.approx(c) == float(ospa(one, none, c, p).distance)
    # three missed targets: GOSPA adds up, OSPA stays at c
    three = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    assert float(gospa(none, three, c, p).distance) == pytest.approx((3 * c ** p / 2) ** (1 / p))
    assert float(ospa(none, three, c, p).distance) == pytest.approx(c)


def test_a_hand_computed_example():
    # estimates (0,0), (5,0); truths (1,0), (100,0), (6,0); c = 10, p = 2
    x = np.array([[0.0, 0.0], [5.0, 0.0]])
    y = np.array([[1.0, 0.0], [100.0, 0.0], [6.0, 0.0]])
    g = gospa(x, y, 10.0, 2.0)
    # pairs (0,0)-(1,0) and (5,0)-(6,0) at distance 1 each; (100,0) missed: 1 + 1 + 100/2 = 52
    assert float(g.localisation) == pytest.approx(2.0) and float(g.missed) == pytest.approx(50.0)
    assert float(g.false) == 0.0 and int(g.assigned) == 2
    assert float(g.distance) == pytest.approx(np.sqrt(52.0), rel=1e-15)
    o = ospa(x, y, 10.0, 2.0)
    # OSPA: (1/3) (1 + 1 + 10^2) = 34; localisation (1/3) 2, cardinality (1/3) 100
    assert float(o.distance) == pytest.approx(np.sqrt(34.0), rel=1e-15)
    assert float(o.localisation) == pytest.approx(np.sqrt(2 / 3)) and float(o.cardinality) == pytest.approx(np.sqrt(100 / 3))


def test_a_pair_beyond_the_cut_off_is_one_miss_and_one_false_track():
    g = gospa(np.array([[0.0, 0.0]]), np.array([[20.0, 0.0]]), 10.0, 1.0)
    assert int(g.assigned) == 0 and int(g.n_missed) == 1 and int(g.n_false) == 1
    assert float(g.distance) == pytest.approx(10.0) and float(g.localisation) == 0.0
    assert float(ospa(np.array([[0.0, 0.0]]), np.array([[20.0, 0.0]]), 10.0, 1.0).distance) == pytest.approx(10.0)


def test_the_optimal_assignment_is_not_the_greedy_one():
    # greedy nearest pairs x0-y0 (d = 1) and then x1-y1 (d = 9); the optimum crosses: 2 + 2 (p = 1)
    x = np.array([[0.0, 0.0], [3.0, 0.0]])
    y = np.array([[1.0, 0.0], [-2.0, 0.0]])
    assert float(gospa(x, y, 100.0, 1.0).distance) == pytest.approx(4.0)
    assert float(ospa(x, y, 100.0, 1.0).distance) == pytest.approx(2.0)


# -- against an enumeration of every assignment ---------------------------------------------------------


@pytest.mark.parametrize("p", [1.0, 2.0, 3.5])
def test_matches_brute_force_on_random_sets(p):
    rng = np.random.default_rng(17)
    for _ in range(120):
        m, n = rng.integers(0, 5, size=2)
        x, y = _random_set(rng, m), _random_set(rng, n)
        c = float(rng.uniform(1.0, 15.0))
        d_o, d_g = _brute(x, y, c, p)
        o, g = ospa(x, y, c, p), gospa(x, y, c, p)
        assert float(o.distance) == pytest.approx(d_o, rel=1e-12, abs=1e-12)
        assert float(g.distance) == pytest.approx(d_g, rel=1e-12, abs=1e-12)
        # the decompositions add up
        assert float(o.distance) ** p == pytest.approx(float(o.localisation) ** p + float(o.cardinality) ** p,
                                                        rel=1e-12, abs=1e-12)
        assert float(g.distance) ** p == pytest.approx(float(g.localisation + g.missed + g.false), rel=1e-12, abs=1e-12)
        assert int(g.assigned) + int(g.n_missed) == n and int(g.assigned) + int(g.n_false) == m


def test_a_padded_batch_equals_each_item_alone():
    rng = np.random.default_rng(3)
    B, T, M, N = 3, 4, 5, 3
    x = rng.uniform(-10, 10, size=(B, T, M, 2))
    y = rng.uniform(-10, 10, size=(B, T, N, 2))
    xv = rng.random((B, T, M)) < 0.6
    yv = rng.random((B, T, N)) < 0.7
    x[~xv] = 1e12  # padding rows must not count, whatever they hold
    o = ospa(x, y, 6.0, 2.0, x_valid=xv, y_valid=yv)
    g = gospa(x, y, 6.0, 2.0, x_valid=xv, y_valid=yv)
    assert o.distance.shape == g.distance.shape == (B, T)
    for b in range(B):
        for t in range(T):
            d_o, d_g = _brute(x[b, t][xv[b, t]], y[b, t][yv[b, t]], 6.0, 2.0)
            assert o.distance[b, t] == pytest.approx(d_o, rel=1e-12, abs=1e-12)
            assert g.distance[b, t] == pytest.approx(d_g, rel=1e-12, abs=1e-12)


# -- metric axioms ------------------------------------------------------------------------------------


def test_symmetry_identity_and_the_triangle_inequality():
    rng = np.random.default_rng(5)
    for p in (1.0, 2.0):
        for _ in range(150):
            a, b, c_ = (_random_set(rng, int(k)) for k in rng.integers(0, 5, size=3))
            cut = 8.0
            for fn in (lambda u, v: float(ospa(u, v, cut, p).distance), lambda u, v: float(gospa(u, v, cut, p).distance)):
                assert fn(a, b) == pytest.approx(fn(b, a), rel=1e-12, abs=1e-12)
                assert fn(a, a) == 0.0
                assert fn(a, c_) <= fn(a, b) + fn(b, c_) + 1e-9
    g_ab = gospa(np.array([[0.0, 0.0]]), np.zeros((0, 2)), 4.0, 2.0)
    g_ba = gospa(np.zeros((0, 2)), np.array([[0.0, 0.0]]), 4.0, 2.0)
    assert float(g_ab.false) == float(g_ba.missed) and float(g_ab.missed) == float(g_ba.false)


@pytest.mark.parametrize("c, p", [(0.0, 1.0), (-1.0, 1.0), (np.inf, 1.0), (1.0, 0.5), (1.0, np.inf), (1.0, np.nan)])
def test_bad_orders_are_refused(c, p):
    with pytest.raises(InputError, match="cut-off|order"):
        ospa(np.zeros((1, 2)), np.zeros((1, 2)), c, p)


def test_mismatched_inputs_are_refused():
    with pytest.raises(InputError, match="components"):
        gospa(np.zeros((1, 2)), np.zeros((1, 3)), 1.0)
    with pytest.raises(InputError, match="batch shapes"):
        gospa(np.zeros((2, 1, 2)), np.zeros((3, 1, 2)), 1.0)
    with pytest.raises(InputError, match="non-finite"):
        gospa(np.array([[np.nan, 0.0]]), np.zeros((1, 2)), 1.0)


# -- a tracker's log ----------------------------------------------------------------------------------


def _log(rng, runs=3, pings=6, max_tracks=4):
    rows = {"run": [], "ping": [], "track_id": [], "status": [], "hit": [], "mean": []}
    for b in range(runs):
        for k in range(pings):
            for i in range(int(rng.integers(0, max_tracks + 1))):
                rows["run"].append(b)
                rows["ping"].append(k)
                rows["track_id"].append(i)
                rows["status"].append(CONFIRMED if rng.random() < 0.75 else TENTATIVE)
                rows["hit"].append(bool(rng.random() < 0.8))
                rows["mean"].append(np.concatenate([rng.uniform(-20, 20, 2), rng.normal(size=2)]))
    return TrackLog(np.array(rows["run"]), np.array(rows["ping"]), np.array(rows["track_id"]),
                    np.array(rows["status"], dtype=np.int8), np.array(rows["hit"]), np.array(rows["mean"]).reshape(-1, 4),
                    runs, pings)


def test_track_metrics_score_the_confirmed_tracks_of_every_run_and_ping():
    rng = np.random.default_rng(11)
    log = _log(rng)
    truth = rng.uniform(-20, 20, size=(log.runs, log.pings, 2, 4))  # two targets, full states
    truth_valid = rng.random((log.runs, log.pings, 2)) < 0.8
    g = track_gospa(log, truth, 10.0, 2.0, truth_valid=truth_valid)
    o = track_ospa(log, truth, 10.0, 2.0, truth_valid=truth_valid)
    assert g.distance.shape == o.distance.shape == (log.runs, log.pings)
    for b in range(log.runs):
        for k in range(log.pings):
            sel = (log.run == b) & (log.ping == k) & (log.status == CONFIRMED)
            est = log.mean[sel, :2]
            tru = truth[b, k][truth_valid[b, k], :2]
            d_o, d_g = _brute(est, tru, 10.0, 2.0)
            assert g.distance[b, k] == pytest.approx(d_g, rel=1e-12, abs=1e-12)
            assert o.distance[b, k] == pytest.approx(d_o, rel=1e-12, abs=1e-12)
    pos, valid = track_positions(log, confirmed_only=False)
    assert valid.sum() == log.run.size and pos.shape[-1] == 2


def test_a_single_target_truth_and_a_log_without_tracks():
    log = TrackLog(*(np.zeros(0, dtype=int),) * 3, np.zeros(0, dtype=np.int8), np.zeros(0, dtype=bool),
                   np.zeros((0, 4)), 2, 3)
    truth = np.zeros((2, 3, 4))
    g = track_gospa(log, truth, 5.0, 1.0)
    assert np.all(g.distance == 2.5) and np.all(g.n_missed == 1)
    with pytest.raises(InputError, match="true positions"):
        track_gospa(log, np.zeros((2, 4, 4)), 5.0)


# -- Stone Soup ----------------------------------------------------------------------------------------


def _stonesoup():
    try:
        from stonesoup.metricgenerator.ospametric import GOSPAMetric, OSPAMetric
        from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
        from stonesoup.types.state import State
        from stonesoup.types.track import Track
    except ImportError as exc:  # pragma: no cover - depends on the environment
        pytest.skip(f"Stone Soup is not installed ({exc}); pip install -e '.[stonesoup]' to cross-check")
    return GOSPAMetric, OSPAMetric, GroundTruthPath, GroundTruthState, State, Track


def _stonesoup_sets(log, truth, truth_valid, run, times):
    """One run's confirmed tracks and truths as Stone Soup tracks and ground-truth paths (positions only)."""
    _, _, GroundTruthPath, GroundTruthState, State, Track = _stonesoup()
    start = datetime(2024, 1, 1)
    stamp = [start + timedelta(seconds=float(t)) for t in times]
    tracks = []
    conf = (log.run == run) & (log.status == CONFIRMED)
    for tid in np.unique(log.track_id[conf]):
        rows = np.flatnonzero(conf & (log.track_id == tid))
        tracks.append(Track([State(log.mean[r, :2].reshape(2, 1), timestamp=stamp[log.ping[r]]) for r in rows]))
    paths = []
    for j in range(truth.shape[2]):
        states = [GroundTruthState(truth[run, k, j, :2].reshape(2, 1), timestamp=stamp[k])
                  for k in range(truth.shape[1]) if truth_valid[run, k, j]]
        if states:
            paths.append(GroundTruthPath(states))
    return tracks, paths, stamp


def _per_time(metric):
    values = metric.value if isinstance(metric.value, list) else [metric]
    return {m.timestamp: m.value for m in values}


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_gospa_agrees_with_stonesoup(p):
    GOSPAMetric, _, *_ = _stonesoup()
    rng = np.random.default_rng(23)
    log = _log(rng, runs=3, pings=8, max_tracks=5)
    truth = rng.uniform(-20, 20, size=(log.runs, log.pings, 3, 4))
    truth_valid = rng.random((log.runs, log.pings, 3)) < 0.7
    c = 12.0
    ours = track_gospa(log, truth, c, p, truth_valid=truth_valid)
    times = np.arange(log.pings) * 2.5
    compared = 0
    for b in range(log.runs):
        tracks, paths, stamp = _stonesoup_sets(log, truth, truth_valid, b, times)
        gen = GOSPAMetric(c=c, p=p)
        theirs = _per_time(gen.compute_over_time(*gen.extract_states(tracks, True), *gen.extract_states(paths, True)))
        for k, t in enumerate(stamp):
            if t not in theirs:  # Stone Soup reports no value where both sets are empty (GOSPA 0)
                assert ours.distance[b, k] == 0.0
                continue
            v = theirs[t]
            for key, mine in (("distance", ours.distance), ("localisation", ours.localisation),
                              ("missed", ours.missed), ("false", ours.false)):
                assert mine[b, k] == pytest.approx(float(v[key]), rel=1e-9, abs=1e-9), (b, k, key)
            compared += 1
    assert compared >= 15


def test_ospa_agrees_with_stonesoup():
    _, OSPAMetric, *_ = _stonesoup()
    rng = np.random.default_rng(29)
    log = _log(rng, runs=3, pings=8, max_tracks=5)
    truth = rng.uniform(-20, 20, size=(log.runs, log.pings, 3, 4))
    truth_valid = rng.random((log.runs, log.pings, 3)) < 0.7
    c = 12.0
    times = np.arange(log.pings) * 1.0
    by_p = {p: track_ospa(log, truth, c, p, truth_valid=truth_valid) for p in (1.0, 2.0)}
    compared = differ = 0
    for b in range(log.runs):
        tracks, paths, stamp = _stonesoup_sets(log, truth, truth_valid, b, times)
        for p, ours in by_p.items():
            gen = OSPAMetric(c=c, p=p)
            theirs = _per_time(gen.compute_over_time(*gen.extract_states(tracks, True), *gen.extract_states(paths, True)))
            for k, t in enumerate(stamp):
                if t not in theirs:
                    assert ours.distance[b, k] == 0.0
                    continue
                value = float(theirs[t])
                if p == 1.0:
                    assert ours.distance[b, k] == pytest.approx(value, rel=1e-9, abs=1e-9), (b, k)
                else:
                    # Stone Soup assigns on d_c, not d_c^p: never below the true minimum, equal when the
                    # assignments agree
                    assert ours.distance[b, k] <= value + 1e-9
                    differ += ours.distance[b, k] < value - 1e-9
                compared += 1
    assert compared >= 30
    assert differ <= compared // 4


def test_ospa_of_order_two_minimises_the_squares_where_stonesoup_does_not():
    # |x1 - y1|^2 = 26, |x2 - y2|^2 = 13 (sum of distances 8.71) against |x1 - y2|^2 = 5, |x2 - y1|^2 = 40 (sum of
    # distances 8.56): OSPA of order 2 takes the first, sqrt(39 / 2); an assignment on the distances the second
    x = np.array([[6.0, 5.0], [7.0, 8.0]])
    y = np.array([[1.0, 6.0], [4.0, 6.0]])
    assert float(ospa(x, y, 100.0, 2.0).distance) == pytest.approx(np.sqrt(39 / 2), rel=1e-15)
    _, OSPAMetric, _, _, State, _ = _stonesoup()
    t = datetime(2024, 1, 1)
    value = OSPAMetric(c=100.0, p=2.0).compute_OSPA_distance([State(v.reshape(2, 1), timestamp=t) for v in x],
                                                             [State(v.reshape(2, 1), timestamp=t) for v in y]).value
    assert float(value) == pytest.approx(np.sqrt(45 / 2), rel=1e-12)
