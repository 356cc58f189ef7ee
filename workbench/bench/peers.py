"""Peer libraries' filters built on the workbench's models, for the benchmarks' same-run comparisons.

:func:`filterpy_range_bearing_ukf`: FilterPy's ``UnscentedKalmanFilter`` for a linear motion model and a planar
range-bearing measurement model with the sensor at the origin, given what our UKF is given: the same ``F``, ``Q``,
``R`` and sigma-point parameters, a wrapped bearing residual and an angle-aware measurement mean (as
:meth:`workbench.models.MeasurementModel.mean`), so that the two filters compute the same estimates and a timing
ratio compares like with like.  FilterPy is an optional extra (``bench``); importing this module does not need it.
"""

from __future__ import annotations

import math

import numpy as np

from ..linalg import wrap_angle

__all__ = ["filterpy_range_bearing_ukf"]


def filterpy_range_bearing_ukf(mean, cov, motion, model, alpha: float, beta: float, kappa: float):
    """A FilterPy UKF at prior ``mean (n,)``, ``cov (n, n)`` for ``motion`` (``F``, ``Q``, ``dt``) and the range-bearing
    ``model`` (``R``; the sensor at the origin), with the sigma points of ``(alpha, beta, kappa)``; its first
    update may come before any predict.  Raises ``ValueError`` for a sensor elsewhere than the origin."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    if tuple(model.sensor_position or (0.0, 0.0)) != (0.0, 0.0):
        raise ValueError("the FilterPy comparison assumes the sensor at the origin")

    def residual_z(a, b):
        d = np.subtract(a, b)
        d[1] = wrap_angle(d[1])
        return d

    def z_mean(sigmas, wm):
        # y_0 + sum w wrap(y_i - y_0) for the bearing, as MeasurementModel.mean
        ref = sigmas[0, 1]
        return np.array([wm @ sigmas[:, 0], wrap_angle(ref + wm @ wrap_angle(sigmas[:, 1] - ref))])

    def hx(x):  # range and bearing from the origin for one state, without array overhead
        return np.array([math.hypot(x[0], x[1]), math.atan2(x[1], x[0])])

    F = np.asarray(motion.F)
    points = MerweScaledSigmaPoints(motion.dim, alpha=alpha, beta=beta, kappa=kappa)
    ukf = UnscentedKalmanFilter(motion.dim, model.dim, motion.dt, hx=hx, fx=lambda x, dt: F @ x, points=points,
                                z_mean_fn=z_mean, residual_z=residual_z)
    ukf.x = np.array(mean, dtype=float)
    ukf.P = np.array(cov, dtype=float)
    ukf.Q = np.array(motion.Q, dtype=float)
    ukf.R = np.array(model.R, dtype=float)
    ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # the first update comes before any predict
    return ukf
