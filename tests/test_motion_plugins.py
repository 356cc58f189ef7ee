"""Motion models as plugins: the hook, the host, the built-in registrations, references with units, and
``workbench check-plugin`` on a motion model (a deliberately wrong one fails with readable messages)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from fixtures import wrong_motion

from workbench import hookimpl
from workbench.cli import check_plugin
from workbench.models import (constant_acceleration, constant_velocity, coordinated_turn, coordinated_turn_rate,
                              growth_model, random_walk_velocity, singer)
from workbench.params import Param
from workbench.plugins import UnknownComponent, load_host
from workbench.specs import MotionModelSpec
from workbench.types import InputError

HOST = load_host()


def _spec(name, build, parameters=(), **extra):
    return MotionModelSpec(name, f"test model {name}", build, params={p.name: p.default for p in parameters},
                           parameters=tuple(parameters), **extra)


def _plugin(*specs):
    return SimpleNamespace(workbench_motion_models=hookimpl(lambda: list(specs)))


_SIGMA_W = Param("sigma_w", 0.01, "turn-rate noise", unit="angular_rate_noise", minimum=0.0)
#: the fixture's correct coordinated turn (tests/fixtures/wrong_motion.py), wrapped in a spec
TURN = _spec("fixture-turn", lambda dt, sigma_w: wrong_motion.coordinated_turn(dt, 0.5, sigma_w), (_SIGMA_W,), dims=2,
             example_state=(300.0, 200.0, -3.0, 4.0, 0.05), example_std=(5.0, 5.0, 2.0, 2.0, 0.02))


# -- the built-ins, registered through the entry point ------------------------------------------------------------

#: each built-in name -> the builder called directly with the same values (the registered defaults, written out)
DIRECT = {
    "cv2d": lambda dt: constant_velocity(2, dt, 0.5),
    "cv3d": lambda dt: constant_velocity(3, dt, 0.5),
    "rwv2d": lambda dt: random_walk_velocity(2, dt, 0.1),
    "ca2d": lambda dt: constant_acceleration(2, dt, 0.1),
    "ca3d": lambda dt: constant_acceleration(3, dt, 0.1),
    "singer2d": lambda dt: singer(2, dt, 1.0, 20.0),
    "singer3d": lambda dt: singer(3, dt, 1.0, 20.0),
    "ct": lambda dt: coordinated_turn(dt, math.radians(3.0), 0.5),
    "ct-rate": lambda dt: coordinated_turn_rate(dt, 0.5, 0.01),
    "growth": lambda dt: growth_model(math.sqrt(10.0)),
}


def test_every_builtin_motion_model_is_registered_by_its_plugin():
    assert set(HOST.motion_models) == set(DIRECT)
    info = next(p for p in HOST.plugins if p.name == "motion_models")
    assert info.status == "ok" and info.distribution == "workbench"
    assert {("motion model", name) for name in DIRECT} <= set(info.provides)


@pytest.mark.parametrize("name", sorted(DIRECT))
def test_a_builtin_builds_what_its_builder_builds_with_the_declared_defaults(name):
    dt = 1.0 if name == "growth" else 0.7
    built, direct = HOST.motion_model(name, dt=dt), DIRECT[name](dt)
    assert type(built) is type(direct) and built.dim == direct.dim and built.dt == direct.dt
    np.testing.assert_array_equal(built.F, direct.F)
    np.testing.assert_array_equal(built.Q, direct.Q)
    x = np.random.default_rng(0).normal(size=(3, direct.dim)) * 10.0
    np.testing.assert_array_equal(built.f(x), direct.f(x))
    spec = HOST.motion_models[name]
    assert len(spec.example_state) == direct.dim and all(p.unit is not None for p in spec.declared)


def test_a_reference_with_parameters_and_units_builds_the_configured_model():
    built = HOST.motion_model("ct(omega=3 deg/s, sigma_a=0.2 m/s^2)", dt="2 s")
    direct = coordinated_turn(2.0, math.radians(3.0), 0.2)
    np.testing.assert_allclose(built.F, direct.F, rtol=1e-15, atol=0)
    np.testing.assert_allclose(built.Q, direct.Q, rtol=1e-15, atol=0)
    assert HOST.motion_model("ct-rate", dt=1.0, sigma_omega=0.03).Q[4, 4] == pytest.approx(0.03**2, rel=1e-12)


@pytest.mark.parametrize("reference, message", [
    ("ct(omega=3 km)", r"motion model 'ct': omega: '3 km' is a length, but this key expects an angular rate"),
    ("ct-rate(sigma_omega=3 deg/s)", r"sigma_omega: '3 deg/s' carries the unit 'deg/s', but this key takes a bare "
                                     r"number in rad/s/sqrt\(s\)"),
    ("ct-rate(sigma_a=-1)", r"motion model 'ct-rate': sigma_a: must be >= 0"),
    ("singer2d(tau=0 s)", r"motion model 'singer2d': tau: must be > 0"),
    ("ct-rate(sigma_omga=0.1)", r"motion model 'ct-rate': unknown parameter 'sigma_omga' \(parameters: sigma_a, "
                                r"sigma_omega\)"),
])
def test_wrong_values_are_refused_naming_the_model_and_the_key(reference, message):
    with pytest.raises(InputError, match=message):
        HOST.motion_model(reference)


def test_a_configured_spec_is_honoured_and_refuses_undeclared_names():
    spec = HOST.motion_models["cv2d"].configure(sigma_a="2 m/s^2")
    assert spec.params["sigma_a"] == 2.0
    np.testing.assert_array_equal(spec.model(1.0).Q, constant_velocity(2, 1.0, 2.0).Q)
    np.testing.assert_array_equal(spec.build(1.0).Q, constant_velocity(2, 1.0, 2.0).Q)  # bound to its values
    with pytest.raises(InputError, match=r"motion model 'cv2d': unknown parameter 'sigma_b'"):
        spec.configure(sigma_b=1.0)
    with pytest.raises(InputError, match=r"motion model 'growth' is a discrete-time model with steps of 1"):
        HOST.motion_model("growth", dt=0.5)


def test_an_unknown_model_is_refused_with_the_installed_ones():
    with pytest.raises(UnknownComponent, match=r"no motion model named 'warp' is installed \(installed: ca2d, ca3d, "
                                               r"ct, ct-rate, cv2d"):
        HOST.motion_model("warp")
    with pytest.raises(UnknownComponent, match=r"'ukf' is a filter, not a motion model"):
        HOST.motion_model("ukf")


# -- plugins that add motion models ----------------------------------------------------------------------------------


def test_a_plugin_adding_a_motion_model_is_found_by_name():
    host = load_host(extra_plugins=[("turns", _plugin(TURN))])
    info = next(p for p in host.plugins if p.name == "turns")
    assert info.status == "ok" and info.provides == (("motion model", "fixture-turn"),)
    model = host.motion_model("fixture-turn(sigma_w=0.02)", dt=2.0)
    direct = wrong_motion.coordinated_turn(2.0, 0.5, 0.02)
    np.testing.assert_array_equal(model.Q, direct.Q)
    x = np.array([[1.0, 2.0, 3.0, 4.0, 0.1]])
    np.testing.assert_array_equal(model.f(x), direct.f(x))
    assert host.find("fixture-turn")[0][0] == "motion model"


def test_a_builtin_motion_model_name_is_reserved():
    impostor = _spec("ct-rate", lambda dt: constant_velocity(2, dt, 9.0))
    host = load_host(extra_plugins=[("aaa-turns", _plugin(impostor))])
    info = next(p for p in host.plugins if p.name == "aaa-turns")
    assert info.status == "ok" and info.provides == ()
    assert "motion model 'ct-rate'" in info.warnings[0] and "built-in names are reserved" in info.warnings[0]
    assert host.motion_model("ct-rate").dim == 5  # the built-in keeps it


def test_two_models_of_one_name_in_one_plugin_make_it_broken():
    host = load_host(extra_plugins=[("twice", _plugin(TURN, TURN))])
    info = next(p for p in host.plugins if p.name == "twice")
    assert info.status == "broken" and "motion model name 'fixture-turn' is provided twice" in info.error


@pytest.mark.parametrize("spec, fragment", [
    (_spec("no-model", lambda dt: "a string"), "its build function returned a str, not a MotionModel"),
    (_spec("short-example", lambda dt: constant_velocity(2, dt, 0.5), example_state=(1.0, 2.0),
           example_std=(1.0, 1.0)), "example_state and example_std must each give the 4 components"),
    (_spec("too-many-axes", lambda dt: constant_velocity(2, dt, 0.5), dims=5),
     "dims must be a whole number of position axes from 1 to the state dimension 4, got 5"),
    (_spec("raises", lambda dt: constant_velocity(0, dt, 0.5)), "building it with its own parameter values"),
])
def test_a_motion_model_that_cannot_build_what_it_declares_makes_its_plugin_broken(spec, fragment):
    host = load_host(extra_plugins=[("bad", _plugin(spec))])
    info = next(p for p in host.plugins if p.name == "bad")
    assert info.status == "broken" and fragment in info.error and spec.name in info.error


# -- check-plugin runs the motion-model kit -----------------------------------------------------------------------

WRONG = _plugin(
    _spec("turn-jacobian-off", lambda dt: wrong_motion.coordinated_turn(dt, cls=wrong_motion.TurnJacobianOff)),
    _spec("not-psd", lambda dt: wrong_motion.not_psd_noise(dt)),
)


def test_check_plugin_runs_the_motion_kit_on_a_builtin():
    lines = []
    assert check_plugin(HOST, "ct-rate", out=lines.append) == 0
    assert lines[0].startswith("-- motion model ct-rate (plugin motion_models")
    assert any(line.startswith("PASSED   ct-rate-check_jacobian") for line in lines)
    assert ", 0 failed" in lines[-1]


@pytest.mark.parametrize("name, check, fragment", [
    ("turn-jacobian-off", "check_jacobian", "jacobian differs from the central differences of f"),
    ("not-psd", "check_noise_psd", "not positive semi-definite"),
])
def test_check_plugin_fails_a_wrong_registered_motion_model_readably(name, check, fragment):
    host = load_host(extra_plugins=[("wrong", WRONG)])
    lines = []
    assert check_plugin(host, name, kind="motion-model", out=lines.append) == 1
    failed = [line for line in lines if line.startswith(f"FAILED   {name}-{check}")]
    assert failed and fragment in failed[0] and "Traceback" not in "\n".join(lines)
