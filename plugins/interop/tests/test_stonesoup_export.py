"""Export to Stone Soup types: the values read back from the Stone Soup objects are the workbench's own, and Stone
Soup's own metric run on the exported objects agrees with the workbench's."""

from datetime import datetime

import numpy as np
import pytest

pytest.importorskip("stonesoup", reason="Stone Soup is not installed: pip install -e '.[stonesoup]'")

from stonesoup.types.angle import Bearing  # noqa: E402
from stonesoup.types.detection import Clutter, Detection  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402

from workbench.metrics import track_gospa  # noqa: E402
from workbench.models import constant_velocity, range_bearing  # noqa: E402
from workbench.tracking import CONFIRMED, TENTATIVE, Track, TrackLog  # noqa: E402
from workbench.trajectory import sample_motion  # noqa: E402
from workbench.types import CLUTTER, InputError, Scans, Truth  # noqa: E402
from workbench_interop.stonesoup_export import (EPOCH, detections, filter_tracks, ground_truth_paths,  # noqa: E402
                                                seconds, timestamps, track_log_tracks)

TIMES = np.array([0.0, 0.5, 1.25, 2.0, 3.000001])  # irregular, one of them at the microsecond


def _values(states):
    return np.stack([np.asarray(s.state_vector, dtype=float)[:, 0] for s in states])


def test_time_stamps_round_trip_to_the_microsecond():
    start = datetime(2024, 5, 17, 12, 30)
    stamps = timestamps(TIMES, start)
    assert stamps[0] == start and np.array_equal(seconds(stamps, start), TIMES)
    assert np.max(np.abs(seconds(timestamps(np.array([1 / 3, 2 / 3])), EPOCH) - [1 / 3, 2 / 3])) <= 5e-7


def test_ground_truth_paths_hold_every_run_state_and_time():
    rng = np.random.default_rng(1)
    truth = sample_motion(rng.normal(size=(3, 4)) * 100, constant_velocity(2, 0.5, 1.0), 5, rng)
    truth = type(truth)(truth.states, TIMES)
    paths = ground_truth_paths(truth)
    assert len(paths) == 3 and [p.id for p in paths] == ["run 0", "run 1", "run 2"]
    for b, path in enumerate(paths):
        assert np.array_equal(_values(path.states), truth.states[b])
        assert np.array_equal(seconds([s.timestamp for s in path.states]), TIMES)


def test_detections_are_detections_or_clutter_with_their_metadata_and_model():
    rng = np.random.default_rng(2)
    B, T, M = 2, TIMES.size, 3
    z = np.stack([rng.uniform(100, 2000, size=(B, T, M)), rng.uniform(-np.pi, np.pi, size=(B, T, M))], axis=-1)
    valid = rng.random((B, T, M)) < 0.7
    origin = np.where(rng.random((B, T, M)) < 0.5, CLUTTER, 0)
    snr = rng.uniform(5, 20, size=(B, T, M))
    scans = Scans(z, valid, TIMES, snr=snr, origin=origin)
    model = range_bearing(10.0, 0.01)
    out = detections(scans, run=1, model=model, ndim_state=4)
    assert [seconds([t])[0] for t, _ in out] == list(TIMES)
    for k, (_, found) in enumerate(out):
        rows = np.flatnonzero(valid[1, k])
        assert len(found) == rows.size
        by_snr = {d.metadata["snr"]: d for d in found}
        for j in rows:
            d = by_snr[snr[1, k, j]]
            assert isinstance(d, Clutter) == (origin[1, k, j] == CLUTTER) and isinstance(d, Detection)
            assert d.metadata["origin"] == origin[1, k, j]
            assert isinstance(d.state_vector[1, 0], Bearing)  # the bearing is an angle to Stone Soup
            assert np.array_equal(np.asarray(d.state_vector, dtype=float)[:, 0], z[1, k, j])
            # the detection's model is the workbench model: same h and R
            state = GaussianState(np.array([[300.0], [400.0], [1.0], [0.0]]), np.eye(4))
            assert np.allclose(np.asarray(d.measurement_model.function(state), dtype=float)[:, 0],
                               model.h(np.array([300.0, 400.0, 1.0, 0.0])), rtol=1e-15)
            assert np.array_equal(np.asarray(d.measurement_model.covar()), model.R)
    with pytest.raises(InputError, match="ndim_state"):
        detections(scans, model=model)
    with pytest.raises(InputError, match="run 5"):
        detections(scans, run=5)


def _log(rng, runs=2, pings=5):
    rows = {"run": [], "ping": [], "track_id": [], "status": []}
    for b in range(runs):
        for k in range(pings):
            for i in rng.choice(4, size=int(rng.integers(0, 4)), replace=False):
                rows["run"].append(b)
                rows["ping"].append(k)
                rows["track_id"].append(int(i))
                rows["status"].append(CONFIRMED if rng.random() < 0.7 else TENTATIVE)
    R = len(rows["run"])
    return TrackLog(np.array(rows["run"]), np.array(rows["ping"]), np.array(rows["track_id"]),
                    np.array(rows["status"], dtype=np.int8), np.ones(R, dtype=bool), rng.normal(size=(R, 4)) * 30,
                    runs, pings)


def test_tracker_tracks_round_trip_and_stonesoup_gospa_on_them_agrees():
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.measures import Euclidean

    rng = np.random.default_rng(3)
    log = _log(rng)
    cov = rng.normal(size=(log.run.size, 4, 4))
    cov = cov @ np.swapaxes(cov, 1, 2)
    for run in range(log.runs):
        for confirmed_only in (True, False):
            tracks = track_log_tracks(log, TIMES, run=run, cov=cov, confirmed_only=confirmed_only)
            sel = (log.run == run) & ((log.status == CONFIRMED) | (not confirmed_only))
            assert sum(len(t.states) for t in tracks) == sel.sum()
            for t in tracks:
                tid = int(t.id.split("-")[1])
                rows = np.flatnonzero(sel & (log.track_id == tid))
                assert np.array_equal(_values(t.states), log.mean[rows])
                assert all(np.array_equal(np.asarray(s.covar), cov[r]) for s, r in zip(t.states, rows))
                assert np.array_equal(seconds([s.timestamp for s in t.states]), TIMES[log.ping[rows]])
    # Stone Soup's GOSPA on the exported objects (positions = the first two components) equals ours
    truth = rng.normal(size=(log.runs, log.pings, 4)) * 30
    ours = track_gospa(log, truth, 20.0, 2.0)
    for run in range(log.runs):
        gen = GOSPAMetric(c=20.0, p=2.0, measure=Euclidean(mapping=(0, 1)))
        paths = ground_truth_paths(Truth(truth[run:run + 1], TIMES))
        metric = gen.compute_over_time(*gen.extract_states(track_log_tracks(log, TIMES, run=run), True),
                                       *gen.extract_states(paths, True))
        for m in metric.value:
            k = int(np.flatnonzero(TIMES == seconds([m.timestamp])[0])[0])
            assert ours.distance[run, k] == pytest.approx(float(m.value["distance"]), rel=1e-9, abs=1e-12)


def test_a_filter_track_becomes_one_stonesoup_track_of_gaussian_states_per_run():
    rng = np.random.default_rng(4)
    B, T = 3, TIMES.size
    cov = rng.normal(size=(B, T, 4, 4))
    track = Track("kf", rng.normal(size=(B, T, 4)), cov @ np.swapaxes(cov, -1, -2), np.zeros((B, T, 4)), {})
    out = filter_tracks(track, TIMES)
    assert [t.id for t in out] == ["run 0", "run 1", "run 2"]
    for b, t in enumerate(out):
        assert all(isinstance(s, GaussianState) for s in t.states)
        assert np.array_equal(_values(t.states), track.mean[b])
        assert np.array_equal(np.stack([np.asarray(s.covar) for s in t.states]), track.cov[b])
    with pytest.raises(InputError, match="one entry per step"):
        filter_tracks(track, TIMES[:3])
