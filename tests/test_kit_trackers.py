"""The tracker kit (workbench.testing.trackers): the built-in trackers pass it, `workbench check-plugin` and the
pytest parametrisation run it, and deliberately broken trackers fail the check that names their fault."""

import dataclasses

import numpy as np
import pytest

from workbench.cli import check_plugin
from workbench.plugins import load_host
from workbench.specs import TrackerSpec
from workbench.testing import checks_for, parametrize_with_checks
from workbench.testing.trackers import (GOSPA_C, GOSPA_P, TRACKER_CHECKS, check_all_clutter, check_empty_scans,
                                        check_gospa, check_inputs_unchanged, check_log_valid, check_nan_detection,
                                        check_same_seed, run_tracker_checks, tracker_kit_scene)
from workbench.metrics.ospa import gospa
from workbench.tracking.records import TrackLog
from workbench.types import CLUTTER

HOST = load_host()


@pytest.mark.slow  # about 6 s on 2 shared cores: the whole kit
def test_mofn_passes_every_check():
    outcomes = list(run_tracker_checks(HOST.tracker("mofn")))
    assert [o.check for o in outcomes] == [c.name for c in TRACKER_CHECKS]
    assert all(o.status == "passed" for o in outcomes), [(o.check, o.message) for o in outcomes
                                                          if o.status != "passed"]


@pytest.mark.slow  # about 6 s on 2 shared cores: the whole kit
def test_check_plugin_runs_the_tracker_kit_for_gnn():
    lines = []
    assert check_plugin(HOST, "gnn", "tracker", out=lines.append) == 0
    assert lines[0].startswith("-- tracker gnn")
    assert sum(line.startswith("PASSED   gnn-check_") for line in lines) == len(TRACKER_CHECKS)
    assert lines[-1] == f"{len(TRACKER_CHECKS)} passed, 0 failed"


def test_pytest_collects_the_tracker_kit():
    spec = HOST.tracker("gnn(gate_probability=0.95)")
    assert [c.name for c in checks_for(spec)] == [c.name for c in TRACKER_CHECKS]
    mark = parametrize_with_checks([spec])
    ids = [p.id for p in mark.args[1]]
    assert ids[0] == "gnn(gate_probability=0.95)-check_parameters" and len(ids) == len(TRACKER_CHECKS)


def test_the_scene_has_crossing_targets_a_birth_a_death_and_clutter():
    truth, scans = tracker_kit_scene()
    assert truth.objects == 3
    assert truth.alive[:, 0, 2].sum() == 0 and truth.alive[:, -1, 2].all()  # C born late
    assert truth.alive[:, 0, 1].all() and truth.alive[:, -1, 1].sum() == 0  # B dies
    d = np.linalg.norm(truth.states[:, :, 0, :2] - truth.states[:, :, 1, :2], axis=-1)
    assert np.nanmin(d) < 10.0  # A and B cross
    assert (scans.valid & (scans.origin == CLUTTER)).sum() > 0


# -- broken trackers fail the check that names their fault -------------------------------------------------


def _wrap(name, run):
    return TrackerSpec(name, "a deliberately broken tracker for the kit's own tests", run)


def _gnn(scans, filt, motion, model, *, seed=0, key=()):
    return HOST.tracker("gnn").run(scans, filt, motion, model, seed=seed, key=key)


def _no_tracks(scans, filt, motion, model, *, seed=0, key=()):
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    return log.select(np.zeros(log.run.size, dtype=bool))


def _mutating(scans, filt, motion, model, *, seed=0, key=()):
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    scans.valid[..., 0] = False  # writes into the caller's scans
    return log


_CALLS = []


def _unseeded(scans, filt, motion, model, *, seed=0, key=()):
    _CALLS.append(1)  # a hidden state: each call differs (as an unseeded random draw would)
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    return dataclasses.replace(log, mean=log.mean + 1e-9 * len(_CALLS))


def _batch_dependent(scans, filt, motion, model, *, seed=0, key=()):
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    return dataclasses.replace(log, mean=log.mean + 1e-3 * scans.batch)  # a run's tracks read the batch's size


def _no_empty(scans, filt, motion, model, *, seed=0, key=()):
    scans.z[..., 0].min()  # raises on scans with no detection row (M = 0)
    return _gnn(scans, filt, motion, model, seed=seed, key=key)


def _asymmetric(scans, filt, motion, model, *, seed=0, key=()):
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    cov = log.cov.copy()
    cov[:, 0, 1] += 1.0
    return dataclasses.replace(log, cov=cov)


def _nan_through(scans, filt, motion, model, *, seed=0, key=()):
    from workbench.types import Scans, _validated

    bad = ~np.all(np.isfinite(scans.z), axis=-1) & scans.valid
    if not bad.any():
        return _gnn(scans, filt, motion, model, seed=seed, key=key)
    # reads a NaN as the same row's value one scan earlier plus 3 m (near the object): neither refused nor skipped
    prev = np.concatenate([scans.z[:, :1], scans.z[:, :-1]], axis=1) + 3.0
    z = np.where(np.isfinite(scans.z), scans.z, prev)
    return _gnn(_validated(Scans, **{**vars(scans), "z": z}), filt, motion, model, seed=seed, key=key)


def _bad_status(scans, filt, motion, model, *, seed=0, key=()):
    log = _gnn(scans, filt, motion, model, seed=seed, key=key)
    return dataclasses.replace(log, status=log.status + 5)


@pytest.mark.parametrize("run, check, match", [
    (_no_tracks, check_gospa, "mean GOSPA"),
    (_mutating, check_inputs_unchanged, "changed its inputs: valid"),
    (_unseeded, check_same_seed, "differ in the log's mean"),
    (_batch_dependent, check_same_seed, "depend on the other runs"),
    (_no_empty, check_empty_scans, "run raised ValueError"),
    (_asymmetric, check_log_valid, "not symmetric"),
    (_nan_through, check_nan_detection, "neither refused"),
    (_bad_status, check_all_clutter, "neither TENTATIVE"),
])
def test_a_broken_tracker_fails_the_check_naming_its_fault(run, check, match):
    with pytest.raises(AssertionError, match=match):
        check(_wrap("broken", run))


def test_the_gospa_bound_reads_against_the_no_track_value():
    truth, _ = tracker_kit_scene()
    empty = np.zeros(truth.alive.shape[:2] + (0, 2))
    g = gospa(empty, truth.states[..., :2], GOSPA_C, GOSPA_P, y_valid=truth.alive)
    # no track: GOSPA^p = n_live c^p / 2 per scan
    np.testing.assert_allclose(g.distance, np.sqrt(truth.alive.sum(axis=2) * GOSPA_C ** 2 / 2))


def test_the_log_round_trip_keeps_existence():
    log = TrackLog(np.array([0]), np.array([1]), np.array([3]), np.array([1]), np.array([True]), np.zeros((1, 4)),
                   1, 2, np.eye(4)[None], np.array([0.7]))
    again = TrackLog.from_arrays(log.to_arrays())
    assert again.existence.tolist() == [0.7]
