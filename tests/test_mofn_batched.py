"""The M-of-N tracker's batched path (every run's tracks as one filter batch, gating, assignment and initiation
pairs within each run) against its per-run path (:func:`workbench.tracking.mofn.tracker_step`, one run at a
time): the same log, bit for bit, under every option the batched path takes; and which roles and filters take it."""

import numpy as np
import pytest

from workbench.models import constant_velocity
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.tracking.gnn import GNN
from workbench.tracking.loop import run
from workbench.tracking.mofn import MofN
from workbench.tracking.records import TrackerConfig
from workbench.types import Scan, Scans

HOST = load_host()
MOTION = constant_velocity(2, 1.0, 0.1)


class _PerRun(MofN):
    """The M-of-N role held to its per-run path."""

    def batched(self, filt, first) -> bool:
        return False


def _scene(runs=7, steps=12, seed=3):
    """Two crossing targets per run (missed at random) in uniform clutter of a different count per run (one run
    without any detection at some pings), padded to a common width."""
    rng = generator(seed, "mofn-batched")
    k = np.arange(float(steps))[:, None]
    targets = np.stack([np.array([40.0, 40.0]) + k * [4.0, 2.0], np.array([120.0, 60.0]) + k * [-1.0, 4.0]], axis=1)
    width = 2 + 30
    z = np.zeros((runs, steps, width, 2))
    valid = np.zeros((runs, steps, width), dtype=bool)
    for b in range(runs):
        n_clutter = 4 * b  # run 0: targets only
        z[b, :, :2] = targets + rng.standard_normal((steps, 2, 2))
        valid[b, :, :2] = rng.random((steps, 2)) < 0.85
        z[b, :, 2:2 + n_clutter] = rng.uniform(0.0, 200.0, (steps, n_clutter, 2))
        valid[b, :, 2:2 + n_clutter] = True
    valid[3, 5] = False  # a ping without detections
    return Scans(z, valid, np.arange(float(steps)))


def _log_arrays(log):
    out = {"run": log.run, "ping": log.ping, "track_id": log.track_id, "status": log.status, "hit": log.hit,
           "mean": log.mean}
    if log.cov is not None:
        out["cov"] = log.cov
    return out


def _both(scans, filt, model, cfg, keep_cov=False):
    logs = []
    for role in (MofN(cfg, 5, ("t",), keep_cov), _PerRun(cfg, 5, ("t",), keep_cov)):
        logs.append(run(filt, scans, MOTION, model, association=role, rng=generator(5, "t", "run")))
    return logs


@pytest.mark.parametrize("name, frame, extra", [
    ("kf", "cartesian", {}),
    ("cmkf-l", "polar", {}),
    ("cmkf-l", "polar", {"detection_sigma": 1.5, "min_speed": 1.0}),
    ("ekf", "polar", {"prior": "speed-course", "initiation_hits": 2}),
    ("kf", "cartesian", {"gate_sigma": 2.0, "confirm_hits": 2, "confirm_window": 4, "dense_limit": 40}),
])
def test_batched_path_equals_the_per_run_path_bit_for_bit(name, frame, extra):
    scans = _scene()
    model = HOST.sensor("active-sonar").measurement_model(frame=frame, sigma_xy=1.0, sigma_r=1.0, sigma_b_deg=0.5)
    filt = HOST.filter(name)
    cfg = TrackerConfig(**extra)
    assert MofN(cfg).batched(filt, scans.scan(0).for_filter())
    batched, per_run = _both(scans, filt, model, cfg, keep_cov=True)
    a, b = _log_arrays(batched), _log_arrays(per_run)
    assert a.keys() == b.keys() and a["run"].size > 50 and np.any(a["status"] == 1)  # tracks confirmed
    assert set(np.unique(a["run"])) == set(range(scans.batch))
    for key in a:
        assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), key


class _GNNPerRun(GNN):
    """The GNN role held to its per-run path."""

    def batched(self, filt, first) -> bool:
        return False


@pytest.mark.parametrize("name, frame", [("kf", "cartesian"), ("cmkf-l", "polar")])
def test_gnn_batched_path_equals_its_per_run_path_bit_for_bit(name, frame):
    scans = _scene()
    model = HOST.sensor("active-sonar").measurement_model(frame=frame, sigma_xy=1.0, sigma_r=1.0, sigma_b_deg=0.5)
    filt = HOST.filter(name)
    cfg = TrackerConfig(gate=100.0)  # a wide gate: clusters where the global and the greedy assignment differ
    assert GNN(cfg).batched(filt, scans.scan(0).for_filter())
    logs = [run(filt, scans, MOTION, model, association=role, rng=generator(5, "t", "run"))
            for role in (GNN(cfg, 5, ("t",), True), _GNNPerRun(cfg, 5, ("t",), True), MofN(cfg, 5, ("t",), True))]
    a, b, greedy = (_log_arrays(log) for log in logs)
    assert a.keys() == b.keys() and a["run"].size > 50 and np.any(a["status"] == 1)
    assert a["mean"].shape != greedy["mean"].shape or not np.array_equal(a["mean"], greedy["mean"])
    for key in a:
        assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), key


def test_only_deterministic_filters_and_the_greedy_assignment_are_batched():
    first = Scan(np.zeros((2, 1, 2)), np.ones((2, 1), dtype=bool))
    own_cov = Scan(np.zeros((2, 1, 2)), np.ones((2, 1), dtype=bool), cov=np.broadcast_to(np.eye(2), (2, 1, 2, 2)))
    assert MofN().batched(HOST.filter("kf"), first)
    assert not MofN().batched(HOST.filter("kf"), own_cov)  # each detection's own covariance: per run
    assert GNN().batched(HOST.filter("kf"), first)  # its clustered assignment keeps runs apart: declared

    class OwnAssign(MofN):
        def assign(self, rows, cols, d2):
            return rows[:0], cols[:0]

    class OwnGNN(GNN):
        def assign(self, rows, cols, d2):
            return rows[:0], cols[:0]

    assert not OwnAssign().batched(HOST.filter("kf"), first)  # its own assignment, undeclared: per run
    assert not OwnGNN().batched(HOST.filter("kf"), first)  # the declaration is not inherited by a new assign
    stochastic = [name for name in HOST.filters if "stochastic" in HOST.filter(name).capabilities]
    assert stochastic and not MofN().batched(HOST.filter(stochastic[0]), first)
