"""The radius gate and the ``Gated`` association role of the core time loop (``workbench.tracking``)."""

import numpy as np
import pytest

from workbench.models import constant_velocity, linear_measurement
from workbench.specs import FilterSpec
from workbench.tracking import Gated, radius_gate, run
from workbench.types import Gaussian, InputError, Scan, Scans


def test_gate_keeps_detections_inside_the_radius_batch_first():
    z = np.zeros((2, 5, 4))
    z[0, :, 0] = [0.0, 900.0, 1100.0, -2400.0, 2600.0]
    z[1, :, 1] = [5000.0, 6000.0, 0.0, 0.0, 0.0]
    valid = np.array([[True] * 5, [True, True, False, False, False]])
    density = np.arange(10.0).reshape(2, 5)
    scan = Scan(z, valid, snr=np.full((2, 5), 6.0), origin=np.array([[0, -1, -1, -1, -1]] * 2),
                clutter_density=density)
    g1, keep1 = radius_gate(scan, np.zeros((2, 3)), 1000.0)
    assert g1.counts.tolist() == [2, 0] and g1.z.shape == (2, 2, 4)
    np.testing.assert_array_equal(g1.z[0, :2, 0], [0.0, 900.0])
    assert keep1.tolist() == [[True, True, False, False, False], [False] * 5]
    np.testing.assert_array_equal(g1.clutter_density[0], [0.0, 1.0])  # travels with its detection
    g25, _ = radius_gate(scan, np.zeros((2, 3)), 2500.0)
    assert g25.counts.tolist() == [4, 0]
    assert g25.origin[0, 0] == 0 and np.all(g25.snr[0, :4] == 6.0)
    np.testing.assert_array_equal(g25.z[0, :4, 0], [0.0, 900.0, 1100.0, -2400.0])  # original order kept
    # a centre away from the origin, distance in the first `dims` components only
    g, keep = radius_gate(scan, np.array([[1000.0, 0.0], [0.0, 5500.0]]), 600.0, dims=2)
    assert keep.tolist() == [[False, True, True, False, False], [True, True, False, False, False]]
    with pytest.raises(InputError, match="gate radius"):
        radius_gate(scan, np.zeros((2, 3)), 0.0)
    with pytest.raises(InputError, match="gate centre"):
        radius_gate(scan, np.zeros((3, 3)), 100.0)


def _recording_filter(seen: list, multi: bool) -> FilterSpec:
    """A Kalman-free filter that keeps its mean as it is and records every scan it is updated with."""

    def init(prior, rng=None):
        return prior

    def predict(state, motion, rng=None):
        return Gaussian(state.mean @ motion.F.T, state.cov)

    def update(state, scan, model, rng=None):
        seen.append(scan)
        return state

    caps = {"multi_measurement"} if multi else set()
    return FilterSpec("recorder", "records its scans", init, predict, update, lambda s: s, frozenset(caps))


def _scans(batch=2, steps=4):
    # item 0 moves along x at 100 m/s; detections at 0, 300 and 2000 m from its predicted position
    times = np.arange(steps, dtype=float)
    z = np.zeros((batch, steps, 3, 2))
    for k in range(steps):
        z[:, k, :, 0] = 100.0 * k + np.array([0.0, 300.0, 2000.0])
    origin = np.broadcast_to(np.array([0, -1, -1]), (batch, steps, 3)).copy()
    return Scans(z, np.ones((batch, steps, 3), bool), times, snr=np.full((batch, steps, 3), 9.0), origin=origin)


def test_gated_role_hands_a_multi_measurement_filter_the_gated_detections_around_the_prediction():
    seen = []
    filt = _recording_filter(seen, multi=True)
    motion = constant_velocity(2, 1.0, 0.0)
    model = linear_measurement(np.hstack([np.eye(2), np.zeros((2, 2))]), np.eye(2))
    prior = Gaussian.broadcast([0.0, 0.0, 100.0, 0.0], np.eye(4), 2)
    track = run(filt, _scans(), motion, model, association=Gated(500.0, dims=2), prior=prior)
    assert len(seen) == 4
    for k, scan in enumerate(seen):
        assert scan.origin is None  # the filter never sees where a detection came from
        assert scan.counts.tolist() == [2, 2]  # 0 and 300 m from F x_{k-1|k-1}; 2000 m is outside
        np.testing.assert_allclose(scan.z[0, :2, 0], 100.0 * k + np.array([0.0, 300.0]))
    np.testing.assert_array_equal(track.records["gated_count"], np.full((2, 4), 2))
    assert track.records["gated"].shape == (2, 4, 3)
    assert track.records["gated"][:, :, 2].sum() == 0
    # the gate centre is the prediction of the last estimate: F x_{k-1|k-1}
    np.testing.assert_allclose(track.predicted_mean[0, :, 0], 100.0 * np.arange(4))


def test_gated_role_sends_other_filters_through_the_pseudo_step():
    seen, calls = [], []
    filt = _recording_filter(seen, multi=False)
    motion = constant_velocity(2, 1.0, 0.0)
    model = linear_measurement(np.hstack([np.eye(2), np.zeros((2, 2))]), np.eye(2))
    prior = Gaussian.broadcast([0.0, 0.0, 100.0, 0.0], np.eye(4), 2)

    def pseudo(gated, predicted, rng):
        calls.append((gated.counts.copy(), predicted.copy()))
        mean = np.where(gated.valid[..., None], gated.z, 0.0).sum(1) / np.maximum(gated.counts, 1)[:, None]
        return Scan.single(mean, gated.counts > 0)

    run(filt, _scans(), motion, model, association=Gated(500.0, pseudo, dims=2), prior=prior)
    assert len(calls) == 4 and all(c.tolist() == [2, 2] for c, _ in calls)
    np.testing.assert_allclose(calls[2][1][:, 0], 200.0)  # the predicted state the step is given
    np.testing.assert_allclose(seen[1].z[:, 0, 0], 100.0 + 150.0)  # the pseudo-measurement reached the filter
    with pytest.raises(InputError, match="pseudo-measurement step"):
        run(filt, _scans(), motion, model, association=Gated(500.0, dims=2), prior=prior)
