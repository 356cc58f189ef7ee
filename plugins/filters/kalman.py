"""Kalman filter (linear) and extended Kalman filter, batch-first.

The state is a :class:`~workbench.types.Gaussian` with ``mean (B, n)`` and ``cov (B, n, n)``.

Predict (both)::

    x- = F x          P- = F P F^T + Q

Update::

    S = H P- H^T + R              innovation covariance
    K = P- H^T S^-1               gain (solved, never inverted)
    x = x- + K wrap(z - h(x-))    residual wraps angular components
    P = (I - K H) P- (I - K H)^T + K R K^T   Joseph form: stays symmetric positive definite

The KF uses the model's ``H``; the EKF linearises ``h`` at ``x-`` with the model's Jacobian.
"""

from __future__ import annotations

import numpy as np

from workbench import hookimpl
from workbench.filtering import keep_where, single_measurement
from workbench.kalman_core import linear_predict
from workbench.linalg import joseph_update, psd_solve, symmetrise
from workbench.models import MeasurementModel, MotionModel
from workbench.specs import FilterSpec
from workbench.types import Gaussian, InputError, Scan


def init(prior: Gaussian, rng=None) -> Gaussian:
    return prior


def predict(state: Gaussian, motion: MotionModel, rng=None) -> Gaussian:
    return linear_predict(state, motion)


def _update(state: Gaussian, scan: Scan, model: MeasurementModel, H: np.ndarray, who: str) -> Gaussian:
    z, present = single_measurement(scan, who)
    if not present.any():
        return state
    P = state.cov
    S = symmetrise(H @ P @ np.swapaxes(H, -1, -2) + model.R)  # S = H P- H^T + R
    PHt = P @ np.swapaxes(H, -1, -2)
    K = np.swapaxes(psd_solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)  # K = P- H^T S^-1
    nu = model.residual(z, model.h(state.mean))  # wrap(z - h(x-))
    mean = state.mean + np.einsum("bij,bj->bi", K, nu)
    cov = joseph_update(P, K, H, model.R)
    return Gaussian(keep_where(present, mean, state.mean), keep_where(present, cov, P))


def kf_update(state: Gaussian, scan: Scan, model: MeasurementModel, rng=None) -> Gaussian:
    if model.H is None:
        raise InputError(f"the Kalman filter needs a linear measurement model; {model.name!r} has no H "
                         "(use the EKF, UKF or CDKF)")
    H = np.broadcast_to(model.H, (state.batch, *model.H.shape))
    return _update(state, scan, model, H, "kf")


def ekf_update(state: Gaussian, scan: Scan, model: MeasurementModel, rng=None) -> Gaussian:
    if model.jacobian is None:
        raise InputError(f"the EKF needs the Jacobian of {model.name!r}, which the sensor does not publish")
    return _update(state, scan, model, model.jacobian(state.mean), "ekf")


def estimate(state: Gaussian) -> Gaussian:
    return state


KF = FilterSpec(
    name="kf",
    summary="Kalman filter (linear models), Joseph-form update",
    init=init, predict=predict, update=kf_update, estimate=estimate,
    capabilities=frozenset({"gaussian", "exact_linear", "linear_only"}),
)

EKF = FilterSpec(
    name="ekf",
    summary="Extended Kalman filter, Jacobian at the prediction, Joseph-form update",
    init=init, predict=predict, update=ekf_update, estimate=estimate,
    capabilities=frozenset({"gaussian", "exact_linear", "needs_jacobian"}),
)


@hookimpl
def workbench_filters():
    return [KF, EKF]
