"""The filter kit's run of a filter under every built-in tracker (workbench.testing.trackers_check.check_each_tracker):
a good filter passes under each tracker that takes it, a refusal counts only when it names the filter's capability,
and a filter that breaks under a tracker fails the check naming the tracker."""

from dataclasses import replace

import pytest

from workbench.testing.kit import _host
from workbench.testing.trackers_check import builtin_trackers, check_each_tracker
from workbench.types import InputError

KF = _host().filter("kf")


def test_the_built_in_trackers_are_the_five():
    assert sorted(builtin_trackers()) == ["gm-phd", "gnn", "jipda", "jpda", "mofn"]


def test_the_kalman_filter_runs_under_every_tracker():
    summary = check_each_tracker(KF)
    assert summary.startswith("under gm-phd, gnn, jipda, jpda:") and "refused" not in summary


def test_a_stochastic_filter_is_refused_by_name_and_counts_as_a_pass():
    # the same Kalman filter declared stochastic: JIPDA, JPDA and GM-PHD refuse it, naming the capability
    summary = check_each_tracker(replace(KF, name="kf-stochastic", capabilities=KF.capabilities | {"stochastic"}))
    assert "refused by name: gm-phd (stochastic), jipda (stochastic), jpda (stochastic)" in summary


def test_a_refusal_that_names_no_capability_fails():
    def update(state, scan, model, rng=None):
        if state.mean.shape[0] > 1:
            raise InputError("kf-one: something is wrong")
        return KF.update(state, scan, model, rng)

    with pytest.raises(AssertionError, match="refused filter 'kf-one' without naming a capability"):
        check_each_tracker(replace(KF, name="kf-one", update=update))


def test_a_filter_that_ignores_its_detections_fails_naming_the_tracker():
    def update(state, scan, model, rng=None):
        return state

    with pytest.raises(AssertionError, match="under tracker 'gm-phd', target A is not held"):
        check_each_tracker(replace(KF, name="kf-deaf", update=update))
