"""The sensor kit passes correct sensors and fails deliberately wrong ones with messages that name the check, the
statistic and the value expected; its checks follow the sensor's declarations, never its name."""

from dataclasses import replace

import numpy as np
import pytest
from fixtures import wrong_components as wrong

from workbench.cli import check_plugin
from workbench.linalg import wrap_angle
from workbench.models import linear_measurement, range_bearing
from workbench.params import Param
from workbench.plugins import load_host
from workbench.testing import SENSOR_CHECKS, checks_for, parametrize_with_checks, run_checks
from workbench.testing.sensors import check_centred_on_h
from workbench.types import CLUTTER, Scans


def _outcomes(spec):
    return {o.check: o for o in run_checks(spec)}


def test_a_correct_sensor_passes_every_check():
    outcomes = _outcomes(wrong.FAIR_SENSOR)
    assert set(outcomes) == {c.name for c in SENSOR_CHECKS}
    assert all(o.status == "passed" for o in outcomes.values()), [o for o in outcomes.values() if o.status != "passed"]
    assert "target detections" in outcomes["check_centred_on_h"].message


def test_a_sensor_biased_by_three_sigma_fails_the_centring_check_readably():
    outcomes = _outcomes(wrong.BIASED_SENSOR)
    bad = outcomes["check_centred_on_h"]
    assert bad.status == "failed"
    msg = bad.message
    # names the check, the component, the statistic and the value expected
    assert msg.startswith("check_centred_on_h: ")
    assert "component 'x': mean residual +3.0" in msg and "expected 0 +- 0.022" in msg
    assert "component 'y': mean residual" not in msg  # the unbiased component is not blamed
    mean = float(msg.split("component 'x': mean residual ")[1].split(" ")[0])
    assert mean == pytest.approx(3.0, abs=0.1)
    # nothing else is wrong with it
    assert all(o.status == "passed" for k, o in outcomes.items() if k != "check_centred_on_h")


def test_a_quarter_sigma_bias_is_caught_and_a_fair_sensor_of_another_spread_passes():
    half = wrong.BIASED_SENSOR.configure(bias_sigmas=0.25)
    with pytest.raises(AssertionError, match="component 'x': mean residual \\+0.2"):
        check_centred_on_h(half)
    check_centred_on_h(wrong.FAIR_SENSOR.configure(sigma=7.0))


def _spread_sensor(sim_sigma, noise_cov=None):
    """Position sensor that simulates with ``sim_sigma`` but publishes R = 2^2 I."""

    def simulate(truth, rng, sigma=2.0, bias_sigmas=0.0):
        B, T, _ = truth.states.shape
        z = truth.states[..., :2] + sim_sigma * rng.standard_normal((B, T, 2))
        return Scans(z[:, :, None, :], np.ones((B, T, 1), bool), truth.times, origin=np.zeros((B, T, 1), int))

    return replace(wrong.FAIR_SENSOR, name="spread", simulate=simulate, noise_cov=noise_cov)


def test_R_that_is_not_the_simulation_noise_fails_unless_the_noise_is_declared():
    narrow = _spread_sensor(1.0)
    with pytest.raises(AssertionError) as info:
        check_centred_on_h(narrow)
    msg = str(info.value)
    assert "component 'x': mean square residual 0.2" in msg and "expected 1 +- " in msg
    assert "SensorSpec.noise_cov" in msg
    # the same sensor declaring its simulation noise passes ...
    check_centred_on_h(_spread_sensor(1.0, noise_cov=lambda truth, scans, **p: np.eye(2)))
    # ... and a declaration that is itself wrong (too narrow) fails
    with pytest.raises(AssertionError, match="mean square residual 4"):
        check_centred_on_h(_spread_sensor(1.0, noise_cov=lambda truth, scans, **p: 0.25 * np.eye(2)))


def test_a_wrong_correlation_is_caught_by_the_whitened_cross_moment():
    def simulate(truth, rng, sigma=2.0, bias_sigmas=0.0):
        B, T, _ = truth.states.shape
        e = rng.standard_normal((B, T, 2))
        # unit variances, correlation 0.6: the marginal spreads match R = 4 I
        noise = 2.0 * np.stack([e[..., 0], 0.6 * e[..., 0] + 0.8 * e[..., 1]], axis=-1)
        z = truth.states[..., :2] + noise
        return Scans(z[:, :, None, :], np.ones((B, T, 1), bool), truth.times, origin=np.zeros((B, T, 1), int))

    with pytest.raises(AssertionError, match="components 'x', 'y': whitened cross-moment \\+0.5"):
        check_centred_on_h(replace(wrong.FAIR_SENSOR, simulate=simulate))


def test_a_model_of_a_derived_state_needs_truth_to_state():
    def model(sigma=2.0, bias_sigmas=0.0):  # h takes the position [x, y] only
        return linear_measurement(np.eye(2), sigma**2 * np.eye(2), name="p", frame="cartesian-2d", std=(sigma, sigma))

    derived = replace(wrong.FAIR_SENSOR, measurement_model=model)
    with pytest.raises(AssertionError, match="does not take the test truth's states.*truth_to_state"):
        check_centred_on_h(derived)
    check_centred_on_h(replace(derived, truth_to_state=lambda states, **p: states[..., :2]))


def test_a_model_in_another_frame_than_the_detections_is_not_centred_on():
    view = replace(wrong.FAIR_SENSOR, measurement_model=lambda **p: range_bearing(0.5, 0.02))
    assert "check_centred_on_h" not in {c.name for c in checks_for(view)}
    skipped = _outcomes(view)["check_centred_on_h"]
    assert skipped.status == "skipped" and "frame of the detections" in skipped.message


def _rb_sensor(wrap: bool):
    model = range_bearing(1.0, 0.05)

    def simulate(truth, rng, sigma=2.0, bias_sigmas=0.0):
        B, T, _ = truth.states.shape
        z = model.h(truth.states) + rng.standard_normal((B, T, 2)) * [1.0, 0.05]
        z[..., 1] = wrap_angle(z[..., 1]) if wrap else np.mod(z[..., 1], 2 * np.pi)  # [0, 2 pi): not wrapped
        return Scans(z[:, :, None, :], np.ones((B, T, 1), bool), truth.times, origin=np.zeros((B, T, 1), int))

    return replace(wrong.FAIR_SENSOR, name="rb", measurement_model=lambda **p: model, simulate=simulate,
                   frame="range-bearing")


def test_angles_must_be_wrapped_and_residuals_wrap_them():
    assert _outcomes(_rb_sensor(True))["check_frame_respected"].status == "passed"
    outcomes = _outcomes(_rb_sensor(False))
    bad = outcomes["check_frame_respected"]
    assert bad.status == "failed" and "bearing values lie outside (-pi, pi]" in bad.message
    # the residual wraps, so the unwrapped bearings are still centred on h
    assert outcomes["check_centred_on_h"].status == "passed"


def test_frame_origin_seed_and_parameter_faults_each_fail_their_own_check():
    def unseeded(truth, rng, sigma=2.0, bias_sigmas=0.0):
        return wrong.simulate_position(truth, np.random.default_rng(), sigma, bias_sigmas)

    def mislabelled(truth, rng, sigma=2.0, bias_sigmas=0.0):
        s = wrong.simulate_position(truth, rng, sigma, bias_sigmas)
        return Scans(s.z, s.valid, s.times, origin=np.full(s.valid.shape, CLUTTER))

    cases = {
        "check_same_seed_same_scans": (replace(wrong.FAIR_SENSOR, simulate=unseeded), "same seed differ in z"),
        "check_origin_labels": (replace(wrong.FAIR_SENSOR, simulate=mislabelled), "labelled [-1], not 0"),
        "check_frame_respected": (replace(wrong.FAIR_SENSOR, frame="range-bearing"),
                                  "bearing values lie outside"),
        "check_parameters": (replace(wrong.FAIR_SENSOR, parameters=(
            Param("sigma", -2.0, "noise", unit="length", above=0.0), wrong.SENSOR_PARAMETERS[1])),
            "the default of 'sigma' (-2.0) fails its own declaration"),
    }
    for check, (spec, text) in cases.items():
        outcome = _outcomes(spec)[check]
        assert outcome.status == "failed" and text in outcome.message, (check, outcome)


def test_parameters_are_refused_by_name():
    spec = wrong.FAIR_SENSOR
    outcome = _outcomes(spec)["check_parameters"]
    assert outcome.status == "passed"
    # what the check relies on: a NaN and a wrong unit are refused naming the key
    from workbench.types import InputError

    with pytest.raises(InputError, match="sigma"):
        spec.configure(sigma=float("nan"))
    with pytest.raises(InputError, match="sigma.*is a time"):
        spec.configure(sigma="1 s")


def test_a_model_that_ignores_its_configured_noise_fails_only_the_configured_values_check():
    # R = 4 I whatever sigma is: right at the default (every other check passes), wrong once sigma is configured
    def fixed_model(sigma=2.0, bias_sigmas=0.0):
        return linear_measurement(np.eye(2, 4), 4.0 * np.eye(2), name="position", frame="cartesian-2d",
                                  std=(2.0, 2.0))

    spec = replace(wrong.FAIR_SENSOR, name="fixed-R", measurement_model=fixed_model)
    outcomes = _outcomes(spec)
    bad = outcomes["check_configured_values"]
    assert bad.status == "failed" and "'sigma', declared affects='model', changed nothing in the published " \
                                       "measurement model when configured from 2 to: 1 changed the simulated z" \
                                       in bad.message, bad
    assert all(o.status == "passed" for k, o in outcomes.items() if k != "check_configured_values")
    assert _outcomes(wrong.FAIR_SENSOR)["check_configured_values"].message == (
        "2 parameters configured, each changed what it declares: sigma -> R, std; bias_sigmas -> z")


@parametrize_with_checks([wrong.FAIR_SENSOR])
def test_parametrize_with_checks_takes_sensors(spec, check):
    check(spec)


def test_parametrize_ids_name_the_sensor_and_the_check():
    mark = parametrize_with_checks([wrong.FAIR_SENSOR])
    ids = [p.id for p in mark.args[1]]
    assert "fair-position-check_centred_on_h" in ids and len(ids) == len(SENSOR_CHECKS)


def test_check_plugin_runs_the_sensor_kit(capsys):
    host = load_host(extra_plugins=[("wrong", wrong)])
    assert check_plugin(host, "fair-position") == 0
    assert check_plugin(host, "biased-position") == 1
    out = capsys.readouterr().out
    assert "PASSED   fair-position-check_centred_on_h: " in out
    assert "FAILED   biased-position-check_centred_on_h: check_centred_on_h: " in out
    assert "component 'x': mean residual +3.0" in out
    assert "5 passed, 1 failed" in out
