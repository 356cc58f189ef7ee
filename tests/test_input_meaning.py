"""Inputs are checked for meaning, not only for shape (issue 29, classes 1, 4, 5, 7 and 11).

Each test feeds a wrong input through the public API (or the CLI, where a scenario file is the natural route) and
expects a named error (the message names the key and the problem) or a correct result checked against an
independent value (a closed form, a hand computation).
"""

import math
import textwrap

import numpy as np
import pytest

import workbench as wb
from workbench import particle_core
from workbench.cli import EXIT, main
from workbench.metrics.ospa import gospa, ospa
from workbench.params import Param, check_value
from workbench.plugins import BUILTIN_DISTRIBUTION
from workbench.scenario import load_scenario
from workbench.types import InputError
from workbench.units import DIMENSIONS

HOST = wb.load_host()

SCENARIO = """
[scenario]
name = "meaning"
seed = 1
runs = 2
steps = 5
dt = "1 s"
{scenario_extra}

[motion]
model = "constant_velocity"
dims = 2
sigma_a = "0.5 m/s^2"

[truth]
initial_state = [100.0, 50.0, 1.0, 1.0]
{truth_extra}

[sensor]
plugin = "range-bearing"
{sensor_extra}

[prior]
mean = [100.0, 50.0, 1.0, 1.0]
std = {prior_std}

[filters]
names = {names}
"""


def _scenario(tmp_path, scenario_extra="", truth_extra="", sensor_extra="", prior_std="[5.0, 5.0, 1.0, 1.0]",
              names='["kf"]'):
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(SCENARIO.format(scenario_extra=scenario_extra, truth_extra=truth_extra,
                                                    sensor_extra=sensor_extra, prior_std=prior_std, names=names)))
    return path


def _cli_error(tmp_path, capsys, **parts) -> str:
    """Run the scenario through ``workbench run``: exit status 2 and the one error line."""
    code = main(["run", str(_scenario(tmp_path, **parts)), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == EXIT["input"], err
    assert err.startswith("workbench: error: ") and "Traceback" not in err
    return err


# -- class 1: every value has a unit dimension that refuses a value of another dimension -------------------------


def _builtin_components():
    dist = {p.name: p.distribution for p in HOST.plugins}
    for hook, comps in HOST.components.items():
        for name, spec in comps.items():
            if dist.get(HOST.owner.get((hook, name))) == BUILTIN_DISTRIBUTION and getattr(spec, "declared", None):
                yield hook, name, spec


#: Dimensions whose values may be negative (positions, levels in dB, gains, a state's own components such as a
#: birth mean): their range is the dimension's limit.
SIGNED = {"length", "decibel", "angle", "state"}


def test_every_builtin_parameter_declares_a_dimension_and_a_range():
    seen = 0
    problems = []
    for hook, name, spec in _builtin_components():
        for p in spec.declared:
            if p.type == "bool":
                continue
            if p.type == "str":
                if not p.choices:
                    problems.append(f"{name}.{p.name}: a string without choices")
                continue
            seen += 1
            where = f"{hook} {name}.{p.name}"
            if p.unit not in DIMENSIONS:
                problems.append(f"{where}: no dimension declared (unit={p.unit!r})")
                continue
            low, high = p.bounds
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                problems.append(f"{where}: range [{low}, {high}]")
            if p.minimum is None and p.above is None and p.unit not in SIGNED:
                problems.append(f"{where}: no lower bound, and a {p.unit} is not signed")
            if "sigma" in p.name and low < 0:
                problems.append(f"{where}: a standard deviation that may be negative")
            if p.name in ("pd", "pfa", "persistent_pd", "false_alarm_pfa", "switch_on", "switch_off") and not (
                    low >= 0 and high <= 1):
                problems.append(f"{where}: a probability outside [0, 1]: [{low}, {high}]")
            if p.name == "particles" and p.footprint is None:
                problems.append(f"{where}: a particle count not bounded by memory (no footprint)")
            try:  # the default is inside its own range and dimension
                check_value(p, p.default, where)
            except InputError as exc:
                problems.append(f"{where}: the default fails: {exc}")
    assert seen > 80, seen  # every numeric parameter of the built-in filters, sensors and clutter plugins
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("key, value, allowed", [
    ("gate", '"3 km"', "chi2, sigma"),
])
def test_a_gate_in_km_is_refused_by_the_cli(tmp_path, capsys, key, value, allowed):
    err = _cli_error(tmp_path, capsys, scenario_extra=f'tracker = "nearest-neighbour"\n{key} = {value}')
    assert f"[scenario] {key}: '3 km' is a length" in err and f"(units: {allowed})" in err


def test_a_turn_rate_in_km_is_refused_by_the_cli(tmp_path, capsys):
    legs = 'legs = [{kind = "turn", duration = "3 s", turn_rate = "3 km"}]'
    err = _cli_error(tmp_path, capsys, truth_extra=legs)
    assert "[truth.legs[0]] turn_rate: '3 km' is a length, but this key expects an angular rate" in err
    assert "(units: rad/s, mrad/s, deg/s)" in err


def test_gate_in_sigma_and_turn_rate_in_deg_per_s_are_converted(tmp_path):
    legs = 'legs = [{kind = "turn", duration = "3 s", turn_rate = "3 deg/s"}]'
    sc = load_scenario(_scenario(tmp_path, scenario_extra='tracker = "nearest-neighbour"\ngate = "3 sigma"',
                                 truth_extra=legs), HOST)
    assert sc.gate == 9.0  # a Mahalanobis distance of 3 is d^2 = 9
    assert sc.legs[0].turn_rate == pytest.approx(3.0 * math.pi / 180.0, rel=1e-15)
    sc = load_scenario(_scenario(tmp_path, scenario_extra='tracker = "nearest-neighbour"\ngate = 9.21'), HOST)
    assert sc.gate == 9.21


def test_a_dimensionless_parameter_refuses_a_unit(tmp_path, capsys):
    with pytest.raises(InputError, match=r"threshold: '3 km' carries the unit 'km', but this key takes a pure number"):
        HOST.filter("sir").configure(threshold="3 km")
    err = _cli_error(tmp_path, capsys, names='["ukf(kappa=3 km)"]')
    assert "kappa: '3 km' carries the unit 'km'" in err
    # a chi-square gate of a filter: 'km' refused, 'sigma' converted
    with pytest.raises(InputError, match=r"nis_threshold: '3 km' is a length, but this key expects a gate"):
        HOST.filter("ekf-nis").configure(nis_threshold="3 km")
    assert HOST.filter("ekf-nis").configure(nis_threshold="4 sigma").params["nis_threshold"] == 16.0


def test_an_angle_held_in_degrees_converts_radians():
    sonar = HOST.sensor("active-sonar").configure(sigma_b_deg="0.01 rad")
    assert sonar.params["sigma_b_deg"] == pytest.approx(0.01 * 180.0 / math.pi, rel=1e-15)
    with pytest.raises(InputError, match=r"sigma_b_deg: '1 m' is a length, but this key expects an angle \(in "
                                         r"degrees\)"):
        HOST.sensor("active-sonar").configure(sigma_b_deg="1 m")


def test_an_undeclared_dimension_takes_bare_numbers_only():
    legacy = Param("gain", 1.0, "a third-party parameter with no declared dimension")
    assert check_value(legacy, 2.5, "plugin: gain") == 2.5
    with pytest.raises(InputError, match=r"plugin: gain: '3 km' carries the unit 'km'"):
        check_value(legacy, "3 km", "plugin: gain")
    with pytest.raises(ValueError, match="unknown unit dimension 'parsec'"):
        Param("x", 1.0, "d", unit="parsec")


# -- class 5: a range on every parameter, so a filter cannot be configured into non-PSD covariances --------------


def test_a_negative_ukf_kappa_is_refused(tmp_path, capsys):
    with pytest.raises(InputError, match=r"filter 'ukf'.*kappa: must be >= 0, got -3"):
        HOST.filter("ukf").configure(kappa=-3.0)
    err = _cli_error(tmp_path, capsys, names='["ukf(kappa=-3)"]')
    assert "kappa: must be >= 0, got -3" in err


def test_a_kappa_of_zero_keeps_the_ukf_covariances_semi_definite():
    """The smallest kappa the range allows: on a linear model the UKF is the Kalman filter (an independent
    computation), and every covariance it writes is symmetric and semi-definite."""
    motion = wb.constant_velocity(2, 1.0, 0.5)
    model = wb.linear_measurement(np.hstack([np.eye(2), np.zeros((2, 2))]), 4.0 * np.eye(2))
    truth = wb.sample_motion(np.tile([0.0, 0.0, 1.0, 1.0], (3, 1)), motion, 6, wb.generator(2, "truth"))
    z = truth.states[..., :2] + 2.0 * wb.generator(2, "noise").standard_normal(truth.states[..., :2].shape)
    scans = wb.Scans(z[:, :, None, :], np.ones(z.shape[:2] + (1,), bool), truth.times)
    prior = wb.Gaussian.broadcast([0.0, 0.0, 1.0, 1.0], np.diag([9.0, 9.0, 1.0, 1.0]), 3)
    ukf = wb.run(HOST.filter("ukf").configure(kappa=0.0), scans, motion, model, prior=prior)
    kf = wb.run(HOST.filter("kf"), scans, motion, model, prior=prior)
    np.testing.assert_allclose(ukf.mean, kf.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ukf.cov, kf.cov, rtol=1e-9, atol=1e-9)
    assert np.linalg.eigvalsh(ukf.cov).min() > 0


@pytest.mark.parametrize("component, kind, key, value, message", [
    ("sir", "filter", "threshold", -0.5, "threshold: must be >= 0"),
    ("tbd-pf", "filter", "switch_on", 1.5, "switch_on: must be <= 1"),
    ("crpf-100", "filter", "q", 400.0, "q: must be <= 16"),
    ("active-sonar", "sensor", "pd", 1.2, "pd: must be <= 1"),
    ("range-bearing", "sensor", "sigma_r", -1.0, "sigma_r: must be >= 0 m"),
    ("sonar-poisson", "clutter", "rate_scale", 1e9, "rate_scale: must be <= 1e+06"),
])
def test_out_of_range_values_are_refused_naming_the_key(component, kind, key, value, message):
    spec = {"filter": HOST.filter, "sensor": HOST.sensor}.get(kind, lambda n: HOST.components[
        "workbench_clutter_generators"][n])(component)
    with pytest.raises(InputError, match=message.replace("+", r"\+")):
        spec.configure(**{key: value})


# -- class 4: the public records refuse dtypes they cannot hold ---------------------------------------------------


def _scan_parts(B=2, T=3):
    z = np.arange(B * T * 2, dtype=float).reshape(B, T, 1, 2)
    return z, np.ones((B, T, 1), bool), np.arange(T, dtype=float)


def test_complex_measurements_are_refused():
    z, valid, times = _scan_parts()
    with pytest.raises(InputError, match=r"Scans.z holds complex numbers"):
        wb.Scans(z + 1j, valid, times)
    with pytest.raises(InputError, match=r"Scan.z holds complex numbers"):
        wb.Scan(z[:, 0] * (1 + 2j), valid[:, 0])
    with pytest.raises(InputError, match=r"Gaussian.mean holds complex numbers"):
        wb.Gaussian(np.zeros((1, 2), complex), np.eye(2)[None])
    with pytest.raises(InputError, match=r"Gaussian.broadcast: cov holds complex numbers"):
        wb.Gaussian.broadcast([0.0, 0.0], np.eye(2) * (1 + 0j), 2)


def test_datetime_times_are_refused_with_how_to_convert():
    z, valid, _ = _scan_parts()
    stamps = np.array(["2024-01-01T00:00:00", "2024-01-01T00:00:01", "2024-01-01T00:00:02"], dtype="datetime64[s]")
    with pytest.raises(InputError, match=r"Scans.times holds datetime64\[s\] values.*np.timedelta64\(1, 's'\)"):
        wb.Scans(z, valid, stamps)
    with pytest.raises(InputError, match=r"Truth.times holds timedelta64"):
        wb.Truth(np.zeros((1, 3, 4)), stamps - stamps[0])
    with pytest.raises(InputError, match=r"Scan.time must be a real number, got datetime64"):
        wb.Scan(z[:, 0], valid[:, 0], time=stamps[0])
    # converted as the message says, the same stamps are accepted as seconds
    seconds = (stamps - stamps[0]) / np.timedelta64(1, "s")
    assert wb.Scans(z, valid, seconds).times.tolist() == [0.0, 1.0, 2.0]


def test_a_text_mask_is_refused_and_a_0_1_mask_reads_as_booleans():
    z, valid, times = _scan_parts()
    text = np.full(valid.shape, "False")
    with pytest.raises(InputError, match=r"Scans.valid holds text"):
        wb.Scans(z, text, times)
    with pytest.raises(InputError, match=r"Scan.valid holds str 'False'"):
        wb.Scan(z[:, 0], np.array([["False"], ["True"]], dtype=object))
    with pytest.raises(InputError, match=r"Scan.valid is a mask: it takes booleans \(or 0 and 1\), got 2"):
        wb.Scan(z[:, 0], np.array([[1], [2]]))
    ints = wb.Scan(z[:, 0], np.array([[0], [1]]))
    assert ints.valid.dtype == bool and ints.valid.tolist() == [[False], [True]]
    assert ints.z[0].tolist() == [[0.0, 0.0]]  # the masked row is zeroed, as for a boolean mask
    with pytest.raises(InputError, match=r"Scans.origin takes whole numbers, got 1.5"):
        wb.Scans(z, valid, times, origin=np.full(valid.shape, 1.5))


def test_int_bool_and_object_numbers_still_work():
    z, valid, times = _scan_parts()
    a = wb.Scans(z.astype(np.int32), valid.astype(np.int8), times.astype(np.int64))
    assert a.z.dtype == float and a.valid.dtype == bool and a.times.tolist() == [0.0, 1.0, 2.0]
    np.testing.assert_array_equal(a.z, z)
    b = wb.Scans(z.astype(object), valid, times)
    np.testing.assert_array_equal(b.z, z)
    with pytest.raises(InputError, match=r"Scans.z holds str '1.5'"):
        wb.Scans(np.full(z.shape, "1.5", dtype=object), valid, times)


def test_scan_single_needs_a_2d_z():
    with pytest.raises(InputError, match=r"Scan.single: z must have shape \(B, m\).*got shape \(3,\); write "
                                         r"z\[:, None\]"):
        wb.Scan.single(np.array([1.0, 2.0, 3.0]))
    with pytest.raises(InputError, match=r"Scan.single: present must have shape \(3,\)"):
        wb.Scan.single(np.zeros((3, 2)), present=[True, False])
    scan = wb.Scan.single(np.array([[1.0, 2.0], [3.0, 4.0]]), present=[1, 0])
    assert scan.z.shape == (2, 1, 2) and scan.valid.tolist() == [[True], [False]]
    assert scan.z[:, 0].tolist() == [[1.0, 2.0], [0.0, 0.0]]


# -- class 7: sizes and extreme finite numbers are range-checked before NumPy sees them --------------------------


@pytest.mark.parametrize("batch, message", [(-1, "batch must be >= 1, got -1"), (0, "batch must be >= 1, got 0"),
                                            (2.5, "batch must be a whole number"), (True, "batch must be a whole"),
                                            (10 ** 12, r"batch = 1000000000000 needs about .* GiB")])
def test_gaussian_broadcast_checks_the_batch(batch, message):
    with pytest.raises(InputError, match=r"Gaussian.broadcast: " + message):
        wb.Gaussian.broadcast([0.0, 0.0], np.eye(2), batch)


@pytest.mark.parametrize("steps, message", [(-1, "steps must be >= 1, got -1"),
                                            (10 ** 12, r"steps = 1000000000000 needs about")])
def test_sample_motion_checks_the_steps(steps, message):
    motion = wb.constant_velocity(2, 1.0, 0.5)
    with pytest.raises(InputError, match=r"sample_motion: " + message):
        wb.sample_motion(np.zeros((2, 4)), motion, steps, wb.generator(0, "truth"))


def test_scan_empty_checks_its_sizes():
    with pytest.raises(InputError, match=r"Scan.empty: batch must be >= 1, got -1"):
        wb.Scan.empty(-1, 2)
    assert wb.Scan.empty(3, 2).z.shape == (3, 0, 2)


def test_an_accuracy_of_1e200_is_refused(tmp_path, capsys):
    with pytest.raises(InputError, match=r"sigma_r: 1e\+200 is beyond the physical range of a length "
                                         r"\(\|value\| <= 1e\+09 m\)"):
        HOST.sensor("range-bearing").configure(sigma_r=1e200)
    err = _cli_error(tmp_path, capsys, sensor_extra="sigma_r = 1e200")
    assert "[sensor] sensor 'range-bearing': sigma_r: 1e+200 is beyond the physical range" in err
    err = _cli_error(tmp_path, capsys, prior_std="[1e200, 5.0, 1.0, 1.0]")
    assert "[prior] std[0]: 1e+200 is beyond the physical range of a number" in err


def test_a_particle_count_beyond_memory_is_refused_before_allocation():
    motion = wb.constant_velocity(2, 1.0, 0.5)
    model = wb.linear_measurement(np.hstack([np.eye(2), np.zeros((2, 2))]), np.eye(2))
    scans = wb.Scans(np.zeros((1, 2, 1, 2)), np.ones((1, 2, 1), bool), np.arange(2.0))
    prior = wb.Gaussian.broadcast([0.0, 0.0, 0.0, 0.0], np.eye(4), 1)
    for name in ("sir", "crpf-100"):
        who = rf"filter '{name}\(particles=1000000000000\)'"
        with pytest.raises(InputError, match=who + r": particles = 1e\+12 for 1 runs needs about"):
            wb.run(HOST.filter(name).configure(particles=10 ** 12), scans, motion, model, prior=prior,
                   rng=wb.generator(0, "run"))
    with pytest.raises(InputError, match=r"particles: 1000000000000000000 is beyond the physical range"):
        HOST.filter("sir").configure(particles=10 ** 18)


def test_an_ospa_order_of_400_is_refused_and_a_large_safe_order_is_exact():
    x = np.array([[0.0, 0.0]])
    y = np.array([[3.0, 4.0]])
    with pytest.raises(InputError, match=r"the order p = 400 with the cut-off c = 100 puts c\^p = 10\^800 outside "
                                         r"the float range.*use p <= 145"):
        ospa(x, y, 100.0, 400.0)
    with pytest.raises(InputError, match=r"the order p = 400"):
        gospa(x, y, 100.0, 400.0)
    # one pair at distance 5 < c: OSPA = (5^p / 1)^(1/p) = 5 for every p; GOSPA's localisation is 5^p
    assert float(ospa(x, y, 100.0, 140.0).distance) == pytest.approx(5.0, rel=1e-12)
    assert float(gospa(x, y, 100.0, 100.0).localisation) == pytest.approx(5.0 ** 100, rel=1e-12)
    # |x - y|^p underflows: refused rather than read as a perfect match
    with pytest.raises(InputError, match=r"the order p = 200 underflows \|x - y\|\^p to 0 for a distance of 0.01"):
        ospa(x, np.array([[0.01, 0.0]]), 10.0, 200.0)
    with pytest.raises(InputError, match=r"the order p must be a real number, got str"):
        ospa(x, y, 100.0, "2")


# -- class 11: a filter that draws needs an explicit generator ----------------------------------------------------


def _quickstart(batch=4):
    motion = wb.random_walk_velocity(dims=2, dt=1.0, sigma_a=0.1)
    truth = wb.sample_motion(np.tile([100.0, 50.0, -1.0, 1.0], (batch, 1)), motion, steps=5,
                             rng=wb.generator(0, "truth"))
    sensor = HOST.sensor("range-bearing")
    scans = sensor.simulate(truth, wb.generator(0, "detections"))
    prior = wb.Gaussian.broadcast([110.0, 40.0, 0.0, 0.0], np.diag([100.0, 100.0, 4.0, 4.0]), batch=batch)
    return motion, scans, sensor.measurement_model(), prior


@pytest.mark.parametrize("name", ["sir", "crpf-100", "sir-jm"])
def test_a_filter_that_draws_without_rng_names_the_fix(name):
    motion, scans, model, prior = _quickstart()
    with pytest.raises(InputError, match=rf"filter '{name}' draws random numbers but no generator was given.*"
                                         r"rng=wb.generator\(seed, key\)"):
        wb.run(HOST.filter(name), scans, motion, model, prior=prior)


def test_with_rng_the_same_seed_gives_the_same_track_and_a_deterministic_filter_needs_none():
    motion, scans, model, prior = _quickstart()
    a = wb.run(HOST.filter("sir"), scans, motion, model, prior=prior, rng=wb.generator(1, "sir"))
    b = wb.run(HOST.filter("sir"), scans, motion, model, prior=prior, rng=wb.generator(1, "sir"))
    np.testing.assert_array_equal(a.mean, b.mean)
    assert np.isfinite(a.mean).all()
    ukf = wb.run(HOST.filter("ukf"), scans, motion, model, prior=prior)  # draws nothing: no rng needed
    assert np.isfinite(ukf.mean).all()


def test_particle_core_refuses_a_missing_generator():
    prior = wb.Gaussian.broadcast([0.0, 0.0], np.eye(2), 2)
    with pytest.raises(InputError, match=r"particle_core.init draws random numbers but got no generator"):
        particle_core.init(prior, None, 10)
