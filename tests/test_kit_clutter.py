"""The clutter kit passes correct generators and removers and fails deliberately wrong ones, each in the right
check, with a message naming the check, the statistic and the value expected."""

from dataclasses import replace

import numpy as np
import pytest
from fixtures import wrong_components as wrong

from workbench import hookimpl
from workbench.cli import check_plugin
from workbench.plugins import load_host
from workbench.testing import GENERATOR_CHECKS, checks_for, parametrize_with_checks, run_checks
from workbench.testing.clutter import check_count_poisson, remover_scene
from workbench.types import CLUTTER, Scans


def _outcomes(spec):
    return {o.check: o for o in run_checks(spec)}


def test_a_correct_generator_passes_every_check():
    outcomes = _outcomes(wrong.FAIR_CLUTTER)
    assert set(outcomes) == {c.name for c in GENERATOR_CHECKS}
    assert all(o.status == "passed" for o in outcomes.values()), [o for o in outcomes.values() if o.status != "passed"]


def test_twice_the_declared_rate_fails_the_count_check_readably():
    outcomes = _outcomes(wrong.DOUBLE_RATE_CLUTTER)
    bad = outcomes["check_count_poisson"]
    assert bad.status == "failed"
    msg = bad.message
    assert msg.startswith("check_count_poisson: ")
    # the statistic (the observed total, its ratio to the declared mean) and the value expected
    assert "2000 scans hold" in msg and "times the declared mean count: expected 6000.0 +- 77.5 (Poisson)" in msg
    ratio = float(msg.split(" clutter points, ")[1].split(" times")[0])
    assert ratio == pytest.approx(2.0, abs=0.05)
    assert "over-dispersed" in msg  # (n - mu)^2 / mu is about 1 + mu per scan, not 1
    # the rate is the only fault: positions and amplitudes still follow their declarations
    assert all(o.status == "passed" for k, o in outcomes.items() if k != "check_count_poisson")


def test_ten_percent_too_many_points_fail_and_a_different_declared_rate_passes():
    with pytest.raises(AssertionError, match="times the declared mean count") as info:
        check_count_poisson(wrong.FAIR_CLUTTER.configure(rate_factor=1.1))
    ratio = float(str(info.value).split(" clutter points, ")[1].split(" times")[0])
    assert ratio == pytest.approx(1.1, abs=0.04)
    check_count_poisson(wrong.FAIR_CLUTTER.configure(rate=0.7))


def _generator(**changes):
    return replace(wrong.FAIR_CLUTTER, **changes)


def test_non_poisson_counts_fail_the_dispersion_test():
    def fixed_count(truth, rng, rate=3.0, rate_factor=1.0, mean_power=10.0):
        B, T = truth.batch, truth.steps
        z = wrong.SIDE * rng.random((B, T, 3, 2))
        return Scans(z, np.ones((B, T, 3), bool), truth.times, snr=10 * np.log10(rng.exponential(10.0, (B, T, 3))),
                     origin=np.full((B, T, 3), CLUTTER))

    with pytest.raises(AssertionError, match="under-dispersed for a Poisson count.*X/K = 0.000, expected 1"):
        check_count_poisson(_generator(generate=fixed_count))


def test_points_outside_the_region_and_a_wrong_amplitude_law_fail_their_checks():
    small = _generator(region=lambda truth, **p: (np.zeros(2), np.full(2, 90.0)))
    bad = _outcomes(small)["check_inside_region"]
    assert bad.status == "failed" and "clutter points lie outside the declared region (expected 0)" in bad.message
    assert "not in [0, 90]" in bad.message

    louder = _generator(amplitude_cdf=lambda s, **p: wrong.amplitude_cdf(s, mean_power=5.0))
    bad = _outcomes(louder)["check_amplitude_law"]
    assert bad.status == "failed" and "Kolmogorov-Smirnov D = " in bad.message and "(expected 0.5)" in bad.message


def test_labels_seed_and_frame_faults_fail_their_own_checks():
    def labelled_target(truth, rng, **p):
        s = wrong.generate_clutter(truth, rng, **p)
        return Scans(s.z, s.valid, s.times, snr=s.snr, origin=np.zeros(s.valid.shape, int))

    def unseeded(truth, rng, **p):
        return wrong.generate_clutter(truth, np.random.default_rng(), **p)

    cases = {
        "check_all_clutter": (_generator(generate=labelled_target), "labelled [0], not CLUTTER (-1)"),
        "check_same_seed_same_scans": (_generator(generate=unseeded), "same seed differ in"),
        "check_frame_respected": (_generator(frame="position-doppler-3d"), "has 4 components"),
    }
    for check, (spec, text) in cases.items():
        outcome = _outcomes(spec)[check]
        assert outcome.status == "failed" and text in outcome.message, (check, outcome)


def test_a_generator_that_ignores_a_configured_value_fails_only_the_configured_values_check():
    def fixed_power(truth, rng, rate=3.0, rate_factor=1.0, mean_power=10.0):  # the mean power is always 10
        return wrong.generate_clutter(truth, rng, rate, rate_factor, 10.0)

    outcomes = _outcomes(_generator(name="fixed-power", generate=fixed_power))
    bad = outcomes["check_configured_values"]
    assert bad.status == "failed" and "'mean_power' changed nothing in the clutter when configured from 10 to: 5 " \
                                       "changed nothing; 16 changed nothing" in bad.message, bad
    assert all(o.status == "passed" for k, o in outcomes.items() if k != "check_configured_values")
    assert _outcomes(wrong.FAIR_CLUTTER)["check_configured_values"].message.startswith(
        "3 parameters configured, each changed the clutter: rate -> ")


def test_checks_follow_the_declarations():
    bare = _generator(expected_count=None, region=None, amplitude_cdf=None)
    names = {c.name for c in checks_for(bare)}
    assert names == {"check_all_clutter", "check_same_seed_same_scans", "check_frame_respected", "check_parameters",
                     "check_configured_values"}
    skipped = _outcomes(bare)["check_count_poisson"]
    assert skipped.status == "skipped" and "needs a declared expected_count" in skipped.message


# -- removers -------------------------------------------------------------------------------------------------


def test_each_wrong_remover_fails_exactly_its_own_check():
    faults = (
        (wrong.LOOKAHEAD_REMOVER, "check_causal", "the remover looks ahead (a causal remover decides scan k from "
                                                  "scans <= k): with scans 5.. replaced"),
        (wrong.ORIGIN_READING_REMOVER, "check_never_reads_origin", "with the origin labels removed, the output "
                                                                   "differs in valid"),
        (wrong.WIDENING_REMOVER, "check_only_narrows", "invalid rows became valid"),
    )
    for spec, check, text in faults:
        outcomes = _outcomes(spec)
        assert outcomes[check].status == "failed" and text in outcomes[check].message, outcomes[check]
        others = {k: o.status for k, o in outcomes.items() if k != check}
        assert set(others.values()) == {"passed"}, (spec.name, others)


def test_remover_scene_is_a_target_line_in_uniform_clutter():
    scans = remover_scene("cartesian-2d", seed=1)
    assert scans.z.shape[2] == 46 and set(np.unique(scans.origin[scans.valid])) == {0, CLUTTER}
    target = scans.z[:, :, 0]
    steps = np.linalg.norm(np.diff(target, axis=1), axis=-1)
    assert 2.0 < np.median(steps) < 6.0  # 4 units per scan, noise 1
    clutter = scans.z[:, :, 1:][scans.valid[:, :, 1:]]
    assert clutter.min() >= 0 and clutter.max() <= 250 and 15 < scans.valid[:, :, 1:].sum(-1).mean() < 25
    angular = remover_scene("range-bearing", seed=1)
    bearings = angular.z[..., 1][angular.valid]
    assert bearings.min() > -np.pi and bearings.max() <= np.pi


@parametrize_with_checks([wrong.FAIR_CLUTTER])
def test_parametrize_with_checks_takes_clutter_generators(spec, check):
    check(spec)


def test_check_plugin_runs_the_clutter_kits(capsys):
    host = load_host(extra_plugins=[("wrong", wrong)])
    assert check_plugin(host, "fair-clutter") == 0
    assert check_plugin(host, "double-rate-clutter") == 1
    assert check_plugin(host, "lookahead-remover") == 1
    out = capsys.readouterr().out
    assert "PASSED   fair-clutter-check_count_poisson: " in out
    assert "FAILED   double-rate-clutter-check_count_poisson: check_count_poisson: " in out
    assert "FAILED   lookahead-remover-check_causal: check_causal: " in out
    assert "PASSED   lookahead-remover-check_never_reads_origin" in out


class _SameName:
    """A plugin whose sensor and clutter generator share a name."""

    @hookimpl
    def workbench_sensors(self):
        return [replace(wrong.FAIR_SENSOR, name="twin")]

    @hookimpl
    def workbench_clutter_generators(self):
        return [replace(wrong.FAIR_CLUTTER, name="twin")]


def test_check_plugin_runs_every_kind_a_name_has_or_the_one_asked_for(capsys):
    host = load_host(extra_plugins=[("twin", _SameName())])
    assert check_plugin(host, "twin") == 0
    out = capsys.readouterr().out
    assert "'twin' is a sensor and a clutter generator" in out and "--kind" in out
    assert "twin-check_centred_on_h" in out and "twin-check_count_poisson" in out
    assert check_plugin(host, "twin", kind="clutter-generator") == 0
    out = capsys.readouterr().out
    assert "twin-check_count_poisson" in out and "twin-check_centred_on_h" not in out
