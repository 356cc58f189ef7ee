"""Linear Kalman-filter steps shared by filter plugins, batch-first.

Plugins may not import each other, so the pieces that more than one Kalman-type filter needs live
here: a linear predict and a linear update in which every batch item has its own measurement
covariance ``R_b`` (a converted-measurement filter builds ``R`` from each item's own range and
bearing).

Predict::

    x- = F x          P- = F P F^T + Q

Update, per item ``b`` with a measurement present::

    S = H P- H^T + R_b            innovation covariance
    K = P- H^T S^-1               gain (solved, never inverted)
    x = x- + K (z - H x-)
    P = (I - K H) P- (I - K H)^T + K R_b K^T      Joseph form

Shapes
------
state : :class:`~workbench.types.Gaussian` with ``mean (B, n)``, ``cov (B, n, n)``
z : (B, m), present : (B,) bool, H : (m, n), R : (B, m, m)
"""

from __future__ import annotations

import numpy as np

from .filtering import keep_where
from .linalg import joseph_update, psd_solve, symmetrise
from .models import MotionModel
from .types import Gaussian, InputError

__all__ = ["linear_predict", "linear_update"]


def linear_predict(state: Gaussian, motion: MotionModel) -> Gaussian:
    """One step of the linear motion model for every item of the batch."""
    mean = state.mean @ motion.F.T  # x- = F x
    cov = symmetrise(motion.F @ state.cov @ motion.F.T + motion.Q)  # P- = F P F^T + Q
    return Gaussian(mean, cov)


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
    return Gaussian(keep_where(present, mean, state.mean), keep_where(present, cov, P))
