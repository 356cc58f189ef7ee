"""Every built-in sensor, found through the host: detections and published model agree.

For each sensor, on a noise-free-looking check: the measurement model's ``h`` applied to the truth is
the centre of the sensor's target detections (their mean residual over many runs is near zero, with
angles wrapped), the detections carry the target's origin label, the same seed gives the same
detections, and the model's ``R`` matches the spread of the detections it describes.
"""

import numpy as np
import pytest

from workbench.sensing.bistatic import range_and_rate
from workbench.plugins import load_host
from workbench.rng import generator
from workbench.trajectory import Leg, piecewise_trajectory
from workbench.types import Truth

HOST = load_host()
BUILTIN = sorted(n for n in HOST.components["workbench_sensors"]
                 if HOST.plugin_of("workbench_sensors", n).distribution == "workbench")


def _truth(name: str, runs: int) -> Truth:
    """A short straight path in the state layout the sensor expects, repeated over runs."""
    if name == "lband-radar":
        one = piecewise_trajectory([40e3, 2e3, 3e3], [-200.0, 0.0, 0.0], [Leg("straight", 10.0)], 1.0)
    elif name == "dtv-pbr":
        one = piecewise_trajectory([250.0, 150.0, 60.0], [6.0, 2.0, 0.0], [Leg("straight", 10.0)], 0.5)
    else:
        one = piecewise_trajectory([100.0, 100.0], [4.0, 2.0], [Leg("straight", 10.0)], 1.0)
    return Truth(np.repeat(one.states, runs, axis=0), one.times)


def _model(name: str):
    spec = HOST.sensor(name)
    # the sonar publishes a polar and a Cartesian view; the detections are Cartesian positions
    return spec.measurement_model(**({"frame": "cartesian"} if name == "active-sonar" else {}))


@pytest.mark.parametrize("name", BUILTIN)
def test_detections_are_centred_on_the_published_model(name):
    truth = _truth(name, 400)
    scans = HOST.sensor(name).simulate(truth, generator(3, "sensor", name))
    model = _model(name)
    assert scans.z.shape[:2] == truth.states.shape[:2] and scans.z.shape[-1] == model.dim
    target = scans.valid & (scans.origin == 0)
    assert target.mean() > 0.05, "the sensor detects the target almost never on an easy path"
    states = truth.states
    if name == "dtv-pbr":  # the filters' state is [bistatic range, range-rate], not the 3-D truth
        params = HOST.sensor(name).params
        states = range_and_rate(truth.states, params["tx"], params["rx"])
    expected = model.h(states)[:, :, None, :]
    residual = model.residual(scans.z, np.broadcast_to(expected, scans.z.shape))[target]
    spread = np.sqrt(np.diag(model.R)) if np.all(np.diag(model.R) > 0) else residual.std(axis=0)
    # unbiased: the mean residual is within 5 standard errors of zero in every component
    assert np.all(np.abs(residual.mean(axis=0)) < 5 * spread / np.sqrt(len(residual)) + 1e-9), residual.mean(axis=0)


@pytest.mark.parametrize("name", BUILTIN)
def test_same_seed_same_detections(name):
    truth = _truth(name, 3)
    a = HOST.sensor(name).simulate(truth, generator(5, name))
    b = HOST.sensor(name).simulate(truth, generator(5, name))
    assert np.array_equal(a.z, b.z) and np.array_equal(a.valid, b.valid)
    assert a.origin is not None and set(np.unique(a.origin[a.valid])) <= {0}
