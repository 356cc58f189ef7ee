"""Converted-measurement Kalman filter with the linearised conversion covariance (CMKF-L, paper 001).

Lerro and Bar-Shalom (1993).  The filter takes range-bearing measurements ``(r, b)`` from a sensor at
``(sx, sy)``, in the **mathematical** bearing convention (angle counter-clockwise from the +x axis,
the convention of :func:`workbench.models.range_bearing`)::

    x = sx + r cos b          y = sy + r sin b

converts each to Cartesian and runs a linear Kalman update with ``H = [I 0]`` and the converted
covariance, linearised at the measurement (eqs 15-17 of paper 001)::

    R11 = sigma_r^2 cos^2 b + r^2 sigma_b^2 sin^2 b
    R22 = sigma_r^2 sin^2 b + r^2 sigma_b^2 cos^2 b
    R12 = (sigma_r^2 - r^2 sigma_b^2) sin b cos b

i.e. ``R_c = A diag(sigma_r^2, sigma_b^2) A^T`` with ``A = d(x, y)/d(r, b) = [[cos b, -r sin b],
[sin b, r cos b]]``.  Where the scan carries each detection's own covariance ``Scan.cov`` (a polar
covariance ``C`` in ``(r, b)``; the ``detection_covariance`` capability), the same linearisation converts it:
``R_c = A C A^T`` (equal to the above for ``C = diag(sigma_r^2, sigma_b^2)``).  (With a compass bearing, ``x = r sin b``, ``y = r cos b``, sin and cos swap; this
plugin does not accept that convention.)  ``sigma_r`` and ``sigma_b`` are read from
the model's declared ``std`` (``sigma_b`` in radians) and the sensor position from its declared
``sensor_position``, as :func:`workbench.models.range_bearing` publishes them.

Predict and update are :func:`workbench.kalman_core.extended_predict` (the linear predict for a linear motion
model; ``f`` and the model's ``jacobian`` for one that overrides ``f``, refused by name without a Jacobian) and
:func:`workbench.kalman_core.linear_update` (the shared linear KF with a per-item ``R``).
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.filtering import single_measurement
from workbench.kalman_core import extended_predict, linear_update
from workbench.models import MeasurementModel, MotionModel, converted_covariance, polar_to_cartesian
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Scan


def _polar_params(model: MeasurementModel) -> tuple[float, float, tuple[float, float]]:
    if model.frame != "range-bearing" or model.std is None:
        raise InputError(f"cmkf-l takes range-bearing measurements only (a model declaring the range-bearing frame "
                         f"and its stated std); got model {model.name!r} in frame {model.frame or 'undeclared'!r}")
    sensor = model.sensor_position if model.sensor_position is not None else (0.0, 0.0)
    return float(model.std[0]), float(model.std[1]), (float(sensor[0]), float(sensor[1]))


def conversion_jacobian(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A = d(x, y)/d(r, b) = [[cos b, -r sin b], [sin b, r cos b]]`` (math bearing), ``(B,) -> (B, 2, 2)``."""
    c, s = np.cos(b), np.sin(b)
    return np.stack([np.stack([c, -r * s], axis=-1), np.stack([s, r * c], axis=-1)], axis=-2)


def init(prior: Gaussian, rng=None) -> Gaussian:
    return prior


def predict(state: Gaussian, motion: MotionModel, rng=None) -> Gaussian:
    return extended_predict(state, motion, "cmkf-l")


def update(state: Gaussian, scan: Scan, model: MeasurementModel, rng=None) -> Gaussian:
    """Convert the (single) range-bearing measurement of each item and run the linear update."""
    sigma_r, sigma_b, sensor = _polar_params(model)
    z, present = single_measurement(scan, "cmkf-l")
    if not present.any():
        return state
    if not np.all(np.isfinite(z[present])):
        item = int(np.argmax(present & ~np.isfinite(z).all(axis=1)))
        raise InputError(f"cmkf-l: batch item {item} has a non-finite (NaN or inf) measurement")
    zc = polar_to_cartesian(z, sensor)
    if scan.cov is None:
        Rc = converted_covariance(z[:, 0], z[:, 1], sigma_r, sigma_b)
    else:  # the detection's own polar covariance C: R_c = A C A^T, A = d(x, y)/d(r, b)
        row = np.argmax(scan.valid, axis=1)
        C = scan.cov[np.arange(scan.batch), row]
        A = conversion_jacobian(z[:, 0], z[:, 1])
        Rc = A @ C @ np.swapaxes(A, -1, -2)
        Rc = 0.5 * (Rc + np.swapaxes(Rc, -1, -2))
        Rc = np.where(present[:, None, None], Rc, np.eye(2))
    n = state.dim
    H = np.zeros((2, n))
    H[0, 0] = H[1, 1] = 1.0  # H = [I 0]: position first in the state
    return linear_update(state, zc, present, H, Rc)


def estimate(state: Gaussian) -> Gaussian:
    return state


CMKF_L = FilterSpec(
    name="cmkf-l",
    summary="Converted-measurement KF, linearised conversion covariance (range-bearing input, math bearing)",
    init=init, predict=predict, update=update, estimate=estimate,
    capabilities=frozenset({"gaussian", "range_bearing_input", "detection_covariance"}),
)


@hookimpl
def workbench_filters():
    return [CMKF_L]
