"""Multi-target track metrics (``workbench.metrics.tracks``) on hand-made track tables with hand-worked answers."""

import numpy as np
import pytest

from workbench.metrics import (continuity, false_track_sums, mean_std, pooled_rmse, removal_rate_pooled,
                               removal_rate_pooled_per_ping, removal_ratio, track_counts, track_truth_match)
from workbench.tracking.multi import CONFIRMED, TENTATIVE, TrackLog
from workbench.types import InputError


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
    with pytest.raises(InputError, match="truth positions"):
        track_counts(log, np.zeros((2, 3, 2)))


def _brute_force_rate(before, after, pings):
    """1 - (false tracks after) / (false tracks before), each count added one (run, ping) at a time."""
    total_before = total_after = 0
    for b in range(len(before)):
        for k in range(len(before[b])):
            if pings[k]:
                total_before += int(before[b][k])
                total_after += int(after[b][k])
    return 1.0 - total_after / total_before if total_before else float("nan")


def test_removal_rate_is_the_ratio_of_sums_over_runs_and_pings():
    # run 2 has false tracks after removal at ping 1 but none before there, run 0 at ping 0: both must count
    before = np.array([[0, 4, 4, 2], [0, 0, 5, 10], [1, 0, 0, 0]])
    after = np.array([[1, 1, 2, 2], [0, 1, 0, 5], [0, 2, 0, 0]])
    # hand-worked: 26 false tracks before, 14 after; on pings 2-3: 21 before, 9 after
    assert np.isclose(removal_rate_pooled(before, after), 1 - 14 / 26)
    assert np.isclose(removal_rate_pooled(before, after, pings=[False, False, True, True]), 1 - 9 / 21)
    # per ping, summed over the runs: ping 0 1 -> 1, ping 1 4 -> 4, ping 2 9 -> 2, ping 3 12 -> 7
    assert np.allclose(removal_rate_pooled_per_ping(before, after), [0.0, 0.0, 7 / 9, 5 / 12])
    assert np.allclose(removal_rate_pooled_per_ping(before, after, pings=[True, False, True, True]),
                       [0.0, np.nan, 7 / 9, 5 / 12], equal_nan=True)
    sb, sa = false_track_sums(before, after, pings=[False, True, True, True])
    assert np.array_equal(sb, [10, 15, 0]) and np.array_equal(sa, [5, 6, 2])
    assert np.isclose(removal_ratio(sb, sa), 1 - 13 / 25)
    # no false track before removal: no rate, even with some after
    assert np.isnan(removal_rate_pooled(np.zeros((2, 3)), np.ones((2, 3))))
    assert np.isnan(removal_rate_pooled_per_ping(np.zeros((2, 3)), np.ones((2, 3)))).all()
    with pytest.raises(InputError, match="removal rate"):
        removal_rate_pooled(before, after[:, :3])
    with pytest.raises(InputError, match="pings must be a mask of 4"):
        removal_rate_pooled(before, after, pings=[True, False])


def test_removal_rate_against_a_brute_force_count_on_sparse_counts():
    # sparse counts like the paper rows' (mostly 0, sometimes 1-3), after removal often where before is 0
    rng = np.random.default_rng(7)
    for trial in range(20):
        before = rng.poisson(0.3, size=(12, 20))
        after = rng.poisson(0.15, size=(12, 20))
        pings = np.arange(20) >= 5
        assert np.sum(after[:, pings][before[:, pings] == 0]) > 0  # the pings the old estimator dropped
        want = _brute_force_rate(before.tolist(), after.tolist(), pings.tolist())
        assert np.isclose(removal_rate_pooled(before, after, pings), want)
        assert np.isclose(removal_ratio(*false_track_sums(before, after, pings)), want)
        for k in range(20):
            one = np.arange(20) == k
            assert np.isclose(removal_rate_pooled_per_ping(before, after)[k],
                              _brute_force_rate(before.tolist(), after.tolist(), one.tolist()), equal_nan=True)


def test_mean_std_of_finite_values():
    m, s, n = mean_std(np.array([0.5, np.nan, 1.0, 0.0]))
    assert n == 3 and np.isclose(m, 0.5) and np.isclose(s, np.std([0.5, 1.0, 0.0], ddof=1))
    assert mean_std(np.array([np.nan])) == (pytest.approx(np.nan, nan_ok=True), pytest.approx(np.nan, nan_ok=True), 0)


def test_continuity_counts_from_the_first_held_ping_to_the_end():
    held = np.array([[0, 1, 0, 1, 1], [0, 0, 0, 0, 0], [1, 1, 1, 1, 0]], bool)
    assert np.allclose(continuity(held), [3 / 4, 0.0, 4 / 5])
