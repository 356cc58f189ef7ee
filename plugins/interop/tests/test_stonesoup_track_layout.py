"""The Stone Soup export of a tracker's log carries each state's covariance (the log's own by default), states the
layout it writes, and offers Stone Soup's [x, vx, y, vy] order: the values against the log with the permutation
written out here, and Stone Soup's own models reading the exported states as the positions and motion they are."""

import numpy as np
import pytest

pytest.importorskip("stonesoup", reason="Stone Soup is not installed: pip install -e '.[stonesoup]'")

from stonesoup.models.measurement.linear import LinearGaussian  # noqa: E402
from stonesoup.models.transition.linear import (CombinedLinearGaussianTransitionModel,  # noqa: E402
                                                ConstantVelocity)
from stonesoup.predictor.kalman import KalmanPredictor  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402

from workbench.models import constant_velocity, coordinated_turn_rate  # noqa: E402
from workbench.tracking import CONFIRMED, TENTATIVE, TrackLog  # noqa: E402
from workbench.types import InputError  # noqa: E402
from workbench_interop.stonesoup_export import seconds, state_order, track_log_tracks  # noqa: E402

TIMES = np.array([0.0, 1.0, 2.5, 3.0])
MOTION = constant_velocity(2, 1.0, 0.3)


def _log(rng, n=4, with_cov=True):
    run = np.array([0, 0, 0, 0, 1, 1, 0])
    ping = np.array([0, 1, 2, 3, 0, 1, 3])
    tid = np.array([5, 5, 5, 5, 2, 2, 9])
    status = np.array([CONFIRMED] * 6 + [TENTATIVE], dtype=np.int8)
    mean = rng.normal(size=(7, n)) * 50
    a = rng.normal(size=(7, n, n))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(n)
    return TrackLog(run, ping, tid, status, np.ones(7, bool), mean, 2, 4, cov if with_cov else None,
                    rng.uniform(0.5, 1.0, 7))


def _vector(state):
    return np.asarray(state.state_vector, dtype=float)[:, 0]


def test_the_log_s_own_covariance_is_exported_in_the_tracker_s_order_with_the_layout_stated():
    log = _log(np.random.default_rng(1))
    tracks = track_log_tracks(log, TIMES, run=0, motion=MOTION)
    assert [t.id for t in tracks] == ["0-5"]  # the tentative track 9 is left out (confirmed_only)
    (track,) = tracks
    assert track.metadata == {"state_layout": ("x", "y", "vx", "vy"), "state_order": "workbench", "run": 0,
                              "track_id": 5}
    assert all(isinstance(s, GaussianState) for s in track.states)
    for s, r in zip(track.states, range(4)):  # rows 0..3 are track 5 at pings 0..3
        assert np.array_equal(_vector(s), log.mean[r]) and np.array_equal(np.asarray(s.covar), log.cov[r])
    assert np.array_equal(seconds([s.timestamp for s in track.states]), TIMES)
    # a covariance given explicitly is used in place of the log's
    other = log.cov * 2.0
    (track,) = track_log_tracks(log, TIMES, run=0, cov=other, motion=MOTION)
    assert np.array_equal(np.asarray(track.states[2].covar), other[2])
    # a log without covariances gives plain states
    (track,) = track_log_tracks(_log(np.random.default_rng(1), with_cov=False), TIMES, run=0)
    assert not any(hasattr(s, "covar") for s in track.states)
    assert track.metadata["state_layout"] == ("s0", "s1", "s2", "s3")


def test_stone_soup_s_order_is_x_vx_y_vy_with_the_covariance_permuted_alike():
    log = _log(np.random.default_rng(2))
    for run, tid, rows in ((0, 5, [0, 1, 2, 3]), (1, 2, [4, 5])):
        (track,) = track_log_tracks(log, TIMES, run=run, motion=MOTION, order="stonesoup")
        assert track.metadata["state_layout"] == ("x", "vx", "y", "vy")
        assert track.metadata["state_order"] == "stonesoup" and track.metadata["track_id"] == tid
        for s, r in zip(track.states, rows):
            x, y, vx, vy = log.mean[r]
            assert np.array_equal(_vector(s), [x, vx, y, vy])
            P = log.cov[r]
            names = {"x": 0, "y": 1, "vx": 2, "vy": 3}
            for i, a in enumerate(("x", "vx", "y", "vy")):
                for j, b in enumerate(("x", "vx", "y", "vy")):
                    assert s.covar[i, j] == P[names[a], names[b]], (a, b)


def test_stone_soup_s_own_models_read_the_exported_state_as_the_tracker_s():
    # Stone Soup's position measurement (mapping (0, 2)) sees the log's (x, y) and its covariance block, and
    # its constant-velocity predictor moves the exported state as our motion model moves the log's
    log = _log(np.random.default_rng(3))
    (track,) = track_log_tracks(log, TIMES, run=0, motion=MOTION, order="stonesoup")
    measure = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.zeros((2, 2)))
    H = measure.matrix()
    for s, r in zip(track.states, range(4)):
        np.testing.assert_array_equal(H @ _vector(s), log.mean[r, :2])
        np.testing.assert_array_equal(H @ np.asarray(s.covar) @ H.T, log.cov[r, :2, :2])
    q = 0.3
    ss_motion = CombinedLinearGaussianTransitionModel([ConstantVelocity(q ** 2)] * 2)
    state = track.states[0]
    ahead = KalmanPredictor(ss_motion).predict(state, timestamp=state.timestamp + (track.states[1].timestamp
                                                                                      - state.timestamp))
    F = np.asarray(MOTION.F)
    mine = F @ log.mean[0]
    np.testing.assert_allclose(_vector(ahead), [mine[0], mine[2], mine[1], mine[3]], rtol=1e-12, atol=1e-9)


def test_other_layouts_and_refusals():
    cv3 = constant_velocity(3, 1.0, 1.0)
    assert state_order(cv3.state_names, "stonesoup") == [0, 3, 1, 4, 2, 5]  # x vx y vy z vz
    ctr = coordinated_turn_rate(1.0, 1.0, 0.1)
    assert tuple(ctr.state_names) == ("x", "y", "vx", "vy", "omega")
    assert state_order(ctr.state_names, "stonesoup") == [0, 2, 1, 3, 4]  # Stone Soup's [x, vx, y, vy, omega]
    assert state_order(("x", "y", "vx", "vy"), "workbench") == [0, 1, 2, 3]
    log = _log(np.random.default_rng(4))
    with pytest.raises(InputError, match=r"order='stonesoup' needs a state layout with positions and their "
                                         r"velocities .* got s0, s1, s2, s3"):
        track_log_tracks(log, TIMES, order="stonesoup")
    with pytest.raises(InputError, match=r"order must be one of workbench, stonesoup, got 'ss'"):
        track_log_tracks(log, TIMES, motion=MOTION, order="ss")
    with pytest.raises(InputError, match=r"got R, Rdot"):
        state_order(("R", "Rdot"), "stonesoup")
