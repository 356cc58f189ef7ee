"""The plugin's own tests: the workbench tracker kit, and the track score against plainly written closed forms."""

import math

import numpy as np
import pytest

from track_score_tracker import (hit_score, initial_score, make_tracker, miss_score, run_score_gnn, thresholds)
from workbench.testing import parametrize_with_checks


@parametrize_with_checks([make_tracker()])
def test_tracker_kit(spec, check):
    check(spec)


def test_installed_and_discovered(workbench_host):
    spec = workbench_host.tracker("score-gnn")
    assert spec.params["p_false_confirm"] == 1e-3 and "existence" in spec.capabilities
    assert workbench_host.plugin_of("workbench_trackers", "score-gnn").distribution == "workbench-track-score"


def test_sprt_thresholds_are_walds():
    # alpha = 0.001, beta = 0.01: T_C = ln(0.99 / 0.001) = ln 990, T_D = ln(0.01 / 0.999)
    t_c, t_d = thresholds(0.001, 0.01)
    assert t_c == pytest.approx(6.907755279 - 0.010050336, abs=1e-8)  # ln 1000 - ln(1000 / 990)
    assert t_d == pytest.approx(-4.605170186 + 0.001000500, abs=1e-8)  # ln 0.01 - ln 0.999


def test_score_increments_in_closed_form():
    """ln(P_D N(nu; 0, S) / beta_FA) for a diagonal S written out by hand: with S = diag(4, 9), nu = (2, 3),
    N = exp(-(1 + 1) / 2) / (2 pi sqrt(36)) = e^-1 / (12 pi)."""
    value = hit_score(np.array([2.0, 3.0]), np.diag([4.0, 9.0]), 0.8, 1e-3)
    assert value == pytest.approx(math.log(0.8 * math.exp(-1.0) / (12 * math.pi) / 1e-3), rel=1e-13)
    # a full S: the density from its explicit inverse and determinant
    S = np.array([[2.0, 0.5], [0.5, 1.0]])
    nu = np.array([0.3, -1.1])
    det = 2.0 * 1.0 - 0.25
    inv = np.array([[1.0, -0.5], [-0.5, 2.0]]) / det
    dens = math.exp(-0.5 * nu @ inv @ nu) / (2 * math.pi * math.sqrt(det))
    assert hit_score(nu, S, 0.9, 2e-4) == pytest.approx(math.log(0.9 * dens / 2e-4), rel=1e-13)
    assert miss_score(0.9, 0.99) == pytest.approx(math.log(1 - 0.891), rel=1e-13)
    assert initial_score(0.9, 1e-5, 1e-4) == pytest.approx(math.log(0.09), rel=1e-13)


def _kf():
    from workbench.testing.trackers import kit_filter

    return kit_filter()


def _one_target(hits):
    """A target at rest at (10, 20), detected exactly at the pings where ``hits`` is True (no noise, no clutter)."""
    from workbench.types import Scans

    T = len(hits)
    z = np.tile([10.0, 20.0], (1, T, 1, 1))
    valid = np.array(hits, dtype=bool)[None, :, None]
    return Scans(np.where(valid[..., None], z, 0.0), valid, np.arange(float(T)))


def test_logged_score_follows_the_closed_form_update():
    """The log's existence is 1 / (1 + exp(-L)); L from a hand-run Kalman filter on a target at rest with the
    score's closed-form increments: start, a hit, a miss, a hit."""
    from workbench.models import constant_velocity, linear_measurement

    motion = constant_velocity(2, 1.0, 0.05)
    R = np.diag([1.0, 1.0])
    model = linear_measurement(np.eye(2, 4), R, name="pos", frame="cartesian-2d")
    pd, bfa, bnt, pg, vs = 0.9, 1e-4, 1e-5, 0.999, 5.0
    log = run_score_gnn(_one_target([True, True, False, True]), _kf(), motion, model, p_detection=pd,
                        false_alarm_density=bfa, new_target_density=bnt, gate_probability=pg, velocity_sigma=vs,
                        p_false_confirm=1e-3, p_true_delete=1e-2)
    # the reference: a plain Kalman filter written here
    H = np.eye(2, 4)
    x = np.array([10.0, 20.0, 0.0, 0.0])
    P = np.diag([1.0, 1.0, vs**2, vs**2])
    L = [math.log(pd * bnt / bfa)]
    for hit in (True, False, True):
        x, P = motion.F @ x, motion.F @ P @ motion.F.T + motion.Q
        if hit:
            S = H @ P @ H.T + R
            nu = np.array([10.0, 20.0]) - H @ x
            d2 = nu @ np.linalg.solve(S, nu)
            L.append(L[-1] + math.log(pd / bfa) - math.log(2 * math.pi) - 0.5 * math.log(np.linalg.det(S)) - d2 / 2)
            K = P @ H.T @ np.linalg.inv(S)
            x, P = x + K @ nu, (np.eye(4) - K @ H) @ P
        else:
            L.append(L[-1] + math.log(1 - pd * pg))
    assert log.track_id.tolist() == [0, 0, 0, 0]
    np.testing.assert_allclose(-np.log(1.0 / log.existence - 1.0), L, rtol=1e-9, atol=1e-9)
    t_c, _ = thresholds(1e-3, 1e-2)
    assert log.status.tolist() == [int(v >= t_c) for v in np.maximum.accumulate(L)]


def test_a_lone_false_alarm_is_deleted_by_the_sprt():
    """One detection, then nothing: L_0 = ln 0.09, then ln(1 - 0.8991) per miss; T_D = ln(0.01 / 0.999) = -4.60,
    so the track's score goes -2.41, then -4.70 <= T_D at ping 1, where it is deleted: it is logged at ping 0 only."""
    from workbench.models import constant_velocity, linear_measurement

    model = linear_measurement(np.eye(2, 4), np.eye(2), name="pos", frame="cartesian-2d")
    log = run_score_gnn(_one_target([True, False, False, False]), _kf(), constant_velocity(2, 1.0, 0.05), model)
    assert log.ping.tolist() == [0]


def test_a_confirmed_track_is_deleted_by_its_score_drop():
    """Blackman's deletion of a confirmed track: L - max L <= T_D = ln(0.01 / 0.999) = -4.604.  Each miss scores
    ln(1 - 0.9 * 0.999) = -2.294: after two misses the drop is -4.588 (kept), after three -6.882 (deleted), however
    high the score had climbed over the eight hits before."""
    from workbench.models import constant_velocity, linear_measurement

    model = linear_measurement(np.eye(2, 4), np.eye(2), name="pos", frame="cartesian-2d")
    log = run_score_gnn(_one_target([True] * 8 + [False] * 6), _kf(), constant_velocity(2, 1.0, 0.05), model)
    assert log.ping.tolist() == list(range(10))
    assert log.status[7] == 1 and log.existence[7] > 1.0 - 1e-12  # P_T = 1 / (1 + e^-L): L > 27
