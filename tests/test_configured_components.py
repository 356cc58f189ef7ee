"""A configured sensor, clutter generator or remover simulates and publishes with its configured values (issue 23,
item 6): ``spec.configure(...)`` binds the new values to every function of the spec, keywords the caller passes still
win, and the kits' ``check_configured_values`` fails a component whose parameter has no effect or whose function reads
a hard-coded value instead of its parameter."""

from __future__ import annotations

import dataclasses
import pickle
import sys

import numpy as np
import pytest
from fixtures import wrong_components as wrong
from scipy import stats

from workbench.linalg import wrap_angle
from workbench.models import linear_measurement, range_bearing
from workbench.params import Param
from workbench.plugins import load_host
from workbench.report.cache import _module_files
from workbench.rng import generator
from workbench.specs import BoundFunction, ClutterGeneratorSpec, SensorSpec
from workbench.testing.clutter import check_generator_configured_values
from workbench.testing.sensors import check_configured_values
from workbench.types import CLUTTER, Scans, Truth

HOST = load_host()


def _far_truth(runs: int, steps: int, seed: int) -> Truth:
    """Targets 2 to 5 km from the origin at every bearing: range-bearing noise of 0.1 rad never wraps near them."""
    rng = generator(seed, "configured-truth")
    r = rng.uniform(2e3, 5e3, runs)
    b = rng.uniform(-np.pi, np.pi, runs)
    v = rng.normal(0.0, 10.0, (runs, 2))
    t = np.arange(steps, dtype=float)
    pos = np.stack([r * np.cos(b), r * np.sin(b)], axis=-1)[:, None, :] + v[:, None, :] * t[None, :, None]
    return Truth(np.concatenate([pos, np.broadcast_to(v[:, None, :], pos.shape)], axis=-1), t)


def _variance_band(n: int, sigma: float, level: float = 1e-6) -> tuple[float, float]:
    """Two-sided band of the mean square of n N(0, sigma^2) draws: sigma^2 chi-square(n) / n."""
    return (sigma**2 * stats.chi2.ppf(level / 2, n) / n, sigma**2 * stats.chi2.isf(level / 2, n) / n)


# -- the case ---------------------------------------------------------------------------------------------


def test_a_configured_range_bearing_sensor_publishes_and_simulates_its_sigma_theta():
    plain = HOST.sensor("range-bearing")
    configured = plain.configure(sigma_theta=0.02)
    assert configured.params["sigma_theta"] == 0.02
    # the published R: diag(sigma_r^2, sigma_theta^2), called without arguments as a FilterPy user would
    np.testing.assert_allclose(configured.measurement_model().R, np.diag([1.0, 0.0004]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(plain.measurement_model().R, np.diag([1.0, 0.01]), rtol=1e-12, atol=0)
    # the simulated bearing noise: its mean square over n detections against sigma_theta^2 chi-square(n) / n
    truth = _far_truth(200, 50, seed=1)
    n = truth.batch * truth.steps
    true_bearing = np.arctan2(truth.states[..., 1], truth.states[..., 0])
    true_range = np.hypot(truth.states[..., 0], truth.states[..., 1])
    spread = {}
    for label, spec in (("configured", configured), ("plain", plain)):
        z = spec.simulate(truth, generator(2, "configured", label)).z[:, :, 0]
        spread[label] = (float(np.mean(wrap_angle(z[..., 1] - true_bearing) ** 2)),
                         float(np.mean((z[..., 0] - true_range) ** 2)))
    low, high = _variance_band(n, 0.02)
    assert low <= spread["configured"][0] <= high, (spread, low, high)
    low, high = _variance_band(n, 0.1)
    assert low <= spread["plain"][0] <= high, (spread, low, high)
    # sigma_r was not configured: 1 m in both
    for label in spread:
        low, high = _variance_band(n, 1.0)
        assert low <= spread[label][1] <= high, (label, spread)


def test_keywords_the_caller_passes_win_and_positional_values_are_not_given_twice():
    configured = HOST.sensor("range-bearing").configure(sigma_theta=0.02)
    raw = configured.simulate.raw
    truth = _far_truth(5, 4, seed=3)
    explicit = configured.simulate(truth, generator(4, "k"), sigma_theta=0.3)
    reference = raw(truth, generator(4, "k"), sigma_r=1.0, sigma_theta=0.3)
    np.testing.assert_array_equal(explicit.z, reference.z)
    positional = configured.simulate(truth, generator(4, "k"), 2.0, 0.3)
    np.testing.assert_array_equal(positional.z, raw(truth, generator(4, "k"), 2.0, 0.3).z)
    assert configured.measurement_model(sigma_r=3.0).R[0, 0] == 9.0
    assert configured.measurement_model(sigma_r=3.0).R[1, 1] == pytest.approx(0.0004, rel=1e-12)


# -- binding: replace, equality, pickling, fingerprints -------------------------------------------------------------


def test_replace_binds_the_plugins_own_function_again_never_a_wrapper_of_a_wrapper():
    from workbench_sensors import range_bearing as module

    plain = HOST.sensor("range-bearing")
    configured = plain.configure(sigma_theta=0.02).configure(sigma_r=4.0)
    for spec in (plain, configured, dataclasses.replace(configured, params={"sigma_r": 2.0, "sigma_theta": 0.5})):
        for name in ("simulate", "measurement_model"):
            bound = getattr(spec, name)
            assert isinstance(bound, BoundFunction) and bound.raw is getattr(module, name)
            assert bound.params is spec.params
    replaced = dataclasses.replace(configured, params={"sigma_r": 2.0, "sigma_theta": 0.5})
    np.testing.assert_allclose(replaced.measurement_model().R, np.diag([4.0, 0.25]))
    # the function another spec bound is bound to this spec's values
    borrowed = dataclasses.replace(plain, measurement_model=configured.measurement_model)
    assert borrowed.measurement_model.raw is module.measurement_model
    np.testing.assert_allclose(borrowed.measurement_model().R, np.diag([1.0, 0.01]))


def test_specs_compare_by_their_values_and_pickle_with_them():
    plain = HOST.sensor("range-bearing")
    assert plain == load_host().sensor("range-bearing")
    assert plain.configure(sigma_theta=0.02) == plain.configure(sigma_theta=0.02)
    assert plain.configure(sigma_theta=0.02) != plain
    assert plain.configure(sigma_theta=0.1) == plain  # the default again
    assert hash(plain.simulate) == hash(plain.configure(sigma_theta=0.02).simulate)
    back = pickle.loads(pickle.dumps(plain.configure(sigma_theta=0.02)))
    np.testing.assert_allclose(back.measurement_model().R, np.diag([1.0, 0.0004]))


def test_the_bound_functions_report_the_plugins_module_for_the_report_fingerprints():
    spec = HOST.sensor("range-bearing").configure(sigma_theta=0.02)
    assert spec.simulate.__module__ == spec.simulate.raw.__module__ == "workbench_sensors.range_bearing"
    assert spec.simulate.__name__ == "simulate" and spec.simulate.__doc__ == spec.simulate.raw.__doc__
    assert sys.modules["workbench_sensors.range_bearing"].__file__ in _module_files(spec)
    import inspect

    assert inspect.signature(spec.simulate).parameters["sigma_theta"].default == 0.02


# -- clutter generators and removers --------------------------------------------------------------------------------


def test_a_configured_clutter_generator_draws_and_declares_its_configured_rate():
    plain = HOST.clutter_generator("sonar-poisson")
    configured = plain.configure(rate_scale=2.0)
    truth = _far_truth(40, 50, seed=5)
    # lambda = rate_scale pfa area / cell = 2 x 5e-4 x 250^2 = 62.5 per ping
    np.testing.assert_allclose(configured.expected_count(truth), 62.5, rtol=1e-12)
    np.testing.assert_allclose(plain.expected_count(truth), 31.25, rtol=1e-12)
    for spec, rate in ((configured, 62.5), (plain, 31.25)):
        total = int(spec.generate(truth, generator(6, "clutter", rate)).valid.sum())
        mean = rate * truth.batch * truth.steps
        low, high = stats.poisson.ppf(1e-6, mean), stats.poisson.isf(1e-6, mean)
        assert low <= total <= high, (rate, total, low, high)


def test_a_configured_remover_removes_with_its_configured_bins():
    plain = HOST.clutter_remover("pbr-zero-doppler")
    configured = plain.configure(bins=3.0)
    rng = generator(7, "remover")
    doppler = rng.uniform(-12.0, 12.0, (3, 5, 8))
    scans = Scans(rng.normal(size=(3, 5, 8, 2)), np.ones((3, 5, 8), bool), np.arange(5.0), doppler=doppler,
                  origin=np.full((3, 5, 8), CLUTTER))
    # keep |f_D| >= bins x doppler_bin_hz: 3 x 2 Hz configured, 1 x 2 Hz by default
    np.testing.assert_array_equal(configured.remove(scans).valid, np.abs(doppler) >= 6.0)
    np.testing.assert_array_equal(plain.remove(scans).valid, np.abs(doppler) >= 2.0)
    np.testing.assert_array_equal(configured.remove(scans, bins=1.0).valid, np.abs(doppler) >= 2.0)


# -- the kit checks: every built-in passes, deliberately wrong components fail ------------------------------------


@pytest.mark.parametrize("name", sorted(HOST.components["workbench_sensors"]))
def test_every_builtin_sensor_honours_each_configured_value(name):
    spec = HOST.sensor(name)
    summary = check_configured_values(spec)
    assert summary.startswith(f"{len(spec.declared)} parameters configured") and "not tried" not in summary, summary


@pytest.mark.parametrize("name", sorted(HOST.components["workbench_clutter_generators"]))
def test_every_builtin_clutter_generator_honours_each_configured_value(name):
    spec = HOST.clutter_generator(name)
    summary = check_generator_configured_values(spec)
    assert summary.startswith(f"{len(spec.declared)} parameters configured") and "not tried" not in summary, summary


def _model_with_fixed_R(sigma: float = 2.0, bias_sigmas: float = 0.0):
    """The fault: R is 4 I whatever sigma is (a value read from the default, not the parameter)."""
    return linear_measurement(np.eye(2, 4), 4.0 * np.eye(2), name="position", frame="cartesian-2d", std=(2.0, 2.0))


def test_a_sensor_whose_model_reads_a_hard_coded_sigma_fails_naming_the_parameter():
    noise = (Param("sigma", 2.0, "position noise per axis", unit="length", above=0.0, affects="noise"),
             wrong.SENSOR_PARAMETERS[1])
    fair = dataclasses.replace(wrong.FAIR_SENSOR, parameters=noise)
    check_configured_values(fair)  # the same sensor with a model that reads sigma passes
    fixed = dataclasses.replace(fair, name="fixed-R", measurement_model=_model_with_fixed_R)
    with pytest.raises(AssertionError) as info:
        check_configured_values(fixed)
    msg = str(info.value)
    assert msg.startswith("check_configured_values: 1 of 2 parameters are not honoured")
    assert "'sigma', declared affects='noise', changed nothing in the published model's R" in msg
    assert "1 changed the simulated z" in msg  # the simulation follows it, the model does not


def _simulate_ignoring_pd(truth, rng, sigma: float = 2.0, pd: float = 0.9):
    """The fault: every scan detects the target, whatever pd is."""
    return wrong.simulate_position(truth, rng, sigma, 0.0)


def test_a_sensor_parameter_without_effect_fails_and_its_twin_passes():
    params = (wrong.SENSOR_PARAMETERS[0],
              Param("pd", 0.9, "detection probability", unit="dimensionless", minimum=0.0, maximum=1.0,
                    affects="simulation"))

    def simulate_with_pd(truth, rng, sigma: float = 2.0, pd: float = 0.9):
        s = wrong.simulate_position(truth, rng, sigma, 0.0)
        return s.with_valid(s.valid & (rng.random(s.valid.shape) < pd))

    def model(sigma: float = 2.0, pd: float = 0.9):
        return wrong.position_model(sigma)

    fair = SensorSpec("pd-sensor", "position with pd", model, simulate_with_pd, {"sigma": 2.0, "pd": 0.9}, params,
                      frame="cartesian-2d")
    assert "pd -> z, valid" in check_configured_values(fair)
    deaf = dataclasses.replace(fair, simulate=_simulate_ignoring_pd)
    with pytest.raises(AssertionError, match="'pd', declared affects='simulation', changed nothing in the simulated "
                                             "detections when configured from 0.9 to: 0.45 changed nothing; 0.95 "
                                             "changed nothing"):
        check_configured_values(deaf)


def test_a_parameter_that_reaches_the_model_in_one_setting_declares_it_with_when():
    def model(sigma: float = 2.0, polar: bool = False, sigma_theta: float = 0.01):
        return range_bearing(sigma, sigma_theta) if polar else wrong.position_model(sigma)

    def simulate(truth, rng, sigma: float = 2.0, polar: bool = False, sigma_theta: float = 0.01):
        return wrong.simulate_position(truth, rng, sigma, 0.0)

    def spec(when):
        return SensorSpec("maybe-polar", "polar or cartesian model", model, simulate,
                          {"sigma": 2.0, "polar": False, "sigma_theta": 0.01},
                          (Param("sigma", 2.0, "noise", unit="length", above=0.0, affects="noise"),
                           Param("polar", False, "polar model", "bool"),
                           Param("sigma_theta", 0.01, "bearing sigma of the polar model", unit="angle", minimum=0.0,
                                 affects="noise", when=when)),
                          frame="cartesian-2d")

    with pytest.raises(AssertionError, match="'sigma_theta', declared affects='noise', changed nothing.*Param.when"):
        check_configured_values(spec(()))
    assert "sigma_theta -> R" in check_configured_values(spec({"polar": True}))


def _generate_fixed_power(truth, rng, rate: float = 3.0, rate_factor: float = 1.0, mean_power: float = 10.0):
    """The fault: the clutter power's mean is the hard-coded 10, whatever mean_power is."""
    return wrong.generate_clutter(truth, rng, rate, rate_factor, 10.0)


def test_a_clutter_generator_that_reads_a_hard_coded_value_fails_naming_the_parameter():
    assert "mean_power -> snr" in check_generator_configured_values(wrong.FAIR_CLUTTER)
    fixed = dataclasses.replace(wrong.FAIR_CLUTTER, name="fixed-power", generate=_generate_fixed_power)
    with pytest.raises(AssertionError) as info:
        check_generator_configured_values(fixed)
    msg = str(info.value)
    assert "1 of 3 parameters are not honoured" in msg
    assert ("'mean_power' changed nothing in the clutter when configured from 10 to: 5 changed nothing; 16 changed "
            "nothing") in msg


def test_a_clutter_parameter_without_effect_fails():
    def generate(truth, rng, rate: float = 3.0, spread: float = 1.0):
        return wrong.generate_clutter(truth, rng, rate, 1.0, 10.0)

    deaf = ClutterGeneratorSpec("deaf", "spread does nothing", generate, {"rate": 3.0, "spread": 1.0},
                                (Param("rate", 3.0, "mean count", minimum=0.0), Param("spread", 1.0, "unused",
                                                                                       above=0.0)),
                                frame="cartesian-2d")
    with pytest.raises(AssertionError, match="1 of 2 parameters are not honoured.*'spread' changed nothing"):
        check_generator_configured_values(deaf)


def test_a_function_that_is_not_its_own_params_function_fails_the_reference_comparison():
    calls = []

    def drifting_model(sigma: float = 2.0, bias_sigmas: float = 0.0):
        """Each call's R grows: a function of something besides its parameters."""
        calls.append(1)
        return wrong.position_model(sigma + 1e-3 * len(calls))

    drifting = dataclasses.replace(wrong.FAIR_SENSOR, measurement_model=drifting_model)
    with pytest.raises(AssertionError, match="is not its plugin's functions called with the configured params: "
                                             "measurement_model\\(\\) differs"):
        check_configured_values(drifting)


def test_a_when_condition_may_ask_for_at_least_a_value():
    from workbench.params import AtLeast, Param

    p = Param("site_pd", 0.7, "probability a site is seen", unit="dimensionless", minimum=0.0, maximum=1.0,
              when={"sites": AtLeast(1)})
    assert p.unmet({"sites": 0}) == (("sites", AtLeast(1)),) and p.unmet({"sites": None}) != ()
    assert p.unmet({"sites": 1}) == () and p.unmet({"sites": 40}) == () and p.reaches_model({"sites": 3})
    assert p.role == "only if sites >= 1"
