"""Paper 001: sonar sensor and clutter, the multi-target tracker, track metrics, recorded CSV data and the
report recipe's content."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from workbench.models import constant_velocity, linear_measurement, range_bearing
from workbench.plugins import load_host
from workbench.recorded.sonar import load_sonar_csv, write_sonar_csv
from workbench.rng import generator
from workbench.specs import RecipeOptions, TaskContext
from workbench.metrics import (continuity, mean_std, pooled_rmse, removal_rate, removal_rate_per_ping,
                                     track_counts, track_truth_match)
from workbench.tracking.multi import (CONFIRMED, TENTATIVE, TrackerConfig, TrackLog, box_pairs, gated_pairs, greedy_assign,
                               join_items, mofn_step, position_covariance, rectangular_pairs, run_tracker,
                               take_items, two_point_prior)
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import CLUTTER, Gaussian, InputError, Scans, Truth

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)


def _truth(runs, steps=20):
    one = piecewise_trajectory((100.0, 100.0), (4.0, 2.0), [Leg("straight", steps - 1.0)], 1.0)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


# -- sensor and clutter -----------------------------------------------------------------------------


def test_active_sonar_statistics_and_models():
    sensor = HOST.sensor("active-sonar")
    truth = _truth(400)
    scans = sensor.simulate(truth, generator(1, "sonar"), **sensor.params)
    assert scans.z.shape == (400, 20, 1, 2) and np.all(scans.origin == 0)
    assert abs(scans.valid.mean() - 0.8) < 0.01
    err = (scans.z[..., 0, :] - truth.states[..., :2])[scans.valid[..., 0]]
    assert np.allclose(err.std(axis=0), 2.0, rtol=0.03) and np.allclose(err.mean(axis=0), 0.0, atol=0.05)
    assert abs(scans.snr.mean() - 20.0) < 0.01 and abs(scans.snr.std() - 0.1) < 0.005
    polar = sensor.measurement_model(frame="polar")
    # math convention: bearing counter-clockwise from +x
    assert np.allclose(polar.h(np.array([[0.0, 50.0, 0.0, 0.0]])), [[50.0, np.pi / 2]])
    assert np.allclose(polar.R, np.diag([0.25, np.deg2rad(1.0) ** 2]))
    assert polar.std[0] == 0.5 and np.isclose(polar.std[1], np.deg2rad(1.0)) and polar.frame == "range-bearing"
    cart = sensor.measurement_model(**sensor.params)
    assert np.allclose(cart.R, 4.0 * np.eye(2)) and np.allclose(cart.H, np.eye(2, 4))
    with pytest.raises(InputError, match="frame"):
        sensor.measurement_model(frame="spherical")


def test_sonar_clutter_rate_area_and_levels():
    gen = HOST.clutter_generator("sonar-poisson")
    truth = _truth(200)
    c = gen.generate(truth, generator(2, "clutter"), **gen.params)
    counts = c.valid.sum(axis=2)
    assert abs(counts.mean() - 31.25) < 0.3 and abs(counts.var() - 31.25) < 2.0  # Poisson(5e-4 x 62 500)
    xy = c.z[c.valid]
    assert xy.min() >= 0.0 and xy.max() <= 250.0 and np.all(c.origin == CLUTTER)
    power = 10.0 ** (c.snr[c.valid] / 10.0)
    assert abs(power.mean() - 10.0) < 0.15  # Rayleigh amplitude, mean power 10 dB
    sur = gen.generate(truth, generator(3, "clutter"), rate_scale=2.0, persistent_sites=5, persistent_pd=0.7)
    assert abs(sur.valid.sum(axis=2).mean() - (62.5 + 3.5)) < 0.6
    sites = sur.z[:, :, -5:][sur.valid[:, :, -5:]]
    assert sites.shape[0] > 0
    with pytest.raises(InputError, match="area"):
        gen.generate(truth, generator(0), area=(0, 0, 0, 1))


# -- tracker pieces ---------------------------------------------------------------------------------


def _machine(hits, start_hist=0b11, start_age=2, cfg=TrackerConfig()):
    """Run the M-of-N machine over a hit sequence for one new track; returns statuses and deletion ping."""
    h, m, a, s = np.array([start_hist]), np.array([0]), np.array([start_age]), np.array([TENTATIVE], np.int8)
    states = []
    for i, hit in enumerate(hits):
        h, m, a, s, d = mofn_step(h, m, a, s, np.array([hit]), cfg)
        states.append(int(s[0]))
        if d[0]:
            return states, i
    return states, None


def test_mofn_state_machine_cases():
    assert _machine([1]) == ([CONFIRMED], None)  # hits at birth, birth-1 and now: 3 of 5
    assert _machine([0, 1]) == ([TENTATIVE, CONFIRMED], None)  # 1,1,0,1: three hits in four pings
    assert _machine([0, 0, 1]) == ([TENTATIVE, TENTATIVE, CONFIRMED], None)  # 3 of 5 exactly
    assert _machine([0, 0, 0]) == ([TENTATIVE] * 3, 2)  # three misses: deleted (also fails 3-of-5)
    # a tentative track with two hits that cannot reach three of its first five
    cfg = TrackerConfig(confirm_hits=4, confirm_window=5, delete_misses=5)
    assert _machine([0, 1, 0], cfg=cfg)[1] == 2
    assert _machine([0], start_hist=0b1, start_age=1, cfg=TrackerConfig(confirm_hits=3, delete_misses=9))[1] is None
    # confirmed: two misses then a hit survives; three consecutive misses delete
    assert _machine([1, 0, 0, 1, 0, 0, 0]) == ([CONFIRMED] * 7, 6)
    assert _machine([1, 0, 0, 1, 1, 0, 1])[1] is None


def test_greedy_assign_equals_sequential_greedy():
    rng = generator(4, "greedy")
    for _ in range(30):
        n = rng.integers(1, 40)
        rows, cols = rng.integers(0, 8, n), rng.integers(0, 8, n)
        pairs = np.unique(np.stack([rows, cols], 1), axis=0)
        cost = rng.random(len(pairs)).round(1)  # ties on purpose
        got = set(zip(*greedy_assign(pairs[:, 0], pairs[:, 1], cost)))
        ref, used_r, used_c = set(), set(), set()
        for i in np.lexsort((pairs[:, 1], pairs[:, 0], cost)):
            r, c = pairs[i]
            if r not in used_r and c not in used_c:
                ref.add((r, c))
                used_r.add(r)
                used_c.add(c)
        assert {(int(a), int(b)) for a, b in got} == {(int(a), int(b)) for a, b in ref}


def test_gate_dense_and_grid_paths_agree():
    rng = generator(5, "gate")
    K = 30
    mean = np.column_stack([rng.uniform(20, 230, (K, 2)), rng.normal(0, 3, (K, 2))])
    cov = np.repeat(np.diag([9.0, 9.0, 4.0, 4.0])[None], K, 0)
    est = Gaussian(mean, cov)
    pos = rng.uniform(0, 250, (400, 2))
    for model in (range_bearing(0.5, np.deg2rad(1.0)), linear_measurement(np.eye(2, 4), 4 * np.eye(2))):
        zm = model.h(np.column_stack([pos, np.zeros((400, 2))]))
        for cfg in (TrackerConfig(), TrackerConfig(gate=25.0, gate_sigma=2.0)):
            dense = gated_pairs(est, pos, zm, model, cfg)
            grid = gated_pairs(est, pos, zm, model, dataclasses.replace(cfg, dense_limit=0))
            a = sorted(zip(dense[0], dense[1], dense[2].round(10)))
            b = sorted(zip(grid[0], grid[1], grid[2].round(10)))
            assert a == b and len(a) > 0
    i, j, d = rectangular_pairs(pos[:50], pos[50:], 8.0)
    i2, j2, _ = rectangular_pairs(pos[:50], pos[50:], 8.0, dense_limit=0)
    assert sorted(zip(i, j)) == sorted(zip(i2, j2))
    assert np.all(np.max(np.abs(pos[:50][i] - pos[50:][j]), axis=1) <= 8.0)


def test_box_pairs_equal_brute_force():
    rng = generator(7, "box")
    for trial in range(20):
        na, nb = rng.integers(0, 300), rng.integers(0, 300)
        a, b = rng.uniform(-50, 400, (na, 2)), rng.uniform(-50, 400, (nb, 2))
        half = rng.uniform(0.5, 40.0, (na, 2)) if trial % 2 else float(rng.uniform(1, 20))
        i, j = box_pairs(a, b, half, cell=None if trial % 3 else float(rng.uniform(0.3, 60)))
        h = np.broadcast_to(np.asarray(half, float), (na, 2)) if np.ndim(half) == 0 else half
        ref = np.nonzero(np.all(np.abs(a[:, None] - b[None]) <= h[:, None], axis=-1))
        assert sorted(zip(i.tolist(), j.tolist())) == sorted(zip(ref[0].tolist(), ref[1].tolist()))


def test_gate_sigma_uses_the_stated_position_accuracy():
    # linear position model: gating with gate_sigma = s is gating with R = s^2 I
    est = Gaussian(np.array([[0.0, 0.0, 1.0, 0.0]]), np.diag([1.0, 1.0, 1.0, 1.0])[None])
    pos = np.array([[3.0, 0.0], [0.0, 4.5], [6.0, 0.0]])
    small = linear_measurement(np.eye(2, 4), 0.25 * np.eye(2))
    big = linear_measurement(np.eye(2, 4), 4.0 * np.eye(2))
    _, _, d_small = gated_pairs(est, pos, pos, small, TrackerConfig(gate=1e9, gate_sigma=2.0))
    _, _, d_big = gated_pairs(est, pos, pos, big, TrackerConfig(gate=1e9))
    assert np.allclose(d_small, d_big)
    # P = I, R_g = 4 I: S = 5 I;  d2 = |z - H x-|^2 / 5
    assert np.allclose(d_small, np.sum((pos - [0.0, 0.0]) ** 2, axis=1) / 5.0)
    with pytest.raises(InputError, match="gate_sigma"):
        TrackerConfig(gate_sigma=0.0)


def test_two_point_prior():
    p0, p1 = np.array([[0.0, 0.0]]), np.array([[3.0, 0.0]])
    g = two_point_prior(p0, p1, 1.0, 4.0 * np.eye(2)[None], sigma_v=1.0, sigma_c=0.5)
    assert np.allclose(g.mean, [[3.0, 0.0, 3.0, 0.0]])
    # course 0: along-track variance sigma_v^2, cross-track v^2 sigma_c^2
    assert np.allclose(g.cov[0], np.diag([4.0, 4.0, 1.0, 9.0 * 0.25]))
    g = two_point_prior(p0, np.array([[0.0, 2.0]]), 1.0, np.eye(2)[None], 1.0, 1.0)
    assert np.allclose(g.cov[0, 2:, 2:], np.diag([4.0, 1.0]))
    model = linear_measurement(np.eye(2, 4), 4 * np.eye(2))
    assert np.allclose(position_covariance(model, np.ones((3, 2)), 4), 4 * np.eye(2))


def test_take_and_join_filter_states():
    from dataclasses import dataclass

    from workbench.types import Particles

    @dataclass(frozen=True)
    class State:
        cloud: Particles
        count: int = 7

    rng = generator(6, "tree")
    a = State(Particles(rng.normal(size=(3, 5, 4)), np.full((3, 5), -np.log(5))))
    b = State(Particles(rng.normal(size=(2, 5, 4)), np.full((2, 5), -np.log(5))), count=1)
    j = join_items(a, b, 3, 2)
    assert j.cloud.particles.shape == (5, 5, 4) and j.count == 7
    t = take_items(j, np.array([4, 0]), 5)
    assert np.array_equal(t.cloud.particles, np.stack([b.cloud.particles[1], a.cloud.particles[0]]))
    g = Gaussian(np.arange(8.0).reshape(2, 4), np.repeat(np.eye(4)[None], 2, 0))
    assert np.array_equal(take_items(g, np.array([1]), 2).mean, g.mean[1:])


def _two_targets(runs=3, clutter=0, seed=7):
    rng = generator(seed, "two")
    k = np.arange(15.0)[:, None]
    t1 = np.array([40.0, 40.0]) + k * [4.0, 2.0]
    t2 = np.array([200.0, 60.0]) + k * [-1.0, 4.0]
    z = np.stack([t1, t2], axis=1)[None] + 1.0 * rng.standard_normal((runs, 15, 2, 2))
    if clutter:
        z = np.concatenate([z, rng.uniform(0, 250, (runs, 15, clutter, 2))], axis=2)
    origin = np.concatenate([np.zeros((runs, 15, 1)), np.ones((runs, 15, 1)),
                             np.full((runs, 15, clutter), CLUTTER)], axis=2).astype(int)
    return Scans(z, np.ones(z.shape[:3], bool), np.arange(15.0), origin=origin), np.stack([t1, t2])


@pytest.mark.parametrize("name, frame", [("kf", "cartesian"), ("cmkf-l", "polar"), ("ekf", "polar")])
def test_tracker_follows_two_targets_with_any_filter(name, frame):
    scans, truth = _two_targets()
    sensor = HOST.sensor("active-sonar")
    model = sensor.measurement_model(frame=frame, sigma_xy=1.0, sigma_r=1.0, sigma_b_deg=0.5)
    log = run_tracker(scans, HOST.filter(name), MOTION, model, TrackerConfig(), seed=1)
    counts = log.confirmed_counts()
    assert np.all(counts[:, 2:] == 2) and np.all(counts[:, :2] == 0)  # confirmed at the third ping
    for target in (0, 1):
        c = (log.status == CONFIRMED)
        d = np.linalg.norm(log.mean[c, :2] - truth[target][log.ping[c]], axis=1)
        pairs = np.unique(np.stack([log.run[c][d < 4.0], log.track_id[c][d < 4.0]]), axis=1)
        assert pairs.shape[1] == log.runs and set(pairs[0]) == set(range(log.runs))  # one track per run


def test_tracker_never_reads_origin_and_is_reproducible():
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


# -- metrics ----------------------------------------------------------------------------------------


def _hand_log():
    """Two runs, four pings; truth at (0, 0) in every ping.

    run 0: track 0 true (confirmed pings 1-3, always near), track 1 false (confirmed pings 2-3, far),
           track 2 tentative only (never counted)
    run 1: track 5 near at pings 1 and 2 but far at 3 (2/3 < 80 %: false); track 6 near all (true)
    """
    rows = [  # run, ping, id, status, x
        (0, 0, 0, TENTATIVE, 0.5), (0, 1, 0, CONFIRMED, 1.0), (0, 2, 0, CONFIRMED, 2.0), (0, 3, 0, CONFIRMED, 1.0),
        (0, 2, 1, CONFIRMED, 50.0), (0, 3, 1, CONFIRMED, 60.0), (0, 3, 2, TENTATIVE, 1.0),
        (1, 1, 5, CONFIRMED, 1.0), (1, 2, 5, CONFIRMED, 2.0), (1, 3, 5, CONFIRMED, 30.0),
        (1, 2, 6, CONFIRMED, 3.0), (1, 3, 6, CONFIRMED, 4.0),
    ]
    r = np.array(rows, dtype=float)
    mean = np.column_stack([r[:, 4], np.zeros((len(r), 3))])
    return TrackLog(r[:, 0].astype(int), r[:, 1].astype(int), r[:, 2].astype(int), r[:, 3].astype(np.int8),
                    np.ones(len(r), bool), mean, 2, 4)


def test_track_counts_on_a_hand_made_table():
    log = _hand_log()
    truth = np.zeros((2, 4, 2))
    runs, ids, frac, is_true = track_truth_match(log, truth)
    got = {(int(r), int(i)): (round(float(f), 3), bool(t)) for r, i, f, t in zip(runs, ids, frac, is_true)}
    assert got == {(0, 0): (1.0, True), (0, 1): (0.0, False), (1, 5): (0.667, False), (1, 6): (1.0, True)}
    c = track_counts(log, truth)
    assert np.array_equal(c.confirmed, [[0, 1, 2, 2], [0, 1, 2, 2]])
    assert np.array_equal(c.false, [[0, 0, 1, 1], [0, 1, 1, 1]])
    assert np.array_equal(c.held, [[False, True, True, True], [False, False, True, True]])
    assert np.allclose(c.sq_error[0, 1:], [1.0, 4.0, 1.0]) and np.allclose(c.sq_error[1, 2:], [9.0, 16.0])
    assert np.allclose(continuity(c.held), [1.0, 1.0])
    assert np.isclose(pooled_rmse(c.sq_error), np.sqrt(np.mean([1, 4, 1, 9, 16])))


def test_removal_rate_definition():
    before = np.array([[0, 4, 4, 2], [0, 0, 5, 10]])
    after = np.array([[1, 1, 2, 2], [0, 1, 0, 5]])
    # run 0: pings 1-3 count: r = 0.75, 0.5, 0.0 -> 0.41667; run 1: pings 2-3: 1.0, 0.5 -> 0.75
    assert np.allclose(removal_rate(before, after), [1.25 / 3, 0.75])
    assert np.allclose(removal_rate(before, after, pings=[False, False, True, True]), [0.25, 0.75])
    assert np.allclose(removal_rate_per_ping(before, after), [np.nan, 0.75, 0.75, 0.25], equal_nan=True)
    assert np.isnan(removal_rate(np.zeros((1, 3)), np.ones((1, 3)))[0])
    m, s, n = mean_std(removal_rate(before, after))
    assert n == 2 and np.isclose(m, (1.25 / 3 + 0.75) / 2) and np.isclose(s, np.std([1.25 / 3, 0.75], ddof=1))
    assert np.allclose(continuity(np.array([[0, 1, 0, 1, 1], [0, 0, 0, 0, 0]], bool)), [0.75, 0.0])


# -- recorded detections ----------------------------------------------------------------------------


def test_csv_round_trip_and_polar_columns(tmp_path):
    rng = generator(8, "csv")
    z = rng.uniform(0, 250, (1, 4, 3, 2)).round(3)
    valid = np.array([[[1, 1, 0], [0, 0, 0], [1, 1, 1], [1, 0, 0]]], bool)
    snr = rng.normal(10, 2, (1, 4, 3)).round(3)
    scans = Scans(z, valid, np.arange(4.0), snr=snr)
    back = load_sonar_csv(write_sonar_csv(tmp_path / "a.csv", scans, comments=["hello"]))
    assert back.steps == 4
    assert np.array_equal(back.valid.sum(axis=2), valid.sum(axis=2))
    assert np.allclose(np.sort(back.z[back.valid], axis=0), np.sort(z[valid], axis=0))
    assert np.allclose(np.sort(back.snr[back.valid]), np.sort(snr[valid]))
    polar = load_sonar_csv(write_sonar_csv(tmp_path / "p.csv", scans, frame="polar", digits=9))
    assert np.allclose(np.sort(polar.z[polar.valid], axis=0), np.sort(z[valid], axis=0), atol=1e-6)
    f = tmp_path / "t.csv"
    f.write_text("time,range,bearing\n0.5,10,90\n0.5,20,0\n2.0,5,180\n")
    t = load_sonar_csv(f)
    assert np.allclose(t.times, [0.5, 2.0]) and np.allclose(t.z[0, 0][t.valid[0, 0]], [[0, 10], [20, 0]], atol=1e-12)
    assert np.allclose(t.z[0, 1, 0], [-5, 0], atol=1e-12) and np.all(np.isnan(t.snr[t.valid]))


@pytest.mark.parametrize("text, match", [
    ("ping,x,y,level\n0,1,2,3\n1,4,abc,3\n", "line 3, column 'y'"),
    ("# c\nping,x,y\n0,1,2\n-1,1,2\n", "line 4, column 'ping'"),
    ("ping,x,y\n0.5,1,2\n", "line 2, column 'ping'"),
    ("ping,x,y\n0,1\n", "line 2: expected 3 fields"),
    ("ping,x,y\n0,nan,2\n", "line 2, column 'x'"),
    ("ping,range,bearing\n0,-3,10\n", "line 2, column 'range'"),
    ("ping,x,z\n0,1,2\n", "line 1: unknown column 'z'"),
    ("ping,x\n0,1\n", "line 1: the header needs both"),
    ("ping,time,x,y\n0,0,1,2\n", "exactly one of 'ping' or 'time'"),
    ("# only comments\n", "no header"),
])
def test_csv_errors_name_the_line_and_column(tmp_path, text, match):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        load_sonar_csv(f)
    assert str(f) in str(info.value)


def test_shipped_surrogate_is_labelled_and_reproducible(tmp_path):
    from workbench_papers.paper001 import recipe as paper001

    text = paper001.SURROGATE_FILE.read_text()
    assert text.splitlines()[0].startswith("# SYNTHETIC SURROGATE")
    scans = load_sonar_csv(paper001.SURROGATE_FILE, pings=20)
    assert scans.steps == 20 and 55 < scans.valid.sum(axis=2).mean() < 80 and scans.origin is None
    again = paper001.write_surrogate(tmp_path / "s.csv", host=HOST)
    assert again.read_text() == text
    doc = (Path(__file__).parents[4] / "docs" / "recorded-data.md").read_text()
    assert "## Active sonar detections" in doc and "SYNTHETIC SURROGATE" in doc


# -- the report recipe ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def report():
    recipe = HOST.recipe("001")
    options = RecipeOptions(size="quick", values=recipe.sizes["quick"], seed=1, filters=recipe.default_filters)
    results = {t.key: {k: np.asarray(v) for k, v in t.run(TaskContext(params=t.params, seed=1, host=HOST)).items()}
               for t in recipe.tasks(options)}
    return recipe, results


def test_report_figures_hold_the_data(report):
    recipe, results = report
    figs = {f.id: f.data(results) for f in recipe.figures}
    assert set(figs) == {f"fig{i}" for i in range(3, 13)}
    # Figs 3-4: the recovered line is the true line (4, 2)-direction through (100, 100)
    rho, theta = figs["fig3"]["line"]
    rho0, theta0 = figs["fig3"]["true_line"]
    assert abs(rho - rho0) <= 4 and abs(np.rad2deg(theta - theta0)) <= 4
    f4 = figs["fig4"]
    assert f4["sinusoids"].shape == (f4["point_target"].size, f4["theta_deg"].size)
    tgt = f4["sinusoids"][f4["point_target"].astype(bool)]
    col = np.argmin(np.abs(np.deg2rad(f4["theta_deg"]) - theta))
    assert np.ptp(tgt[:, col]) < 6.0  # the target sinusoids meet near the peak
    # Figs 5-6: detections and confirmed tracks of run 0; after removal fewer detections are kept
    assert figs["fig5"]["det_kept"].all() and figs["fig6"]["det_kept"].sum() < 0.5 * figs["fig6"]["det_kept"].size
    assert figs["fig6"]["trk_xy"].shape[1] == 2 and figs["fig5"]["trk_true"].dtype == bool
    # The surrogate figures: every detection of the file before removal, fewer after.
    assert figs["fig7"]["det_kept"].all() and 0 < figs["fig8"]["det_kept"].sum() < figs["fig8"]["det_kept"].size
    np.testing.assert_array_equal(figs["fig7"]["det_xy"], figs["fig8"]["det_xy"])
    # Figs 9-10: counts per ping; no confirmed track during the warm-up after removal
    for fid in ("fig9", "fig10", "fig11", "fig12"):
        assert figs[fid]["ping"].tolist() == list(range(1, 21))
    assert np.all(figs["fig10"]["mean"][:5] == 0) and figs["fig9"]["mean"][5:].mean() > 3
    assert figs["fig10"]["mean"][5:].mean() < figs["fig9"]["mean"][5:].mean()
    assert int(figs["fig11"]["runs"]) == 1  # the surrogate file is one run


def test_report_tables_criteria_and_notes(report):
    recipe, results = report
    tables = {t.id: t.make(results) for t in recipe.tables}
    removal = tables["removal-rate"]
    assert [r[2] for r in removal.rows] == ["78 %", "84 %", "84 %"]
    assert "SYNTHETIC" in removal.rows[1][0] and "SYNTHETIC" in removal.rows[2][0]
    assert len(tables["removal-per-ping"].rows) == 21
    assert len(tables["dtheta-sweep"].rows) == 3 and len(tables["matched-r"].rows) == 2
    # criteria recomputed independently from the raw counts
    b, a = results["sim/cmkf-l/before"], results["sim/cmkf-l/after/main"]
    post = np.arange(20) >= 5
    rate = np.nanmean(removal_rate(b["false"], a["false"], post))
    crit = {c.id: c for c in recipe.criteria(results)}
    assert set(crit) == {"1", "2", "3"}
    assert crit["1"].met == bool(0.6 <= rate <= 0.95) and f"{100 * rate:.1f} %" in crit["1"].detail
    assert crit["2"].met == bool(np.mean(continuity(a["held"]) >= 0.8) >= 0.9)
    both = b["held"] & a["held"]
    assert crit["3"].met == bool(pooled_rmse(np.where(both, a["sq_error"], np.nan))
                                 <= pooled_rmse(np.where(both, b["sq_error"], np.nan)))
    assert "warm-up" in recipe.notes.lower() and "surrogate" in recipe.notes.lower()
    assert recipe.published["removal_rate_simulation"] == 0.78 and recipe.published["removal_rate_sea_trial"] == 0.84
    assert str(results["sim/cmkf-l/before"]["model_used"][0]).startswith("polar")
    assert str(results["matched/after"]["model_used"][0]).startswith("cartesian")
