"""The plugin test kit passes a correct Kalman filter and fails broken ones with readable messages."""

from dataclasses import replace

import numpy as np
import pytest

from workbench.linalg import psd_solve, symmetrise
from workbench.plugins import load_host
from workbench.specs import FilterSpec
from workbench.testing import checks_for, run_checks
from workbench.types import Gaussian

KF = load_host().filter("kf")


def _wrong_cov_update(state, scan, model, rng=None):
    """A Kalman update whose covariance uses (I + KH) instead of (I - KH)."""
    present = scan.valid[:, 0] if scan.z.shape[1] else np.zeros(state.batch, bool)
    if not present.any():
        return state
    H, P = model.H, state.cov
    S = H @ P @ H.T + model.R
    K = np.swapaxes(psd_solve(S, (P @ H.T).swapaxes(-1, -2)), -1, -2)
    mean = state.mean + np.einsum("bij,bj->bi", K, scan.z[:, 0] - state.mean @ H.T)
    cov = symmetrise((np.eye(4) + K @ H) @ P)  # the bug
    keep = present[:, None]
    return Gaussian(np.where(keep, mean, state.mean), np.where(keep[..., None], cov, P))


def _mutating_predict(state, motion, rng=None):
    state.mean[...] = state.mean @ motion.F.T  # writes into its input
    return Gaussian(state.mean, motion.F @ state.cov @ motion.F.T + motion.Q)


def test_correct_kalman_filter_passes_every_check():
    outcomes = run_checks(KF)
    assert {o.status for o in outcomes} <= {"passed", "skipped"}, [o for o in outcomes if o.status == "failed"]
    assert sum(o.status == "passed" for o in outcomes) >= 7


def test_wrong_covariance_update_fails_with_a_readable_message():
    wrong = replace(KF, name="kf-wrong", update=_wrong_cov_update)
    outcomes = {o.check: o for o in run_checks(wrong)}
    bad = outcomes["check_matches_kalman"]
    assert bad.status == "failed"
    assert "differs from the closed-form Kalman filter" in bad.message and "covariance error" in bad.message
    assert outcomes["check_nees_consistency"].status == "failed"
    assert "NEES inconsistent" in outcomes["check_nees_consistency"].message


def test_mutating_filter_fails_no_mutation():
    bad = replace(KF, name="kf-mutating", predict=_mutating_predict)
    outcome = next(o for o in run_checks(bad) if o.check == "check_no_mutation")
    assert outcome.status == "failed" and "in place" in outcome.message


def test_checks_follow_capabilities_not_names():
    names = {c.name for c in checks_for(replace(KF, name="anything"))}
    assert "check_matches_kalman" in names and "check_batch_consistency" in names
    stochastic = replace(KF, capabilities=frozenset({"stochastic"}))
    names = {c.name for c in checks_for(stochastic)}
    assert "check_matches_kalman" not in names and "check_batch_consistency" not in names
    assert "check_same_seed" in names


def test_expected_failures_are_honoured_and_validated():
    wrong = replace(KF, name="kf-wrong", update=_wrong_cov_update,
                    expected_failures={"check_matches_kalman": "known", "check_nees_consistency": "known"})
    statuses = {o.check: o.status for o in run_checks(wrong)}
    assert statuses["check_matches_kalman"] == "xfailed"
    with pytest.raises(ValueError, match="unknown checks"):
        checks_for(replace(KF, expected_failures={"check_nonsense": "x"}))


def test_check_plugin_command(capsys):
    from workbench.cli import main

    assert main(["check-plugin", "kf"]) == 0
    out = capsys.readouterr().out
    assert "PASSED   kf-check_matches_kalman" in out and " 0 failed" in out


def test_the_kit_drives_filters_through_the_one_time_loop(monkeypatch):
    from workbench.testing import kit
    from workbench.tracking import Direct

    calls = []
    real = kit.run

    def spy(filt, scans, motion, model, **kw):
        calls.append(type(kw.get("association")))
        return real(filt, scans, motion, model, **kw)

    monkeypatch.setattr(kit, "run", spy)
    kit.check_matches_kalman(KF)
    assert calls == [Direct]


def test_check_plugin_command_fits_the_kit_to_the_kind(capsys):
    from workbench.cli import main

    assert main(["check-plugin", "sonar-poisson"]) == 0
    assert main(["check-plugin", "hough"]) == 0
    out = capsys.readouterr().out
    assert "PASSED   sonar-poisson-check_count_poisson: " in out and "PASSED   hough-check_causal: " in out
    assert main(["check-plugin", "no-such-thing"]) == 2
    assert "no filter, sensor, clutter generator or clutter remover named 'no-such-thing'" in capsys.readouterr().err
    assert main(["check-plugin", "kf", "--kind", "sensor"]) == 2
