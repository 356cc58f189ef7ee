"""Range-bearing sensor at the origin (paper 003): one detection of the target per scan.

``z = h(x) + n`` with ``h(x) = [sqrt(x^2 + y^2), atan2(y, x)]`` and ``n = [sigma_r e1, sigma_theta e2]``,
``e ~ N(0, I)`` (the paper's "noise value multiplied by a standard normal value").  The measured
bearing is wrapped to (-pi, pi]; the measured range is left as drawn (it can be negative only when
the target is within a few ``sigma_r`` of the sensor).  The published measurement model is
:func:`workbench.models.range_bearing`.

Shapes: truth ``(B, T, n)`` with ``x, y`` first -> scans ``z (B, T, 1, 2)``, ``valid (B, T, 1)``.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.linalg import wrap_angle
from workbench.models import MeasurementModel, range_bearing
from workbench.params import Param
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth


def measurement_model(sigma_r: float = 1.0, sigma_theta: float = 0.1) -> MeasurementModel:
    """The model filters use: ``R = diag(sigma_r^2, sigma_theta^2)``, bearing angular."""
    return range_bearing(sigma_r, sigma_theta)


def simulate(truth: Truth, rng: np.random.Generator, sigma_r: float = 1.0, sigma_theta: float = 0.1) -> Scans:
    """One noisy range-bearing detection of each truth state; ``origin`` is 0 (the single target)."""
    if sigma_r < 0 or sigma_theta < 0:
        raise InputError(f"range-bearing sensor: sigma_r and sigma_theta must be >= 0, got {sigma_r}, {sigma_theta}")
    states = truth.states
    model = range_bearing(sigma_r, sigma_theta)
    e = rng.standard_normal(states.shape[:2] + (2,))
    # z = h(x) + [sigma_r e1, sigma_theta e2]
    z = model.h(states) + e * np.array([sigma_r, sigma_theta])
    z[..., 1] = wrap_angle(z[..., 1])
    B, T = states.shape[:2]
    return Scans(z[:, :, None, :], np.ones((B, T, 1), dtype=bool), truth.times,
                 origin=np.zeros((B, T, 1), dtype=int))


PARAMETERS = (
    Param("sigma_r", 1.0, "range noise standard deviation", unit="length", minimum=0.0, affects="noise"),
    Param("sigma_theta", 0.1, "bearing noise standard deviation", unit="angle", minimum=0.0, affects="noise"),
)

RANGE_BEARING = SensorSpec(
    name="range-bearing",
    summary="Range and bearing from a sensor at the origin, additive Gaussian noise",
    measurement_model=measurement_model,
    simulate=simulate,
    params={"sigma_r": 1.0, "sigma_theta": 0.1},
    parameters=PARAMETERS,
    frame="range-bearing",
)


@hookimpl
def workbench_sensors():
    return [RANGE_BEARING]
