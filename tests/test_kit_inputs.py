"""The kit feeds filters the variety real inputs have, and catches a filter that mishandles any one of them.

Each broken filter of :mod:`fixtures.broken_filters_inputs` is the built-in Kalman filter with one mistake in how it
handles one input (time steps, noise statistics, scan contents, priors, batch composition, its reported
covariance); the kit must fail it on the check meant for that input, while the correct filter passes every check.
"""

import numpy as np
import pytest
from fixtures.broken_filters_inputs import BROKEN_INPUTS, KF
from scipy import stats

from workbench.metrics import nees
from workbench.plugins import load_host
from workbench.testing import kit, run_checks

#: the checks of the varied inputs
VARIED = {"check_irregular_time_steps", "check_noise_statistics", "check_scan_contents", "check_prior_handling",
          "check_batch_composition", "check_information", "check_nis_consistency"}


def _outcome(spec, check):
    return next(o for o in run_checks(spec) if o.check == check)


@pytest.mark.parametrize("broken, what, check", BROKEN_INPUTS, ids=[spec.name for spec, _, _ in BROKEN_INPUTS])
def test_the_kit_fails_a_filter_that_mishandles_one_input_on_the_check_for_it(broken, what, check):
    outcome = _outcome(broken, check)
    assert outcome.status == "failed", (what, outcome)
    assert outcome.message, outcome


@pytest.mark.parametrize("broken, what, check", [b for b in BROKEN_INPUTS if "exact_linear" in b[0].capabilities],
                         ids=[spec.name for spec, _, _ in BROKEN_INPUTS if "exact_linear" in spec.capabilities])
def test_the_tidy_case_alone_misses_each_exact_broken_filter(broken, what, check):
    """On the kit's tidy case (steps of 1 s, one row per scan, one diagonal prior for all) each of these equals the
    Kalman filter: only the varied inputs show the mistake."""
    assert _outcome(broken, "check_matches_kalman").status == "passed"


@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "alpha-beta"])
def test_correct_filters_pass_every_check(name):
    spec = load_host().filter(name)
    outcomes = {o.check: o for o in run_checks(spec)}
    assert {o.status for o in outcomes.values()} <= {"passed", "skipped"}, \
        {k: o.message for k, o in outcomes.items() if o.status == "failed"}
    assert VARIED <= {k for k, o in outcomes.items() if o.status == "passed"}


def test_the_messages_name_the_case_and_the_evidence():
    by_name = {spec.name: (spec, check) for spec, _, check in BROKEN_INPUTS}
    msg = lambda name: _outcome(*by_name[name]).message  # noqa: E731
    assert msg("kf-ignores-dt").startswith("irregular time steps: differs from the reference Kalman filter")
    assert "anisotropic" in msg("kf-trace-r") or "small noise" in msg("kf-trace-r")
    assert "mean NEES" in msg("kf-inflated") or "NEES inconsistent" in msg("kf-inflated")
    assert "did not shrink the position covariance" in msg("kf-cov-frozen")
    assert "a batch of one" in msg("kf-breaks-on-one")


def test_the_varied_cases_vary_what_they_claim():
    truth, scans, prior, motion, model = kit._varied_problem(KF, 8, 15, 31, times=kit._irregular_times(15, 31))
    dt = np.diff(scans.times)
    assert dt.min() >= kit.IRREGULAR_DT[0] and dt.max() <= kit.IRREGULAR_DT[1] and np.ptp(dt) > 1.0
    assert not np.allclose(dt, np.round(dt))  # not whole seconds
    mask = np.resize(kit.SCAN_MASK_PATTERN, (8, 15))
    _, padded, _, _, _ = kit._varied_problem(KF, 8, 15, 35, rows=3, mask=mask)
    rows = np.argmax(padded.valid, axis=-1)[padded.valid.any(axis=-1)]
    assert set(rows.tolist()) == {0, 1, 2}  # the valid row is not always the first
    assert np.array_equal(padded.valid.any(axis=-1), mask) and not mask.all()
    garbage = kit._with_garbage(padded)
    assert np.array_equal(garbage.z[padded.valid], padded.z[padded.valid])  # the detections are untouched
    pad = garbage.z[~padded.valid]
    assert np.isnan(pad).any() and (np.abs(pad) >= 1e300).any()
    means, covs = kit._prior_mix(10)
    corr = covs[:, 0, 2] / np.sqrt(covs[:, 0, 0] * covs[:, 2, 2])
    assert np.isclose(corr.max(), 0.9) and np.isclose(corr.min(), -0.8)
    assert covs[:, 0, 0].max() / covs[:, 0, 0].min() >= 1e6 and np.ptp(means[:, 0]) > 100.0


def test_reference_filter_equals_the_plain_kalman_filter_on_regular_steps():
    """Two independent write-ups (one item at a time with explicit inverses; batched with a per-interval rebuild of
    the motion model, the valid row found by the mask, Joseph form) agree where both apply."""
    _, scans, prior, motion, model = kit._problem(KF, 4, seed=22, steps=12)
    exact, exact_cov = kit.reference_kalman(prior, scans, motion.F, motion.Q, model.H, model.R)
    mean, cov = kit.reference_filter(prior, scans, motion, model)
    assert np.allclose(mean, exact, rtol=1e-9, atol=1e-9) and np.allclose(cov, exact_cov, rtol=1e-9, atol=1e-9)


def test_reference_filter_is_consistent_on_irregular_steps():
    """On irregular steps its NEES over 1,000 runs matches chi-square(4) at every scan (a check of the reference
    against the distribution the errors must follow, not against itself): each scan's run-averaged NEES lies in
    its band at level 1e-3 / 15 (Bonferroni over the scans)."""
    runs, steps = 1000, 15
    truth, scans, prior, motion, model = kit._varied_problem(KF, runs, steps, 44, times=kit._irregular_times(steps, 44),
                                                             R=[[16.0, -3.0], [-3.0, 2.25]])
    mean, cov = kit.reference_filter(prior, scans, motion, model)
    e = nees(truth.states, mean, cov).mean(axis=0)
    lo, hi = stats.chi2.ppf([0.5e-3 / steps, 1 - 0.5e-3 / steps], 4 * runs) / runs
    assert np.all((e >= lo) & (e <= hi)), (e, lo, hi)
