"""Multi-target track metrics (``workbench.metrics.tracks``) on hand-made track tables with hand-worked answers."""

import numpy as np
import pytest

from workbench.metrics import (continuity, mean_std, pooled_rmse, removal_rate, removal_rate_per_ping, track_counts,
                               track_truth_match)
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


def test_continuity_counts_from_the_first_held_ping_to_the_end():
    held = np.array([[0, 1, 0, 1, 1], [0, 0, 0, 0, 0], [1, 1, 1, 1, 0]], bool)
    assert np.allclose(continuity(held), [3 / 4, 0.0, 4 / 5])
