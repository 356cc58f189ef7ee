"""Kalman-filter steps shared by filter plugins, batch-first.

Plugins may not import each other, so the pieces that more than one Kalman-type filter needs live
here: a linear predict, the KF/EKF update of a scan (:func:`kf_update`, :func:`ekf_update`, which honour a
scan's per-detection covariances), and a linear update in which every batch item has its own measurement
covariance ``R_b`` (a converted-measurement filter builds ``R`` from each item's own range and
bearing).

Predict::

    x- = F x          P- = F P F^T + Q

and, for a motion model that overrides ``f`` (not :attr:`~workbench.models.MotionModel.linear`), the extended
predict (:func:`extended_predict`) with the model's Jacobian ``J = df/dx`` at ``x``::

    x- = f(x)         P- = J P J^T + Q

:func:`linear_predict` refuses such a model by name: no filter reads ``F`` from a model that overrides ``f``.

Update, per item ``b`` with a measurement present::

    S = H P- H^T + R_b            innovation covariance
    K = P- H^T S^-1               gain (solved, never inverted)
    x = x- + K (z - H x-)
    P = (I - K H) P- (I - K H)^T + K R_b K^T      Joseph form

Innovations, on request (``update(state, scan, model, rng, innovations=True)`` returns ``(state, Innovations)``;
the filters that can declare the ``innovations`` capability), per item with a measurement::

    y   = wrap(z - h(x-))              innovation (B, m)
    S   = H P- H^T + R                 its covariance (B, m, m)
    NIS = y^T S^-1 y                   (B,), chi-square with m degrees of freedom for a consistent filter
    log N(z; h(x-), S) = -(NIS + log det S + m log 2 pi) / 2       (B,)

and NaN for an item without one (``Innovations.present`` says which).  These are FilterPy's ``y``, ``S``,
``mahalanobis ** 2`` and ``log_likelihood`` after ``update``.

Shapes
------
state : :class:`~workbench.types.Gaussian` with ``mean (B, n)``, ``cov (B, n, n)``
z : (B, m), present : (B,) bool, H : (m, n), R : (B, m, m)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .filtering import keep_where, single_measurement
from .kernels.backend import BackendRecord, resolve
from .linalg import joseph_update, psd_solve, symmetrise
from .models import MeasurementModel, MotionModel, require_jacobian, require_linear
from .types import Gaussian, InputError, Scan

__all__ = ["cached_angle_mask", "linear_predict", "extended_predict", "linearised", "linear_update", "kalman_update", "kf_update", "ekf_update",
           "measurement_covariance", "last_backend", "backend_counts", "Innovations", "gaussian_innovations"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Innovations:
    """What an update saw, per batch item: the innovation ``y (B, m)``, its covariance ``S (B, m, m)``, the
    normalised innovation squared ``nis = y^T S^-1 y (B,)``, the log-likelihood of the measurement ``(B,)`` and
    ``present (B,)``, whether the item had a measurement (where not, the numbers are NaN).  A time loop asked for
    them (``run(..., innovations=True)``) holds the same fields over the scans, ``(B, T, ...)``.

    For the Kalman family the log-likelihood is the Gaussian ``log N(y; 0, S)``; for an IMM it is the mixture's,
    ``log sum_j cbar_j N(z; z^_j, S_j)``, while ``y`` and ``S`` are the moments of the modes' predicted
    measurements (see ``plugins/filters/imm.py``)."""

    y: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    log_likelihood: np.ndarray
    present: np.ndarray

    #: Every field is batch-first (the filter-state take / join contract of :mod:`workbench.specs`).
    batch_fields: ClassVar[tuple[str, ...]] = ("y", "S", "nis", "log_likelihood", "present")

    @staticmethod
    def absent(batch: int, m: int) -> "Innovations":
        """The record of a scan without a measurement for any item (NaN everywhere, ``present`` all False)."""
        return Innovations(np.full((batch, m), np.nan), np.full((batch, m, m), np.nan), np.full(batch, np.nan),
                           np.full(batch, np.nan), np.zeros(batch, dtype=bool))


def gaussian_innovations(y: np.ndarray, S: np.ndarray, present: np.ndarray) -> Innovations:
    """:class:`Innovations` of innovations ``y (B, m)`` with covariances ``S (B, m, m)`` (symmetric positive
    definite where ``present``): ``nis = y^T S^-1 y`` and ``log N(y; 0, S)`` through a Cholesky factor; NaN where
    not ``present``."""
    y = np.asarray(y, dtype=float)
    S = np.asarray(S, dtype=float)
    present = np.asarray(present, dtype=bool)
    B, m = y.shape
    S_safe = np.where(present[:, None, None], S, np.eye(m))
    y_safe = np.where(present[:, None], y, 0.0)
    L = np.linalg.cholesky(S_safe)
    w = np.linalg.solve(L, y_safe[..., None])[..., 0]  # L w = y: ||w||^2 = y^T S^-1 y
    nis = np.sum(w * w, axis=-1)
    logdet = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    loglik = -0.5 * (nis + logdet + m * _LOG_2PI)
    return Innovations(np.where(present[:, None], y, np.nan), np.where(present[:, None, None], S, np.nan),
                       np.where(present, nis, np.nan), np.where(present, loglik, np.nan), present.copy())


# Every batch takes the compiled item-by-item loops (:mod:`workbench.kernels.kalman_numba`) where the backend
# policy has Numba (5 to 10 times the batched NumPy code per item at any batch size); the batched NumPy code below
# is their reference and the fallback.


_LOOPS: list = []
_RECORD = BackendRecord()  # which code the last linear_predict / kalman_update of this thread ran


def last_backend() -> str | None:
    """Which code computed this thread's last :func:`linear_predict` or :func:`kalman_update`: ``"numba"`` (the
    compiled loops) or ``"numpy"`` (the batched NumPy code, also the fallback where the compiled
    update declines an item); ``None`` before the first call.  For tests, which must know which path ran."""
    return _RECORD.last()


def backend_counts() -> dict:
    """Calls per backend (``{"numba": k, "numpy": m}``) of this thread so far, for the same functions as
    :func:`last_backend`."""
    return _RECORD.counts()


def _compiled():
    """The compiled item-by-item loops, or ``None`` (no Numba on this arch)."""
    if resolve("auto") != "numba":
        return None
    if not _LOOPS:
        from .kernels import kalman_numba

        _LOOPS.append(kalman_numba)
    return _LOOPS[0]


def _present_any(present: np.ndarray) -> bool:
    """``present.any()``, without NumPy's reduction machinery for one item (a tenth of the time at B = 1)."""
    return bool(present[0]) if present.shape[0] == 1 else bool(present.any())


_ANGLES: dict = {}


def cached_angle_mask(model: MeasurementModel) -> np.ndarray:
    """``model.angle_mask``, one shared array per declared ``angular`` tuple (read, never written, by the compiled
    loops): built once instead of at every call of a one-track update."""
    mask = _ANGLES.get(model.angular)
    if mask is None:
        mask = _ANGLES.setdefault(model.angular, np.array(model.angular, dtype=bool))
    return mask


def linear_predict(state: Gaussian, motion: MotionModel, who: str = "kf") -> Gaussian:
    """One step of the linear motion model for every item of the batch; :class:`~workbench.types.InputError`
    naming the filter ``who`` and the model when the model overrides ``f`` (it is not linear)."""
    require_linear(motion, who)
    return _linear_predict(state, motion)


def _linear_predict(state: Gaussian, motion: MotionModel) -> Gaussian:
    """:func:`linear_predict` of a model known to be linear."""
    if (fast := _compiled()) is not None:
        mean, cov = np.empty(state.mean.shape), np.empty(state.cov.shape)
        if fast.predict_items(state.mean, state.cov, np.ascontiguousarray(motion.F, dtype=float),
                              np.ascontiguousarray(motion.Q, dtype=float), mean, cov):
            _RECORD.note("numba")
            return Gaussian.kernel_output(mean, cov)  # float, shapes of `state`, every number checked finite
        # a number that is not finite: the NumPy code below computes it again and Gaussian.trusted names it
    _RECORD.note("numpy")
    mean = state.mean @ motion.F.T  # x- = F x
    cov = symmetrise(motion.F @ state.cov @ motion.F.T + motion.Q)  # P- = F P F^T + Q
    return Gaussian.trusted(mean, cov)


def extended_predict(state: Gaussian, motion: MotionModel, who: str = "ekf") -> Gaussian:
    """The EKF's predict: :func:`linear_predict` (the same code, bit for bit) for a linear model; for a model that
    overrides ``f``, ``x- = f(x)``, ``P- = J P J^T + Q`` with the model's ``jacobian`` at ``x``.  A nonlinear
    model without a Jacobian is refused naming the filter ``who`` and the model."""
    if motion.linear:
        return _linear_predict(state, motion)  # linear_predict, whose one check this is
    mean, J = linearised(state.mean, motion, who)
    _RECORD.note("numpy")
    cov = symmetrise(J @ state.cov @ np.swapaxes(J, -1, -2) + motion.Q)  # P- = J P J^T + Q
    return Gaussian.trusted(mean, cov)


def linearised(mean: np.ndarray, motion: MotionModel, who: str) -> tuple[np.ndarray, np.ndarray]:
    """``f(x) (B, n)`` and the Jacobian ``J (B, n, n)`` of a model that overrides ``f``, at the means ``(B, n)``
    (the EKF-style predicts); the model's Jacobian is required (:func:`~workbench.models.require_jacobian`), and
    :class:`~workbench.types.InputError` names the filter ``who`` and the model when either has another shape."""
    jac = require_jacobian(motion, who)
    B, n = mean.shape
    moved = np.asarray(motion.f(mean), dtype=float)  # x- = f(x)
    J = np.asarray(jac(mean), dtype=float)
    if moved.shape != (B, n) or J.shape != (B, n, n):
        raise InputError(f"filter {who!r}: motion model {motion.name!r} gave f of shape {moved.shape} and a "
                         f"jacobian of shape {J.shape} for states {(B, n)}; expected {(B, n)} and {(B, n, n)}")
    return moved, J


def linear_update(state: Gaussian, z: np.ndarray, present: np.ndarray, H: np.ndarray, R: np.ndarray) -> Gaussian:
    """Kalman update with a linear measurement ``z = H x + v``, ``v ~ N(0, R_b)`` per item.

    Items with ``present[b] == False`` come back unchanged.  ``z`` must be finite where present.

    Shapes: ``z (B, m)``, ``present (B,)``, ``H (m, n)``, ``R (B, m, m)``.
    """
    z = np.asarray(z, dtype=float)
    present = np.asarray(present, dtype=bool)
    R = np.asarray(R, dtype=float)
    H = np.asarray(H, dtype=float)
    B, n = state.mean.shape
    m = H.shape[0]
    if z.shape != (B, m) or present.shape != (B,) or R.shape != (B, m, m) or H.shape != (m, n):
        raise InputError(f"linear_update: expected z {(B, m)}, present {(B,)}, R {(B, m, m)}, H {(m, n)}; "
                         f"got {z.shape}, {present.shape}, {R.shape}, {H.shape}")
    if not present.any():
        return state
    if not np.all(np.isfinite(z[present])) or not np.all(np.isfinite(R[present])):
        item = int(np.argmax(present & ~(np.isfinite(z).all(axis=1) & np.isfinite(R).all(axis=(1, 2)))))
        raise InputError(f"linear_update: batch item {item} has a non-finite measurement or covariance")
    # Absent items use a harmless identity so the batched solve never sees garbage.
    R_safe = np.where(present[:, None, None], R, np.eye(m))
    z_safe = np.where(present[:, None], z, 0.0)
    P = state.cov
    PHt = P @ H.T  # (B, n, m)
    S = symmetrise(H @ PHt + R_safe)  # S = H P- H^T + R
    K = np.swapaxes(psd_solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)  # K = P- H^T S^-1
    nu = z_safe - state.mean @ H.T  # nu = z - H x-
    mean = state.mean + np.einsum("bij,bj->bi", K, nu)
    cov = joseph_update(P, K, H, R_safe)
    return Gaussian.trusted(keep_where(present, mean, state.mean), keep_where(present, cov, P))


def measurement_covariance(scan: Scan, model: MeasurementModel, present: np.ndarray) -> np.ndarray:
    """The noise covariance of each item's measurement: the scan's own ``cov`` of the valid row where the scan
    carries one, else the model's ``R``.  ``(m, m)`` (the model's, shared) or ``(B, m, m)``."""
    if scan.cov is None:
        return model.R
    row = np.argmax(scan.valid, axis=1) if scan.z.shape[1] else np.zeros(scan.batch, dtype=int)
    m = model.dim
    cov = scan.cov[np.arange(scan.batch), row] if scan.z.shape[1] else np.broadcast_to(np.eye(m), (scan.batch, m, m))
    return np.where(present[:, None, None], cov, np.eye(m))


def kalman_update(state: Gaussian, scan: Scan, model: MeasurementModel, H: np.ndarray, who: str,
                  innovations: bool = False):
    """The Kalman update of a scan with at most one valid row per item, linearised as ``H (B, m, n)``::

        S = H P- H^T + R              innovation covariance (R: the detection's own where the scan has one)
        K = P- H^T S^-1               gain (solved, never inverted)
        x = x- + K wrap(z - h(x-))    residual wraps angular components
        P = (I - K H) P- (I - K H)^T + K R K^T   Joseph form

    Items without a measurement come back unchanged.  With ``innovations``, returns ``(state, innovations)``, the
    second an :class:`Innovations`: ``y = wrap(z - h(x-))``, ``S``, NIS and ``log N(y; 0, S)`` of the same update.
    """
    z, present = single_measurement(scan, who)
    B, n = state.mean.shape
    H = np.asarray(H, dtype=float)
    if H.shape != (B, model.dim, n):  # the compiled loops index by it; NumPy would broadcast or fail unnamed
        raise InputError(f"filter {who!r}: measurement model {model.name!r} gave H (its Jacobian) of shape "
                         f"{H.shape} for states {(B, n)}; expected {(B, model.dim, n)}")
    if not _present_any(present):
        return (state, Innovations.absent(state.batch, model.dim)) if innovations else state
    R = measurement_covariance(scan, model, present)
    if innovations:
        nu = model.residual(np.where(present[:, None], z, 0.0), model.h(state.mean))  # wrap(z - h(x-))
        Ht = np.swapaxes(H, -1, -2)
        S = symmetrise(H @ state.cov @ Ht + R)
        return kalman_update(state, scan, model, H, who), gaussian_innovations(nu, S, present)
    if (fast := _compiled()) is not None:
        m = z.shape[1]
        hx = np.ascontiguousarray(model.h(state.mean), dtype=float)
        angular = cached_angle_mask(model)
        if type(model).residual is not MeasurementModel.residual or hx.shape != (B, m) or angular.shape != (m,):
            # the model's own residual (or an h of another shape, which the NumPy code then reports): nu itself,
            # as z with h = 0 and no angle (z - 0 is z exactly)
            z = np.ascontiguousarray(model.residual(z, hx), dtype=float)
            hx, angular = np.zeros((B, m)), np.zeros(m, dtype=bool)
        Rb = np.ascontiguousarray(R if R.ndim == 3 else R[None] if B == 1 else np.broadcast_to(R, (B, *R.shape)),
                                  dtype=float)
        Hc = np.ascontiguousarray(H)
        if not Hc.flags.writeable:  # a model's cached read-only H: one compiled signature (a second costs ~3 s)
            Hc = Hc.copy()
        if z.shape == (B, m) and Hc.shape == (B, m, n) and Rb.shape == (B, m, m):  # the loops index by these
            mean, cov = np.empty(state.mean.shape), np.empty(state.cov.shape)
            if fast.update_items(state.mean, state.cov, np.ascontiguousarray(z, dtype=float), hx, angular, Hc, Rb,
                                 present, mean, cov):
                _RECORD.note("numba")
                return Gaussian.kernel_output(mean, cov)  # shapes of `state`, every number checked finite
        z, _ = single_measurement(scan, who)  # declined: the NumPy code computes it again and names any problem
    _RECORD.note("numpy")
    P = state.cov
    S = symmetrise(H @ P @ np.swapaxes(H, -1, -2) + R)  # S = H P- H^T + R
    PHt = P @ np.swapaxes(H, -1, -2)
    K = np.swapaxes(psd_solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)  # K = P- H^T S^-1
    nu = model.residual(z, model.h(state.mean))  # wrap(z - h(x-))
    mean = state.mean + np.einsum("bij,bj->bi", K, nu)
    cov = joseph_update(P, K, H, R)
    return Gaussian.trusted(keep_where(present, mean, state.mean), keep_where(present, cov, P))


def kf_update(state: Gaussian, scan: Scan, model: MeasurementModel, rng=None, *, innovations: bool = False):
    """The Kalman filter's update (the model's ``H``); with ``innovations``, ``(state, innovations)`` (an
    :class:`Innovations`)."""
    if model.H is None:
        raise InputError(f"the Kalman filter needs a linear measurement model; {model.name!r} has no H "
                         "(use the EKF, UKF or CDKF)")
    H = np.broadcast_to(model.H, (state.batch, *model.H.shape))
    return kalman_update(state, scan, model, H, "kf", innovations)


def ekf_update(state: Gaussian, scan: Scan, model: MeasurementModel, rng=None, *, innovations: bool = False):
    """The extended Kalman filter's update (the model's Jacobian at the prediction); with ``innovations``,
    ``(state, innovations)`` (an :class:`Innovations`)."""
    if model.jacobian is None:
        raise InputError(f"the EKF needs the Jacobian of {model.name!r}, which the sensor does not publish")
    return kalman_update(state, scan, model, model.jacobian(state.mean), "ekf", innovations)
