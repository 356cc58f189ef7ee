"""Bearings-only sensor at a declared position in the plane: one bearing of the target per scan, or a miss.

``z = wrap(h(x) + sigma_theta e)``, ``e ~ N(0, 1)``, with ``h(x) = atan2(y - sy, x - sx)`` (counter-clockwise from
+x, the math convention of the ``range-bearing`` frame), wrapped to (-pi, pi].  Each scan detects the target with
probability ``pd`` (independently); a missed scan is marked invalid.  The detections and the published
measurement model are in the built-in ``bearing`` frame (one angular component, no range, so no position).

The published model (:func:`bearing_model`): ``h`` as above on states ``(..., n)`` with ``x, y`` first, the
Jacobian ``[-dy / r^2, dx / r^2, 0, ...]`` (``dx = x - sx``, ``dy = y - sy``, ``r^2 = dx^2 + dy^2``; undefined at
the sensor itself, ``r = 0``, where it is NaN), ``R = [[sigma_theta^2]]``, ``sensor_position = position``.

Shapes: truth ``(B, T, n)`` with ``x, y`` first -> scans ``z (B, T, 1, 1)``, ``valid (B, T, 1)``, ``origin`` 0.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.linalg import wrap_angle
from workbench.models import MeasurementModel
from workbench.params import Param
from workbench.specs import SensorSpec
from workbench.types import InputError, Scans, Truth

DEFAULTS = {"sigma_theta": 0.01, "pd": 0.9, "position": (0.0, 0.0)}


def _check(sigma_theta, pd, position) -> tuple[float, float]:
    if not (np.isfinite(sigma_theta) and sigma_theta > 0):
        raise InputError(f"bearings-only: sigma_theta must be a finite angle > 0 (rad), got {sigma_theta}")
    if not 0.0 <= pd <= 1.0:
        raise InputError(f"bearings-only: pd must be in [0, 1], got {pd}")
    s = np.asarray(position, dtype=float)
    if s.shape != (2,) or not np.all(np.isfinite(s)):
        raise InputError(f"bearings-only: position must be a finite (x, y) pair in metres, got {position!r}")
    return float(s[0]), float(s[1])


def bearing_jacobian(x: np.ndarray, sensor=(0.0, 0.0)) -> np.ndarray:
    """Jacobian of ``atan2(y - sy, x - sx)`` for states ``(B, n)`` with ``x, y`` first: ``(B, 1, n)``,
    ``[-dy / r^2, dx / r^2, 0, ...]``; NaN where ``r = 0`` (the bearing is undefined at the sensor)."""
    x = np.asarray(x, dtype=float)
    dx = x[:, 0] - sensor[0]
    dy = x[:, 1] - sensor[1]
    r2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(r2 > 0, 1.0 / np.where(r2 > 0, r2, 1.0), np.nan)
    jac = np.zeros((x.shape[0], 1, x.shape[1]))
    jac[:, 0, 0] = -dy * inv
    jac[:, 0, 1] = dx * inv
    return jac


def bearing_model(sigma_theta: float, position=(0.0, 0.0)) -> MeasurementModel:
    """The bearing of a 2-D position from ``position``: ``h(x) = [atan2(dy, dx)]``, ``R = [[sigma_theta^2]]``,
    angular, frame ``bearing``."""
    sx, sy = _check(sigma_theta, 0.0, position)

    def h(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return np.arctan2(x[..., 1] - sy, x[..., 0] - sx)[..., None]

    return MeasurementModel(
        name="bearing",
        h=h,
        R=np.array([[float(sigma_theta) ** 2]]),
        jacobian=lambda x: bearing_jacobian(x, (sx, sy)),
        angular=(True,),
        frame="bearing",
        std=(float(sigma_theta),),
        sensor_position=(sx, sy),
    )


def measurement_model(sigma_theta: float = 0.01, pd: float = 0.9, position=(0.0, 0.0)) -> MeasurementModel:
    """The model filters use (:func:`bearing_model`); ``pd`` shapes only the simulation."""
    _check(sigma_theta, pd, position)
    return bearing_model(sigma_theta, position)


def simulate(truth: Truth, rng: np.random.Generator, sigma_theta: float = 0.01, pd: float = 0.9,
             position=(0.0, 0.0)) -> Scans:
    """One bearing of each truth state, detected with probability ``pd`` (a miss is invalid); ``origin`` 0."""
    _check(sigma_theta, pd, position)
    states = np.asarray(truth.states, dtype=float)
    if states.ndim != 3 or states.shape[-1] < 2:
        raise InputError(f"bearings-only: the truth states must be (B, T, n) with x, y first, got {states.shape}")
    B, T = states.shape[:2]
    detected = rng.random((B, T)) < pd
    e = rng.standard_normal((B, T, 1))
    # z = wrap(atan2(dy, dx) + sigma_theta e)
    z = wrap_angle(bearing_model(sigma_theta, position).h(states) + sigma_theta * e)
    return Scans(z[:, :, None, :], detected[:, :, None], truth.times, origin=np.zeros((B, T, 1), dtype=int))


PARAMETERS = (
    Param("sigma_theta", DEFAULTS["sigma_theta"], "bearing noise standard deviation", unit="angle", above=0.0,
          maximum=np.pi, affects="noise"),
    Param("pd", DEFAULTS["pd"], "probability that the target is detected per scan", unit="dimensionless",
          minimum=0.0, maximum=1.0, affects="simulation"),
    Param("position", DEFAULTS["position"], "sensor position (x, y)", "vector", unit="length", length=2),
)

BEARINGS_ONLY = SensorSpec(
    name="bearings-only",
    summary="Bearing of the target from a sensor at a declared position, Gaussian noise, detection probability pd",
    measurement_model=measurement_model,
    simulate=simulate,
    params=dict(DEFAULTS),
    parameters=PARAMETERS,
    frame="bearing",
)


@hookimpl
def workbench_sensors():
    return [BEARINGS_ONLY]
