"""Kalman filter (linear) and extended Kalman filter, batch-first.

The state is a :class:`~workbench.types.Gaussian` with ``mean (B, n)`` and ``cov (B, n, n)``.

Predict (both, for a linear motion model)::

    x- = F x          P- = F P F^T + Q

A motion model that overrides ``f`` (nonlinear): the KF refuses it by name; the EKF predicts ``x- = f(x)``,
``P- = J P J^T + Q`` with the model's ``jacobian`` (:func:`workbench.kalman_core.extended_predict`), and refuses a
model without one by name.

Update::

    S = H P- H^T + R              innovation covariance
    K = P- H^T S^-1               gain (solved, never inverted)
    x = x- + K wrap(z - h(x-))    residual wraps angular components
    P = (I - K H) P- (I - K H)^T + K R K^T   Joseph form: stays symmetric positive definite

The KF uses the model's ``H``; the EKF linearises ``h`` at ``x-`` with the model's Jacobian.  Where a scan
carries each detection's own covariance (``Scan.cov``) it replaces ``R``.  Both declare ``innovations``:
``update(state, scan, model, rng, innovations=True)`` returns ``(state, Innovations)`` with the innovation ``y``,
``S``, NIS and the Gaussian log-likelihood per item (:class:`workbench.kalman_core.Innovations`), and
``run(..., innovations=True)`` collects them over the scans.  The steps are
:mod:`workbench.kalman_core`'s, which other filter plugins share.
"""

from __future__ import annotations


from workbench import hookimpl
from workbench.kalman_core import ekf_update, extended_predict, kf_update, linear_predict
from workbench.specs import FilterSpec
from workbench.types import Gaussian


def init(prior: Gaussian, rng=None) -> Gaussian:
    return prior


def predict(state: Gaussian, motion, rng=None) -> Gaussian:
    return linear_predict(state, motion, "kf")


def ekf_predict(state: Gaussian, motion, rng=None) -> Gaussian:
    return extended_predict(state, motion, "ekf")


def estimate(state: Gaussian) -> Gaussian:
    return state


KF = FilterSpec(
    name="kf",
    summary="Kalman filter (linear models), Joseph-form update",
    init=init, predict=predict, update=kf_update, estimate=estimate,
    capabilities=frozenset({"gaussian", "exact_linear", "linear_only", "detection_covariance", "innovations"}),
)

EKF = FilterSpec(
    name="ekf",
    summary="Extended Kalman filter, Jacobian at the prediction, Joseph-form update",
    init=init, predict=ekf_predict, update=ekf_update, estimate=estimate,
    capabilities=frozenset({"gaussian", "exact_linear", "needs_jacobian", "detection_covariance", "innovations"}),
)


@hookimpl
def workbench_filters():
    return [KF, EKF]
