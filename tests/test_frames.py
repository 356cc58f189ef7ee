"""Measurement frames: the built-ins are always known; plugins add frames through ``workbench_frames``, found by name
once the host has loaded them, usable by their sensors' measurement models, checked by the sensor kit, and refused
(the plugin broken) when they redefine a built-in frame or another plugin's."""

import numpy as np
import pytest

from workbench import frames, hookimpl
from workbench.frames import BUILTIN_FRAMES, FRAMES, Frame
from workbench.models import MeasurementModel
from workbench.params import Param
from workbench.plugins import load_host
from workbench.specs import SensorSpec
from workbench.testing import run_checks
from workbench.types import InputError, Scans

# -- a fixture plugin: an azimuth-elevation frame (two angles, 3-D space) and a sensor that makes detections in it --

AZEL = Frame("test-azimuth-elevation", ("azimuth", "elevation"), ("rad", "rad"), (True, True),
             "azimuth counter-clockwise from +x and elevation above the x-y plane, from the sensor", 3)


def _azel(x):
    x = np.asarray(x, dtype=float)
    return np.stack([np.arctan2(x[..., 1], x[..., 0]), np.arctan2(x[..., 2], np.hypot(x[..., 0], x[..., 1]))], -1)


def azel_model(sigma=0.01):
    return MeasurementModel("azel", _azel, sigma**2 * np.eye(2), angular=(True, True), frame=AZEL.name,
                            std=(sigma, sigma), sensor_position=(0.0, 0.0, 0.0))


def azel_simulate(truth, rng, sigma=0.01):
    B, T, _ = truth.states.shape
    z = _azel(truth.states) + sigma * rng.standard_normal((B, T, 2))
    z = np.angle(np.exp(1j * z))  # wrapped to (-pi, pi]
    return Scans(z[:, :, None, :], np.ones((B, T, 1), bool), truth.times, origin=np.zeros((B, T, 1), int))


AZEL_SENSOR = SensorSpec("test-azel", "azimuth and elevation", azel_model, azel_simulate, {"sigma": 0.01},
                         (Param("sigma", 0.01, "angle noise", unit="angle", above=0.0, affects="noise"),),
                         frame=AZEL.name)


class AzElPlugin:
    @hookimpl
    def workbench_frames(self):
        return [AZEL]

    @hookimpl
    def workbench_sensors(self):
        return [AZEL_SENSOR]


def _plugin(*items):
    class Plugin:
        @hookimpl
        def workbench_frames(self):
            return list(items)

    return Plugin()


def _status(host, name):
    return next(p for p in host.plugins if p.name == name)


def test_the_built_in_bearing_frame():
    f = frames.frame("bearing")
    assert (f.components, f.units, f.angular, f.space, f.dim) == (("bearing",), ("rad",), (True,), 2, 1)
    with pytest.raises(InputError, match="does not give a Cartesian position"):
        f.to_position(np.array([[0.3]]))
    # the built-ins are there with no host loaded (a fresh interpreter sees them too: they are module constants)
    assert set(BUILTIN_FRAMES) <= set(FRAMES) and "bearing" in BUILTIN_FRAMES
    # positions come in the frame's declared space
    assert frames.frame("range-bearing").to_position(np.array([2.0, np.pi / 2])) == pytest.approx([0.0, 2.0])
    assert frames.frame("position-doppler-3d").to_position(np.array([1.0, 2.0, 3.0, 4.0])).tolist() == [1, 2, 3]


@pytest.mark.parametrize("kwargs, text", [
    (dict(units=("m",)), "one entry each per component"),
    (dict(units=("m", "m")), "angular components ['elevation'] must be in 'rad'"),
    (dict(space=0), "space"),
    (dict(components=("a", "a")), "distinct"),
    (dict(name="bad(name)"), "name"),
])
def test_a_self_contradicting_frame_is_refused_naming_it(kwargs, text):
    fields = dict(name="t", components=("azimuth", "elevation"), units=("rad", "rad"), angular=(False, True), doc="",
                  space=3)
    fields.update(kwargs)
    with pytest.raises(InputError, match="measurement frame") as info:
        Frame(**fields)
    assert text in str(info.value)


def test_a_plugin_frame_is_found_by_name_and_used_by_its_sensor():
    with pytest.raises(InputError, match="known once the plugin host has loaded|unknown measurement frame"):
        frames.frame("test-azimuth-elevation-2")  # not provided by any plugin: unknown
    host = load_host(entry_points=[], extra_plugins=[("azel", AzElPlugin())])
    assert _status(host, "azel").status == "ok", _status(host, "azel").error
    assert ("frame", AZEL.name) in _status(host, "azel").provides
    assert frames.frame(AZEL.name) is AZEL and host.frame(AZEL.name) is AZEL and FRAMES[AZEL.name] is AZEL
    assert host.frame("bearing") is BUILTIN_FRAMES["bearing"] and AZEL.name in host.frames
    # its sensor's measurement model declares it: the dimension is checked against the frame's
    model = host.sensor("test-azel").measurement_model()
    assert model.frame == AZEL.name and model.dim == 2
    with pytest.raises(InputError, match="has 2 components, R has 1"):
        MeasurementModel("wrong", _azel, np.eye(1), frame=AZEL.name)
    # the sensor kit draws truths in the frame's declared 3-D space and passes the sensor
    outcomes = {o.check: o for o in run_checks(host.sensor("test-azel"))}
    assert all(o.status == "passed" for o in outcomes.values()), outcomes
    assert "'test-azimuth-elevation' detections of dimension 2, angles in (-pi, pi]" in \
        outcomes["check_frame_respected"].message


def test_a_duplicated_frame_makes_the_later_plugin_broken():
    first = Frame("test-dup", ("u",), ("m",), (False,), "first", 1)
    second = Frame("test-dup", ("u",), ("m",), (False,), "second", 1)
    host = load_host(entry_points=[], extra_plugins=[("a-frames", _plugin(first)), ("b-frames", _plugin(second))])
    assert _status(host, "a-frames").status == "ok"
    b = _status(host, "b-frames")
    assert b.status == "broken"
    assert "frame 'test-dup' is already provided by plugin 'a-frames'" in b.error and "never shadowed" in b.error
    assert host.frame("test-dup") is first and frames.frame("test-dup") is first
    # the same plugin loaded again by another host is fine; another plugin's different definition is not
    again = load_host(entry_points=[], extra_plugins=[("a-frames", _plugin(first))])
    assert _status(again, "a-frames").status == "ok"
    other = load_host(entry_points=[], extra_plugins=[("c-frames", _plugin(second))])
    c = _status(other, "c-frames")
    assert c.status == "broken" and "already defined differently by plugin 'a-frames'" in c.error


def test_a_plugin_cannot_redefine_a_built_in_frame():
    mine = Frame("bearing", ("bearing",), ("rad",), (True,), "clockwise from north", 2)
    host = load_host(entry_points=[], extra_plugins=[("north", _plugin(mine))])
    info = _status(host, "north")
    assert info.status == "broken" and "frame 'bearing' is a built-in frame and cannot be redefined" in info.error
    assert frames.frame("bearing") is BUILTIN_FRAMES["bearing"]


def test_a_frame_hook_returning_something_else_is_broken():
    host = load_host(entry_points=[], extra_plugins=[("junk", _plugin("bearing"))])
    info = _status(host, "junk")
    assert info.status == "broken" and "expected Frame" in info.error
